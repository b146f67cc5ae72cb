//! The diagnosis in words: `report.md` and the one-screen terminal summary.
//! Pure functions of the [`Report`], so they are unit-tested without files.

use std::fmt::Write as _;

use crate::diagnose::engine::{EffectResult, Report, WhereCell};
use crate::diagnose::report::DetectionFloor;
use crate::numfmt::{bar as fmt_bar, pct, sig3 as num, MISSING};

/// `writeln!` into a `String`, which cannot fail.
macro_rules! line {
    ($s:expr) => {{
        let _ = writeln!($s);
    }};
    ($s:expr, $($t:tt)*) => {{
        let _ = writeln!($s, $($t)*);
    }};
}

mod close_call;
mod evidence;
mod shrink;
use close_call::close_call_md;
use evidence::{chambers_md, force_balance_md, model_free_md};
use shrink::shrink_md;

/// Where cells listed in the Markdown report.
const TOP_WHERE: usize = 10;

/// Catalogue parameters on one line: `key=value, …`, nested objects as `effect.key=value`.
pub(super) fn params_inline(v: &serde_json::Value) -> String {
    fn walk(prefix: &str, v: &serde_json::Value, out: &mut Vec<String>) {
        match v {
            serde_json::Value::Object(m) => {
                for (k, x) in m {
                    let key = if prefix.is_empty() {
                        k.clone()
                    } else {
                        format!("{prefix}.{k}")
                    };
                    walk(&key, x, out);
                }
            }
            serde_json::Value::Number(n) => out.push(format!("{prefix}={}", n.as_f64().map_or(n.to_string(), num))),
            other => out.push(format!("{prefix}={other}")),
        }
    }
    let mut out = Vec::new();
    walk("", v, &mut out);
    out.join(", ")
}

/// How a compared signal is shown: name, factor from SI and unit.
fn signal_display(signal: &str) -> (&str, f64, &'static str) {
    match signal {
        "p_rear_pa" => ("rear pressure", 1e-5, "bar"),
        "p_front_pa" => ("front pressure", 1e-5, "bar"),
        "accel_mps2" => ("acceleration", 1.0, "m/s²"),
        "velocity_mps" => ("velocity", 1.0, "m/s"),
        other => (other, 1.0, ""),
    }
}

/// A value of `signal` with its display unit, e.g. `0.123 bar`.
pub(super) fn with_unit(signal: &str, si: f64) -> String {
    let (_, scale, unit) = signal_display(signal);
    let v = num(si * scale);
    if unit.is_empty() || !si.is_finite() {
        v
    } else {
        format!("{v} {unit}")
    }
}

fn shift_ms(s: f64) -> String {
    if s.is_finite() {
        format!("{:+.2}", s * 1e3)
    } else {
        MISSING.into()
    }
}

/// Table cells must not contain `|` or line breaks.
fn cell(s: &str) -> String {
    s.replace('|', "\\|").replace(['\n', '\r'], " ")
}

/// The verdict's effects joined by ` + `, a close call as `one of (a | b)`;
/// `None` when no effect was named.
pub fn verdict_name(r: &Report) -> Option<String> {
    let mut e: Vec<String> = r
        .verdict
        .effects
        .iter()
        .filter(|e| !e.is_empty() && *e != "none")
        .cloned()
        .collect();
    for g in &r.verdict.alternatives {
        let members: Vec<&str> = g.iter().map(|a| a.effect.as_str()).collect();
        e.push(format!("one of ({})", members.join(" | ")));
    }
    (!e.is_empty()).then(|| e.join(" + "))
}

/// The result the verdict rests on: the named single effect or pair (a
/// close call's first member in it), else the best single effect.
fn top_result(r: &Report) -> Option<&EffectResult> {
    let mut names: Vec<&str> = r.verdict.effects.iter().map(String::as_str).collect();
    names.extend(
        r.verdict
            .alternatives
            .iter()
            .filter_map(|g| Some(g.first()?.effect.as_str())),
    );
    // In either order: a close call may group a pair's first.
    names.sort_unstable();
    let same = |e: &&EffectResult| {
        let mut of: Vec<&str> = e.name.split('+').collect();
        of.sort_unstable();
        of == names
    };
    r.effects
        .iter()
        .chain(&r.pairs)
        .find(same)
        .or_else(|| r.effects.first())
}

