use super::{between, rel, Diagnosed};
use crate::fit::ParamSpec;
use hammer_sim::effects::SupplyRestriction;
use hammer_sim::sensor::Rng;

/// Fits the orifice; the line's volume keeps its default.
impl Diagnosed for SupplyRestriction {
    fn free_params(_distinct_pressures: usize) -> Vec<ParamSpec> {
        vec![ParamSpec {
            key: "orifice_diameter_m",
            lo: 5e-4,
            hi: 0.03,
            log: true,
            step: 0.01,
        }]
    }

    fn from_fit(theta: &[f64], _pressures: (f64, f64)) -> Self {
        SupplyRestriction {
            orifice_diameter_m: theta[0],
            ..Default::default()
        }
    }

    fn parting_test() -> Option<&'static str> {
        Some("the supply pressure at the hammer's inlet while it runs: a restriction makes it sag in every stroke")
    }

    fn draw(rng: &mut Rng) -> Self {
        SupplyRestriction {
            orifice_diameter_m: between(rng, 1.5e-3, 2.5e-3),
            ..Default::default()
        }
    }

    fn magnitude_error(truth: &Self, fitted: &Self, _points: &[f64]) -> f64 {
        rel(fitted.orifice_diameter_m, truth.orifice_diameter_m)
    }
}
