//! `accel_zero_shift`: piezo accelerometer zero shift after impacts (a sensor effect).

use serde::{Deserialize, Serialize};

use super::{Effect, Param};

/// Piezo accelerometer zero shift: after every impact the output carries an
/// offset of random sign that decays with the sensor's discharge time constant.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct AccelZeroShift {
    pub amplitude_mps2: f64,
    pub tau_s: f64,
}

impl Default for AccelZeroShift {
    fn default() -> Self {
        Self {
            amplitude_mps2: 20.0,
            tau_s: 0.02,
        }
    }
}

impl Effect for AccelZeroShift {
    const PARAMS: &'static [Param] = &[
        Param::new("amplitude_mps2", "m/s²", 0.0, 1e4),
        Param::new("tau_s", "s", 1e-4, 10.0),
    ];
    const SENSOR: bool = true;
}
