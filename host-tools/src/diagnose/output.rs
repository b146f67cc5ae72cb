//! The output of `hammer diagnose`: `report.json` (the [`Report`] as is),
//! `report.md` (the same for people) and one figure per operating point,
//! `gap-<bar>bar.png`: the measured mean cycle against the nominal and the
//! fitted model, the gap between measurement and nominal model shaded.
//!
//! Units in the Markdown: pressures in bar, acceleration in m/s², velocity in
//! m/s, times in ms, energies in J, frequencies in Hz.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::sync::Once;

use anyhow::{anyhow, Context, Result};
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use super::engine::{EffectResult, Outcome, PointWaves, Report, WhereCell};
use super::gap::SIGNALS;
use super::stages::Stage;
use crate::plot::{BLUE, EFFECT, NOMINAL};

/// Pixel size of the gap figures.
pub const FIGURE_SIZE: (u32, u32) = (1200, 1000);

/// Where cells listed in the Markdown report.
const TOP_WHERE: usize = 10;

/// Acceleration panel: the y range is taken from the samples after this
/// time since the impact (the shock clips the accelerometer before it).
const ACCEL_LIMITS_FROM_MS: f64 = 1.5;

/// Writes DIR/report.json, DIR/report.md and DIR/gap-<bar>bar.png per operating point; returns the paths written.
///
/// Order: report.json, the figures, report.md (written last: it links the figures).
pub fn write_all(dir: &Path, outcome: &Outcome) -> Result<Vec<PathBuf>> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let mut written = Vec::new();

    let json_path = dir.join("report.json");
    let json = serde_json::to_string_pretty(&outcome.report).context("serializing the diagnosis report")?;
    std::fs::write(&json_path, json + "\n").with_context(|| format!("writing {}", json_path.display()))?;
    written.push(json_path);

    let fitted_label = verdict_name(&outcome.report);
    let mut figures = Vec::new();
    for pw in &outcome.waves {
        let name = figure_name(pw.supply_bar);
        let path = dir.join(&name);
        gap_png(&path, pw, fitted_label.as_deref()).with_context(|| format!("drawing {}", path.display()))?;
        figures.push(name);
        written.push(path);
    }

    let md_path = dir.join("report.md");
    std::fs::write(&md_path, markdown(&outcome.report, &figures))
        .with_context(|| format!("writing {}", md_path.display()))?;
    written.push(md_path);
    Ok(written)
}

/// `gap-4bar.png`, `gap-5.5bar.png`.
pub fn figure_name(supply_bar: f64) -> String {
    format!("gap-{}bar.png", fmt_bar(supply_bar))
}

/// A supply pressure without trailing zeros: `4`, `5.5`, `6.25`.
fn fmt_bar(bar: f64) -> String {
    if !bar.is_finite() {
        return "unknown".into();
    }
    let r = (bar * 100.0).round() / 100.0;
    // `-0` would print as "-0".
    format!("{}", if r == 0.0 { 0.0 } else { r })
}

/// Three significant digits, plain notation where it reads well; `–` when not finite.
fn num(x: f64) -> String {
    if !x.is_finite() {
        return "–".into();
    }
    let a = x.abs();
    if a == 0.0 {
        "0".into()
    } else if !(1e-3..1e5).contains(&a) {
        format!("{x:.2e}")
    } else {
        let decimals = (2.0 - a.log10().floor()).max(0.0) as usize;
        format!("{x:.decimals$}")
    }
}

/// A percentage (`x` already in %): one decimal, two below 1 %.
fn pct(x: f64) -> String {
    if !x.is_finite() {
        "–".into()
    } else if x != 0.0 && x.abs() < 1.0 {
        format!("{x:.2}")
    } else {
        format!("{x:.1}")
    }
}

/// Catalogue parameters on one line: `key=value, …`, nested objects as `effect.key=value`.
fn params_inline(v: &serde_json::Value) -> String {
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
fn with_unit(signal: &str, si: f64) -> String {
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
        "–".into()
    }
}

/// Table cells must not contain `|` or line breaks.
fn cell(s: &str) -> String {
    s.replace('|', "\\|").replace(['\n', '\r'], " ")
}

/// The verdict's effects joined by ` + `, `None` when no effect was named.
fn verdict_name(r: &Report) -> Option<String> {
    let e: Vec<&str> = r
        .verdict
        .effects
        .iter()
        .map(String::as_str)
        .filter(|e| !e.is_empty() && *e != "none")
        .collect();
    (!e.is_empty()).then(|| e.join(" + "))
}

/// The result the verdict rests on: the named single effect or pair, else the best single effect.
fn top_result(r: &Report) -> Option<&EffectResult> {
    let joined = r.verdict.effects.join("+");
    r.effects
        .iter()
        .chain(&r.pairs)
        .find(|e| e.name == joined)
        .or_else(|| r.effects.first())
}

