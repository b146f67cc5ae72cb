//! The `[estimator]` table of the project configuration: how the estimator
//! reads a hammer. Plain data, so the trace tools, the simulator and the CLI
//! can share it without depending on each other.

use hammer_estimator::{ChannelSpec, Config};
use serde::{Deserialize, Serialize};

/// The `[estimator]` table of a config file: thresholds and the sensors'
/// calibration accuracy (what the stated uncertainty is built from).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct EstimatorParams {
    pub impact_threshold_mps2: f64,
    pub blank_before_s: f64,
    pub blank_after_s: f64,
    pub min_period_s: f64,
    pub max_period_s: f64,
    /// Discharge time constant of the piezo accelerometer (0: no zero-shift fit).
    pub accel_zero_shift_tau_s: f64,
    pub coverage_factor: f64,
    pub residual_correlation_factor: f64,
    pub stuck_after_s: f64,
    pub pressure_gain_uncertainty: f64,
    pub pressure_offset_uncertainty_pa: f64,
    pub accel_gain_uncertainty: f64,
    pub accel_offset_uncertainty_mps2: f64,
    pub wear_budget_j: f64,
    pub baseline_cycles: u16,
    pub cusum_k: f64,
    pub cusum_h: f64,
}

/// The defaults are the estimator's own ([`Config::default`]).
impl Default for EstimatorParams {
    fn default() -> Self {
        Self::from_config(&Config::default())
    }
}

/// The one mapping between the `[estimator]` table and the estimator's
/// [`Config`], both ways. (The device's wire form, `DeviceConfig`, maps to
/// and from `Config` in `hammer_estimator::device`.)
impl EstimatorParams {
    /// The table that describes `c`'s estimator settings.
    pub fn from_config(c: &Config) -> Self {
        Self {
            impact_threshold_mps2: c.impact_threshold_mps2 as f64,
            blank_before_s: c.blank_before_s as f64,
            blank_after_s: c.blank_after_s as f64,
            min_period_s: c.min_period_s as f64,
            max_period_s: c.max_period_s as f64,
            accel_zero_shift_tau_s: c.accel_zero_shift_tau_s as f64,
            coverage_factor: c.coverage_factor as f64,
            residual_correlation_factor: c.residual_correlation_factor as f64,
            stuck_after_s: c.stuck_after_s as f64,
            pressure_gain_uncertainty: c.rear_spec.gain_rel as f64,
            pressure_offset_uncertainty_pa: c.rear_spec.offset as f64,
            accel_gain_uncertainty: c.accel_spec.gain_rel as f64,
            accel_offset_uncertainty_mps2: c.accel_spec.offset as f64,
            wear_budget_j: c.wear.budget_j as f64,
            baseline_cycles: c.wear.baseline_cycles,
            cusum_k: c.wear.cusum_k as f64,
            cusum_h: c.wear.cusum_h as f64,
        }
    }

    /// Sets every estimator setting this table holds in `c`, and nothing
    /// else: the hammer, the sensors' calibration, the sample rate and the
    /// supply pressure come from elsewhere. Validate `c` afterwards.
    pub fn apply(&self, c: &mut Config) {
        let pressure = ChannelSpec {
            gain_rel: self.pressure_gain_uncertainty as f32,
            offset: self.pressure_offset_uncertainty_pa as f32,
        };
        c.rear_spec = pressure;
        c.front_spec = pressure;
        c.accel_spec = ChannelSpec {
            gain_rel: self.accel_gain_uncertainty as f32,
            offset: self.accel_offset_uncertainty_mps2 as f32,
        };
        c.impact_threshold_mps2 = self.impact_threshold_mps2 as f32;
        c.blank_before_s = self.blank_before_s as f32;
        c.blank_after_s = self.blank_after_s as f32;
        c.min_period_s = self.min_period_s as f32;
        c.max_period_s = self.max_period_s as f32;
        c.accel_zero_shift_tau_s = self.accel_zero_shift_tau_s as f32;
        c.coverage_factor = self.coverage_factor as f32;
        c.residual_correlation_factor = self.residual_correlation_factor as f32;
        c.stuck_after_s = self.stuck_after_s as f32;
        c.wear.budget_j = self.wear_budget_j as f32;
        c.wear.baseline_cycles = self.baseline_cycles;
        c.wear.cusum_k = self.cusum_k as f32;
        c.wear.cusum_h = self.cusum_h as f32;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_table_maps_to_the_config_and_back() {
        let mut c = Config::default();
        EstimatorParams::default().apply(&mut c);
        // Compared as text: the unknown supply pressure is a NaN.
        assert_eq!(format!("{c:?}"), format!("{:?}", Config::default()));
        let p = EstimatorParams {
            impact_threshold_mps2: 1200.0,
            pressure_gain_uncertainty: 0.007_812_5, // 2^-7: exact in f32
            accel_offset_uncertainty_mps2: 2.5,
            baseline_cycles: 80,
            cusum_h: 8.0,
            ..EstimatorParams::default()
        };
        p.apply(&mut c);
        assert_eq!(c.front_spec, c.rear_spec);
        assert_eq!(c.accel_spec.offset, 2.5);
        assert_eq!(EstimatorParams::from_config(&c), p);
        // f32 -> f64 -> f32 keeps every value: the config survives the round trip.
        let mut again = Config::default();
        EstimatorParams::from_config(&c).apply(&mut again);
        assert_eq!(format!("{again:?}"), format!("{c:?}"));
    }
}
