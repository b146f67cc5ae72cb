use super::{between, pooled_size, rel, Diagnosed};
use crate::fitset::FitSet;
use crate::features::VISCOUS;
use crate::fit::ParamSpec;
use hammer_sim::effects::ViscousFriction;
use hammer_sim::sensor::Rng;

impl Diagnosed for ViscousFriction {
    fn free_params(_distinct_pressures: usize) -> Vec<ParamSpec> {
        vec![ParamSpec {
            key: "c_n_s_per_m",
            lo: 0.01,
            hi: 200.0,
            log: true,
            step: 0.02,
        }]
    }

    fn from_fit(theta: &[f64], _pressures: (f64, f64)) -> Self {
        ViscousFriction { c_n_s_per_m: theta[0] }
    }

    fn start_values(fs: &FitSet, _specs: &[ParamSpec]) -> Vec<f64> {
        vec![fs.avg(VISCOUS).max(0.05)]
    }

    fn model_free_z(fs: &FitSet) -> Option<f64> {
        fs.off_nominal_z(VISCOUS)
    }

    fn force_balance_reading(change: &dyn Fn(usize) -> (f64, f64)) -> Vec<(&'static str, f64, f64)> {
        let (c, sc) = change(VISCOUS);
        vec![("c_n_s_per_m", c, sc)]
    }

    /// The force balance's coefficient, pooled over the fit points.
    fn measured_size(fs: &FitSet) -> Option<(Vec<f64>, Vec<f64>)> {
        pooled_size::<Self>(fs)
    }

    fn model_free_floor(fs: &FitSet, z_min: f64) -> Option<(&'static str, f64)> {
        let se = fs.mean_se(VISCOUS).1;
        (se > 0.0).then(|| ("c_n_s_per_m", z_min * se))
    }

    fn evidence(fs: &FitSet) -> Option<String> {
        let (c, sc) = fs.mean_se(VISCOUS);
        Some(format!(
            "force balance: a force growing with the speed, {c:.2} ± {sc:.2} N·s/m, not a constant offset"
        ))
    }

    fn draw(rng: &mut Rng) -> Self {
        ViscousFriction {
            c_n_s_per_m: between(rng, 1.0, 5.0),
        }
    }

    fn magnitude_error(truth: &Self, fitted: &Self, _points: &[f64]) -> f64 {
        rel(fitted.c_n_s_per_m, truth.c_n_s_per_m)
    }
}
