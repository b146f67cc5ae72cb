//! The model side of the diagnosis: a plant plus candidate effects, read by
//! the same feature extractor as the measurement.
//!
//! Module map:
//! - [`plant`]: the seam, [`Plant`]: what the diagnosis asks of any model
//!   (run at a point with nuisance values and effects; name its nuisance
//!   parameters and the effects it carries) and the [`ModelTrace`] it returns;
//! - [`builtin`]: the built-in simulator behind that seam;
//! - [`fmu`]: a user's FMU behind it, through its model map (issue 46);
//! - [`memo`]: any plant, its runs remembered within one diagnosis;
//! - [`pinned`]: any plant, the nuisance parameters it did not respond to
//!   held at nominal;
//! - here, [`ModelRunner`]: a plant at given nuisance values, read like a
//!   measurement (sensor effects, transducer floors, features).

use std::sync::Arc;

use super::features::{summarize, Extractor, Signals, N_FEATURES};
pub use super::report::Candidate;
use hammer_sim::effects::Effects;
use hammer_sim::params::HammerParams;

pub mod builtin;
pub mod fmu;
pub mod memo;
pub mod pinned;
pub mod plant;

pub use builtin::{Builtin, NUISANCE};
pub use fmu::FmuPlant;
pub use memo::{Memo, MEMO_BYTES};
pub use pinned::Pinned;
pub use plant::{Impact, Keep, ModelTrace, Motion, NuisanceParam, Plant};

/// E[u²] of the zero-shift magnitude factor u ~ U(0.5, 1.5) (`sim::sensor`).
pub const ZERO_SHIFT_SQ_FACTOR: f64 = 1.0 + 1.0 / 12.0;

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
    pub plant: Arc<dyn Plant>,
    /// The nuisance parameters' values this runner runs the plant at (its
    /// nominal ones, or where a recalibration moved them).
    pub nuisance: Vec<f64>,
    /// The measured hammer's geometry: what the stages are read with.
    pub hammer: HammerParams,
    pub extractor: Extractor,
    /// How the candidate's sensor effects read the model.
    pub reads: &'static dyn SensorReads,
    /// Simulated time per run; the cycles after `settle_s` are averaged.
    pub duration_s: f64,
    pub settle_s: f64,
}

impl ModelRunner {
    /// One run of the plant at `supply_bar` with `effects`' physics.
    pub fn run(&self, supply_bar: f64, effects: &Effects, keep: Keep) -> Result<ModelTrace, String> {
        self.plant
            .run(supply_bar, &self.nuisance, &effects.physics(), self.duration_s, keep)
    }

    /// Each nuisance parameter's prior relative standard deviation: the
    /// plant's own, or `h` (the diagnosis' `nominal_uncertainty`).
    pub fn prior_sds(&self, h: f64) -> Vec<f64> {
        self.plant
            .nuisance()
            .iter()
            .map(|p| p.relative_uncertainty.unwrap_or(h))
            .collect()
    }

    /// This runner with nuisance parameter `k` at `factor` × its value.
    pub fn moved(&self, k: usize, factor: f64) -> Self {
        let mut r = self.clone();
        r.nuisance[k] *= factor;
        r
    }

    /// The ideal (noiseless) solution of the physical part of a candidate,
    /// with everything the plant offers.
    pub fn truth(&self, supply_bar: f64, cand: &Candidate) -> Option<ModelTrace> {
        self.run(supply_bar, &cand.effects, Keep::All).ok()
    }

    /// Mean steady features of the candidate at `supply_bar`; `nominal_truth`
    /// is reused when the candidate has no physical effect. A run of its
    /// own keeps only the three signals the extractor reads.
    pub fn features(&self, supply_bar: f64, cand: &Candidate, nominal_truth: Option<&ModelTrace>) -> Option<Vec<f64>> {
        if let Some(t) = nominal_truth.filter(|_| !cand.has_physics()) {
            return self.features_of_truth(t, &cand.effects, supply_bar);
        }
        let ModelTrace {
            dt_s,
            mut p_rear_pa,
            mut p_front_pa,
            accel_mps2,
            ..
        } = self.run(supply_bar, &cand.effects, Keep::Signals).ok()?;
        if !self.reads_as_is(&cand.effects) {
            self.read_pressures(&cand.effects, &mut p_rear_pa, &mut p_front_pa);
        }
        self.features_of(dt_s, &p_rear_pa, &p_front_pa, &accel_mps2, &cand.effects, supply_bar)
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
    pub fn features_of_truth(&self, truth: &ModelTrace, effects: &Effects, supply_bar: f64) -> Option<Vec<f64>> {
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