fn fitted_params(e: &EffectResult) -> String {
    if e.fitted.is_empty() {
        return MISSING.into();
    }
    e.fitted
        .iter()
        .map(|p| format!("{} = {} ± {}", p.key, num(p.value), num(p.sd)))
        .collect::<Vec<_>>()
        .join(", ")
}

fn where_sentence(c: &WhereCell) -> String {
    let (name, _, _) = signal_display(&c.signal);
    format!(
        "{name} in {} at {} bar: RMS {} ({} % of the signal's RMS), bias {}, best aligned shifted by {} ms",
        c.stage.name(),
        fmt_bar(c.supply_bar),
        with_unit(&c.signal, c.rms),
        pct(100.0 * c.relative_rms),
        with_unit(&c.signal, c.bias),
        shift_ms(c.timing_shift_s),
    )
}

fn bars_list(bars: &[f64]) -> String {
    if bars.is_empty() {
        "none".into()
    } else {
        bars.iter().map(|b| fmt_bar(*b)).collect::<Vec<_>>().join(", ") + " bar"
    }
}

fn effects_table(s: &mut String, results: &[EffectResult]) {
    let _ = writeln!(s, "| rank | effect | score (ΔBIC) | explained, % | fitted parameters |");
    let _ = writeln!(s, "|---:|---|---:|---:|---|");
    for (i, e) in results.iter().enumerate() {
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} | {} |",
            i + 1,
            cell(&e.name),
            num(e.score),
            pct(100.0 * e.explained_fraction),
            cell(&fitted_params(e))
        );
    }
}

/// The Markdown report (also printed by the CLI's summary): pure function, unit-testable.
pub fn markdown(report: &Report, figures: &[String]) -> String {
    let mut s = String::new();
    line!(s, "# Sim-to-real gap diagnosis");
    line!(s);
    line!(s, "Where the measurement and the nominal model differ (by signal and stage of the cycle), which effect of the catalogue explains it, and how far the gap shrinks on held-out data once that effect is in the model.");
    line!(s);

    inputs_md(&mut s, report);
    verdict_md(&mut s, report);
    where_md(&mut s, report);
    which_md(&mut s, report);
    shrink_md(&mut s, report);
    figures_md(&mut s, figures);
    footer_md(&mut s, report);
    s
}

/// The inputs and the fit set.
fn inputs_md(s: &mut String, report: &Report) {
    line!(s, "## Inputs");
    line!(s);
    line!(
        s,
        "| trace | supply, bar | cycles | start-up cycles | fit cycles | held-out cycles |"
    );
    line!(s, "|---|---:|---:|---:|---:|---:|");
    for i in &report.inputs {
        line!(
            s,
            "| {} | {} | {} | {} | {} | {} |",
            cell(&i.label),
            fmt_bar(i.supply_bar),
            i.cycles,
            i.startup_cycles,
            i.fit_cycles,
            i.held_out_cycles
        );
    }
    line!(s);
    if !report.references.is_empty() {
        let refs: Vec<String> = report
            .references
            .iter()
            .map(|r| {
                format!(
                    "{} ({} bar, {} cycles)",
                    cell(&r.label),
                    fmt_bar(r.supply_bar),
                    r.cycles
                )
            })
            .collect();
        line!(
            s,
            "Read as a change from the same hammer's reference record: {}. Each point's features are moved by the nominal model minus the reference's mean, so the model's form error, common to both records, cancels; the energies and frequencies below are the model's plus the measured change.",
            refs.join(", ")
        );
        line!(s);
        let dead: Vec<String> = report
            .dead_volumes
            .iter()
            .map(|d| {
                format!(
                    "{} {:.2} cm³ (configured {:.2} cm³)",
                    d.chamber,
                    1e6 * d.used_m3,
                    1e6 * d.nominal_m3
                )
            })
            .collect();
        if !dead.is_empty() {
            line!(
                s,
                "Both records were read through the dead volumes the reference's closed phases ask for: {}. Near the impact most of the front chamber is dead volume, and a drawing's estimate a tenth off moves a late feed's onset by milliseconds.",
                dead.join(", ")
            );
            line!(s);
        }
    }
    line!(
        s,
        "Fit set: {} ({} cycles); {} features compared; χ² of the nominal model {}.",
        bars_list(&report.fit_points),
        report.fit_cycles,
        report.features_compared,
        num(report.chi2_nominal)
    );
    line!(s);
}

