use super::{between, rel, Diagnosed};
use crate::features::FRONT_EXPONENT;
use crate::fit::ParamSpec;
use crate::fitset::FitSet;
use hammer_sim::effects::HeatTransfer;
use hammer_sim::sensor::Rng;

/// A rise of the front exponent at one operating point, in standard
/// errors, that no heat exchange can give (the ranking's own threshold for
/// a model-free signature).
const MIN_RISE_Z: f64 = 3.0;

/// Against the hammer's own reference record, heat exchange with the walls
/// shows in the chamber characteristics: the front chamber's closed
/// compression bends towards the isotherm, its exponent falls. That holds
/// on any hammer: compressed air is hotter than the wall and gives heat to
/// it, whatever the wall's law. Of the catalogue's other effects only a
/// leak can lower that exponent (the second family's leaks mostly do not:
/// 2 of 20 benchmark leaks did, `examples/bench_case.rs`), so a drop is a
/// heat exchange's evidence and its absence rules one out. Against the
/// model alone the exponent carries the form (±20 % of dead volume moves it
/// by about ±0.13), so there heat exchange stays model-based.
impl Diagnosed for HeatTransfer {
    fn free_params(_distinct_pressures: usize) -> Vec<ParamSpec> {
        vec![ParamSpec {
            key: "h_w_per_m2_k",
            lo: 1.0,
            hi: 5e4,
            log: true,
            step: 0.02,
        }]
    }

    fn from_fit(theta: &[f64], _pressures: (f64, f64)) -> Self {
        HeatTransfer { h_w_per_m2_k: theta[0] }
    }

    fn seen_in_chambers() -> bool {
        true
    }

    /// The front exponent's fall does not part it from a leak: every closed
    /// compression starts below the wall's temperature (the chamber has
    /// just blown down), so a weak exchange raises the exponent as a leak
    /// into the chamber does, and only a strong one lowers it; 2 of 20 of
    /// the second family's leaks lowered it too (field notes, "Telling a
    /// leak from heat exchange"). It stays evidence for naming heat
    /// exchange before a leak the waveforms score a little higher, not for
    /// ruling the leak out.
    fn signature_parts() -> bool {
        false
    }

    fn parting_test() -> Option<&'static str> {
        Some("a chamber gas temperature (a fast thermocouple in the front chamber): heat exchange moves it, which p, x and a cannot show")
    }

    fn model_free_z(fs: &FitSet) -> Option<f64> {
        if !fs.reads_change(FRONT_EXPONENT) {
            return None;
        }
        // It lowers the exponent at every operating point: a point where it
        // rose beyond the threshold rules it out, whatever the mean.
        let rise = fs
            .points
            .iter()
            .zip(&fs.nominal_features)
            .map(|(p, nom)| (p.1.mean[FRONT_EXPONENT] - nom[FRONT_EXPONENT]) / p.2[FRONT_EXPONENT])
            .filter(|z| z.is_finite())
            .fold(f64::NEG_INFINITY, f64::max);
        if rise >= MIN_RISE_Z {
            return Some(-rise);
        }
        fs.off_nominal_z(FRONT_EXPONENT).map(|z| -z)
    }

    fn evidence(fs: &FitSet) -> Option<String> {
        Self::model_free_z(fs)?;
        let (d, sd) = fs.off_nominal(FRONT_EXPONENT);
        Some(format!(
            "chamber characteristics: the front chamber's closed compression exponent moved {d:+.4} ± {sd:.4} since the reference (heat exchange lowers it)"
        ))
    }

    fn draw(rng: &mut Rng) -> Self {
        HeatTransfer {
            h_w_per_m2_k: between(rng, 200.0, 1500.0),
        }
    }

    fn magnitude_error(truth: &Self, fitted: &Self, _points: &[f64]) -> f64 {
        rel(fitted.h_w_per_m2_k, truth.h_w_per_m2_k)
    }
}
