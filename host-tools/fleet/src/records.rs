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

/// What a report line says, in order: (label, field, decimals).
pub const LINE: [(&str, &str, usize); 7] = [
    ("t", "t_impact_s", 6),
    ("friction", "friction_n", 2),
    ("energy", "impact_energy_j", 3),
    ("w/o friction", "impact_energy_frictionless_j", 3),
    ("", "frequency_hz", 2),
    ("wear", "wear_index_j", 1),
    ("drift", "drift_score", 2),
];

/// One line per report, for headless runs (the monitor's and the demo's):
/// `cycle     12  t 1.234567 s  friction 12.34 ± 1.12 N  energy 4.616 ± 0.166 J  w/o friction 5.299 ± 0.180 J  21.79 Hz  wear 6.1 J  drift 0.00 σ  flags -`
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
mod tests {
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

    #[test]
    fn the_line_reads_like_the_dashboard() {
        assert_eq!(
            report_line(&sample()),
            "cycle     12  t 1.234567 s  friction 12.34 ± 1.12 N  energy 4.616 ± 0.166 J  \
             w/o friction 5.299 ± 0.180 J  21.79 Hz  wear 6.1 J  drift 0.00 σ  flags accel_zero_shift"
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
