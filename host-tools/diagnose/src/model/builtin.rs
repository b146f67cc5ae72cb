//! The built-in simulator as a [`Plant`]: the paper's hammer (`hammer-sim`)
//! with the catalogue's effects in its equations.

use super::plant::{Impact, Keep, ModelTrace, Motion, NuisanceParam, Plant};
use hammer_sim::effects::Effects;
use hammer_sim::run::{output_len, run_model, SimRun, TruthSample, TruthSink};
use hammer_sim::{simulate_truth, SimConfig};

pub use hammer_sim::params::NUISANCE;

/// The built-in model of `base` (its geometry, nominal values and solver).
#[derive(Debug, Clone)]
pub struct Builtin {
    base: SimConfig,
    nuisance: Vec<NuisanceParam>,
}

impl Builtin {
    pub fn new(base: SimConfig) -> Self {
        let mut probe = base.clone();
        let nuisance = NUISANCE
            .iter()
            .map(|(name, field)| NuisanceParam {
                name: name.to_string(),
                nominal: *field(&mut probe),
                relative_uncertainty: None,
            })
            .collect();
        Self { base, nuisance }
    }

    pub fn base(&self) -> &SimConfig {
        &self.base
    }

    /// The config of one run: `base` at `supply_bar` for `duration_s`, the
    /// nuisance parameters at `nuisance`, `effects` on. A value equal to
    /// the nominal one leaves the field's bits as they were.
    pub fn config(&self, supply_bar: f64, nuisance: &[f64], effects: &Effects, duration_s: f64) -> SimConfig {
        let mut c = self.base.clone();
        c.supply.pressure_bar = supply_bar;
        c.solver.duration_s = duration_s;
        c.effects = effects.clone();
        for ((_, field), v) in NUISANCE.iter().zip(nuisance) {
            *field(&mut c) = *v;
        }
        c
    }
}

impl Plant for Builtin {
    fn nuisance(&self) -> &[NuisanceParam] {
        &self.nuisance
    }

    fn carries(&self, name: &str) -> bool {
        hammer_sim::effects::entry(name).is_some()
    }

    fn run(
        &self,
        supply_bar: f64,
        nuisance: &[f64],
        effects: &Effects,
        duration_s: f64,
        keep: Keep,
    ) -> Result<ModelTrace, String> {
        let cfg = self.config(supply_bar, nuisance, effects, duration_s);
        match keep {
            Keep::Signals => {
                let mut read = Signals::with_capacity(output_len(&cfg));
                run_model(&cfg, &mut read).map_err(|e| e.to_string())?;
                Ok(ModelTrace {
                    dt_s: cfg.solver.output_step_s,
                    p_rear_pa: read.p_rear_pa,
                    p_front_pa: read.p_front_pa,
                    accel_mps2: read.accel_mps2,
                    motion: None,
                    impacts: Vec::new(),
                })
            }
            Keep::All => simulate_truth(&cfg).map(ModelTrace::from).map_err(|e| e.to_string()),
        }
    }
}

impl From<SimRun> for ModelTrace {
    /// A built-in run as the diagnosis reads any model's.
    fn from(run: SimRun) -> Self {
        let t = run.truth;
        ModelTrace {
            dt_s: t.dt_s,
            p_rear_pa: t.p_rear_pa,
            p_front_pa: t.p_front_pa,
            accel_mps2: t.accel_mps2,
            motion: Some(Motion {
                x_m: t.x_m,
                v_mps: t.v_mps,
            }),
            impacts: run
                .cycles
                .iter()
                .map(|c| Impact {
                    t_impact_s: c.t_impact_s,
                    period_s: c.period_s,
                })
                .collect(),
        }
    }
}

/// A run's signals as the extractor reads them, and nothing else: a
/// candidate's run is read once, for its features (a third of the stores
/// a whole truth trace makes).
struct Signals {
    p_rear_pa: Vec<f64>,
    p_front_pa: Vec<f64>,
    accel_mps2: Vec<f64>,
}

impl Signals {
    fn with_capacity(n: usize) -> Self {
        Self {
            p_rear_pa: Vec::with_capacity(n),
            p_front_pa: Vec::with_capacity(n),
            accel_mps2: Vec::with_capacity(n),
        }
    }
}

impl TruthSink for Signals {
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

    /// At its nominal values the built-in plant runs `base` itself: the
    /// config it builds is the old path's to the bit.
    #[test]
    fn nominal_values_leave_the_config_as_it_was() {
        let base = SimConfig::default();
        let b = Builtin::new(base.clone());
        let nominal: Vec<f64> = b.nuisance().iter().map(|p| p.nominal).collect();
        let c = b.config(5.0, &nominal, &Effects::default(), 0.45);
        let mut old = base.clone();
        old.supply.pressure_bar = 5.0;
        old.solver.duration_s = 0.45;
        assert_eq!(serde_json::to_string(&c).unwrap(), serde_json::to_string(&old).unwrap());
        let mut moved = nominal.clone();
        moved[1] *= 1.2;
        let c = b.config(5.0, &moved, &Effects::default(), 0.45);
        assert_eq!(c.valve.cd.to_bits(), (base.valve.cd * 1.2).to_bits());
    }
}
