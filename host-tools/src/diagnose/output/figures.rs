//! The gap figures, `gap-<bar>bar.png`: per operating point the measured
//! mean cycle against the nominal and the fitted model, the gap between
//! measurement and nominal model shaded and the cycle's stages in a strip,
//! drawn on the shared chart renderer (its frame, font, axes and legend).

use std::fmt::Write as _;
use std::path::Path;

use anyhow::Result;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use crate::chart::render::{self, plot_err, Area, Axes, Ctx};
use crate::chart::{BLUE, EFFECT, NOMINAL};
use crate::diagnose::engine::PointWaves;
use crate::diagnose::stages::Stage;
use crate::numfmt::bar as fmt_bar;

/// Pixel size of the gap figures.
pub const FIGURE_SIZE: (u32, u32) = (1200, 1000);

/// Acceleration panel: the y range is taken from the samples after this
/// time since the impact (the shock clips the accelerometer before it).
const ACCEL_LIMITS_FROM_MS: f64 = 1.5;

/// `gap-4bar.png`, `gap-5.5bar.png`.
pub fn figure_name(supply_bar: f64) -> String {
    format!("gap-{}bar.png", fmt_bar(supply_bar))
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
pub(super) fn gap_png(path: &Path, pw: &PointWaves, fitted_label: Option<&str>) -> Result<()> {
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
    let font = if title.chars().count() > 100 { 17 } else { 22 };
    render::stacked(path, FIGURE_SIZE, &title, font, panels.len(), |i, area| {
        let last = i + 1 == panels.len();
        draw_panel(
            area,
            &panels[i],
            &t_ms,
            &pw.stages,
            x_range,
            last,
            i == 0,
            &fitted_legend,
        )
    })
}

/// One panel; the first carries the stage names and the legend.
#[allow(clippy::too_many_arguments)]
fn draw_panel(
    area: &Area,
    p: &GapPanel,
    t_ms: &[f64],
    stages: &[Stage],
    (x0, x1): (f64, f64),
    last: bool,
    first: bool,
    fitted_label: &str,
) -> Result<()> {
    let (y0, y1, strip) = y_extent(p, t_ms);
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

    let axes = Axes {
        y_label: p.y_label,
        x_label: last.then_some("time since impact, ms (cycles stretched onto the nominal period)"),
        x_label_area: if last { 40 } else { 22 },
        y_label_area: 75,
        tick: Some(&tick),
    };
    let mut ctx = render::panel(area, (x0, x1), (y0, y1), &axes)?;
    draw_stage_strip(&mut ctx, t_ms, stages, (x0, x1), (y0, strip), first)?;
    draw_gap(&mut ctx, t_ms, &measured, &nominal, step)?;
    // The curves: nominal, measured, and the fitted model dashed on top (it may cover the measurement).
    let mut lines: Vec<(&str, RGBColor, &[f64], bool)> = vec![
        ("nominal model", NOMINAL, &nominal, false),
        ("measured (mean cycle)", BLUE, &measured, false),
    ];
    if let Some(f) = &fitted {
        lines.push((fitted_label, EFFECT, f, true));
    }
    for (label, color, y, dashed) in lines {
        draw_curve(&mut ctx, t_ms, y, step, (label, color, dashed))?;
    }
    if !first {
        return Ok(());
    }
    render::legend(&mut ctx, SeriesLabelPosition::UpperRight)
}

/// The panel's y range (bottom, top) and the height of the stage strip
/// below the curves; the acceleration's range skips the shock.
fn y_extent(p: &GapPanel, t_ms: &[f64]) -> (f64, f64, f64) {
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
    (y0, y1, strip)
}

/// The strip of the cycle's stages along the bottom, named in the first panel.
fn draw_stage_strip(
    ctx: &mut Ctx,
    t_ms: &[f64],
    stages: &[Stage],
    (x0, x1): (f64, f64),
    (y0, strip): (f64, f64),
    first: bool,
) -> Result<()> {
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
    Ok(())
}

/// The gap between measurement and nominal model, shaded where both are on scale.
fn draw_gap(ctx: &mut Ctx, t_ms: &[f64], measured: &[f64], nominal: &[f64], step: usize) -> Result<()> {
    let gap_fill = GAP.mix(GAP_ALPHA).filled();
    let mut labelled = false;
    for r in finite_runs(t_ms, &[measured, nominal]) {
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
    Ok(())
}

/// One curve, broken where it is off scale, thinned to the pixels; labelled once.
fn draw_curve(
    ctx: &mut Ctx,
    t_ms: &[f64],
    y: &[f64],
    step: usize,
    (label, color, dashed): (&str, RGBColor, bool),
) -> Result<()> {
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
    Ok(())
}
