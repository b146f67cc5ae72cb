//! Every rendering of a cycle report, driven by the one table of its fields
//! ([`FIELDS`] in `hammer-types`): the CSV of `hammer estimate` and the
//! monitor's `cycles.csv`, the JSON lines, and the one-line summary the
//! headless monitor and `hammer demo --headless` print. A field added to
//! [`CycleReport`] shows up in each of them without touching this file.

use hammer_estimator::fields::{field, Value, FIELDS};
use hammer_estimator::{CycleReport, Flags};

/// The columns after the report's fields: `valid` ([`CycleReport::is_valid`])
/// and `flags` (names joined by `|`, `-` when none: [`flag_list`]).
pub const TRAILING_COLUMNS: [&str; 2] = ["valid", "flags"];

/// Every column of a report record: the fields' names (unit-suffixed), `valid`, `flags`.
pub fn columns() -> impl Iterator<Item = &'static str> {
    FIELDS.iter().map(|f| f.name).chain(TRAILING_COLUMNS)
}

/// The CSV header of [`csv_record`].
pub fn csv_header() -> String {
    columns().collect::<Vec<_>>().join(",")
}

/// One CSV record: every field at full precision (the shortest text that
/// reads back to the same number), then `valid` and `flags`.
pub fn csv_record(r: &CycleReport) -> String {
    let mut s = String::new();
    for f in &FIELDS {
        s.push_str(&f.value(r).to_string());
        s.push(',');
    }
    s.push_str(if r.is_valid() { "true" } else { "false" });
    s.push(',');
    s.push_str(&flag_list(r.flags));
    s
}

fn json(v: Value) -> serde_json::Value {
    match v {
        Value::U32(v) => serde_json::json!(v),
        Value::F32(v) => serde_json::json!(v),
        Value::F64(v) => serde_json::json!(v),
    }
}

/// One JSON object: every field by its column name, `valid`, and `flags` as an array of names.
pub fn json_record(r: &CycleReport) -> serde_json::Value {
    let mut m = serde_json::Map::new();
    for f in &FIELDS {
        m.insert(f.name.into(), json(f.value(r)));
    }
    m.insert("valid".into(), r.is_valid().into());
    m.insert("flags".into(), r.flags.names().collect::<Vec<_>>().into());
    serde_json::Value::Object(m)
}

/// Flag names joined by `|`, or `-` when none.
pub fn flag_list(flags: Flags) -> String {
    let names: Vec<&str> = flags.names().collect();
    let unknown = flags.0 & !Flags::NAMES.iter().fold(0, |a, (f, _)| a | f.0);
    let mut s = names.join("|");
    if unknown != 0 {
        if !s.is_empty() {
            s.push('|');
        }
        s.push_str(&format!("0x{unknown:04x}"));
    }
    if s.is_empty() {
        "-".into()
    } else {
        s
    }
}

/// A field as a person reads it: `12.34 ± 1.12` (its uncertainty from the
/// table) at `decimals`, `n/a` when not a number.
pub fn shown(r: &CycleReport, name: &str, decimals: usize) -> String {
    let Some(f) = field(name) else {
        return format!("<no field {name}>");
    };
    let v = f.f64(r);
    if !v.is_finite() {
        return "n/a".into();
    }
    match f.uncertainty.and_then(field).map(|u| u.f64(r)) {
        Some(u) if u.is_finite() => format!("{v:.decimals$} ± {u:.decimals$}"),
        Some(_) => format!("{v:.decimals$} ± n/a"),
        None => format!("{v:.decimals$}"),
    }
}

/// The unit a field is shown in.
pub fn unit(name: &str) -> &'static str {
    field(name).map_or("", |f| f.unit)
}

/// What a report line says, in order: (label, field, decimals). The
/// chambers' feed onsets close it (`n/a` until read: `chambers_unread`).
pub const LINE: [(&str, &str, usize); 9] = [
    ("t", "t_impact_s", 6),
    ("friction", "friction_n", 2),
    ("energy", "impact_energy_j", 3),
    ("w/o friction", "impact_energy_frictionless_j", 3),
    ("", "frequency_hz", 2),
    ("wear", "wear_index_j", 1),
    ("drift", "drift_score", 2),
    ("front feed", "front_feed_s", 6),
    ("rear feed", "rear_feed_s", 6),
];