/// The verdict: the named effects, why, and their parameters; then what moved and what is left.
fn verdict_md(s: &mut String, report: &Report) {
    line!(s, "## Verdict");
    line!(s);
    match verdict_name(report) {
        Some(v) => line!(s, "**{v}** (score {} ΔBIC)", num(report.verdict.score)),
        None => line!(
            s,
            "**none**: no effect of the catalogue explains the gap (best single effect's score {} ΔBIC).",
            num(report.verdict.score)
        ),
    }
    line!(s);
    if !report.verdict.reason.is_empty() {
        line!(s, "{}", report.verdict.reason);
        line!(s);
    }
    let params = serde_json::to_string_pretty(&report.verdict.params).unwrap_or_else(|_| "{}".into());
    line!(s, "Parameters, in the catalogue's terms:");
    line!(s);
    line!(s, "```json");
    line!(s, "{params}");
    line!(s, "```");
    line!(s);
    close_call_md(s, report);
    model_free_md(s, report);
    force_balance_md(s, report);
    chambers_md(s, report);
    recalibration_md(s, report);
    remainder_md(s, report);
    floors_md(s, report);
}

/// Where the gap lies: the largest cells against the nominal model.
fn where_md(s: &mut String, report: &Report) {
    line!(s, "## Where the gap lies");
    line!(s);
    match report.where_.first() {
        Some(c) => {
            line!(s, "The largest gap against the nominal model: {}.", where_sentence(c));
            line!(s);
            line!(s,
                "Top {} of {} cells, by RMS relative to the signal's RMS over the simulated cycle (bias: measured − simulated; shift: the measurement's delay that best aligns the stage):",
                report.where_.len().min(TOP_WHERE),
                report.where_.len()
            );
            line!(s);
            line!(
                s,
                "| # | supply, bar | signal | stage | bias | RMS | relative RMS, % | time shift, ms |"
            );
            line!(s, "|---:|---:|---|---|---:|---:|---:|---:|");
            for (k, c) in report.where_.iter().take(TOP_WHERE).enumerate() {
                line!(
                    s,
                    "| {} | {} | {} | {} | {} | {} | {} | {} |",
                    k + 1,
                    fmt_bar(c.supply_bar),
                    cell(signal_display(&c.signal).0),
                    c.stage.name(),
                    with_unit(&c.signal, c.bias),
                    with_unit(&c.signal, c.rms),
                    pct(100.0 * c.relative_rms),
                    shift_ms(c.timing_shift_s)
                );
            }
        }
        None => line!(s, "No gap cells: no measured cycle could be aligned with the model."),
    }
    line!(s);
}

/// Which effect: the ranking, the evidence for the top one, the pairs.
fn which_md(s: &mut String, report: &Report) {
    line!(s, "## Which effect");
    line!(s);
    if report.effects.is_empty() {
        line!(s, "No effect was fitted.");
    } else {
        line!(s, "Score: BIC difference against the nominal model (higher explains more); explained: share of the nominal χ² removed. Parameters are fitted value ± standard deviation.");
        line!(s);
        effects_table(s, &report.effects);
    }
    line!(s);
    if let Some(top) = top_result(report) {
        if !top.evidence.is_empty() {
            line!(s, "Evidence for **{}**:", top.name);
            line!(s);
            for e in &top.evidence {
                line!(s, "- {e}");
            }
            line!(s);
        }
    }
    if !report.pairs.is_empty() {
        line!(s, "### Pairs of effects");
        line!(s);
        effects_table(s, &report.pairs);
        line!(s);
    }
}

