//! `viscous_friction`: viscous friction of the lubricant film.

use serde::{Deserialize, Serialize};

use super::{Effect, Param};

/// Viscous friction F = c·v from the lubricant film.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ViscousFriction {
    pub c_n_s_per_m: f64,
}

impl Default for ViscousFriction {
    fn default() -> Self {
        // ~5 N at the 2 m/s typical of flight: the same order as the Coulomb term.
        Self { c_n_s_per_m: 2.5 }
    }
}

impl Effect for ViscousFriction {
    const PARAMS: &'static [Param] = &[Param::new("c_n_s_per_m", "N·s/m", 0.0, 1e3)];
}
