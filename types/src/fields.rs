//! The one table of a report's per-cycle fields: column name, unit, value.
//!
//! Every rendering of a [`CycleReport`] is driven by [`FIELDS`]: `hammer
//! estimate --format csv|jsonl|table`, the monitor's `cycles.csv`, the
//! headless report lines and the dashboard's cycle panel. A column's name is
//! the struct field's, which ends in its unit (`wear_index_j`,
//! `friction_n`); dimensionless fields have unit `"1"` (or name what they
//! count). A test asserts the table has every field of the struct, in order.
//! One exception: the wire's integer `t_impact_us` is the column
//! `t_impact_s`, so logs read the same as before it was an integer.

use core::fmt;

use crate::CycleReport;

/// One field's value, in the type the report holds it in, so a rendering can
/// print the shortest text that reads back to the very same number.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Value {
    U32(u32),
    F32(f32),
    F64(f64),
}

impl Value {
    /// The same value, bit for bit (a NaN is the same as itself).
    pub fn same(self, other: Value) -> bool {
        match (self, other) {
            (Value::U32(a), Value::U32(b)) => a == b,
            (Value::F32(a), Value::F32(b)) => a.to_bits() == b.to_bits(),
            (Value::F64(a), Value::F64(b)) => a.to_bits() == b.to_bits(),
            _ => false,
        }
    }

    pub fn as_f64(self) -> f64 {
        match self {
            Value::U32(v) => v as f64,
            Value::F32(v) => v as f64,
            Value::F64(v) => v,
        }
    }
}

/// The shortest decimal that reads back to the same value (`0.047`, not `0.04699999839067459`).
impl fmt::Display for Value {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Value::U32(v) => write!(f, "{v}"),
            Value::F32(v) => write!(f, "{v}"),
            Value::F64(v) => write!(f, "{v}"),
        }
    }
}

/// A per-cycle field of [`CycleReport`].
#[derive(Clone, Copy)]
pub struct Field {
    /// Column and key name: the struct field's, unit suffix included.
    pub name: &'static str,
    /// SI unit ("1" for a ratio, "" for the sequence number).
    pub unit: &'static str,
    /// What it is, for a human (a label, a column description).
    pub label: &'static str,
    /// The field holding this one's expanded uncertainty, if any.
    pub uncertainty: Option<&'static str>,
    pub get: fn(&CycleReport) -> Value,
}

impl fmt::Debug for Field {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Field")
            .field("name", &self.name)
            .field("unit", &self.unit)
            .finish()
    }
}

impl Field {
    pub fn value(&self, r: &CycleReport) -> Value {
        (self.get)(r)
    }

    /// The value as an f64 (for summaries and charts).
    pub fn f64(&self, r: &CycleReport) -> f64 {
        (self.get)(r).as_f64()
    }
}

macro_rules! fields {
    ($($name:ident: $kind:ident $(via $get:ident())?, $unit:literal, $label:literal $(, pm $u:ident)?;)*) => {
        /// Every per-cycle field of [`CycleReport`] but `flags`, in struct (= wire) order.
        /// `flags` is rendered by name ([`crate::Flags::names`]), next to the
        /// derived `valid` ([`CycleReport::is_valid`]).
        pub const FIELDS: [Field; [$(stringify!($name)),*].len()] = [$(
            Field {
                name: stringify!($name),
                unit: $unit,
                label: $label,
                uncertainty: fields!(@u $($u)?),
                get: |r: &CycleReport| Value::$kind(fields!(@get r, $name $(, $get)?)),
            },
        )*];
    };
    (@get $r:ident, $name:ident) => { $r.$name };
    (@get $r:ident, $name:ident, $get:ident) => { $r.$get() };
    (@u) => { None };
    (@u $u:ident) => { Some(stringify!($u)) };
}

