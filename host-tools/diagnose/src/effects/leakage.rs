use super::{between, rel, Diagnosed};
use crate::fit::ParamSpec;
use hammer_sim::effects::Leakage;
use hammer_sim::sensor::Rng;

/// Fits the gap; the eccentricity and the rod guide keep their defaults.
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
