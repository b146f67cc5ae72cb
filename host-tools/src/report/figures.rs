//! The report's figures in the shared chart model: `cycle.png` (one cycle
//! with its stroke/backhaul split), `run.png` (the per-cycle estimates over
//! the run) and `truth.png` (the estimate against the simulator's truth).

use std::ops::Range;
use std::path::Path;

use anyhow::{anyhow, Result};
use hammer_estimator::{Config, CycleReport};

use super::analysis::{truth_summary, Analysis, Matched, Supply, MATCH_TOLERANCE_S};
use super::{CYCLE_SIZE, RUN_SIZE, TRUTH_SIZE};
use crate::chart::render::figure_png;
use crate::chart::{
    Band, Chart, Crosses, RGBColor, Series, SeriesLabelPosition, Span, VLine, BLUE, EFFECT, GREEN, NOMINAL, ORANGE,
};
use hammer_sim::CycleTruth;
use hammer_trace::trace::Trace;

/// Runs with more cycles than this draw plain lines, without a dot per cycle.
const MAX_DOTTED_CYCLES: usize = 60;

/// A long title (a long file name, a flagged cycle) gets a smaller font rather than clipped.
fn title_font(title: &str) -> u32 {
    if title.chars().count() > 105 {
        16
    } else {
        20
    }
}

/// Margin around the cycle window so both blanked shocks are visible, s.
const CYCLE_MARGIN_S: f64 = 2e-3;

// ---------------------------------------------------------------------------
// cycle.png

/// The cycle the figure shows: a valid one in the middle of the run (past the
/// start-up transient, before any late fault), else the middle one.
fn pick_cycle(reports: &[CycleReport]) -> Option<&CycleReport> {
    let valid: Vec<&CycleReport> = reports.iter().filter(|r| r.is_valid()).collect();
    match valid.len() {
        0 => reports.get(reports.len() / 2),
        n => Some(valid[n / 2]),
    }
}

/// One cycle's sample window and the velocity the estimator's numbers imply.
struct CycleView {
    /// Samples from before the opening impact to after the closing one.
    window: Range<usize>,
    /// Time of each window sample since the opening impact, ms.
    t_ms: Vec<f64>,
    /// Velocity over the window (NaN in the shock blanking and outside the cycle).
    v_mps: Vec<f64>,
    turn_ms: Option<f64>,
    period_ms: f64,
}

fn cycle_view(a: &Analysis, r: &CycleReport) -> CycleView {
    let dt = a.trace.dt_s;
    let n = a.trace.len();
    let t_prev = r.t_impact_s() - r.period_s as f64;
    let index = |t: f64| ((t / dt).floor().max(0.0) as usize).min(n - 1);
    let window = index(t_prev - CYCLE_MARGIN_S)..index(r.t_impact_s() + CYCLE_MARGIN_S) + 1;
    let t_ms: Vec<f64> = window.clone().map(|i| (i as f64 * dt - t_prev) * 1e3).collect();
    let first = index(t_prev + a.cfg.blank_after_s as f64).max(window.start);
    let last = index(r.t_impact_s());
    let mut v_mps = vec![f64::NAN; window.len()];
    let mut turn_ms = None;
    if first < last {
        let (v, turn) = pressure_velocity(&a.trace, &a.cfg, r, first..last + 1);
        v_mps[first - window.start..=last - window.start].copy_from_slice(&v);
        turn_ms = turn.map(|j| ((first as f64 + j) * dt - t_prev) * 1e3);
    }
    CycleView {
        window,
        t_ms,
        v_mps,
        turn_ms,
        period_ms: r.period_s as f64 * 1e3,
    }
}

