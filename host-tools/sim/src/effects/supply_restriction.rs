//! `supply_restriction`: a restricted supply hose of finite volume.

use serde::{Deserialize, Serialize};

use super::{Effect, Param};

/// A supply hose of finite volume fed through a restriction: the valve-inlet
/// pressure sags while the hammer draws air.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SupplyRestriction {
    pub orifice_diameter_m: f64,
    pub line_volume_m3: f64,
}

impl Default for SupplyRestriction {
    fn default() -> Self {
        Self {
            orifice_diameter_m: 0.0016,
            line_volume_m3: 50e-6,
        }
    }
}

impl Effect for SupplyRestriction {
    const PARAMS: &'static [Param] = &[
        Param::new("orifice_diameter_m", "m", 5e-4, 0.05),
        Param::new("line_volume_m3", "m³", 1e-6, 0.1),
    ];
}