fn fitted_params(e: &EffectResult) -> String {
    if e.fitted.is_empty() {
        return "–".into();
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
    macro_rules! line {
        ($($t:tt)*) => {{ let _ = writeln!(s, $($t)*); }};
    }
    line!("# Sim-to-real gap diagnosis");
    line!();
    line!("Where the measurement and the nominal model differ (by signal and stage of the cycle), which effect of the catalogue explains it, and how far the gap shrinks on held-out data once that effect is in the model.");
    line!();

    // Inputs.
    line!("## Inputs");
    line!();
    line!("| trace | supply, bar | cycles | start-up cycles | fit cycles | held-out cycles |");
    line!("|---|---:|---:|---:|---:|---:|");
    for i in &report.inputs {
        line!(
            "| {} | {} | {} | {} | {} | {} |",
            cell(&i.label),
            fmt_bar(i.supply_bar),
            i.cycles,
            i.startup_cycles,
            i.fit_cycles,
            i.held_out_cycles
        );
    }
    line!();
    line!(
        "Fit set: {} ({} cycles); {} features compared; χ² of the nominal model {}.",
        bars_list(&report.fit_points),
        report.fit_cycles,
        report.features_compared,
        num(report.chi2_nominal)
    );
    line!();

    // Verdict.
    line!("## Verdict");
    line!();
    match verdict_name(report) {
        Some(v) => line!("**{v}** (score {} ΔBIC)", num(report.verdict.score)),
        None => line!(
            "**none**: no effect of the catalogue explains the gap (best single effect's score {} ΔBIC).",
            num(report.verdict.score)
        ),
    }
    line!();
    if !report.verdict.reason.is_empty() {
        line!("{}", report.verdict.reason);
        line!();
    }
    let params = serde_json::to_string_pretty(&report.verdict.params).unwrap_or_else(|_| "{}".into());
    line!("Parameters, in the catalogue's terms:");
    line!();
    line!("```json");
    line!("{params}");
    line!("```");
    line!();
    recalibration_md(&mut s, report);
    remainder_md(&mut s, report);

    // Where.
    line!("## Where the gap lies");
    line!();
    match report.where_.first() {
        Some(c) => {
            line!("The largest gap against the nominal model: {}.", where_sentence(c));
            line!();
            line!(
                "Top {} of {} cells, by RMS relative to the signal's RMS over the simulated cycle (bias: measured − simulated; shift: the measurement's delay that best aligns the stage):",
                report.where_.len().min(TOP_WHERE),
                report.where_.len()
            );
            line!();
            line!("| # | supply, bar | signal | stage | bias | RMS | relative RMS, % | time shift, ms |");
            line!("|---:|---:|---|---|---:|---:|---:|---:|");
            for (k, c) in report.where_.iter().take(TOP_WHERE).enumerate() {
                line!(
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
        None => line!("No gap cells: no measured cycle could be aligned with the model."),
    }
    line!();

    // Which effect.
    line!("## Which effect");
    line!();
    if report.effects.is_empty() {
        line!("No effect was fitted.");
    } else {
        line!("Score: BIC difference against the nominal model (higher explains more); explained: share of the nominal χ² removed. Parameters are fitted value ± standard deviation.");
        line!();
        effects_table(&mut s, &report.effects);
    }
    line!();
    if let Some(top) = top_result(report) {
        if !top.evidence.is_empty() {
            line!("Evidence for **{}**:", top.name);
            line!();
            for e in &top.evidence {
                line!("- {e}");
            }
            line!();
        }
    }
    if !report.pairs.is_empty() {
        line!("### Pairs of effects");
        line!();
        effects_table(&mut s, &report.pairs);
        line!();
    }

    // Shrink.
    let sh = &report.shrink;
    line!("## How far it shrinks");
    line!();
    line!("Mean |simulated − measured| / measured, nominal model → recalibrated model with the named effects:");
    line!();
    line!(
        "- impact energy error: {} % → {} %",
        pct(sh.impact_energy_error_before),
        pct(sh.impact_energy_error_after)
    );
    line!(
        "- frequency error: {} % → {} %",
        pct(sh.frequency_error_before),
        pct(sh.frequency_error_after)
    );
    line!(
        "- control, the nominal parameters recalibrated and no effect added: impact energy error {} %",
        pct(sh.impact_energy_error_recalibrated_only)
    );
    line!();
    line!(
        "Judged on {}. Held-out operating points: {}.",
        sh.judged_on,
        bars_list(&sh.held_out_points)
    );
    line!();
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
        line!("Per operating point (RMS of the binned waveform residual):");
        line!();
        line!("{head}");
        line!("{rule}");
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
            line!("{row}");
        }
        line!();
    }

    // Figures.
    if !figures.is_empty() {
        line!("## Figures");
        line!();
        line!("Mean measured cycle (blue) against the nominal model (grey) and the fitted model (red), from the impact on; measured cycles are stretched onto the simulated period. Shaded: the gap between measurement and nominal model. The strip at the bottom of each panel shows the stage of the cycle.");
        line!();
        for f in figures {
            let alt = f.trim_end_matches(".png").replace('-', " ");
            line!("![{alt}]({f})");
            line!();
        }
    }

    line!("---");
    line!();
    line!(
        "{}: {} simulations, {} s.",
        report.tool,
        report.simulations,
        if report.elapsed_s.is_finite() {
            format!("{:.1}", report.elapsed_s)
        } else {
            "–".into()
        }
    );
    s
}

/// The verdict's second part: the nominal parameters that moved.
fn recalibration_md(s: &mut String, report: &Report) {
    macro_rules! line {
        ($($t:tt)*) => {{ let _ = writeln!(s, $($t)*); }};
    }
    line!("### Recalibrated nominal parameters");
    line!();
    if report.recalibration.is_empty() {
        line!("No recalibration (the nominal parameters were held).");
        line!();
        return;
    }
    line!(
        "Fitted with the named effects held, each within a prior of ±{} % of its nominal value; **bold**: moved beyond one prior standard deviation.",
        pct(100.0 * report.options.nominal_uncertainty)
    );
    line!();
    line!("| parameter | nominal | recalibrated | ± | prior sd moved |");
    line!("|---|---:|---:|---:|---:|");
    for r in &report.recalibration {
        let name = if r.beyond_prior {
            format!("**{}**", r.parameter)
        } else {
            r.parameter.clone()
        };
        line!(
            "| {name} | {} | {} | {} | {:+.2} |",
            num(r.nominal),
            num(r.value),
            num(r.sd),
            r.prior_sds
        );
    }
    line!();
}

/// The verdict's third part: what neither explains, and where.
fn remainder_md(s: &mut String, report: &Report) {
    macro_rules! line {
        ($($t:tt)*) => {{ let _ = writeln!(s, $($t)*); }};
    }
    line!("### Unexplained remainder");
    line!();
    if report.remainder.is_empty() {
        line!("None above 10 % of a signal's RMS in any stage: the model's form matches the hammer's where it was measured.");
        line!();
        return;
    }
    line!("After the recalibrated model with the named effects, by signal × stage (largest first):");
    line!();
    for r in &report.remainder {
        line!(
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
        line!();
        line!(
            "Model-form factors (the recalibrated nominal model's residual over the noise and floors; these features were weighed down by them, the force balance was not): {}.",
            groups.join(", ")
        );
    }
    line!();
}

/// One-screen terminal summary: verdict, top 3 'where' cells, top 3 effects, shrink line.
pub fn summary(report: &Report) -> String {
    let mut s = String::new();
    macro_rules! line {
        ($($t:tt)*) => {{ let _ = writeln!(s, $($t)*); }};
    }
    match verdict_name(report) {
        Some(v) => line!("verdict: {v} (score {} ΔBIC)", num(report.verdict.score)),
        None => line!(
            "verdict: none (best single effect's score {} ΔBIC)",
            num(report.verdict.score)
        ),
    }
    if !report.verdict.reason.is_empty() {
        line!("  {}", report.verdict.reason);
    }
    if report.verdict.params.as_object().is_some_and(|o| !o.is_empty()) {
        line!("  params: {}", params_inline(&report.verdict.params));
    }
    let moved: Vec<String> = report
        .recalibration
        .iter()
        .filter(|r| r.beyond_prior)
        .map(|r| format!("{} {} → {} ± {}", r.parameter, num(r.nominal), num(r.value), num(r.sd)))
        .collect();
    line!(
        "recalibrated: {}",
        if moved.is_empty() {
            "no nominal parameter beyond its prior".to_string()
        } else {
            moved.join("; ")
        }
    );
    match report.remainder.first() {
        Some(r) => line!("unexplained: {} ({} bar)", r.statement, fmt_bar(r.supply_bar)),
        None => line!("unexplained: nothing above 10 % of a signal's RMS"),
    }
    if !report.where_.is_empty() {
        line!("where the gap lies:");
        for (k, c) in report.where_.iter().take(3).enumerate() {
            line!("  {}. {}", k + 1, where_sentence(c));
        }
    }
    if !report.effects.is_empty() {
        line!("which effect (score ΔBIC, explained):");
        for (k, e) in report.effects.iter().take(3).enumerate() {
            line!(
                "  {}. {:<22} {:>9}  {:>5} %  {}",
                k + 1,
                e.name,
                num(e.score),
                pct(100.0 * e.explained_fraction),
                fitted_params(e)
            );
        }
    }
    let sh = &report.shrink;
    line!(
        "shrink: impact energy error {} % nominal, {} % recalibrated, {} % with the effects; frequency error {} % → {} % (held out: {})",
        pct(sh.impact_energy_error_before),
        pct(sh.impact_energy_error_recalibrated_only),
        pct(sh.impact_energy_error_after),
        pct(sh.frequency_error_before),
        pct(sh.frequency_error_after),
        bars_list(&sh.held_out_points)
    );
    s
}

// ---------------------------------------------------------------- figures

static FONT: Once = Once::new();

/// Same font as `crate::plot`: figures render alike without system fonts.
fn register_font() {
    FONT.call_once(|| {
        let _ = plotters::style::register_font("sans-serif", FontStyle::Normal, dejavu::sans::regular());
    });
}

fn plot_err<E: std::fmt::Display>(e: E) -> anyhow::Error {
    anyhow!("{e}")
}

/// Light colors of the stages for the strip under each panel.
fn stage_color(s: Stage) -> RGBColor {
    match s {
        Stage::StrokeIntake => RGBColor(158, 202, 225),
        Stage::StrokeClosed => RGBColor(107, 174, 214),
        Stage::StrokeVenting => RGBColor(66, 146, 198),
        Stage::Impact => RGBColor(90, 90, 90),
        Stage::BackhaulFed => RGBColor(253, 174, 107),
        Stage::BackhaulCushion => RGBColor(253, 141, 60),
        Stage::BackhaulVented => RGBColor(230, 85, 13),
    }
}

/// Shading of the gap between measurement and nominal model.
const GAP: RGBColor = RGBColor(31, 119, 180);
const GAP_ALPHA: f64 = 0.25;

struct GapPanel<'a> {
    y_label: &'a str,
    measured: Vec<f64>,
    nominal: Vec<f64>,
    fitted: Option<Vec<f64>>,
    /// Take the y range only from samples after this time, ms.
    limits_from_ms: Option<f64>,
}

/// `x` resampled onto `len` samples spanning the same cycle (linear; NaN propagates).
fn resample(x: &[f64], len: usize) -> Vec<f64> {
    if x.len() == len {
        return x.to_vec();
    }
    match x.len() {
        0 => vec![f64::NAN; len],
        1 => vec![x[0]; len],
        n => {
            let scale = (n - 1) as f64 / (len.max(2) - 1) as f64;
            (0..len)
                .map(|i| {
                    let t = i as f64 * scale;
                    let k = (t.floor() as usize).min(n - 2);
                    let f = t - k as f64;
                    x[k] * (1.0 - f) + x[k + 1] * f
                })
                .collect()
        }
    }
}

/// Runs of consecutive points where `x` and every `ys` are finite.
fn finite_runs(x: &[f64], ys: &[&[f64]]) -> Vec<std::ops::Range<usize>> {
    let n = ys.iter().map(|y| y.len()).fold(x.len(), usize::min);
    let mut out = Vec::new();
    let mut start = None;
    for i in 0..n {
        let ok = x[i].is_finite() && ys.iter().all(|y| y[i].is_finite());
        match (ok, start) {
            (true, None) => start = Some(i),
            (false, Some(s)) => {
                out.push(s..i);
                start = None;
            }
            _ => {}
        }
    }
    if let Some(s) = start {
        out.push(s..n);
    }
    out
}

/// Indices of `r` at most every `step`-th, the last one included: bitmap
/// lines of many points per pixel come out thick and jagged.
fn thinned(r: std::ops::Range<usize>, step: usize) -> Vec<usize> {
    let last = r.end.checked_sub(1).filter(|l| *l >= r.start);
    let mut idx: Vec<usize> = r.step_by(step.max(1)).collect();
    if let Some(l) = last {
        if idx.last() != Some(&l) {
            idx.push(l);
        }
    }
    idx
}

/// Finite range of `values` with `margin` of the span on each side; never empty or infinite.
fn padded_range(values: impl Iterator<Item = f64>, margin: f64) -> (f64, f64) {
    let (lo, hi) = values
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| (lo.min(v), hi.max(v)));
    if !(lo.is_finite() && hi.is_finite()) {
        return (0.0, 1.0);
    }
    let span = hi - lo;
    let pad = if span > 0.0 {
        margin * span
    } else {
        0.5 * lo.abs().max(1e-3)
    };
    (lo - pad, hi + pad)
}

/// Draws the figure of one operating point.
fn gap_png(path: &Path, pw: &PointWaves, fitted_label: Option<&str>) -> Result<()> {
    register_font();
    let n = pw.t_s.len();
    let t_ms: Vec<f64> = pw.t_s.iter().map(|t| t * 1e3).collect();
    let fitted = pw.fitted.as_ref().filter(|f| !f.is_empty());
    let scaled = |x: &[f64], scale: f64| -> Vec<f64> { resample(x, n).iter().map(|v| v * scale).collect() };
    let panel = |y_label, signal: usize, scale: f64, limits_from_ms| GapPanel {
        y_label,
        measured: scaled(pw.measured.get(signal), scale),
        nominal: scaled(pw.nominal.get(signal), scale),
        // The fitted cycle has its own period: stretched onto the nominal one like the measurement.
        fitted: fitted.map(|f| scaled(f.get(signal), scale)),
        limits_from_ms,
    };
    let panels = [
        panel("rear pressure, bar", 0, 1e-5, None),
        panel("front pressure, bar", 1, 1e-5, None),
        panel("acceleration, m/s²", 2, 1.0, Some(ACCEL_LIMITS_FROM_MS)),
        panel("velocity, m/s", 3, 1.0, None),
    ];
    let x_range = {
        let (lo, hi) = padded_range(t_ms.iter().copied(), 0.0);
        if hi > lo {
            (lo, hi)
        } else {
            (0.0, 1.0)
        }
    };

    let fitted_name = fitted_label.unwrap_or("model");
    let mut title = format!("gap at {} bar: measured vs nominal model", fmt_bar(pw.supply_bar));
    if fitted.is_some() {
        let _ = write!(title, " and fitted {fitted_name}");
    }
    let fitted_legend = format!("fitted: {fitted_name}");
    let root = BitMapBackend::new(path, FIGURE_SIZE).into_drawing_area();
    root.fill(&WHITE).map_err(plot_err)?;
    let font = if title.chars().count() > 100 { 17 } else { 22 };
    let root = root.titled(&title, ("sans-serif", font)).map_err(plot_err)?;
    let areas = root.split_evenly((panels.len(), 1));
    for (i, (p, area)) in panels.iter().zip(&areas).enumerate() {
        let last = i + 1 == panels.len();
        draw_panel(area, p, &t_ms, &pw.stages, x_range, last, i == 0, &fitted_legend)?;
    }
    root.present()
        .map_err(plot_err)
        .with_context(|| format!("writing {}", path.display()))
}

/// One panel; the first carries the stage names and the legend.
#[allow(clippy::too_many_arguments)]
fn draw_panel(
    area: &DrawingArea<BitMapBackend<'_>, Shift>,
    p: &GapPanel,
    t_ms: &[f64],
    stages: &[Stage],
    (x0, x1): (f64, f64),
    last: bool,
    first: bool,
    fitted_label: &str,
) -> Result<()> {
    let mut curves: Vec<&[f64]> = vec![&p.measured, &p.nominal];
    if let Some(f) = &p.fitted {
        curves.push(f);
    }
    let from = p.limits_from_ms.unwrap_or(f64::NEG_INFINITY);
    let margin = if p.limits_from_ms.is_some() { 0.10 } else { 0.05 };
    let (y0, mut y1) = padded_range(
        curves
            .iter()
            .flat_map(|c| t_ms.iter().zip(c.iter()).filter(|(t, _)| **t > from).map(|(_, y)| *y)),
        margin,
    );
    // Room for the stage strip at the bottom and the legend.
    let strip = 0.05 * (y1 - y0);
    let y0 = y0 - strip;
    y1 += 0.02 * (y1 - y0);
    // Off-scale samples (the shock in the acceleration panel) break the lines rather than run along the edge.
    let on_scale = |c: &[f64]| -> Vec<f64> {
        c.iter()
            .map(|&y| if (y0..=y1).contains(&y) { y } else { f64::NAN })
            .collect()
    };
    let measured = on_scale(&p.measured);
    let nominal = on_scale(&p.nominal);
    let fitted = p.fitted.as_deref().map(on_scale);
    let tick = |v: &f64| format!("{}", (v * 1e6).round() / 1e6);
    // About two points per pixel column.
    let step = t_ms.len().div_ceil(2 * FIGURE_SIZE.0 as usize).max(1);

    let mut ctx = ChartBuilder::on(area)
        .margin(8)
        .x_label_area_size(if last { 40 } else { 22 })
        .y_label_area_size(75)
        .build_cartesian_2d(x0..x1, y0..y1)
        .map_err(plot_err)?;
    let mut mesh = ctx.configure_mesh();
    mesh.y_desc(p.y_label)
        .label_style(("sans-serif", 13))
        .x_label_formatter(&tick)
        .y_label_formatter(&tick)
        .light_line_style(WHITE.mix(0.0));
    if last {
        mesh.x_desc("time since impact, ms (cycles stretched onto the nominal period)");
    }
    mesh.draw().map_err(plot_err)?;

    // Stage strip.
    let n_st = stages.len().min(t_ms.len());
    let mut runs: Vec<(Stage, f64, f64)> = Vec::new();
    for i in 0..n_st {
        let (t, s) = (t_ms[i], stages[i]);
        if !t.is_finite() {
            continue;
        }
        let t_end = t_ms.get(i + 1).copied().filter(|x| x.is_finite()).unwrap_or(t);
        match runs.last_mut() {
            Some(r) if r.0 == s => r.2 = t_end,
            _ => runs.push((s, t, t_end)),
        }
    }
    let strip_top = y0 + 0.6 * strip;
    ctx.draw_series(
        runs.iter()
            .map(|&(s, a, b)| Rectangle::new([(a, y0), (b, strip_top)], stage_color(s).mix(0.9).filled())),
    )
    .map_err(plot_err)?;
    if first {
        let ink = BLACK.mix(0.75);
        let style = TextStyle::from(("sans-serif", 12).into_font())
            .color(&ink)
            .pos(Pos::new(HPos::Center, VPos::Bottom));
        let min_width = 0.085 * (x1 - x0);
        ctx.draw_series(
            runs.iter()
                .filter(|r| r.2 - r.1 >= min_width)
                .map(|&(s, a, b)| Text::new(s.name(), (0.5 * (a + b), strip_top + 0.3 * strip), style.clone())),
        )
        .map_err(plot_err)?;
    }

    // The gap between measurement and nominal model.
    let gap_fill = GAP.mix(GAP_ALPHA).filled();
    let mut labelled = false;
    for r in finite_runs(t_ms, &[&measured, &nominal]) {
        if r.len() < 2 {
            continue;
        }
        let idx = thinned(r, step);
        let mut poly: Vec<(f64, f64)> = idx.iter().map(|&i| (t_ms[i], measured[i])).collect();
        poly.extend(idx.iter().rev().map(|&i| (t_ms[i], nominal[i])));
        let anno = ctx
            .draw_series(std::iter::once(Polygon::new(poly, gap_fill)))
            .map_err(plot_err)?;
        if !std::mem::replace(&mut labelled, true) {
            anno.label("gap to nominal")
                .legend(move |(x, y)| Rectangle::new([(x, y - 6), (x + 18, y + 6)], gap_fill));
        }
    }

    // The curves: nominal, measured, and the fitted model dashed on top (it may cover the measurement).
    let mut lines: Vec<(&str, RGBColor, &[f64], bool)> = vec![
        ("nominal model", NOMINAL, &nominal, false),
        ("measured (mean cycle)", BLUE, &measured, false),
    ];
    if let Some(f) = &fitted {
        lines.push((fitted_label, EFFECT, f, true));
    }
    for (label, color, y, dashed) in lines {
        let style = color.stroke_width(2);
        let mut unlabelled = true;
        for r in finite_runs(t_ms, &[y]) {
            let pts: Vec<(f64, f64)> = thinned(r, step).into_iter().map(|i| (t_ms[i], y[i])).collect();
            let anno = if dashed {
                ctx.draw_series(DashedLineSeries::new(pts, 9, 6, style))
            } else {
                ctx.draw_series(LineSeries::new(pts, style))
            }
            .map_err(plot_err)?;
            if std::mem::take(&mut unlabelled) {
                anno.label(label).legend(move |(x, y)| {
                    let to = if dashed { x + 8 } else { x + 18 };
                    PathElement::new(vec![(x, y), (to, y)], style)
                });
            }
        }
    }
    if !first {
        return Ok(());
    }
    ctx.configure_series_labels()
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK.mix(0.3))
        .label_font(("sans-serif", 13))
        .position(SeriesLabelPosition::UpperRight)
        .draw()
        .map_err(plot_err)
}