/// Piston velocity from the pressures, `m·dv/dt = p1·A1 − p2·A2 + m·g·sinθ ∓ F`,
/// integrated backwards from the impact, where it equals the reported impact
/// velocity: through the stroke with −F_s until v reaches zero (the turning
/// point, returned as a fractional index into `samples`), then through the
/// backhaul with +F_b. This is the integral the estimator closes, so its zero
/// crossing is the estimator's stroke/backhaul split.
fn pressure_velocity(trace: &Trace, cfg: &Config, r: &CycleReport, samples: Range<usize>) -> (Vec<f64>, Option<f64>) {
    let (m, dt) = (cfg.mass_kg() as f64, trace.dt_s);
    let (a1, a2, fg) = (
        cfg.rear_area_m2() as f64,
        cfg.front_area_m2() as f64,
        cfg.gravity_n() as f64,
    );
    let force_n = |i: usize| a1 * trace.p_rear_pa[i] - a2 * trace.p_front_pa[i] + fg;
    let (fs, fb) = (r.friction_stroke_n as f64, r.friction_backhaul_n as f64);
    let mut v = vec![f64::NAN; samples.len()];
    let v_imp = r.impact_velocity_mps as f64;
    if v.is_empty() || !(v_imp.is_finite() && fs.is_finite() && fb.is_finite()) {
        return (v, None);
    }
    let last = v.len() - 1;
    v[last] = v_imp;
    let mut turn = None;
    for j in (1..=last).rev() {
        let i = samples.start + j;
        let friction_n = if turn.is_none() { -fs } else { fb };
        v[j - 1] = v[j] - dt / m * (0.5 * (force_n(i) + force_n(i - 1)) + friction_n);
        if turn.is_none() && v[j - 1] < 0.0 {
            turn = Some((j - 1) as f64 + -v[j - 1] / (v[j] - v[j - 1]));
        }
    }
    (v, turn)
}

/// Accel limits from the samples outside the blanked shocks (0.5–99.5 %
/// quantiles, padded): the impact spikes would flatten the flight phase.
fn accel_limits(accel: &[f64], t_ms: &[f64], blanks: &[(f64, f64)]) -> Option<(f64, f64)> {
    let mut xs: Vec<f64> = accel
        .iter()
        .zip(t_ms)
        .filter(|(a, t)| a.is_finite() && !blanks.iter().any(|&(b0, b1)| (b0..=b1).contains(*t)))
        .map(|(&a, _)| a)
        .collect();
    if xs.len() < 10 {
        return None;
    }
    xs.sort_by(f64::total_cmp);
    let q = |p: f64| xs[((xs.len() - 1) as f64 * p).round() as usize];
    let (lo, hi) = (q(0.005), q(0.995));
    let pad = 0.3 * (hi - lo).max(1.0);
    Some((lo - pad, hi + pad))
}

pub(super) fn cycle_figure(a: &Analysis, path: &Path) -> Result<()> {
    let r = pick_cycle(&a.reports).ok_or_else(|| anyhow!("no cycle to draw"))?;
    let view = cycle_view(a, r);
    let w = view.window.clone();
    let tr = &a.trace;
    let scaled = |col: &[f64], k: f64| col[w.clone()].iter().map(|v| v * k).collect::<Vec<f64>>();
    let (before_ms, after_ms) = (a.cfg.blank_before_s as f64 * 1e3, a.cfg.blank_after_s as f64 * 1e3);
    let blanks = [
        (-before_ms, after_ms),
        (view.period_ms - before_ms, view.period_ms + after_ms),
    ];
    let series = |label: &str, color, y| Series {
        label: label.into(),
        color,
        x: &view.t_ms,
        y,
    };
    let pressure = Chart::new(
        "pressure, bar",
        vec![
            series("rear p1", BLUE, scaled(&tr.p_rear_pa, 1e-5)),
            series("front p2", ORANGE, scaled(&tr.p_front_pa, 1e-5)),
        ],
    );
    let mut accel = Chart::new(
        "accel, m/s²",
        vec![series("measured", GREEN, scaled(&tr.accel_mps2, 1.0))],
    );
    accel.y_limits = accel_limits(&accel.series[0].y, &view.t_ms, &blanks);
    // Truth first, so the estimate is drawn over it where they coincide.
    let mut velocity_series = Vec::new();
    if let Some(v) = tr.extra.get("v_mps") {
        velocity_series.push(series("truth (trace column v_mps)", NOMINAL, scaled(v, 1.0)));
    }
    velocity_series.push(series(
        "from pressures, friction as estimated",
        BLUE,
        view.v_mps.clone(),
    ));
    let mut velocity = Chart::new("velocity, m/s", velocity_series);
    velocity.zero_line = true;
    velocity.legend = SeriesLabelPosition::UpperLeft;
    let mut charts = [pressure, accel, velocity];
    for (k, c) in charts.iter_mut().enumerate() {
        mark_phases(c, &view, &blanks, k == 0, k == 2);
    }
    let x_label = "time since the impact that opens the cycle, ms";
    let title = cycle_title(a, r);
    figure_png(path, &title, title_font(&title), x_label, &charts, CYCLE_SIZE)
}

