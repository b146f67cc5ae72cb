use super::{between, rel, Diagnosed};
use crate::fit::ParamSpec;
use hammer_sim::effects::HeatTransfer;
use hammer_sim::sensor::Rng;

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

    fn draw(rng: &mut Rng) -> Self {
        HeatTransfer {
            h_w_per_m2_k: between(rng, 200.0, 1500.0),
        }
    }

    fn magnitude_error(truth: &Self, fitted: &Self, _points: &[f64]) -> f64 {
        rel(fitted.h_w_per_m2_k, truth.h_w_per_m2_k)
    }
}
