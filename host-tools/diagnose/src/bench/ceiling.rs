//! What the evidence against the model alone can reach on the benchmark's
//! hammers, whatever rule reads it: the ceiling the scoring against the
//! detection floors is measured under.
//!
//! Without a reference, an effect the force balance cannot see has two
//! kinds of evidence. The waveforms, read through each effect's law: the
//! diagnosis names the law that fits best, so it can name the hidden
//! effect only where that is its own law (a preference of one law over
//! another would trade cases where their roles are reversed, and be set
//! on the benchmark's hammers). And the chamber characteristics, read against
//! the nominal model: there they carry the hammer's form as well as the
//! effect, and the no-effect controls measure how far the form alone
//! moves them. A change within that span is not evidence of an effect.

use serde::{Deserialize, Serialize};

use super::summary::above_floor;
use super::{CaseResult, Hidden};

#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct ModelAloneCeiling {
    /// Single unseen effects hidden at or beyond their floor: (those whose
    /// own law explains the largest share of the gap of every effect's, all).
    pub best_fit: (usize, usize),
    /// The others: (case, the effect whose law fitted better).
    pub fitted_better: Vec<(usize, String)>,
    /// Each chamber characteristic's change from the nominal model in the
    /// no-effect controls, and the singles at or beyond their floor whose
    /// change lies outside it.
    pub form_spans: Vec<FormSpan>,
}

#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct FormSpan {
    pub feature: String,
    /// The controls' smallest and largest change (measured − nominal).
    pub controls: (f64, f64),
    /// (case, hidden effect, change) outside the controls' span.
    pub outside: Vec<(usize, String, f64)>,
}

/// The ceiling over `cases` (a benchmark without references: against a
/// record the characteristics measure a change, not the form).
pub fn model_alone_ceiling(cases: &[CaseResult]) -> ModelAloneCeiling {
    let beyond: Vec<(&CaseResult, &str)> = cases
        .iter()
        .filter(|c| above_floor(c) == Some(true))
        .filter_map(|c| match &c.hidden {
            Hidden::One(name) => Some((c, name.as_str())),
            _ => None,
        })
        .collect();
    let mut ceiling = ModelAloneCeiling {
        best_fit: (0, beyond.len()),
        ..Default::default()
    };
    for (c, name) in &beyond {
        let best = c
            .ranking
            .iter()
            .max_by(|a, b| a.explained_fraction.total_cmp(&b.explained_fraction));
        match best {
            Some(b) if b.name == *name => ceiling.best_fit.0 += 1,
            Some(b) => ceiling.fitted_better.push((c.index, b.name.clone())),
            None => {}
        }
    }
    let controls: Vec<&CaseResult> = cases.iter().filter(|c| c.hidden == Hidden::None).collect();
    let change = |c: &CaseResult, feature: &str| {
        c.chambers
            .iter()
            .find(|m| m.feature == feature && m.read)
            .map(|m| m.measured - m.nominal)
            .filter(|d| d.is_finite())
    };
    let features: Vec<String> = controls
        .first()
        .map(|c| c.chambers.iter().map(|m| m.feature.clone()).collect())
        .unwrap_or_default();
    for feature in features {
        let span = controls
            .iter()
            .filter_map(|c| change(c, &feature))
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), d| (lo.min(d), hi.max(d)));
        if !span.0.is_finite() {
            continue;
        }
        let outside = beyond
            .iter()
            .filter_map(|(c, name)| {
                let d = change(c, &feature)?;
                (d < span.0 || d > span.1).then(|| (c.index, name.to_string(), d))
            })
            .collect();
        ceiling.form_spans.push(FormSpan {
            feature,
            controls: span,
            outside,
        });
    }
    ceiling
}

/// The ceiling as lines of the benchmark's text page.
pub fn render(out: &mut String, c: &ModelAloneCeiling) {
    use std::fmt::Write as _;
    let (best, all) = c.best_fit;
    let better: Vec<String> = c
        .fitted_better
        .iter()
        .map(|(i, name)| format!("case {i}: {name}"))
        .collect();
    let _ = writeln!(
        out,
        "  of those at or beyond it, the hidden effect's own law fitted best in {best} of {all}: naming the law that fits best names no more (another law fitted better in {})",
        if better.is_empty() { "none".into() } else { better.join(", ") }
    );
    let _ = writeln!(
        out,
        "  chamber characteristics against the nominal model, the no-effect controls' span (the form alone) and the cases at or beyond their floor outside it:"
    );
    for s in &c.form_spans {
        let outside: Vec<String> = s
            .outside
            .iter()
            .map(|(i, name, d)| format!("case {i} ({name}) {d:+.4e}"))
            .collect();
        let _ = writeln!(
            out,
            "    {:<24} {:+.4e} … {:+.4e}   {}",
            s.feature,
            s.controls.0,
            s.controls.1,
            if outside.is_empty() {
                "none".into()
            } else {
                outside.join(", ")
            }
        );
    }
}

/// The oracle's lines (`diagnose-bench --oracle`): of the singles whose
/// truth was checked, how many truths pass the rule that names an effect,
/// and of those the diagnosis left `none` or named wrong, which the
/// features held (the truth passes: a miss) and which they did not (the
/// truth fails too: the ceiling of these features under this rule).
pub fn render_oracle(out: &mut String, cases: &[CaseResult]) {
    use std::fmt::Write as _;
    let checked: Vec<(&CaseResult, &crate::report::OracleCheck)> =
        cases.iter().filter_map(|c| Some((c, c.oracle.as_ref()?))).collect();
    if checked.is_empty() {
        return;
    }
    let passes = checked.iter().filter(|(_, o)| o.passes).count();
    let _ = writeln!(
        out,
        "\nthe oracle (each single's truth in the model, its nominal values settled from the true ones, against them refitted without any effect, by the confirm stage's rule): the truth passes in {passes} of {}",
        checked.len()
    );
    let missed: Vec<_> = checked
        .iter()
        .filter(|(c, _)| matches!(c.outcome, super::Outcome::None | super::Outcome::Wrong))
        .collect();
    let line = |pass: bool| -> Vec<String> {
        missed
            .iter()
            .filter(|(_, o)| o.passes == pass)
            .map(|(c, o)| {
                format!(
                    "case {} {} ({}): adds {:.1}, explains {:.0} %",
                    c.index,
                    o.effect,
                    c.outcome.label(),
                    o.score,
                    100.0 * o.explained_fraction
                )
            })
            .collect()
    };
    let (held, ceiling) = (line(true), line(false));
    let list = |v: &[String]| if v.is_empty() { "none".to_string() } else { v.join("; ") };
    let _ = writeln!(
        out,
        "  singles left none or named wrong: {}; the truth passes (the features held it, the diagnosis missed it) in {}: {}",
        missed.len(),
        held.len(),
        list(&held)
    );
    let _ = writeln!(
        out,
        "  the truth fails too (the ceiling of these features under this rule) in {}: {}",
        ceiling.len(),
        list(&ceiling)
    );
}