/// Shades the blanked shocks and marks the turning point; the first panel
/// carries their legend, the last names the phases (the velocity is low there).
fn mark_phases(c: &mut Chart, view: &CycleView, blanks: &[(f64, f64)], first: bool, last: bool) {
    for (k, &(x0, x1)) in blanks.iter().enumerate() {
        c.spans.push(Span {
            x0,
            x1,
            color: NOMINAL,
            label: (first && k == 0).then(|| "blanked (shock)".to_string()),
        });
    }
    if let Some(t) = view.turn_ms {
        c.vlines.push(VLine {
            x: t,
            color: EFFECT,
            label: first.then(|| format!("turning point, {t:.1} ms")),
        });
        if last {
            let after = blanks[0].1;
            c.notes.push((after + 0.4, "backhaul".into()));
            c.notes.push((t + 0.4, "stroke".into()));
        }
    }
}

fn cycle_title(a: &Analysis, r: &CycleReport) -> String {
    let state = if r.is_valid() {
        String::new()
    } else {
        format!(" [flagged: {}]", r.flags.names().collect::<Vec<_>>().join(","))
    };
    format!(
        "{}: cycle {} (impact at {:.4} s){state}: friction {:.2} ± {:.2} N, impact {:.3} m/s, {:.3} J{}",
        a.name,
        r.seq,
        r.t_impact_s() + a.t0_s(),
        r.friction_n,
        r.friction_uncertainty_n,
        r.impact_velocity_mps,
        r.impact_energy_j,
        supply_text(a.supply)
    )
}

fn supply_text(s: Supply) -> String {
    s.bar().map_or_else(String::new, |b| format!(", supply {b} bar"))
}

// ---------------------------------------------------------------------------
// run.png and truth.png

/// The valid cycles' values (NaN for flagged ones) and the flagged cycles' values.
fn split_valid(reports: &[CycleReport], f: impl Fn(&CycleReport) -> f32) -> (Vec<f64>, Vec<f64>) {
    let pick = |keep: bool, r: &CycleReport| if keep { f(r) as f64 } else { f64::NAN };
    (
        reports.iter().map(|r| pick(r.is_valid(), r)).collect(),
        reports.iter().map(|r| pick(!r.is_valid(), r)).collect(),
    )
}

/// A line of a run panel: its label, color, value and expanded uncertainty.
type RunLine<'l> = (
    &'l str,
    RGBColor,
    fn(&CycleReport) -> f32,
    Option<fn(&CycleReport) -> f32>,
);
/// A truth line of the truth figure: its label and value.
type TruthLine = (&'static str, fn(&CycleTruth) -> f64);

/// A run panel: the valid values as a line, their uncertainty as a band, the
/// flagged ones as crosses.
fn run_chart<'a>(reports: &[CycleReport], k: f32, x: &'a [f64], y_label: &str, lines: &[RunLine]) -> Chart<'a> {
    let mut chart = Chart::new(y_label, Vec::new());
    // Dots show the cycles while they can be told apart; beyond that they only thicken the line.
    chart.points = reports.len() <= MAX_DOTTED_CYCLES;
    for &(label, color, value, uncertainty) in lines {
        let (y, flagged) = split_valid(reports, value);
        let mut label = label.to_string();
        if let Some(u) = uncertainty {
            let (u, _) = split_valid(reports, u);
            chart.bands.push(Band {
                color,
                x,
                lo: y.iter().zip(&u).map(|(y, u)| y - u).collect(),
                hi: y.iter().zip(&u).map(|(y, u)| y + u).collect(),
            });
            label += &format!(", band ± U (k = {k})");
        }
        chart.series.push(Series { label, color, x, y });
        if flagged.iter().any(|v| v.is_finite()) {
            let first = chart.crosses.is_empty();
            chart.crosses.push(Crosses {
                label: first.then(|| "flagged (off-scale ones at the edge)".into()),
                color: EFFECT,
                x,
                y: flagged,
            });
        }
    }
    chart
}

