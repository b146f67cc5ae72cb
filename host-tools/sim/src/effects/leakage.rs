//! `leakage`: laminar gas leakage past the piston and the rod guide.

use serde::{Deserialize, Serialize};

use super::{Effect, Param};

/// Laminar gas leakage through the piston's annular clearance (rear ↔ front)
/// and the rod guide (front → atmosphere).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Leakage {
    /// Radial gap: half the paper's 0.05 mm diametral clearance.
    pub gap_m: f64,
    /// Paper: eccentricity ratio 1 (piston touching the wall).
    pub eccentricity: f64,
    /// Length of the rod guide seen by the front chamber's leak to atmosphere (estimate).
    pub rod_guide_length_m: f64,
}

impl Default for Leakage {
    fn default() -> Self {
        Self {
            gap_m: 25e-6,
            eccentricity: 1.0,
            rod_guide_length_m: 0.020,
        }
    }
}

impl Effect for Leakage {
    const PARAMS: &'static [Param] = &[
        Param::new("gap_m", "m", 0.0, 2e-4),
        Param::new("eccentricity", "1", 0.0, 1.0),
        Param::new("rod_guide_length_m", "m", 1e-3, 0.2),
    ];
}
