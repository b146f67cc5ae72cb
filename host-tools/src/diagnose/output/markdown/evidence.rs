//! The report's tables of evidence measured from the signals: the force
//! balance, and the chamber characteristics, each against the nominal model.

use std::fmt::Write as _;

use crate::diagnose::engine::Report;
use crate::diagnose::report::ModelFreeStat;
use crate::numfmt::{bar as fmt_bar, sig3 as num};

/// The force balance against the nominal model: the evidence no valve or
/// port model stands behind.
pub(super) fn model_free_md(s: &mut String, report: &Report) {
    let note = format!("Fit points' mean; z = (measured − nominal) / standard error; an effect the force balance sees is named only at z ≥ {}.", num(report.options.min_model_free_z));
    stats_md(
        s,
        "Model-free evidence (the force balance)",
        &note,
        "measured",
        &report.model_free,
    );
}

/// The chamber characteristics against the nominal model, or their change
/// since the reference: where the gap lies in physical terms, true also
/// when no effect can be named.
pub(super) fn chambers_md(s: &mut String, report: &Report) {
    let stats = &report.chambers;
    if stats.is_empty() {
        return;
    }
    let opt = |v: Option<f64>| v.map_or_else(|| "–".to_string(), num);
    // A measured column of a characteristic no fit point read.
    let measured = |m: &ModelFreeStat, v: f64| if m.read { num(v) } else { "not read".to_string() };
    let (note, header, rows): (&str, &[&str], Vec<Vec<String>>) = if report.references.is_empty() {
        (
            "Fit points' mean, read from the pressures and the piston's track with no valve or port model (docs/estimator.md). Against the model alone a difference includes the model's form error; what the recalibrated model (its uncertain parameters refitted, no effect) still misses is the form's or an effect's.",
            &["measured", "nominal model", "recalibrated model", "measured − nominal", "±", "z"],
            stats
                .iter()
                .map(|m| {
                    vec![
                        measured(m, m.measured),
                        num(m.nominal),
                        opt(m.recalibrated),
                        measured(m, m.measured - m.nominal),
                        num(m.se),
                        measured(m, m.z),
                    ]
                })
                .collect(),
        )
    } else {
        (
            "Fit points' mean. The change since the reference record is the evidence (the hammer's form cancels); the models' columns say how far the model's form is from this hammer.",
            &["reference record", "now", "change", "±", "z", "nominal model", "recalibrated model"],
            stats
                .iter()
                .map(|m| {
                    let change = m.measured - m.nominal;
                    vec![
                        opt(m.reference),
                        if m.read {
                            opt(m.reference.map(|r| r + change))
                        } else {
                            "not read".to_string()
                        },
                        measured(m, change),
                        num(m.se),
                        measured(m, m.z),
                        num(m.nominal),
                        opt(m.recalibrated),
                    ]
                })
                .collect(),
        )
    };
    line!(
        s,
        "### Chamber characteristics (valve switching, fills, closed phases, the front exhaust's floor)"
    );
    line!(s);
    line!(s, "{note}");
    line!(s);
    line!(s, "| quantity | {} |", header.join(" | "));
    line!(s, "|---|{}", "---:|".repeat(header.len()));
    for (m, row) in stats.iter().zip(rows) {
        line!(s, "| {} | {} |", m.feature, row.join(" | "));
    }
    line!(s);
}

/// A table of features against the nominal model under `title`; `measured`
/// heads the measurement's column.
fn stats_md(s: &mut String, title: &str, note: &str, measured: &str, stats: &[ModelFreeStat]) {
    if stats.is_empty() {
        return;
    }
    line!(s, "### {title}");
    line!(s);
    line!(s, "{note}");
    line!(s);
    line!(s, "| quantity | {measured} | nominal model | ± | z |");
    line!(s, "|---|---:|---:|---:|---:|");
    for m in stats {
        line!(
            s,
            "| {} | {} | {} | {} | {} |",
            m.feature,
            num(m.measured),
            num(m.nominal),
            num(m.se),
            num(m.z)
        );
    }
    line!(s);
}

/// The force balance at every operating point, with U.
pub(super) fn force_balance_md(s: &mut String, report: &Report) {
    let Some(first) = report.force_balance.first() else {
        return;
    };
    line!(s, "### The force balance at every operating point");
    line!(s);
    line!(
        s,
        "Each quantity is the change since {} (value ± U, U = 2u: the cycles' scatter over their number{}). The force balance needs no valve or port law: the sizes of friction, viscous friction, a gain error and a zero shift are taken from it.",
        if first.against_record { "the record" } else { "the nominal model" },
        if first.against_record { " and the record's" } else { "" }
    );
    line!(s);
    let keys: Vec<&str> = first.quantities.iter().map(|q| q.key.as_str()).collect();
    line!(s, "| supply, bar | fitted | {} |", keys.join(" | "));
    line!(s, "|---:|---|{}", "---:|".repeat(keys.len()));
    for row in &report.force_balance {
        let vals: Vec<String> = row
            .quantities
            .iter()
            .map(|q| format!("{} ± {}", num(q.value), num(q.expanded_u)))
            .collect();
        line!(
            s,
            "| {} | {} | {} |",
            fmt_bar(row.supply_bar),
            if row.fit_point { "yes" } else { "held out" },
            vals.join(" | ")
        );
    }
    line!(s);
}
