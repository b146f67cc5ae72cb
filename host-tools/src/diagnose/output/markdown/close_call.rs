//! A close call in the report: the group's members side by side, and the
//! tests that would part them.

use std::fmt::Write as _;

use super::{cell, params_inline};
use crate::diagnose::engine::Report;
use crate::numfmt::{pct, sig3 as num};

/// A close call: each member's size, score and held-out check, and what
/// would part them.
pub(super) fn close_call_md(s: &mut String, report: &Report) {
    for g in &report.verdict.alternatives {
        line!(s, "### A close call: one of {}", g.len());
        line!(s);
        line!(
            s,
            "The signals cannot part these effects here: each fits within the close-call margin of the other and no model-free evidence tells them apart. Each member's held-out check is run with it in the model."
        );
        line!(s);
        line!(
            s,
            "| effect | score (ΔBIC) | held-out energy error, % | held-out frequency error, % | parameters |"
        );
        line!(s, "|---|---:|---:|---:|---|");
        for a in g {
            line!(
                s,
                "| {} | {} | {} | {} | {} |",
                cell(&a.effect),
                num(a.score),
                pct(a.impact_energy_error_after),
                pct(a.frequency_error_after),
                cell(&params_inline(&a.params))
            );
        }
        line!(s);
        line!(s, "What would part them:");
        line!(s);
        for a in g {
            if let Some(t) = &a.parting_test {
                line!(s, "- for {}: {t}", a.effect);
            }
        }
        line!(s);
    }
    if let Some(p) = &report.verdict.parted {
        let scores: Vec<String> = p
            .group
            .iter()
            .zip(&p.alone_scores)
            .map(|(e, sc)| format!("{e} {}", sc.map_or_else(|| "not fitted".into(), num)))
            .collect();
        line!(s, "### A close call of the change, parted by the model alone");
        line!(s);
        line!(
            s,
            "Against the record, the change could not part {}. The same traces fitted by the model alone name {} outright, with no close call of their own (scores, ΔBIC: {}): together the two readings part the group, and {} is named.",
            p.group.join(" and "),
            p.group[0],
            scores.join(", "),
            p.group[0]
        );
        line!(s);
    }
}
