use super::{between, rel, Diagnosed};
use crate::features::FRONT_FLOOR;
use crate::fit::ParamSpec;
use crate::fitset::FitSet;
use hammer_sim::effects::Leakage;
use hammer_sim::sensor::Rng;

/// How far the front chamber's floor must fall, in standard errors, to
/// rule a leak out (the ranking's threshold for a model-free signature).
const MIN_FALL_Z: f64 = 3.0;

/// Fits the gap; the eccentricity and the rod guide keep their defaults.
///
/// Against the hammer's own record, a leak past the piston feeds the front
/// chamber from the rear while the front exhausts in the stroke: its floor
/// rises, on any hammer whose piston leaks. A floor that fell is another
/// cause's (a starved supply or a late valve: both lower it on both model
/// families, `examples/front_floor.rs`), and rules the leak out. A rise is
/// no leak's proof: heat exchange and friction raise the floor too, so the
/// leak stays named by its waveforms.
impl Diagnosed for Leakage {
    fn free_params(_distinct_pressures: usize) -> Vec<ParamSpec> {
        vec![ParamSpec {
            key: "gap_m",
            lo: 1e-6,
            hi: 1.5e-4,
            log: true,
            step: 0.01,
        }]
    }

    fn from_fit(theta: &[f64], _pressures: (f64, f64)) -> Self {
        Leakage {
            gap_m: theta[0],
            ..Default::default()
        }
    }

    fn parting_test() -> Option<&'static str> {
        Some("a leak-down test at rest: supply the rear chamber with the piston held and watch the front chamber's pressure rise")
    }

    fn contradicted(fs: &FitSet) -> Option<String> {
        // Pooled over the fit points that read the floor: at a low supply
        // the exhausting chamber can dip below the transducer's range,
        // and a clipped floor is not read (`features::front_floor_pa`).
        let read: Vec<(f64, f64)> = fs
            .points
            .iter()
            .zip(&fs.nominal_features)
            .map(|(p, nom)| (p.1.mean[FRONT_FLOOR] - nom[FRONT_FLOOR], p.2[FRONT_FLOOR]))
            .filter(|(d, sd)| d.is_finite() && sd.is_finite() && *sd > 0.0)
            .collect();
        if !fs.against_reference || read.is_empty() {
            return None;
        }
        let n = read.len() as f64;
        let d = read.iter().map(|r| r.0).sum::<f64>() / n;
        let se = read.iter().map(|r| r.1 * r.1).sum::<f64>().sqrt() / n;
        let z = d / se;
        (z <= -MIN_FALL_Z).then(|| {
            format!(
                "the front chamber's floor fell by {:.2} ± {:.2} mbar since the reference ({z:.1} standard errors, {} of {} fit points read it): a leak past the piston raises it",
                -d / 100.0,
                se / 100.0,
                read.len(),
                fs.points.len()
            )
        })
    }

    fn draw(rng: &mut Rng) -> Self {
        Leakage {
            gap_m: between(rng, 12e-6, 35e-6),
            ..Default::default()
        }
    }

    fn magnitude_error(truth: &Self, fitted: &Self, _points: &[f64]) -> f64 {
        rel(fitted.gap_m, truth.gap_m)
    }
}