#[cfg(test)]
mod tests {
    use std::collections::BTreeMap;

    use super::super::engine::{
        EffectResult, FittedParam, InputInfo, Options, PointShrink, Report, Shrink, Verdict, WhereCell,
    };
    use super::super::gap::CycleSignals;
    use super::super::model::Candidate;
    use super::*;

    fn effect(name: &str, score: f64, explained: f64, value: f64) -> EffectResult {
        EffectResult {
            name: name.into(),
            params: serde_json::json!({ "force_n": value }),
            fitted: vec![FittedParam {
                key: format!("{name}.force_n"),
                value,
                sd: 0.05,
            }],
            chi2: 12.0,
            score,
            explained_fraction: explained,
            evidence: vec![format!("force balance: evidence for {name}")],
            simulations: 10,
            candidate: Candidate::default(),
        }
    }

    fn report() -> Report {
        let rms = |x: f64| -> BTreeMap<String, f64> { SIGNALS.iter().map(|s| (s.to_string(), x)).collect() };
        Report {
            tool: "hammer diagnose test".into(),
            inputs: vec![InputInfo {
                label: "run-4bar.trace".into(),
                supply_bar: 4.0,
                cycles: 30,
                startup_cycles: 3,
                fit_cycles: 14,
                held_out_cycles: 13,
            }],
            fit_points: vec![4.0],
            where_: vec![
                WhereCell {
                    supply_bar: 4.0,
                    signal: "p_rear_pa".into(),
                    stage: Stage::StrokeClosed,
                    bias: -5_000.0,
                    rms: 12_000.0,
                    relative_rms: 0.083,
                    timing_shift_s: 2.0e-4,
                },
                WhereCell {
                    supply_bar: 4.0,
                    signal: "accel_mps2".into(),
                    stage: Stage::BackhaulFed,
                    bias: 3.0,
                    rms: 20.0,
                    relative_rms: f64::NAN,
                    timing_shift_s: f64::INFINITY,
                },
            ],
            effects: vec![
                effect("coulomb_friction", 1234.5, 0.87, 2.3),
                effect("viscous_friction", 100.0, 0.2, 0.4),
            ],
            pairs: vec![effect("coulomb_friction+leakage", 1200.0, 0.88, 1.0)],
            verdict: Verdict {
                effects: vec!["coulomb_friction".into()],
                params: serde_json::json!({ "force_n": 2.3 }),
                score: 1234.5,
                reason: "explains 87 % of the nominal chi2".into(),
            },
            recalibration: vec![],
            remainder: vec![],
            model_form: vec![],
            shrink: Shrink {
                impact_energy_error_before: 12.34,
                impact_energy_error_after: 1.23,
                frequency_error_before: 5.0,
                frequency_error_after: 0.4,
                impact_energy_error_recalibrated_only: 7.5,
                held_out_points: vec![],
                judged_on: "the later half of the cycles".into(),
                points: vec![PointShrink {
                    supply_bar: 4.0,
                    held_out_point: false,
                    cycles: 13,
                    impact_energy_measured_j: 1.0,
                    impact_energy_nominal_j: 1.12,
                    impact_energy_fitted_j: 1.01,
                    impact_energy_recalibrated_j: 0.95,
                    frequency_measured_hz: 30.0,
                    frequency_nominal_hz: 31.5,
                    frequency_fitted_hz: 30.1,
                    rms_before: rms(1000.0),
                    rms_after: rms(f64::NAN),
                }],
            },
            chi2_nominal: 1500.0,
            features_compared: 200,
            fit_cycles: 14,
            options: Options::default(),
            simulations: 321,
            elapsed_s: 4.25,
        }
    }

