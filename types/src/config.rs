//! The device's configuration on the wire. The estimator derives its
//! runtime `Config` from this (and maps it back); field order is wire order.

use serde::{Deserialize, Serialize};

/// One channel's calibration: `value = (code − zero_code)·scale`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ChannelCalibration {
    pub zero_code: f32,
    pub scale: f32,
    pub full_scale_code: u16,
    pub gain_uncertainty: f32,
    pub offset_uncertainty: f32,
}

/// The device's configuration: the hammer, the sensors, the thresholds.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct DeviceConfig {
    pub sample_rate_hz: f32,
    pub piston_mass_kg: f32,
    pub bore_diameter_m: f32,
    pub rod_diameter_m: f32,
    pub inclination_deg: f32,
    pub rear: ChannelCalibration,
    pub front: ChannelCalibration,
    pub accel: ChannelCalibration,
    pub impact_threshold_mps2: f32,
    pub blank_before_s: f32,
    pub blank_after_s: f32,
    pub min_period_s: f32,
    pub max_period_s: f32,
    pub accel_zero_shift_tau_s: f32,
    pub coverage_factor: f32,
    /// Gauge supply pressure, NaN when unknown.
    pub supply_pressure_pa: f32,
    pub wear_budget_j: f32,
    pub baseline_cycles: u16,
    pub cusum_k: f32,
    pub cusum_h: f32,
}
