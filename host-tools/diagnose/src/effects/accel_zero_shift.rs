use super::{between, pooled, rel, Diagnosed};
use crate::fitset::FitSet;
use crate::features::ZERO_SHIFT_SQ;
use crate::fit::ParamSpec;
use crate::model::ZERO_SHIFT_SQ_FACTOR;
use hammer_sim::effects::{AccelZeroShift, Effects};
use hammer_sim::sensor::Rng;

/// Fits the amplitude; the discharge time constant keeps its default.
impl Diagnosed for AccelZeroShift {
    fn free_params(_distinct_pressures: usize) -> Vec<ParamSpec> {
        vec![ParamSpec {
            key: "amplitude_mps2",
            lo: 0.0,
            hi: 1e3,
            log: false,
            step: 0.1,
        }]
    }

    fn from_fit(theta: &[f64], _pressures: (f64, f64)) -> Self {
        AccelZeroShift {
            amplitude_mps2: theta[0],
            ..Default::default()
        }
    }

    fn start_values(fs: &FitSet, _specs: &[ParamSpec]) -> Vec<f64> {
        let nominal_zs = fs
            .nominal_truth
            .first()
            .zip(fs.points.first())
            .and_then(|(t, p)| fs.runner.features_of_truth(t, &Effects::default(), p.0))
            .map_or(0.0, |f| f[ZERO_SHIFT_SQ]);
        vec![((fs.avg(ZERO_SHIFT_SQ) - nominal_zs).max(0.0) / ZERO_SHIFT_SQ_FACTOR).sqrt()]
    }

    fn model_free_z(fs: &FitSet) -> Option<f64> {
        fs.off_nominal_z(ZERO_SHIFT_SQ)
    }

    /// The mean square's change, E[u²]·A²: read as a mean square, because
    /// its noise is symmetric there and not in A (the pooled size's square
    /// root is taken once).
    fn force_balance_reading(change: &dyn Fn(usize) -> (f64, f64)) -> Vec<(&'static str, f64, f64)> {
        let (z, sz) = change(ZERO_SHIFT_SQ);
        vec![("mean_square_m2ps4", z, sz)]
    }

    /// A = √(ΔZ² / E[u²]), ΔZ² pooled over the fit points; its standard
    /// deviation by the square root's slope.
    fn measured_size(fs: &FitSet) -> Option<(Vec<f64>, Vec<f64>)> {
        let (z, sz) = pooled::<Self>(fs, 0)?;
        let a = (z / ZERO_SHIFT_SQ_FACTOR).sqrt();
        let spec = Self::free_params(fs.distinct)[0];
        (a.is_finite() && a > spec.lo && a <= spec.hi).then(|| (vec![a], vec![sz / (2.0 * ZERO_SHIFT_SQ_FACTOR * a)]))
    }

    /// An amplitude A adds E[u²]·A² to the mean square.
    fn model_free_floor(fs: &FitSet, z_min: f64) -> Option<(&'static str, f64)> {
        let se = fs.mean_se(ZERO_SHIFT_SQ).1;
        (se > 0.0).then(|| ("amplitude_mps2", (z_min * se / ZERO_SHIFT_SQ_FACTOR).sqrt()))
    }

    fn evidence(fs: &FitSet) -> Option<String> {
        let (z, _) = fs.mean_se(ZERO_SHIFT_SQ);
        Some(format!(
            "force balance: an acceleration offset of random sign decaying from each impact, RMS {:.1} m/s²",
            z.max(0.0).sqrt()
        ))
    }

    /// Its sign is random per impact: its expected effect on the corrected
    /// waveforms is nil, on the squared amplitude E[u²]·A².
    fn shift_expected_features(&self, mean: &mut [f64]) {
        mean[ZERO_SHIFT_SQ] += ZERO_SHIFT_SQ_FACTOR * self.amplitude_mps2 * self.amplitude_mps2;
    }

    fn draw(rng: &mut Rng) -> Self {
        AccelZeroShift {
            amplitude_mps2: between(rng, 10.0, 40.0),
            ..Default::default()
        }
    }

    fn magnitude_error(truth: &Self, fitted: &Self, _points: &[f64]) -> f64 {
        rel(fitted.amplitude_mps2, truth.amplitude_mps2)
    }
}
