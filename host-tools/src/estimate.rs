//! Per-cycle records of `hammer estimate`: the output formats. Traces are
//! opened for the estimator by `hammer_sim::estimation`, the same crate and
//! code path as the firmware; only the sample source differs. Every format is
//! driven by the one table of report fields (`hammer_types::FIELDS`, through
//! [`crate::records`]): the CSV and JSON carry every field under its
//! unit-suffixed name, the table a selection of them.

use std::fmt::Write as _;

use hammer_estimator::CycleReport;

pub use crate::records::{csv_header, csv_record, json_record as jsonl_record};
use crate::records::{flag_list, shown};

/// The table's columns: (field, decimals, with its uncertainty). The
/// chambers' feed onsets close it, `n/a` where not read (`chambers_unread`).
pub const TABLE: [(&str, usize, bool); 12] = [
    ("seq", 0, false),
    ("t_impact_s", 4, false),
    ("frequency_hz", 3, false),
    ("friction_n", 2, true),
    ("friction_stroke_n", 2, false),
    ("friction_backhaul_n", 2, false),
    ("impact_energy_j", 3, true),
    ("impact_energy_frictionless_j", 3, false),
    ("stroke_m", 4, false),
    ("wear_index_j", 1, false),
    ("front_feed_s", 6, true),
    ("rear_feed_s", 6, true),
];

fn cell(r: &CycleReport, name: &str, decimals: usize, pm: bool) -> String {
    if pm {
        return shown(r, name, decimals);
    }
    match hammer_estimator::fields::field(name).map(|f| f.f64(r)) {
        Some(v) if v.is_finite() => format!("{v:.decimals$}"),
        _ => "n/a".into(),
    }
}

/// A human-readable table (columns named like the CSV's, see [`TABLE`]) with
/// a summary line over the valid cycles.
pub fn table(reports: &[CycleReport]) -> String {
    let rows: Vec<Vec<String>> = reports
        .iter()
        .map(|r| TABLE.iter().map(|&(n, d, pm)| cell(r, n, d, pm)).collect())
        .collect();
    let widths: Vec<usize> = TABLE
        .iter()
        .enumerate()
        .map(|(i, (n, _, _))| rows.iter().map(|row| row[i].chars().count()).fold(n.len(), usize::max))
        .collect();
    let mut s = String::new();
    let line = |s: &mut String, cells: &mut dyn Iterator<Item = String>, flags: &str| {
        for (c, w) in cells.zip(&widths) {
            let pad = w.saturating_sub(c.chars().count());
            let _ = write!(s, "{:pad$}{c} ", "");
        }
        let _ = writeln!(s, " {flags}");
    };
    line(&mut s, &mut TABLE.iter().map(|(n, _, _)| n.to_string()), "flags");
    for (r, row) in reports.iter().zip(rows) {
        line(&mut s, &mut row.into_iter(), &flag_list(r.flags));
    }
    let valid: Vec<&CycleReport> = reports.iter().filter(|r| r.is_valid()).collect();
    if !valid.is_empty() {
        let n = valid.len() as f32;
        let mean = |f: fn(&CycleReport) -> f32| valid.iter().map(|r| f(r)).sum::<f32>() / n;
        let sd = |f: fn(&CycleReport) -> f32| {
            let m = mean(f);
            (valid.iter().map(|r| (f(r) - m).powi(2)).sum::<f32>() / (n - 1.0).max(1.0)).sqrt()
        };
        let _ = writeln!(
            s,
            "summary: {} of {} cycles valid; friction {:.3} N (cycle-to-cycle sd {:.3}), energy {:.4} J (sd {:.4}), friction-blind energy {:.4} J, frequency {:.3} Hz, friction work {:.1} % of impact energy",
            valid.len(),
            reports.len(),
            mean(|r| r.friction_n),
            sd(|r| r.friction_n),
            mean(|r| r.impact_energy_j),
            sd(|r| r.impact_energy_j),
            mean(|r| r.impact_energy_frictionless_j),
            mean(|r| r.frequency_hz),
            100.0 * mean(|r| r.friction_work_ratio)
        );
    } else {
        let _ = writeln!(s, "summary: no valid cycle among {}", reports.len());
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_table_shows_the_feed_onsets_and_n_a_where_unread() {
        let mut unread = CycleReport {
            seq: 1,
            friction_n: 10.0,
            ..Default::default()
        };
        unread.mark_chambers_unread();
        let read = CycleReport {
            seq: 2,
            front_feed_s: 1.57e-3,
            front_feed_uncertainty_s: 3.6e-5,
            rear_feed_s: -2.5e-4,
            rear_feed_uncertainty_s: f32::NAN,
            ..Default::default()
        };
        let t = table(&[unread, read]);
        let lines: Vec<&str> = t.lines().collect();
        assert!(
            lines[0].contains(" front_feed_s ") && lines[0].contains(" rear_feed_s "),
            "{t}"
        );
        let unread: Vec<&str> = lines[1].split_whitespace().collect();
        assert_eq!(unread[unread.len() - 3..], ["n/a", "n/a", "chambers_unread"], "{t}");
        assert!(lines[2].ends_with(" 0.001570 ± 0.000036 -0.000250 ± n/a  -"), "{t}");
    }
}
