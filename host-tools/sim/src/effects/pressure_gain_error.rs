//! `pressure_gain_error`: relative gain errors of the pressure channels (a sensor effect).

use serde::{Deserialize, Serialize};

use super::{Effect, Param};

/// Relative gain errors of the pressure channels (reading = (1 + g)·true).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PressureGainError {
    pub rear: f64,
    pub front: f64,
}

impl Default for PressureGainError {
    fn default() -> Self {
        Self {
            rear: 0.02,
            front: 0.02,
        }
    }
}

impl Effect for PressureGainError {
    const PARAMS: &'static [Param] = &[Param::new("rear", "1", -0.5, 0.5), Param::new("front", "1", -0.5, 0.5)];
    const SENSOR: bool = true;
}