/// The figures, each with its alt text.
fn figures_md(s: &mut String, figures: &[String]) {
    if !figures.is_empty() {
        line!(s, "## Figures");
        line!(s);
        line!(s, "Mean measured cycle (blue) against the nominal model (grey) and the fitted model (red), from the impact on; measured cycles are stretched onto the simulated period. Shaded: the gap between measurement and nominal model. The strip at the bottom of each panel shows the stage of the cycle.");
        line!(s);
        for f in figures {
            let alt = f.trim_end_matches(".png").replace('-', " ");
            line!(s, "![{alt}]({f})");
            line!(s);
        }
    }
}

/// The tool, its cost and its time.
fn footer_md(s: &mut String, report: &Report) {
    line!(s, "---");
    line!(s);
    line!(
        s,
        "{}: {} simulations, {} s.",
        report.tool,
        report.simulations,
        if report.elapsed_s.is_finite() {
            format!("{:.1}", report.elapsed_s)
        } else {
            MISSING.into()
        }
    );
}

/// The verdict's second part: the nominal parameters that moved.
fn recalibration_md(s: &mut String, report: &Report) {
    line!(s, "### Recalibrated nominal parameters");
    line!(s);
    if !report.held_nuisance.is_empty() {
        line!(
            s,
            "Held at nominal, not fitted (no fitted feature moved when they did, at any fit point): {}.",
            report.held_nuisance.join(", ")
        );
        line!(s);
    }
    if report.recalibration.is_empty() {
        line!(s, "No recalibration (the nominal parameters were held).");
        line!(s);
        return;
    }
    line!(s,
        "Fitted with the named effects held, each within a prior of ±{} % of its nominal value; **bold**: moved beyond one prior standard deviation.",
        pct(100.0 * report.options.nominal_uncertainty)
    );
    line!(s);
    line!(s, "| parameter | nominal | recalibrated | ± | prior sd moved |");
    line!(s, "|---|---:|---:|---:|---:|");
    for r in &report.recalibration {
        let name = if r.beyond_prior {
            format!("**{}**", r.parameter)
        } else {
            r.parameter.clone()
        };
        line!(
            s,
            "| {name} | {} | {} | {} | {:+.2} |",
            num(r.nominal),
            num(r.value),
            num(r.sd),
            r.prior_sds
        );
    }
    line!(s);
}

/// The verdict's third part: what neither explains, and where.
fn remainder_md(s: &mut String, report: &Report) {
    line!(s, "### Unexplained remainder");
    line!(s);
    if report.remainder.is_empty() {
        line!(s, "None above 10 % of a signal's RMS in any stage: the model's form matches the hammer's where it was measured.");
        line!(s);
        return;
    }
    line!(
        s,
        "After the recalibrated model with the named effects, by signal × stage (largest first):"
    );
    line!(s);
    for r in &report.remainder {
        line!(
            s,
            "- {} bar: {} (nominal model: {} %)",
            fmt_bar(r.supply_bar),
            r.statement,
            pct(100.0 * r.relative_rms_nominal)
        );
    }
    if !report.model_form.is_empty() {
        let groups: Vec<String> = report
            .model_form
            .iter()
            .map(|m| format!("{} ×{}", m.group, num(m.factor)))
            .collect();
        line!(s);
        line!(s,
            "Model-form factors (the recalibrated nominal model's residual over the noise and floors; these features were weighed down by them, the force balance was not): {}.",
            groups.join(", ")
        );
    }
    line!(s);
}

/// How large each effect the force balance cannot see would have to be to
/// be named: what a `none` (or the named effects) cannot exclude.
fn floors_md(s: &mut String, report: &Report) {
    if unnamed_floors(report).next().is_none() {
        return;
    }
    line!(s, "### What could hide in the remainder");
    line!(s);
    line!(
        s,
        "The weakest magnitude at which each effect not named would have been named on this data (one the force balance sees: its signature there at {} standard errors; one it cannot see: its signature in the waveforms against what is unexplained, by the naming rule):",
        num(report.options.min_model_free_z)
    );
    line!(s);
    for f in unnamed_floors(report) {
        line!(s, "- {}", f.statement);
    }
    line!(s);
}

