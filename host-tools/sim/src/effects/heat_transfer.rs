//! `heat_transfer`: convective heat exchange with the walls.

use serde::{Deserialize, Serialize};

use super::{Effect, Param};

/// Convective heat exchange between chamber air and walls held at ambient temperature.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct HeatTransfer {
    pub h_w_per_m2_k: f64,
}

impl Default for HeatTransfer {
    fn default() -> Self {
        Self { h_w_per_m2_k: 500.0 }
    }
}

impl Effect for HeatTransfer {
    const PARAMS: &'static [Param] = &[Param::new("h_w_per_m2_k", "W/(m²·K)", 0.0, 1e5)];
}
