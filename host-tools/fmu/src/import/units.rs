//! The units a foreign FMU's signals may come in, and their factor to SI:
//! the few each quantity needs (tools write `m/s2`, `m/s^2` or `m/s²`).

use hammer_sim::gas::P_ATM_PA;

use super::map::Reference;

/// What a signal measures.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Quantity {
    Pressure,
    Acceleration,
    Length,
    Velocity,
}

/// Standard gravity, m/s² (an accelerometer's `g`).
const G_MPS2: f64 = 9.806_65;

impl Quantity {
    pub fn si(self) -> &'static str {
        match self {
            Quantity::Pressure => "Pa",
            Quantity::Acceleration => "m/s2",
            Quantity::Length => "m",
            Quantity::Velocity => "m/s",
        }
    }

    pub fn what(self) -> &'static str {
        match self {
            Quantity::Pressure => "pressure",
            Quantity::Acceleration => "acceleration",
            Quantity::Length => "length",
            Quantity::Velocity => "velocity",
        }
    }

    /// SI per `unit`, or None when `unit` is not one of this quantity's.
    pub fn to_si(self, unit: &str) -> Option<f64> {
        let u = normal(unit);
        let table: &[(&str, f64)] = match self {
            Quantity::Pressure => &[
                ("Pa", 1.0),
                ("kPa", 1e3),
                ("MPa", 1e6),
                ("bar", 1e5),
                ("mbar", 100.0),
                ("psi", 6_894.757_293_168_361),
            ],
            Quantity::Acceleration => &[("m/s2", 1.0), ("g", G_MPS2), ("mm/s2", 1e-3)],
            Quantity::Length => &[("m", 1.0), ("mm", 1e-3), ("cm", 1e-2)],
            Quantity::Velocity => &[("m/s", 1.0), ("mm/s", 1e-3)],
        };
        table.iter().find(|(n, _)| *n == u).map(|(_, f)| *f)
    }
}

/// A unit's spelling without its typography: `m/s²`, `m/s^2` → `m/s2`,
/// `N·s/m` → `N.s/m`, `m³` → `m3`.
pub fn normal(unit: &str) -> String {
    unit.trim()
        .replace('²', "2")
        .replace('³', "3")
        .replace('^', "")
        .replace(['·', '*'], ".")
}

/// The same unit, however spelt.
pub fn same_unit(a: &str, b: &str) -> bool {
    normal(a) == normal(b)
}

/// A pressure in `unit` (gauge or absolute) as SI gauge, Pa.
pub fn gauge_pa(value: f64, per_unit: f64, reference: Reference) -> f64 {
    match reference {
        Reference::Gauge => value * per_unit,
        Reference::Absolute => value * per_unit - P_ATM_PA,
    }
}

/// An SI gauge pressure in `unit` (gauge or absolute).
pub fn from_gauge_pa(p_pa: f64, per_unit: f64, reference: Reference) -> f64 {
    match reference {
        Reference::Gauge => p_pa / per_unit,
        Reference::Absolute => (p_pa + P_ATM_PA) / per_unit,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn units_convert_and_round_trip() {
        assert_eq!(Quantity::Pressure.to_si("bar"), Some(1e5));
        assert_eq!(Quantity::Acceleration.to_si("m/s²"), Some(1.0));
        assert_eq!(Quantity::Acceleration.to_si("m/s^2"), Some(1.0));
        assert_eq!(Quantity::Pressure.to_si("m"), None);
        assert!(same_unit("N·s/m", "N.s/m"));
        let f = Quantity::Pressure.to_si("bar").unwrap();
        let abs = from_gauge_pa(4e5, f, Reference::Absolute);
        assert!((abs - 5.01325).abs() < 1e-12);
        assert!((gauge_pa(abs, f, Reference::Absolute) - 4e5).abs() < 1e-9);
    }
}
