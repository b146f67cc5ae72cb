//! The one renderer of the figures: the font (registered once), the frame
//! of stacked panels, axes and legend, and the layers of a [`Chart`]. A
//! figure with layers of its own (the gap figure's stage strip and shaded
//! gap) draws them on the same frame, axes and legend.

use std::path::Path;
use std::sync::Once;

use anyhow::{anyhow, Context, Result};
use plotters::coord::Shift;
use plotters::prelude::*;

use super::Chart;

static FONT: Once = Once::new();

/// plotters draws text with ab_glyph; the font comes from the `dejavu` crate
/// so figures render identically on a machine without system fonts.
fn register_font() {
    FONT.call_once(|| {
        let _ = plotters::style::register_font("sans-serif", FontStyle::Normal, dejavu::sans::regular());
    });
}

pub fn plot_err(e: impl std::fmt::Display) -> anyhow::Error {
    anyhow!("drawing: {e}")
}

/// Finite points of parallel slices.
fn finite<'s>(x: &'s [f64], y: &'s [f64]) -> impl Iterator<Item = (f64, f64)> + 's {
    x.iter()
        .zip(y)
        .filter(|(x, y)| x.is_finite() && y.is_finite())
        .map(|(&x, &y)| (x, y))
}

fn extend(r: &mut (f64, f64), v: f64) {
    r.0 = r.0.min(v);
    r.1 = r.1.max(v);
}

/// A usable (non-empty, finite) range.
fn usable(r: (f64, f64)) -> (f64, f64) {
    match r {
        (a, b) if a.is_finite() && b > a => (a, b),
        (a, _) if a.is_finite() => (a - 0.5, a + 0.5),
        _ => (0.0, 1.0),
    }
}

/// The x range shared by all panels of a figure.
fn x_range(charts: &[Chart]) -> (f64, f64) {
    let mut r = (f64::INFINITY, f64::NEG_INFINITY);
    for c in charts {
        for s in &c.series {
            finite(s.x, &s.y).for_each(|(x, _)| extend(&mut r, x));
        }
        for b in &c.bands {
            finite(b.x, &b.hi).for_each(|(x, _)| extend(&mut r, x));
        }
        for d in &c.crosses {
            d.x.iter().filter(|x| x.is_finite()).for_each(|&x| extend(&mut r, x));
        }
    }
    usable(r)
}

/// The panel's y range: lines and bands, clamped to its limits, padded 5 %.
fn y_range(c: &Chart) -> (f64, f64) {
    let mut r = (f64::INFINITY, f64::NEG_INFINITY);
    for s in &c.series {
        finite(s.x, &s.y).for_each(|(_, y)| extend(&mut r, y));
    }
    for b in &c.bands {
        finite(b.x, &b.lo)
            .chain(finite(b.x, &b.hi))
            .for_each(|(_, y)| extend(&mut r, y));
    }
    if c.zero_line {
        extend(&mut r, 0.0);
    }
    if let Some((lo, hi)) = c.y_limits {
        r = (r.0.max(lo), r.1.min(hi));
    }
    let (lo, hi) = usable(r);
    let pad = 0.05 * (hi - lo);
    (lo - pad, hi + pad)
}

/// Runs of consecutive finite points: a flagged cycle (NaN) breaks a line.
fn segments(x: &[f64], y: &[f64]) -> Vec<Vec<(f64, f64)>> {
    let mut out: Vec<Vec<(f64, f64)>> = vec![Vec::new()];
    for (&x, &y) in x.iter().zip(y) {
        if x.is_finite() && y.is_finite() {
            if let Some(s) = out.last_mut() {
                s.push((x, y));
            }
        } else if out.last().is_some_and(|s| !s.is_empty()) {
            out.push(Vec::new());
        }
    }
    out.retain(|s| !s.is_empty());
    out
}

/// Draws `charts` stacked vertically into a PNG of `size` pixels, sharing
/// one x range; the title in `title_font` points.
pub fn figure_png(
    path: &Path,
    title: &str,
    title_font: u32,
    x_label: &str,
    charts: &[Chart],
    size: (u32, u32),
) -> Result<()> {
    let xr = x_range(charts);
    stacked(path, size, title, title_font, charts.len(), |i, area| {
        let last = i + 1 == charts.len();
        draw_chart(area, &charts[i], xr, last.then_some(x_label))
    })
}