    /// A synthetic cycle: pressures rising, an impact spike, velocity NaN in the first ms.
    fn cycle(n: usize, dt: f64, gain: f64) -> CycleSignals {
        let t: Vec<f64> = (0..n).map(|k| k as f64 * dt).collect();
        let w = (1e-3 / dt).round() as usize;
        CycleSignals {
            dt_s: dt,
            p_rear_pa: t.iter().map(|t| gain * 3e5 * (1.0 - (-t * 200.0).exp())).collect(),
            p_front_pa: t.iter().map(|t| gain * 2e5 * (t * 150.0).sin().abs()).collect(),
            accel_mps2: t
                .iter()
                .enumerate()
                .map(|(k, t)| {
                    if k < w {
                        -2.0e4
                    } else {
                        gain * 300.0 * (t * 200.0).cos()
                    }
                })
                .collect(),
            velocity_mps: t
                .iter()
                .enumerate()
                .map(|(k, t)| {
                    if k < w {
                        f64::NAN
                    } else {
                        gain * 3.0 * (t * 200.0).sin()
                    }
                })
                .collect(),
        }
    }

    fn waves(bar: f64, fitted: bool) -> PointWaves {
        let (n, dt) = (3000, 1e-5);
        let t_s: Vec<f64> = (0..n).map(|k| k as f64 * dt).collect();
        let stages = t_s
            .iter()
            .map(|&t| match t {
                t if t < 1e-3 => Stage::Impact,
                t if t < 8e-3 => Stage::BackhaulFed,
                t if t < 14e-3 => Stage::BackhaulCushion,
                t if t < 17e-3 => Stage::BackhaulVented,
                t if t < 22e-3 => Stage::StrokeIntake,
                t if t < 27e-3 => Stage::StrokeClosed,
                _ => Stage::StrokeVenting,
            })
            .collect();
        let mut measured = cycle(n, dt, 1.1);
        measured.p_rear_pa[100] = f64::NAN;
        measured.accel_mps2[2000] = f64::INFINITY;
        PointWaves {
            supply_bar: bar,
            t_s,
            stages,
            measured,
            nominal: cycle(n, dt, 1.0),
            // A different length: the fitted cycle has its own period.
            fitted: fitted.then(|| cycle(3100, dt, 1.08)),
        }
    }

