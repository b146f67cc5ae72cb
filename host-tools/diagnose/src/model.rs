//! The model side of the diagnosis: the nominal simulator plus candidate
//! effects, read by the same feature extractor as the measurement.

use super::features::{summarize, Extractor, Signals, N_FEATURES};
pub use super::report::Candidate;
use hammer_sim::effects::Effects;
use hammer_sim::run::{output_len, run_model, TruthSample, TruthSink, TruthTrace};
use hammer_sim::{simulate_truth, SimConfig};

/// E[u²] of the zero-shift magnitude factor u ~ U(0.5, 1.5) (`sim::sensor`).
pub const ZERO_SHIFT_SQ_FACTOR: f64 = 1.0 + 1.0 / 12.0;

/// The nominal parameters a modeller knows only to a few percent (calibrated
/// or estimated in docs/model.md): the diagnosis lets each of them move
/// within a Gaussian prior rather than blame an effect for what they explain.
/// Mass and piston areas are not among them: they are measured.
pub const NUISANCE: [(&str, fn(&mut SimConfig) -> &mut f64); 9] = [
    ("valve.full_open_area_m2", |c| &mut c.valve.full_open_area_m2),
    ("valve.cd", |c| &mut c.valve.cd),
    ("valve.damping_n_s_per_m", |c| &mut c.valve.damping_n_s_per_m),
    ("valve.pilot_area_rear_m2", |c| &mut c.valve.pilot_area_rear_m2),
    ("valve.pilot_area_front_m2", |c| &mut c.valve.pilot_area_front_m2),
    ("hammer.outlet_cd", |c| &mut c.hammer.outlet_cd),
    ("hammer.rear_dead_volume_m3", |c| &mut c.hammer.rear_dead_volume_m3),
    ("hammer.front_dead_volume_m3", |c| &mut c.hammer.front_dead_volume_m3),
    ("contact.restitution", |c| &mut c.contact.restitution),
];

/// How a candidate's sensor effects read a model: the factors on the
/// pressure readings and the expected shift of the mean features (what
/// the extractor cannot see in a noiseless solution). The catalogue's
/// diagnosis hooks supply it ([`crate::effects`]), so the model imports no
/// effect, and the effects, which read the fit set and run the model, sit
/// above it.
pub trait SensorReads: Sync + std::fmt::Debug {
    fn pressure_reading_factors(&self, effects: &Effects) -> (f64, f64);
    fn shift_expected_features(&self, effects: &Effects, mean: &mut [f64]);
}

/// The model's runs are averaged over the cycles after this: its start-up
/// (from rest, the chambers at ambient) has settled by then. A truth read
/// off a run to compare with the model's leaves out the same start.
pub const SETTLE_S: f64 = 0.27;

/// Runs the model at operating points and reads it like a measurement
/// (`ModelRunner::new`, in [`crate::effects`], reads it through the
/// catalogue's sensor effects).
#[derive(Debug, Clone)]
pub struct ModelRunner {
    pub base: SimConfig,
    pub extractor: Extractor,
    /// How the candidate's sensor effects read the model.
    pub reads: &'static dyn SensorReads,
    /// Simulated time per run; the cycles after `settle_s` are averaged.
    pub duration_s: f64,
    pub settle_s: f64,
}

impl ModelRunner {
    pub fn config(&self, supply_bar: f64, effects: &Effects) -> SimConfig {
        let mut c = self.base.clone();
        c.supply.pressure_bar = supply_bar;
        c.solver.duration_s = self.duration_s;
        c.effects = effects.clone();
        c
    }

    /// The ideal (noiseless) solution of the physical part of a candidate.
    pub fn truth(&self, supply_bar: f64, cand: &Candidate) -> Option<TruthTrace> {
        simulate_truth(&self.config(supply_bar, &cand.physics()))
            .ok()
            .map(|r| r.truth)
    }

    /// Mean steady features of the candidate at `supply_bar`; `nominal_truth`
    /// is reused when the candidate has no physical effect. A run of its
    /// own keeps only the three signals the extractor reads.
    pub fn features(&self, supply_bar: f64, cand: &Candidate, nominal_truth: Option<&TruthTrace>) -> Option<Vec<f64>> {
        if let Some(t) = nominal_truth.filter(|_| !cand.has_physics()) {
            return self.features_of_truth(t, &cand.effects, supply_bar);
        }
        let cfg = self.config(supply_bar, &cand.physics());
        let mut read = Measured::with_capacity(output_len(&cfg));
        run_model(&cfg, &mut read).ok()?;
        let Measured {
            mut p_rear_pa,
            mut p_front_pa,
            accel_mps2,
        } = read;
        if !self.reads_as_is(&cand.effects) {
            self.read_pressures(&cand.effects, &mut p_rear_pa, &mut p_front_pa);
        }
        self.features_of(
            cfg.solver.output_step_s,
            &p_rear_pa,
            &p_front_pa,
            &accel_mps2,
            &cand.effects,
            supply_bar,
        )
    }