pub(super) fn run_figure(a: &Analysis, path: &Path) -> Result<()> {
    let x: &[f64] = &a
        .reports
        .iter()
        .map(|r| r.t_impact_s() + a.t0_s())
        .collect::<Vec<f64>>();
    let (reports, k) = (a.reports.as_slice(), a.cfg.coverage_factor);
    let friction = run_chart(
        reports,
        k,
        x,
        "friction, N",
        &[("friction", BLUE, |r| r.friction_n, Some(|r| r.friction_uncertainty_n))],
    );
    let energy = run_chart(
        reports,
        k,
        x,
        "impact energy, J",
        &[
            (
                "with friction",
                BLUE,
                |r| r.impact_energy_j,
                Some(|r| r.impact_energy_uncertainty_j),
            ),
            (
                "friction-blind",
                ORANGE,
                |r| r.impact_energy_frictionless_j,
                Some(|r| r.impact_energy_frictionless_uncertainty_j),
            ),
        ],
    );
    let frequency = run_chart(
        reports,
        k,
        x,
        "frequency, Hz",
        &[("frequency", BLUE, |r| r.frequency_hz, None)],
    );
    let wear = run_chart(
        reports,
        k,
        x,
        "wear index, J",
        &[("cumulative friction work", BLUE, |r| r.wear_index_j, None)],
    );
    let flagged = match a.reports.iter().filter(|r| !r.is_valid()).count() {
        0 => "none flagged".to_string(),
        n => format!("{n} flagged (×, left out of the lines)"),
    };
    let title = format!(
        "{}: {} cycles, {flagged}{}",
        a.name,
        a.reports.len(),
        supply_text(a.supply)
    );
    let mut charts = [friction, energy, frequency, wear];
    charts[1].legend = SeriesLabelPosition::MiddleRight;
    charts[3].legend = SeriesLabelPosition::UpperLeft;
    figure_png(path, &title, title_font(&title), "impact time, s", &charts, RUN_SIZE)
}

pub(super) fn truth_figure(a: &Analysis, matched: &[Matched], path: &Path) -> Result<()> {
    let x: Vec<f64> = matched.iter().map(|m| m.truth.t_impact_s).collect();
    let reports: Vec<CycleReport> = matched.iter().map(|m| *m.report).collect();
    let (reports, k) = (reports.as_slice(), a.cfg.coverage_factor);
    let s = truth_summary(matched);
    let err = |e: f64, unit: &str| format!("estimate (mean error {e:+.3} {unit})");
    let energy_err = format!("estimate (mean error {:+.2} %)", 100.0 * s.energy_error_j / s.energy_j);
    let frequency_err = format!("estimate (mean error {:+.4} Hz)", s.frequency_error_hz);
    let mut charts = [
        run_chart(
            reports,
            k,
            &x,
            "friction, N",
            &[(
                &err(s.friction_error_n, "N"),
                BLUE,
                |r| r.friction_n,
                Some(|r| r.friction_uncertainty_n),
            )],
        ),
        run_chart(
            reports,
            k,
            &x,
            "impact energy, J",
            &[(
                &energy_err,
                BLUE,
                |r| r.impact_energy_j,
                Some(|r| r.impact_energy_uncertainty_j),
            )],
        ),
        run_chart(
            reports,
            k,
            &x,
            "frequency, Hz",
            &[(&frequency_err, BLUE, |r| r.frequency_hz, None)],
        ),
    ];
    // Truth first, so the estimate is drawn over it.
    let truths: [TruthLine; 3] = [
        ("truth (cycle mean)", |t| t.friction_cycle_n),
        ("truth", |t| t.impact_energy_j),
        ("truth", |t| t.frequency_hz),
    ];
    for (chart, (label, f)) in charts.iter_mut().zip(truths) {
        let y = matched.iter().map(|m| f(m.truth)).collect();
        let line = Series {
            label: label.into(),
            color: NOMINAL,
            x: &x,
            y,
        };
        chart.series.insert(0, line);
    }
    let title = format!(
        "{}: estimate vs simulator truth, {} cycles matched by impact time (±{:.0} µs)",
        a.name,
        matched.len(),
        MATCH_TOLERANCE_S * 1e6
    );
    figure_png(path, &title, title_font(&title), "impact time, s", &charts, TRUTH_SIZE)
}