    #[test]
    fn numbers_read_well() {
        assert_eq!(fmt_bar(4.0), "4");
        assert_eq!(fmt_bar(5.5), "5.5");
        assert_eq!(fmt_bar(6.25), "6.25");
        assert_eq!(figure_name(5.5), "gap-5.5bar.png");
        assert_eq!(num(0.0), "0");
        assert_eq!(num(123.456), "123");
        assert_eq!(num(0.012345), "0.0123");
        assert_eq!(num(-2.345), "-2.35");
        assert_eq!(num(f64::NAN), "–");
        assert_eq!(with_unit("p_rear_pa", 12_000.0), "0.120 bar");
    }

    #[test]
    fn markdown_names_verdict_where_and_shrink() {
        let md = markdown(&report(), &["gap-4bar.png".to_string()]);
        assert!(md.contains("**coulomb_friction** (score 1234 ΔBIC)"), "{md}");
        assert!(md.contains("explains 87 % of the nominal chi2"));
        assert!(md.contains("\"force_n\": 2.3"));
        // The top where cell, in the sentence and the table.
        assert!(
            md.contains("rear pressure in stroke_closed at 4 bar: RMS 0.120 bar (8.3 %"),
            "{md}"
        );
        assert!(md.contains("| 1 | 4 | rear pressure | stroke_closed | -0.0500 bar | 0.120 bar | 8.3 | +0.20 |"));
        // Effects, evidence, pairs.
        assert!(
            md.contains("| 1 | coulomb_friction | 1234 | 87.0 | coulomb_friction.force_n = 2.30 ± 0.0500 |"),
            "{md}"
        );
        assert!(md.contains("- force balance: evidence for coulomb_friction"));
        assert!(!md.contains("evidence for viscous_friction"));
        assert!(md.contains("### Pairs of effects"));
        // Shrink.
        assert!(md.contains("impact energy error: 12.3 % → 1.2 %"));
        assert!(md.contains("frequency error: 5.0 % → 0.40 %"));
        assert!(
            md.contains("| 4 | no | 13 | 1.00 / 1.12 / 1.01 | 30.0 / 31.5 / 30.1 | 0.0100 → – |"),
            "{md}"
        );
        assert!(md.contains("![gap 4bar](gap-4bar.png)"));
        assert!(md.contains("321 simulations, 4.2 s") || md.contains("321 simulations, 4.3 s"));
        // Non-finite numbers are shown, not panicked on.
        assert!(md.contains("| – | – |"));
    }

