use super::{between, pooled_size, rel, Diagnosed};
use crate::fitset::FitSet;
use crate::features::{GAIN_FRONT, GAIN_REAR};
use crate::fit::ParamSpec;
use hammer_sim::effects::PressureGainError;
use hammer_sim::sensor::Rng;

impl Diagnosed for PressureGainError {
    fn free_params(_distinct_pressures: usize) -> Vec<ParamSpec> {
        let p = |key, lo, hi, log, step| ParamSpec { key, lo, hi, log, step };
        vec![p("rear", -0.3, 0.3, false, 1e-3), p("front", -0.3, 0.3, false, 1e-3)]
    }

    fn from_fit(theta: &[f64], _pressures: (f64, f64)) -> Self {
        PressureGainError {
            rear: theta[0],
            front: theta[1],
        }
    }

    fn start_values(fs: &FitSet, _specs: &[ParamSpec]) -> Vec<f64> {
        vec![fs.avg(GAIN_REAR), fs.avg(GAIN_FRONT)]
    }

    /// The clearer of the two channels' gains, either sign.
    fn model_free_z(fs: &FitSet) -> Option<f64> {
        let z = |j| fs.off_nominal_z(j).map_or(0.0, f64::abs);
        Some(z(GAIN_REAR).max(z(GAIN_FRONT)))
    }

    /// γ of each channel: the force balance's share of the chamber force
    /// that a reading factor of (1 + γ) adds.
    fn force_balance_reading(change: &dyn Fn(usize) -> (f64, f64)) -> Vec<(&'static str, f64, f64)> {
        let (r, sr) = change(GAIN_REAR);
        let (f, sf) = change(GAIN_FRONT);
        vec![("rear", r, sr), ("front", f, sf)]
    }

    /// Both channels' γ, pooled over the fit points (within 1 % of the
    /// truth where the waveforms' fit, against a record, was 6.5–67 % off).
    fn measured_size(fs: &FitSet) -> Option<(Vec<f64>, Vec<f64>)> {
        pooled_size::<Self>(fs)
    }

    /// The clearer channel names it: the floor of the smaller error.
    fn model_free_floor(fs: &FitSet, z_min: f64) -> Option<(&'static str, f64)> {
        let se = fs.mean_se(GAIN_REAR).1.min(fs.mean_se(GAIN_FRONT).1);
        (se > 0.0).then(|| ("gain", z_min * se))
    }

    fn evidence(fs: &FitSet) -> Option<String> {
        let (g1, s1) = fs.mean_se(GAIN_REAR);
        let (g2, s2) = fs.mean_se(GAIN_FRONT);
        Some(format!(
            "force balance: a force proportional to the chamber forces, rear {g1:+.4} ± {s1:.4}, front {g2:+.4} ± {s2:.4}, that does not flip with the direction of motion"
        ))
    }

    fn pressure_reading_factors(&self) -> (f64, f64) {
        (1.0 + self.rear, 1.0 + self.front)
    }

    fn draw(rng: &mut Rng) -> Self {
        let mut g = || {
            let s = if rng.next_u64() & 1 == 0 { 1.0 } else { -1.0 };
            s * between(rng, 0.01, 0.05)
        };
        PressureGainError { rear: g(), front: g() }
    }

    /// The worse of the two gains.
    fn magnitude_error(truth: &Self, fitted: &Self, _points: &[f64]) -> f64 {
        rel(fitted.rear, truth.rear).max(rel(fitted.front, truth.front))
    }
}
