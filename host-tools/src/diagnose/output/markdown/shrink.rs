//! The held-out check's section of `report.md`: how far the gap shrinks
//! at the points the fit did not see, against the nominal model, the
//! recalibration alone and the named effects alone.

use std::fmt::Write as _;

use super::{bars_list, signal_display};
use crate::diagnose::engine::Report;
use crate::diagnose::gap::SIGNALS;
use crate::numfmt::{bar as fmt_bar, pct, sig3 as num};

/// How far the gap shrinks on the held-out data.
pub(super) fn shrink_md(s: &mut String, report: &Report) {
    let sh = &report.shrink;
    line!(s, "## How far it shrinks");
    line!(s);
    line!(
        s,
        "Mean |simulated − measured| / measured, nominal model → recalibrated model with the named effects:"
    );
    line!(s);
    line!(
        s,
        "- impact energy error: {} % → {} %",
        pct(sh.impact_energy_error_before),
        pct(sh.impact_energy_error_after)
    );
    line!(
        s,
        "- frequency error: {} % → {} %",
        pct(sh.frequency_error_before),
        pct(sh.frequency_error_after)
    );
    line!(
        s,
        "- control, the nominal parameters recalibrated and no effect added: impact energy error {} %",
        pct(sh.impact_energy_error_recalibrated_only)
    );
    line!(
        s,
        "- the named effects in the nominal model, nothing recalibrated: impact energy error {} %",
        pct(sh.impact_energy_error_effects_only)
    );
    if !sh.refitted.is_empty() {
        let sizes: Vec<String> = sh
            .refitted
            .iter()
            .map(|p| format!("{} = {:.4e}", p.key, p.value))
            .collect();
        line!(
            s,
            "- the check's model has the waveform-only sizes refitted with the nominal parameters on the fit points: {}",
            sizes.join(", ")
        );
    }
    if let Some(c) = sh.caution() {
        line!(s);
        line!(s, "**Caution:** {c}.");
    }
    line!(s);
    line!(
        s,
        "Judged on {}. Held-out operating points: {}.",
        sh.judged_on,
        bars_list(&sh.held_out_points)
    );
    line!(s);
    if !sh.points.is_empty() {
        // Signals in their usual order, then any other.
        let mut signals: Vec<&str> = SIGNALS
            .iter()
            .copied()
            .filter(|k| {
                sh.points
                    .iter()
                    .any(|p| p.rms_before.contains_key(*k) || p.rms_after.contains_key(*k))
            })
            .collect();
        for p in &sh.points {
            for k in p.rms_before.keys().chain(p.rms_after.keys()) {
                if !signals.contains(&k.as_str()) {
                    signals.push(k);
                }
            }
        }
        let mut head = String::from(
            "| supply, bar | held out | cycles | impact energy, J (measured / nominal / fitted) | frequency, Hz (measured / nominal / fitted) |",
        );
        let mut rule = String::from("|---:|---|---:|---|---|");
        for k in &signals {
            let (name, _, unit) = signal_display(k);
            let _ = write!(head, " RMS {name}, {unit} (nominal → fitted) |");
            rule.push_str("---|");
        }
        line!(s, "Per operating point (RMS of the binned waveform residual):");
        line!(s);
        line!(s, "{head}");
        line!(s, "{rule}");
        for p in &sh.points {
            let mut row = format!(
                "| {} | {} | {} | {} / {} / {} | {} / {} / {} |",
                fmt_bar(p.supply_bar),
                if p.held_out_point { "yes" } else { "no" },
                p.cycles,
                num(p.impact_energy_measured_j),
                num(p.impact_energy_nominal_j),
                num(p.impact_energy_fitted_j),
                num(p.frequency_measured_hz),
                num(p.frequency_nominal_hz),
                num(p.frequency_fitted_hz),
            );
            for k in &signals {
                let (_, scale, _) = signal_display(k);
                let get = |m: &std::collections::BTreeMap<String, f64>| m.get(*k).map_or(f64::NAN, |v| v * scale);
                let _ = write!(row, " {} → {} |", num(get(&p.rms_before)), num(get(&p.rms_after)));
            }
            line!(s, "{row}");
        }
        line!(s);
    }
}