    #[test]
    fn markdown_and_summary_of_an_empty_report() {
        let mut r = report();
        r.where_.clear();
        r.effects.clear();
        r.pairs.clear();
        r.shrink.points.clear();
        r.verdict = Verdict {
            effects: vec!["none".into()],
            params: serde_json::json!({}),
            score: f64::NAN,
            reason: String::new(),
        };
        let md = markdown(&r, &[]);
        assert!(md.contains("**none**"));
        assert!(md.contains("No gap cells"));
        let s = summary(&r);
        assert!(s.starts_with("verdict: none"));
    }

    #[test]
    fn summary_fits_one_screen() {
        let s = summary(&report());
        assert!(s.starts_with("verdict: coulomb_friction"));
        assert!(s.contains("1. rear pressure in stroke_closed at 4 bar"));
        assert!(
            s.contains("impact energy error 12.3 % nominal, 7.5 % recalibrated, 1.2 % with the effects"),
            "{s}"
        );
        assert!(s.contains("  params: force_n=2.30\n"), "{s}");
        assert!(s.contains("recalibrated: no nominal parameter beyond its prior"), "{s}");
        assert!(s.contains("unexplained: nothing above 10 %"), "{s}");
        assert_eq!(
            params_inline(&serde_json::json!({"a": {"x": 1.5, "on": true}, "b": {"y": 0.012345}})),
            "a.on=true, a.x=1.50, b.y=0.0123"
        );
        assert!(s.lines().count() <= 24, "{s}");
    }