/// A drawing area of a figure: one panel.
pub type Area<'b> = DrawingArea<BitMapBackend<'b>, Shift>;

/// The frame every figure shares: a white PNG of `size` pixels, `title` on
/// top, `n` panels stacked below, each drawn by `draw(index, area)`.
pub fn stacked(
    path: &Path,
    size: (u32, u32),
    title: &str,
    title_font: u32,
    n: usize,
    mut draw: impl FnMut(usize, &Area) -> Result<()>,
) -> Result<()> {
    register_font();
    let root = BitMapBackend::new(path, size).into_drawing_area();
    root.fill(&WHITE).map_err(plot_err)?;
    let root = root.titled(title, ("sans-serif", title_font)).map_err(plot_err)?;
    let areas = root.split_evenly((n, 1));
    for (i, area) in areas.iter().enumerate() {
        draw(i, area)?;
    }
    root.present()
        .map_err(plot_err)
        .with_context(|| format!("writing {}", path.display()))
}

/// How a panel's axes are laid out: the label areas' sizes in pixels, the
/// axis descriptions and, optionally, how tick labels are written.
pub struct Axes<'a> {
    pub y_label: &'a str,
    /// Only the bottom panel describes the shared x axis.
    pub x_label: Option<&'a str>,
    pub x_label_area: u32,
    pub y_label_area: u32,
    pub tick: Option<&'a dyn Fn(&f64) -> String>,
}

/// A panel's coordinate system on `area`, its mesh drawn (no minor grid).
pub fn panel<'a, 'b>(
    area: &'a Area<'b>,
    (x0, x1): (f64, f64),
    (y0, y1): (f64, f64),
    axes: &Axes,
) -> Result<Ctx<'a, 'b>> {
    let mut ctx = ChartBuilder::on(area)
        .margin(8)
        .x_label_area_size(axes.x_label_area)
        .y_label_area_size(axes.y_label_area)
        .build_cartesian_2d(x0..x1, y0..y1)
        .map_err(plot_err)?;
    let mut mesh = ctx.configure_mesh();
    mesh.y_desc(axes.y_label).label_style(("sans-serif", 13));
    if let Some(tick) = axes.tick {
        mesh.x_label_formatter(tick).y_label_formatter(tick);
    }
    mesh.light_line_style(WHITE.mix(0.0));
    if let Some(l) = axes.x_label {
        mesh.x_desc(l);
    }
    mesh.draw().map_err(plot_err)?;
    Ok(ctx)
}

/// The legend box of the series drawn with a label.
pub fn legend<'c, 'b: 'c>(ctx: &mut Ctx<'c, 'b>, position: SeriesLabelPosition) -> Result<()> {
    ctx.configure_series_labels()
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK.mix(0.3))
        .label_font(("sans-serif", 13))
        .position(position)
        .draw()
        .map_err(plot_err)
}

pub type Ctx<'c, 'b> = ChartContext<
    'c,
    BitMapBackend<'b>,
    Cartesian2d<plotters::coord::types::RangedCoordf64, plotters::coord::types::RangedCoordf64>,
>;

fn draw_chart(area: &Area, c: &Chart, (x0, x1): (f64, f64), x_label: Option<&str>) -> Result<()> {
    let (y0, y1) = y_range(c);
    let axes = Axes {
        y_label: c.y_label.as_str(),
        x_label,
        x_label_area: if x_label.is_some() { 36 } else { 20 },
        y_label_area: 70,
        tick: None,
    };
    let mut ctx = panel(area, (x0, x1), (y0, y1), &axes)?;
    draw_spans(&mut ctx, c, (y0, y1))?;
    draw_bands(&mut ctx, c, (y0, y1))?;
    draw_lines(&mut ctx, c, (x0, x1), (y0, y1))?;
    draw_marks(&mut ctx, c, (y0, y1))?;
    legend(&mut ctx, c.legend.clone())
}

