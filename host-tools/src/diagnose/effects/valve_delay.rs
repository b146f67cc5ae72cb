use super::{between, rel, Diagnosed};
use crate::diagnose::fit::ParamSpec;
use hammer_sim::effects::ValveDelay;
use hammer_sim::sensor::Rng;

impl Diagnosed for ValveDelay {
    fn free_params(_distinct_pressures: usize) -> Vec<ParamSpec> {
        vec![ParamSpec {
            key: "tau_s",
            lo: 1e-5,
            hi: 0.03,
            log: true,
            step: 0.02,
        }]
    }

    fn from_fit(theta: &[f64], _pressures: (f64, f64)) -> Self {
        ValveDelay { tau_s: theta[0] }
    }

    fn draw(rng: &mut Rng) -> Self {
        ValveDelay {
            tau_s: between(rng, 0.4e-3, 2.5e-3),
        }
    }

    fn magnitude_error(truth: &Self, fitted: &Self, _points: &[f64]) -> f64 {
        rel(fitted.tau_s, truth.tau_s)
    }
}
