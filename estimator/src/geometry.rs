//! The hammer's piston geometry: the one place where mass, effective areas
//! and travel are defined, shared by the estimator, the simulator and the
//! firmware.

/// Piston mass of the paper's small pneumatic hammer.
pub const PAPER_PISTON_MASS_KG: f64 = 1.12;
/// Piston (bore) diameter: the rear chamber acts on the full bore.
pub const PAPER_BORE_DIAMETER_M: f64 = 0.041;
/// Piston rod diameter: the front chamber acts on the annulus bore − rod.
pub const PAPER_ROD_DIAMETER_M: f64 = 0.028;
/// How far the piston can move: its rear face runs from the rear cover
/// (x = 0) to the impact position, the paper's 10 mm rest + 42 mm stroke
/// ([`crate::chambers::PAPER_IMPACT_POSITION_M`], the one value).
pub const PAPER_TRAVEL_M: f64 = crate::chambers::PAPER_IMPACT_POSITION_M;
/// Standard gravity, for the inclination term.
pub const STANDARD_GRAVITY_MPS2: f64 = 9.806_65;

/// Mass and effective areas of the piston.
///
/// Kept in `f64` because the simulator integrates in `f64`; the estimator
/// converts once to `f32` at configuration time.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Geometry {
    pub piston_mass_kg: f64,
    pub bore_diameter_m: f64,
    pub rod_diameter_m: f64,
    /// The most the piston can travel between the rear cover and the
    /// impact (a simulator's `hammer.impact_position_m`): no stroke is
    /// longer, and no impact carries more energy than the air's force over
    /// it (the plausibility of a cycle, `estimate`). In `f32`: only the
    /// estimator reads it (the simulator integrates its own positions), and
    /// on the board a double costs flash.
    pub travel_m: f32,
}

impl Geometry {
    /// The hammer of the reference paper (1.12 kg, 41 mm bore, 28 mm rod).
    pub const PAPER: Geometry = Geometry {
        piston_mass_kg: PAPER_PISTON_MASS_KG,
        bore_diameter_m: PAPER_BORE_DIAMETER_M,
        rod_diameter_m: PAPER_ROD_DIAMETER_M,
        travel_m: PAPER_TRAVEL_M as f32,
    };

    /// Rear (full-bore) effective area A1.
    pub fn rear_area_m2(&self) -> f64 {
        circle_area(self.bore_diameter_m)
    }

    /// Front (annulus) effective area A2.
    pub fn front_area_m2(&self) -> f64 {
        circle_area(self.bore_diameter_m) - circle_area(self.rod_diameter_m)
    }

    /// True when every quantity is finite and physically possible.
    pub fn is_valid(&self) -> bool {
        self.piston_mass_kg.is_finite()
            && self.piston_mass_kg > 0.0
            && self.bore_diameter_m.is_finite()
            && self.rod_diameter_m.is_finite()
            && self.rod_diameter_m >= 0.0
            && self.bore_diameter_m > self.rod_diameter_m
            && self.travel_m.is_finite()
            && self.travel_m > 0.0
    }
}

impl Default for Geometry {
    fn default() -> Self {
        Self::PAPER
    }
}

/// `circle_area` in single precision, for the estimator: the Cortex-M4's FPU
/// has no double precision, and software `f64` arithmetic costs ~2.6 KB of
/// flash. The areas agree with the `f64` ones to 1e-7 relative.
pub(crate) fn circle_area_f32(diameter_m: f32) -> f32 {
    core::f32::consts::PI * 0.25 * diameter_m * diameter_m
}

fn circle_area(diameter_m: f64) -> f64 {
    core::f64::consts::PI * 0.25 * diameter_m * diameter_m
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn paper_areas_match_the_field_notes() {
        let g = Geometry::PAPER;
        // Field notes: bore area ~1320 mm², annulus ~705 mm².
        assert!((g.rear_area_m2() * 1e6 - 1320.3).abs() < 0.5);
        assert!((g.front_area_m2() * 1e6 - 704.5).abs() < 0.5);
        assert!(g.is_valid());
        let bore = g.bore_diameter_m as f32;
        let rod = g.rod_diameter_m as f32;
        let a1 = circle_area_f32(bore);
        let a2 = a1 - circle_area_f32(rod);
        assert!((f64::from(a1) / g.rear_area_m2() - 1.0).abs() < 1e-6);
        assert!((f64::from(a2) / g.front_area_m2() - 1.0).abs() < 1e-6);
    }

    #[test]
    fn impossible_geometry_is_invalid() {
        let mut g = Geometry::PAPER;
        g.rod_diameter_m = 0.05;
        assert!(!g.is_valid());
        g = Geometry::PAPER;
        g.piston_mass_kg = f64::NAN;
        assert!(!g.is_valid());
        g = Geometry::PAPER;
        g.travel_m = 0.0;
        assert!(!g.is_valid());
    }
}