    #[test]
    fn write_all_writes_json_markdown_and_figures() {
        let dir = std::env::temp_dir().join(format!("hammer-diagnose-output-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let outcome = Outcome {
            report: report(),
            waves: vec![waves(4.0, true), waves(5.5, false)],
        };
        let written = write_all(&dir, &outcome).unwrap();
        assert_eq!(written.len(), 4, "{written:?}");
        for name in ["gap-4bar.png", "gap-5.5bar.png"] {
            let png = dir.join(name);
            assert!(written.contains(&png));
            let bytes = std::fs::read(&png).unwrap();
            assert!(bytes.len() > 1000);
            assert_eq!(&bytes[1..4], b"PNG");
            // Width and height from the IHDR chunk.
            let w = u32::from_be_bytes(bytes[16..20].try_into().unwrap());
            let h = u32::from_be_bytes(bytes[20..24].try_into().unwrap());
            assert_eq!((w, h), FIGURE_SIZE);
        }
        let json: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(dir.join("report.json")).unwrap()).unwrap();
        for key in ["where", "effects", "verdict", "shrink"] {
            assert!(json.get(key).is_some(), "{key} missing");
        }
        assert_eq!(json["verdict"]["effects"][0], "coulomb_friction");
        assert!(json["effects"][0].get("candidate").is_none());
        let md = std::fs::read_to_string(dir.join("report.md")).unwrap();
        assert!(md.contains("![gap 5.5bar](gap-5.5bar.png)"));
        if std::env::var_os("KEEP_DIAGNOSE_OUTPUT").is_none() {
            let _ = std::fs::remove_dir_all(&dir);
        }
    }