/// One line per report, for headless runs (the monitor's and the demo's):
/// `cycle     12  t 1.234567 s  friction 12.34 ± 1.12 N  energy 4.616 ± 0.166 J  w/o friction 5.299 ± 0.180 J  21.79 Hz  wear 6.1 J  drift 0.00 σ  front feed 0.001570 ± 0.000036 s  rear feed n/a s  flags -`
pub fn report_line(r: &CycleReport) -> String {
    let mut s = format!("cycle {:>6}", r.seq);
    for (label, name, decimals) in LINE {
        s.push_str("  ");
        if !label.is_empty() {
            s.push_str(label);
            s.push(' ');
        }
        s.push_str(&shown(r, name, decimals));
        s.push(' ');
        s.push_str(unit(name));
    }
    s.push_str("  flags ");
    s.push_str(&flag_list(r.flags));
    if !r.is_valid() {
        s.push_str("  INVALID");
    }
    s
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    fn sample() -> CycleReport {
        CycleReport {
            seq: 12,
            t_impact_us: 1_234_567,
            period_s: 0.047,
            frequency_hz: 21.79,
            friction_n: 12.34,
            friction_uncertainty_n: 1.12,
            impact_energy_j: 4.616,
            impact_energy_uncertainty_j: 0.166,
            impact_energy_frictionless_j: 5.299,
            impact_energy_frictionless_uncertainty_j: 0.18,
            wear_index_j: 6.125,
            flags: Flags::ACCEL_ZERO_SHIFT,
            ..Default::default()
        }
    }

    #[test]
    fn every_record_has_every_field_of_the_report() {
        let r = sample();
        let header = csv_header();
        let record = csv_record(&r);
        assert_eq!(header.split(',').count(), record.split(',').count());
        assert_eq!(header.split(',').count(), FIELDS.len() + 2);
        // Serde's view of the struct: every key but flags is a column, and a column's JSON is the struct's.
        let serde = serde_json::to_value(r).unwrap();
        let json = json_record(&r);
        for (k, v) in serde.as_object().unwrap() {
            if k == "t_impact_us" {
                // The wire's integer µs is the column t_impact_s, in seconds.
                assert_eq!(json["t_impact_s"].as_f64(), Some(v.as_f64().unwrap() / 1e6));
                continue;
            }
            assert!(header.split(',').any(|c| c == k), "{k} is no column");
            if k != "flags" {
                assert_eq!(&json[k], v, "{k}");
            }
        }
        assert_eq!(json["flags"], serde_json::json!(["accel_zero_shift"]));
        assert_eq!(json["valid"], serde_json::json!(true));
        assert!(record.starts_with("12,1.234567,0.047,21.79,12.34,"), "{record}");
        assert!(record.ends_with(",true,accel_zero_shift"), "{record}");
        assert!(header.contains(",wear_index_j,"), "{header}");
    }

    /// The chambers' characteristics (protocol 6) and their units.
    pub const CHAMBERS: [(&str, &str); 18] = [
        ("front_feed_s", "s"),
        ("front_feed_uncertainty_s", "s"),
        ("front_feed_x_m", "m"),
        ("front_feed_p_rear_pa", "Pa"),
        ("front_feed_p_front_pa", "Pa"),
        ("front_closed_exponent", "1"),
        ("front_closed_exponent_uncertainty", "1"),
        ("front_feed_area_m2", "m²"),
        ("front_feed_area_uncertainty_m2", "m²"),
        ("rear_feed_s", "s"),
        ("rear_feed_uncertainty_s", "s"),
        ("rear_feed_x_m", "m"),
        ("rear_feed_p_rear_pa", "Pa"),
        ("rear_feed_p_front_pa", "Pa"),
        ("rear_closed_exponent", "1"),
        ("rear_closed_exponent_uncertainty", "1"),
        ("rear_feed_area_m2", "m²"),
        ("rear_feed_area_uncertainty_m2", "m²"),
    ];

    /// `r` with the front chamber read and the rear read with nothing to
    /// read (NaN), not flagged unread.
    pub fn read_front(r: CycleReport) -> CycleReport {
        let mut r = CycleReport {
            front_feed_s: 1.57e-3,
            front_feed_uncertainty_s: 3.6e-5,
            front_feed_x_m: 0.0412,
            front_feed_p_rear_pa: 2.13e5,
            front_feed_p_front_pa: 1.2e4,
            front_closed_exponent: 1.32,
            front_closed_exponent_uncertainty: 0.021,
            front_feed_area_m2: 1.23e-5,
            front_feed_area_uncertainty_m2: 5.6e-7,
            rear_feed_s: f32::NAN,
            rear_feed_uncertainty_s: f32::NAN,
            rear_feed_x_m: f32::NAN,
            rear_feed_p_rear_pa: f32::NAN,
            rear_feed_p_front_pa: f32::NAN,
            rear_closed_exponent: f32::NAN,
            rear_closed_exponent_uncertainty: f32::NAN,
            rear_feed_area_m2: f32::NAN,
            rear_feed_area_uncertainty_m2: f32::NAN,
            ..r
        };
        r.flags.remove(Flags::CHAMBERS_UNREAD);
        r
    }

    #[test]
    fn the_chambers_are_in_every_record_and_a_nan_reads_back_as_missing() {
        let header: Vec<String> = csv_header().split(',').map(String::from).collect();
        for (name, u) in CHAMBERS {
            assert!(header.iter().any(|c| c == name), "{name} is no CSV column");
            assert_eq!(unit(name), u, "{name}");
        }
        let cells = |r: &CycleReport| -> Vec<(String, String)> {
            header
                .iter()
                .cloned()
                .zip(csv_record(r).split(',').map(String::from))
                .collect()
        };
        let cell = |cells: &[(String, String)], k: &str| cells.iter().find(|(c, _)| c == k).unwrap().1.clone();
        // Unread: every characteristic NaN, "NaN" in the CSV (read back as
        // NaN by Rust, pandas, NumPy), null in the JSON, and flagged.
        let mut unread = sample();
        unread.mark_chambers_unread();
        let (csv, json) = (cells(&unread), json_record(&unread));
        for (name, _) in CHAMBERS {
            assert_eq!(cell(&csv, name), "NaN", "{name}");
            assert!(cell(&csv, name).parse::<f32>().unwrap().is_nan());
            assert!(json[name].is_null(), "{name}: {}", json[name]);
        }
        assert_eq!(cell(&csv, "flags"), "accel_zero_shift|chambers_unread");
        assert_eq!(
            json["flags"],
            serde_json::json!(["accel_zero_shift", "chambers_unread"])
        );
        assert_eq!(json["valid"], serde_json::json!(true), "unread is no invalid cycle");
        // Read: each value at full precision, back to the same bits.
        let r = read_front(sample());
        let (csv, json) = (cells(&r), json_record(&r));
        for (name, _) in CHAMBERS {
            let f = field(name).unwrap();
            let Value::F32(v) = f.value(&r) else { panic!("{name}") };
            let back: f32 = cell(&csv, name).parse().unwrap();
            assert_eq!(back.to_bits(), v.to_bits(), "{name}: {}", cell(&csv, name));
            match json[name].as_f64() {
                Some(j) => assert_eq!(j as f32, v, "{name}"),
                None => assert!(v.is_nan() && json[name].is_null(), "{name}"),
            }
        }
        assert_eq!(cell(&csv, "front_feed_s"), "0.00157");
        assert_eq!(cell(&csv, "rear_feed_s"), "NaN");
        assert_eq!(cell(&csv, "flags"), "accel_zero_shift");
        // The line: the onsets with their U, n/a where not read.
        let line = report_line(&r);
        assert!(
            line.contains("  front feed 0.001570 ± 0.000036 s  rear feed n/a s  flags accel_zero_shift"),
            "{line}"
        );
        let line = report_line(&unread);
        assert!(
            line.contains("  front feed n/a s  rear feed n/a s  flags accel_zero_shift|chambers_unread"),
            "{line}"
        );
    }

    #[test]
    fn the_line_reads_like_the_dashboard() {
        assert_eq!(
            report_line(&sample()),
            "cycle     12  t 1.234567 s  friction 12.34 ± 1.12 N  energy 4.616 ± 0.166 J  \
             w/o friction 5.299 ± 0.180 J  21.79 Hz  wear 6.1 J  drift 0.00 σ  \
             front feed 0.000000 ± 0.000000 s  rear feed 0.000000 ± 0.000000 s  flags accel_zero_shift"
        );
        let bad = CycleReport {
            friction_n: f32::NAN,
            flags: Flags::NO_REVERSAL,
            ..sample()
        };
        let line = report_line(&bad);
        assert!(
            line.contains("friction n/a N") && line.ends_with("flags no_reversal  INVALID"),
            "{line}"
        );
    }
}
