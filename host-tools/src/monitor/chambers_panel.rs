//! The dashboard's panel of the latest report's chambers (protocol 6): each
//! chamber's feed onset, closed-phase exponent and feed area with their
//! expanded uncertainty, one row per chamber, so a maintenance person sees
//! how the valve fed them in the cycle just reported. Units as the drift
//! panel's (`crate::drift::unit_of`: ms, mm²).

use hammer_estimator::fields::field;
use hammer_estimator::{CycleReport, Flags};
use ratatui::style::{Style, Stylize};
use ratatui::text::{Line, Span};
use ratatui::widgets::{Block, Paragraph};

/// The panel's columns: (header, field after the chamber's `front_`/`rear_`, decimals).
const COLUMNS: [(&str, &str, usize); 3] = [
    ("feed onset", "feed_s", 3),
    ("closed exponent", "closed_exponent", 3),
    ("feed area", "feed_area_m2", 2),
];

/// A column's width: the widest value (`-12.345 ± 0.036 ms`) and a gap.
const WIDTH: usize = 20;

/// One characteristic as shown, `1.570 ± 0.036 ms`; `n/a (unread)` where
/// the board did not read the chambers (`chambers_unread`), `n/a` where it
/// read them and this chamber showed nothing to read.
pub fn cell(r: &CycleReport, name: &str, decimals: usize) -> String {
    let Some(f) = field(name) else {
        return format!("<no field {name}>");
    };
    let (scale, unit) = crate::drift::unit_of(name);
    let v = f.f64(r) * scale;
    if !v.is_finite() {
        let unread = r.flags.contains(Flags::CHAMBERS_UNREAD);
        return if unread { "n/a (unread)" } else { "n/a" }.into();
    }
    let u = f.uncertainty.and_then(field).map_or(f64::NAN, |u| u.f64(r) * scale);
    let u = if u.is_finite() {
        format!("{u:.decimals$}")
    } else {
        "n/a".into()
    };
    format!("{v:.decimals$} ± {u}{unit}")
}

/// The panel of `last`, the latest report (none yet: says so).
pub fn chambers_panel(last: Option<&CycleReport>) -> Paragraph<'static> {
    let Some(r) = last else {
        let block = Block::bordered().title(" Chambers ");
        return Paragraph::new(Line::from("waiting for the first report…").dim()).block(block);
    };
    let block = Block::bordered().title(format!(" Chambers, cycle {} ", r.seq));
    let mut header = vec![Span::raw(format!("{:<7}", ""))];
    header.extend(COLUMNS.iter().map(|(h, _, _)| Span::raw(format!("{h:<WIDTH$}")).dim()));
    let mut lines = vec![Line::from(header)];
    for chamber in ["front", "rear"] {
        let mut spans = vec![Span::raw(format!("{chamber:<7}"))];
        for (_, name, decimals) in COLUMNS {
            let text = cell(r, &format!("{chamber}_{name}"), decimals);
            let style = if text.starts_with("n/a") {
                Style::new().dim()
            } else {
                Style::new().bold()
            };
            spans.push(Span::styled(format!("{text:<WIDTH$}"), style));
        }
        lines.push(Line::from(spans));
    }
    Paragraph::new(lines).block(block)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_cell_scales_to_the_drift_panels_units_and_says_n_a_and_why() {
        let mut r = CycleReport {
            front_feed_s: 1.57e-3,
            front_feed_uncertainty_s: 3.6e-5,
            front_closed_exponent: 1.32,
            front_closed_exponent_uncertainty: 0.021,
            front_feed_area_m2: 1.23e-5,
            front_feed_area_uncertainty_m2: f32::NAN,
            rear_feed_s: f32::NAN,
            ..Default::default()
        };
        assert_eq!(cell(&r, "front_feed_s", 3), "1.570 ± 0.036 ms");
        assert_eq!(cell(&r, "front_closed_exponent", 3), "1.320 ± 0.021");
        assert_eq!(cell(&r, "front_feed_area_m2", 2), "12.30 ± n/a mm²");
        assert_eq!(cell(&r, "rear_feed_s", 3), "n/a", "read, nothing to read");
        r.mark_chambers_unread();
        assert_eq!(cell(&r, "front_feed_s", 3), "n/a (unread)");
        assert_eq!(cell(&r, "no_such_field", 3), "<no field no_such_field>");
    }
}