    #[test]
    fn degenerate_waves_do_not_panic() {
        let dir = std::env::temp_dir().join(format!("hammer-diagnose-degenerate-{}", std::process::id()));
        let empty = CycleSignals {
            dt_s: 1e-5,
            p_rear_pa: vec![],
            p_front_pa: vec![],
            accel_mps2: vec![],
            velocity_mps: vec![],
        };
        let mut nan = cycle(50, 1e-5, 1.0);
        nan.p_rear_pa.iter_mut().for_each(|x| *x = f64::NAN);
        let mut r = report();
        r.where_.clear();
        let outcome = Outcome {
            report: r,
            waves: vec![
                PointWaves {
                    supply_bar: 3.0,
                    t_s: vec![],
                    stages: vec![],
                    measured: empty.clone(),
                    nominal: empty.clone(),
                    fitted: Some(empty),
                },
                PointWaves {
                    supply_bar: f64::NAN,
                    t_s: (0..50).map(|k| k as f64 * 1e-5).collect(),
                    stages: vec![Stage::Impact; 10],
                    measured: nan.clone(),
                    nominal: nan,
                    fitted: None,
                },
            ],
        };
        let written = write_all(&dir, &outcome).unwrap();
        assert!(written.iter().all(|p| p.exists()));
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// End to end on simulated data: `KEEP_DIAGNOSE_OUTPUT=1 cargo test --release -p hammer-host --lib
    /// diagnose::output -- --ignored` and look at the figures in the temporary directory.
    #[test]
    #[ignore = "runs the whole diagnosis (seconds to minutes)"]
    fn end_to_end_on_simulated_friction() {
        use super::super::engine::{diagnose, MeasuredInput};
        use hammer_sim::simulate::simulate;
        use hammer_sim::SimConfig;
        let mut inputs = Vec::new();
        for bar in [4.0, 5.5, 7.0] {
            let mut c = SimConfig::nominal(bar);
            c.solver.duration_s = 1.0;
            c.seed = 5;
            c.effects.apply_spec("coulomb_friction").unwrap();
            let sim = simulate(&c).unwrap();
            inputs.push(MeasuredInput {
                label: format!("friction at {bar} bar"),
                supply_bar: bar,
                trace: sim.trace(),
                fit: bar != 5.5,
            });
        }
        let out = diagnose(&inputs, &SimConfig::default(), &Options::default(), &|_, _, _| {}).unwrap();
        let dir = std::env::temp_dir().join(format!("hammer-diagnose-e2e-{}", std::process::id()));
        let written = write_all(&dir, &out).unwrap();
        println!("{}", summary(&out.report));
        println!("{written:?}");
        assert_eq!(written.len(), 2 + out.waves.len());
        if std::env::var_os("KEEP_DIAGNOSE_OUTPUT").is_none() {
            let _ = std::fs::remove_dir_all(&dir);
        }
    }
}
