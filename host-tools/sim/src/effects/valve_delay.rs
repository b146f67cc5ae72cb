//! `valve_delay`: the valve's pilot signal lags the chamber pressures.

use serde::{Deserialize, Serialize};

use super::{Effect, Param};

/// The valve's pilot signal lags the chamber pressures: a first-order lag of
/// time constant `tau_s` on the pilot pressure difference (pilot-line filling).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ValveDelay {
    pub tau_s: f64,
}

impl Default for ValveDelay {
    fn default() -> Self {
        Self { tau_s: 1.0e-3 }
    }
}

impl Effect for ValveDelay {
    const PARAMS: &'static [Param] = &[Param::new("tau_s", "s", 1e-6, 0.05)];
}