fields! {
    seq: U32, "", "cycle";
    // The wire's integer `t_impact_us`, shown in seconds.
    t_impact_s: F64 via t_impact_s(), "s", "impact time";
    period_s: F32, "s", "period";
    frequency_hz: F32, "Hz", "frequency";
    friction_n: F32, "N", "friction", pm friction_uncertainty_n;
    friction_stroke_n: F32, "N", "stroke friction", pm friction_stroke_uncertainty_n;
    friction_backhaul_n: F32, "N", "backhaul friction", pm friction_backhaul_uncertainty_n;
    friction_uncertainty_n: F32, "N", "friction uncertainty";
    friction_stroke_uncertainty_n: F32, "N", "stroke friction uncertainty";
    friction_backhaul_uncertainty_n: F32, "N", "backhaul friction uncertainty";
    impact_velocity_mps: F32, "m/s", "impact velocity";
    impact_velocity_frictionless_mps: F32, "m/s", "friction-blind impact velocity";
    impact_energy_j: F32, "J", "impact energy", pm impact_energy_uncertainty_j;
    impact_energy_frictionless_j: F32, "J", "friction-blind impact energy", pm impact_energy_frictionless_uncertainty_j;
    impact_energy_uncertainty_j: F32, "J", "impact energy uncertainty";
    impact_energy_frictionless_uncertainty_j: F32, "J", "friction-blind impact energy uncertainty";
    friction_work_j: F32, "J", "friction work";
    friction_work_ratio: F32, "1", "friction work / impact energy";
    stroke_m: F32, "m", "stroke";
    peak_rear_pa: F32, "Pa", "peak rear pressure";
    peak_front_pa: F32, "Pa", "peak front pressure";
    accel_zero_shift_mps2: F32, "m/s²", "accelerometer zero shift";
    wear_index_j: F32, "J", "wear index";
    wear_remaining_fraction: F32, "1", "wear budget left";
    remaining_life_cycles: F32, "cycles", "remaining life";
    drift_score: F32, "σ", "drift score";
    calibration_hash: U32, "", "calibration hash";
    front_feed_s: F32, "s", "front feed onset after the impact", pm front_feed_uncertainty_s;
    front_feed_uncertainty_s: F32, "s", "front feed onset uncertainty";
    front_feed_x_m: F32, "m", "piston position at the front feed";
    front_feed_p_rear_pa: F32, "Pa", "rear pressure at the front feed";
    front_feed_p_front_pa: F32, "Pa", "front pressure at the front feed";
    front_closed_exponent: F32, "1", "front closed-phase exponent", pm front_closed_exponent_uncertainty;
    front_closed_exponent_uncertainty: F32, "1", "front closed-phase exponent uncertainty";
    front_feed_area_m2: F32, "m²", "front feed area", pm front_feed_area_uncertainty_m2;
    front_feed_area_uncertainty_m2: F32, "m²", "front feed area uncertainty";
    rear_feed_s: F32, "s", "rear feed onset after the impact", pm rear_feed_uncertainty_s;
    rear_feed_uncertainty_s: F32, "s", "rear feed onset uncertainty";
    rear_feed_x_m: F32, "m", "piston position at the rear feed";
    rear_feed_p_rear_pa: F32, "Pa", "rear pressure at the rear feed";
    rear_feed_p_front_pa: F32, "Pa", "front pressure at the rear feed";
    rear_closed_exponent: F32, "1", "rear closed-phase exponent", pm rear_closed_exponent_uncertainty;
    rear_closed_exponent_uncertainty: F32, "1", "rear closed-phase exponent uncertainty";
    rear_feed_area_m2: F32, "m²", "rear feed area", pm rear_feed_area_uncertainty_m2;
    rear_feed_area_uncertainty_m2: F32, "m²", "rear feed area uncertainty";
}

/// The field named `name` (a column of [`FIELDS`]).
pub fn field(name: &str) -> Option<&'static Field> {
    FIELDS.iter().find(|f| f.name == name)
}

/// `name`'s value and, if it has one, its uncertainty's.
pub fn with_uncertainty(r: &CycleReport, name: &str) -> Option<(Value, Option<Value>)> {
    let f = field(name)?;
    Some((f.value(r), f.uncertainty.and_then(field).map(|u| u.value(r))))
}

#[cfg(test)]
mod tests {
    extern crate std;
    use std::vec::Vec;

    use super::*;
    use crate::Flags;

    /// Every field of the struct is in the table, in struct order (what
    /// serde sees is what the wire and the JSON carry).
    #[test]
    fn the_table_has_every_field_of_the_report_in_order() {
        let r = CycleReport {
            seq: 3,
            flags: Flags(1),
            ..Default::default()
        };
        let json = serde_json::to_value(r).unwrap();
        // The table shows the wire's `t_impact_us` in seconds.
        let mut keys: Vec<&str> = json
            .as_object()
            .unwrap()
            .keys()
            .map(|k| if k == "t_impact_us" { "t_impact_s" } else { k.as_str() })
            .collect();
        keys.sort_unstable();
        let mut names: Vec<&str> = FIELDS.iter().map(|f| f.name).collect();
        names.push("flags");
        let mut sorted = names.clone();
        sorted.sort_unstable();
        assert_eq!(keys, sorted);
        // Struct order: serialise to a sequence-preserving form.
        let order: Vec<&str> = {
            let text = serde_json::to_string(&r).unwrap().replace("t_impact_us", "t_impact_s");
            let mut at: Vec<(usize, &str)> = names.iter().map(|n| (text.find(&format_key(n)).unwrap(), *n)).collect();
            at.sort_unstable();
            at.into_iter().map(|(_, n)| n).collect()
        };
        assert_eq!(order, names);
        for f in &FIELDS {
            if let Some(u) = f.uncertainty {
                assert!(field(u).is_some_and(|u| u.unit == f.unit), "{}", f.name);
            }
            assert!(
                f.unit.is_empty() || f.unit == "1" || f.unit == "σ" || f.name.ends_with(unit_suffix(f.unit)),
                "{} does not end in its unit {}",
                f.name,
                f.unit
            );
        }
        assert_eq!(field("seq").unwrap().value(&r), Value::U32(3));
    }

    fn format_key(n: &str) -> std::string::String {
        std::format!("\"{n}\":")
    }

    fn unit_suffix(unit: &str) -> &str {
        match unit {
            "s" => "_s",
            "Hz" => "_hz",
            "N" => "_n",
            "m/s" => "_mps",
            "J" => "_j",
            "m" => "_m",
            "Pa" => "_pa",
            "m/s²" => "_mps2",
            "cycles" => "_cycles",
            "m²" => "_m2",
            other => other,
        }
    }

    #[test]
    fn flags_are_their_bare_integer() {
        assert_eq!(serde_json::to_string(&Flags(0x0801)).unwrap(), "2049");
        assert_eq!(serde_json::to_string(&Flags::CHAMBERS_UNREAD).unwrap(), "65536");
    }
}