fn draw_spans(ctx: &mut Ctx, c: &Chart, (y0, y1): (f64, f64)) -> Result<()> {
    for s in &c.spans {
        let fill = s.color.mix(0.18).filled();
        let anno = ctx
            .draw_series(std::iter::once(Rectangle::new([(s.x0, y0), (s.x1, y1)], fill)))
            .map_err(plot_err)?;
        if let Some(label) = &s.label {
            anno.label(label.clone())
                .legend(move |(x, y)| Rectangle::new([(x, y - 6), (x + 18, y + 6)], fill));
        }
    }
    Ok(())
}

fn draw_bands(ctx: &mut Ctx, c: &Chart, (y0, y1): (f64, f64)) -> Result<()> {
    for b in &c.bands {
        let fill = b.color.mix(0.2).filled();
        for (lo, hi) in segments(b.x, &b.lo).into_iter().zip(segments(b.x, &b.hi)) {
            let mut poly: Vec<(f64, f64)> = hi.iter().map(|&(x, y)| (x, y.clamp(y0, y1))).collect();
            poly.extend(lo.iter().rev().map(|&(x, y)| (x, y.clamp(y0, y1))));
            ctx.draw_series(std::iter::once(Polygon::new(poly, fill)))
                .map_err(plot_err)?;
        }
    }
    Ok(())
}

fn draw_lines(ctx: &mut Ctx, c: &Chart, (x0, x1): (f64, f64), (y0, y1): (f64, f64)) -> Result<()> {
    if c.zero_line {
        ctx.draw_series(LineSeries::new([(x0, 0.0), (x1, 0.0)], BLACK.mix(0.4).stroke_width(1)))
            .map_err(plot_err)?;
    }
    for s in &c.series {
        let color = s.color;
        let mut first = true;
        for seg in segments(s.x, &s.y) {
            let pts: Vec<(f64, f64)> = seg.iter().map(|&(x, y)| (x, y.clamp(y0, y1))).collect();
            if c.points {
                ctx.draw_series(pts.iter().map(|&p| Circle::new(p, 3, color.filled())))
                    .map_err(plot_err)?;
            }
            let anno = ctx
                .draw_series(LineSeries::new(pts, color.stroke_width(2)))
                .map_err(plot_err)?;
            if std::mem::take(&mut first) {
                anno.label(s.label.clone())
                    .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], color.stroke_width(2)));
            }
        }
    }
    Ok(())
}

fn draw_marks(ctx: &mut Ctx, c: &Chart, (y0, y1): (f64, f64)) -> Result<()> {
    // Off-scale values sit just inside the edge, so they stay visible.
    let inset = 0.03 * (y1 - y0);
    for d in &c.crosses {
        let color = d.color;
        let pts: Vec<(f64, f64)> = finite(d.x, &d.y)
            .map(|(x, y)| (x, y.clamp(y0 + inset, y1 - inset)))
            .collect();
        if pts.is_empty() {
            continue;
        }
        let anno = ctx
            .draw_series(pts.into_iter().map(|p| Cross::new(p, 5, color.stroke_width(2))))
            .map_err(plot_err)?;
        if let Some(label) = &d.label {
            anno.label(label.clone())
                .legend(move |(x, y)| Cross::new((x + 9, y), 5, color.stroke_width(2)));
        }
    }
    for v in &c.vlines {
        let style: ShapeStyle = v.color.stroke_width(2);
        let anno = ctx
            .draw_series(DashedLineSeries::new([(v.x, y0), (v.x, y1)], 7, 5, style))
            .map_err(plot_err)?;
        if let Some(label) = &v.label {
            anno.label(label.clone())
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], style));
        }
    }
    let span = y1 - y0;
    for (x, text) in &c.notes {
        ctx.draw_series(std::iter::once(Text::new(
            text.clone(),
            (*x, y0 + 0.13 * span),
            ("sans-serif", 15).into_font().color(&BLACK.mix(0.75)),
        )))
        .map_err(plot_err)?;
    }
    Ok(())
}