    /// Whether the measurement's transducers read the model's pressures as
    /// they are (no gain effect, no floor): then they need no copy.
    fn reads_as_is(&self, effects: &Effects) -> bool {
        self.reads.pressure_reading_factors(effects) == (1.0, 1.0)
            && self.extractor.pressure_floor_pa.iter().all(|f| !f.is_finite())
    }

    /// A model's pressures as the measurement's transducers read them: the
    /// candidate's sensor gains, then the transducers' floor. Every model
    /// signal compared with the measurement goes through here.
    pub fn read_pressures(&self, effects: &Effects, p_rear_pa: &mut [f64], p_front_pa: &mut [f64]) {
        let (f1, f2) = self.reads.pressure_reading_factors(effects);
        let [floor1, floor2] = self.extractor.pressure_floor_pa;
        p_rear_pa.iter_mut().for_each(|p| *p = (*p * f1).max(floor1));
        p_front_pa.iter_mut().for_each(|p| *p = (*p * f2).max(floor2));
    }

    /// Features of a simulated solution at `supply_bar` seen through the
    /// candidate's sensor effects.
    pub fn features_of_truth(&self, truth: &TruthTrace, effects: &Effects, supply_bar: f64) -> Option<Vec<f64>> {
        let mut read;
        let (p1, p2): (&[f64], &[f64]) = if self.reads_as_is(effects) {
            (&truth.p_rear_pa, &truth.p_front_pa)
        } else {
            read = (truth.p_rear_pa.clone(), truth.p_front_pa.clone());
            self.read_pressures(effects, &mut read.0, &mut read.1);
            (&read.0, &read.1)
        };
        self.features_of(truth.dt_s, p1, p2, &truth.accel_mps2, effects, supply_bar)
    }

    /// Mean steady features of pressures already read by the transducers.
    fn features_of(
        &self,
        dt_s: f64,
        p1: &[f64],
        p2: &[f64],
        accel_mps2: &[f64],
        effects: &Effects,
        supply_bar: f64,
    ) -> Option<Vec<f64>> {
        let s = Signals {
            dt_s,
            p_rear_pa: p1,
            p_front_pa: p2,
            accel_mps2,
            supply_pa: supply_bar * 1e5,
        };
        let cycles = self.extractor.cycles_from(&s, self.settle_s);
        if cycles.is_empty() {
            return None;
        }
        let mut mean = summarize(&cycles).mean;
        self.reads.shift_expected_features(effects, &mut mean);
        debug_assert_eq!(mean.len(), N_FEATURES);
        Some(mean)
    }
}

/// A model run's signals as the extractor reads them, and nothing else: a
/// candidate's run is read once, for its features (a third of the stores
/// a whole truth trace makes).
struct Measured {
    p_rear_pa: Vec<f64>,
    p_front_pa: Vec<f64>,
    accel_mps2: Vec<f64>,
}

impl Measured {
    fn with_capacity(n: usize) -> Self {
        Self {
            p_rear_pa: Vec::with_capacity(n),
            p_front_pa: Vec::with_capacity(n),
            accel_mps2: Vec::with_capacity(n),
        }
    }
}

impl TruthSink for Measured {
    type Error = std::convert::Infallible;
    fn sample(&mut self, s: &TruthSample) -> Result<(), Self::Error> {
        self.p_rear_pa.push(s.p_rear_pa);
        self.p_front_pa.push(s.p_front_pa);
        self.accel_mps2.push(s.accel_mps2);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pipeline::tests::nominal_runner;

    /// A candidate's own run, which keeps only the three signals read, gives
    /// the features of its whole truth trace to the bit, through a sensor
    /// gain too.
    #[test]
    fn a_candidates_own_run_reads_as_its_truth_does() {
        let runner = nominal_runner();
        for spec in ["leakage", "valve_delay", "pressure_gain_error:rear=0.03"] {
            let mut cand = Candidate::default();
            cand.effects.apply_spec("heat_transfer").unwrap();
            cand.effects.apply_spec(spec).unwrap();
            let lean = runner.features(5.0, &cand, None).expect("the model runs");
            let truth = runner.truth(5.0, &cand).expect("the model runs");
            let whole = runner.features_of_truth(&truth, &cand.effects, 5.0).expect("read");
            let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&lean), bits(&whole), "{spec}");
        }
    }
}
