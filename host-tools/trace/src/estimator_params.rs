//! The `[estimator]` table of the project configuration: how the estimator
//! reads a hammer. Plain data, so the trace tools, the simulator and the CLI
//! can share it without depending on each other.

use hammer_estimator::Config;
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

impl Default for EstimatorParams {
    fn default() -> Self {
        let c = Config::default();
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
}
