//! The diagnosis as a pipeline of named stages, each a function of the one
//! before's result (see [`crate`] for the map):
//!
//! 1. [`group`]: inputs → operating points, cycles split into fit and held out;
//!    [`reference`] (with reference records): each point read as a change
//!    from the same hammer's earlier record, moved onto the nominal model;
//! 2. [`nominal`]: the nominal model at every point → the fit set;
//!    [`force_balance`]: what the force balance measures at every point;
//! 3. [`rank`]: every effect fitted ([`effect_fit`]) and ranked → the verdict;
//!    [`confirm`] (against the model alone): an effect the waveforms alone
//!    named, checked with the nominal values refitted on the model itself;
//!    [`floor`]: how large each unseen effect must be to be named here;
//!    [`oracle`] (benchmarks only): whether the hammer's truth itself would
//!    pass the confirm stage's rule;
//!    [`part`] (against a record): a close call of the change that the
//!    model alone's verdict on the same traces parts;
//! 4. [`held_out`]: the verdict's model against the held-out data → the shrink;
//! 5. [`where_`]: the gap and its remainder by signal × stage → where to look.
//!
//! [`crate::engine::diagnose`] runs them in this order and
//! assembles the report; a stage's unit test runs it alone.

pub(crate) mod confirm;
pub(crate) mod effect_fit;
pub(crate) mod floor;
pub(crate) mod force_balance;
pub(crate) mod group;
pub(crate) mod held_out;
pub(crate) mod joint;
pub(crate) mod nominal;
pub(crate) mod oracle;
pub(crate) mod part;
pub(crate) mod rank;
pub(crate) mod reference;
pub(crate) mod rerank;
pub(crate) mod where_;

#[cfg(test)]
pub(crate) mod tests {
    use crate::features::extractor_for;
    use crate::input::MeasuredInput;
    use crate::model::ModelRunner;
    use crate::options::Options;
    use hammer_sim::simulate::simulate;
    use hammer_sim::SimConfig;

    /// A short simulated measurement of the nominal hammer at `bar`.
    pub(crate) fn measured(bar: f64, fit: bool) -> MeasuredInput {
        let mut c = SimConfig::nominal(bar);
        c.solver.duration_s = 0.4;
        c.seed = 3;
        let sim = simulate(&c).unwrap();
        MeasuredInput {
            label: format!("nominal at {bar} bar"),
            supply_bar: bar,
            trace: sim.trace(),
            fit,
        }
    }

    /// The default hammer at 4 and 7 bar (both fitted), 0.4 s each,
    /// changed by `change`.
    pub(crate) fn hammer_at_4_and_7(change: &dyn Fn(&mut SimConfig)) -> Vec<MeasuredInput> {
        [4.0, 7.0]
            .iter()
            .map(|&bar| {
                let mut c = SimConfig::nominal(bar);
                c.solver.duration_s = 0.4;
                c.seed = 3;
                change(&mut c);
                MeasuredInput {
                    label: format!("{bar} bar"),
                    supply_bar: bar,
                    trace: simulate(&c).unwrap().trace(),
                    fit: true,
                }
            })
            .collect()
    }

    /// The diagnosis' model of the default hammer, as the engine builds it.
    pub(crate) fn nominal_runner() -> ModelRunner {
        let base = SimConfig::default();
        ModelRunner::new(base.clone(), extractor_for(&base))
    }

    /// The options a stage's test runs with: two threads, no figures.
    pub(crate) fn options() -> Options {
        Options {
            figures: false,
            threads: 2,
            ..Options::default()
        }
    }

    /// A progress callback that reports nothing.
    pub(crate) fn quiet(_: &str) {}
}