/// The floors of the effects the verdict did not name: a named effect is
/// not hiding.
fn unnamed_floors(report: &Report) -> impl Iterator<Item = &DetectionFloor> {
    report
        .detection_floors
        .iter()
        .filter(|f| !report.verdict.effects.contains(&f.effect))
}

/// The floors in one line: the magnitude each effect could have and not be named.
fn floors_inline(report: &Report) -> String {
    unnamed_floors(report)
        .map(|f| match f.value {
            Some(v) => format!(
                "{} {} {} {}",
                f.effect,
                f.parameter,
                if f.stronger_above { "<" } else { ">" },
                num(v)
            ),
            None => format!("{} at any {}", f.effect, f.parameter),
        })
        .collect::<Vec<_>>()
        .join(", ")
}

/// One-screen terminal summary: verdict, top 3 'where' cells, top 3 effects, shrink line.
pub fn summary(report: &Report) -> String {
    let mut s = String::new();
    if !report.references.is_empty() {
        line!(
            s,
            "read as a change from {} reference record(s) of the same hammer",
            report.references.len()
        );
    }
    match verdict_name(report) {
        Some(v) => line!(s, "verdict: {v} (score {} ΔBIC)", num(report.verdict.score)),
        None => line!(
            s,
            "verdict: none (best single effect's score {} ΔBIC)",
            num(report.verdict.score)
        ),
    }
    if !report.verdict.reason.is_empty() {
        line!(s, "  {}", report.verdict.reason);
    }
    if report.verdict.params.as_object().is_some_and(|o| !o.is_empty()) {
        line!(s, "  params: {}", params_inline(&report.verdict.params));
    }
    let moved: Vec<String> = report
        .recalibration
        .iter()
        .filter(|r| r.beyond_prior)
        .map(|r| format!("{} {} → {} ± {}", r.parameter, num(r.nominal), num(r.value), num(r.sd)))
        .collect();
    line!(
        s,
        "recalibrated: {}",
        if moved.is_empty() {
            "no nominal parameter beyond its prior".to_string()
        } else {
            moved.join("; ")
        }
    );
    match report.remainder.first() {
        Some(r) => line!(s, "unexplained: {} ({} bar)", r.statement, fmt_bar(r.supply_bar)),
        None => line!(s, "unexplained: nothing above 10 % of a signal's RMS"),
    }
    if unnamed_floors(report).next().is_some() {
        line!(s, "could hide unnamed: {}", floors_inline(report));
    }
    if !report.where_.is_empty() {
        line!(s, "where the gap lies:");
        for (k, c) in report.where_.iter().take(3).enumerate() {
            line!(s, "  {}. {}", k + 1, where_sentence(c));
        }
    }
    if !report.effects.is_empty() {
        line!(s, "which effect (score ΔBIC, explained, force-balance z):");
        for (k, e) in report.effects.iter().take(3).enumerate() {
            line!(
                s,
                "  {}. {:<22} {:>9}  {:>5} %  {:>6}  {}",
                k + 1,
                e.name,
                num(e.score),
                pct(100.0 * e.explained_fraction),
                e.model_free_z.map_or_else(|| "-".to_string(), num),
                fitted_params(e)
            );
        }
    }
    let sh = &report.shrink;
    line!(s,
        "shrink: impact energy error {} % nominal, {} % recalibrated, {} % with the effects ({} % with them in the nominal model); frequency error {} % → {} % (held out: {})",
        pct(sh.impact_energy_error_before),
        pct(sh.impact_energy_error_recalibrated_only),
        pct(sh.impact_energy_error_after),
        pct(sh.impact_energy_error_effects_only),
        pct(sh.frequency_error_before),
        pct(sh.frequency_error_after),
        bars_list(&sh.held_out_points)
    );
    if let Some(c) = sh.caution() {
        line!(s, "caution: {c}");
    }
    s
}
