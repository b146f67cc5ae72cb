//! PNG figures: stacked time-series panels sharing one x axis.

use std::path::{Path, PathBuf};
use std::sync::Once;

use anyhow::{anyhow, Context, Result};
use plotters::prelude::*;

use hammer_sim::simulate::{simulate, Simulation};
use hammer_sim::{SimConfig, EFFECT_NAMES};

pub struct Series<'a> {
    pub label: String,
    pub color: RGBColor,
    pub x: &'a [f64],
    pub y: Vec<f64>,
}

pub struct Panel<'a> {
    pub y_label: String,
    pub series: Vec<Series<'a>>,
    /// Clamp the y range (impacts would otherwise flatten the flight phase).
    pub y_limits: Option<(f64, f64)>,
}

static FONT: Once = Once::new();

/// plotters draws text with ab_glyph; the font comes from the `dejavu` crate
/// so figures render identically on a machine without system fonts.
fn register_font() {
    FONT.call_once(|| {
        let _ = plotters::style::register_font("sans-serif", FontStyle::Normal, dejavu::sans::regular());
    });
}

pub const NOMINAL: RGBColor = RGBColor(90, 90, 90);
pub const EFFECT: RGBColor = RGBColor(214, 39, 40);
pub const BLUE: RGBColor = RGBColor(31, 119, 180);

/// Draws `panels` stacked vertically into a PNG of `width` × `height` pixels.
pub fn stacked_png(path: &Path, title: &str, x_label: &str, panels: &[Panel], width: u32, height: u32) -> Result<()> {
    register_font();
    let root = BitMapBackend::new(path, (width, height)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| anyhow!("{e}"))?;
    let root = root.titled(title, ("sans-serif", 22)).map_err(|e| anyhow!("{e}"))?;
    let areas = root.split_evenly((panels.len(), 1));
    for (i, (panel, area)) in panels.iter().zip(areas.iter()).enumerate() {
        let (mut x0, mut x1, mut y0, mut y1) = (f64::INFINITY, f64::NEG_INFINITY, f64::INFINITY, f64::NEG_INFINITY);
        for s in &panel.series {
            for (&x, &y) in s.x.iter().zip(&s.y) {
                if x.is_finite() && y.is_finite() {
                    x0 = x0.min(x);
                    x1 = x1.max(x);
                    y0 = y0.min(y);
                    y1 = y1.max(y);
                }
            }
        }
        if let Some((lo, hi)) = panel.y_limits {
            y0 = y0.max(lo);
            y1 = y1.min(hi);
        }
        // A panel with no finite point gets a unit range instead of an infinite one.
        if !(x0.is_finite() && x1.is_finite()) {
            (x0, x1) = (0.0, 1.0);
        }
        if !(y0.is_finite() && y1.is_finite()) {
            (y0, y1) = (0.0, 1.0);
        }
        if !(x1 > x0) {
            x1 = x0 + 1.0;
        }
        if !(y1 > y0) {
            y1 = y0 + 1.0;
        }
        let pad = 0.05 * (y1 - y0);
        let mut chart = ChartBuilder::on(area)
            .margin(8)
            .x_label_area_size(if i + 1 == panels.len() { 36 } else { 20 })
            .y_label_area_size(70)
            .build_cartesian_2d(x0..x1, (y0 - pad)..(y1 + pad))
            .map_err(|e| anyhow!("{e}"))?;
        let mut mesh = chart.configure_mesh();
        mesh.y_desc(panel.y_label.as_str())
            .label_style(("sans-serif", 13))
            .light_line_style(WHITE.mix(0.0));
        if i + 1 == panels.len() {
            mesh.x_desc(x_label);
        }
        mesh.draw().map_err(|e| anyhow!("{e}"))?;
        for s in &panel.series {
            let (lo, hi) = (y0 - pad, y1 + pad);
            let color = s.color;
            chart
                .draw_series(LineSeries::new(
                    s.x.iter()
                        .zip(&s.y)
                        .filter(|(x, y)| x.is_finite() && y.is_finite())
                        .map(|(&x, &y)| (x, y.clamp(lo, hi))),
                    color.stroke_width(2),
                ))
                .map_err(|e| anyhow!("{e}"))?
                .label(s.label.clone())
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], color.stroke_width(2)));
        }
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK.mix(0.3))
            .label_font(("sans-serif", 13))
            .position(SeriesLabelPosition::UpperRight)
            .draw()
            .map_err(|e| anyhow!("{e}"))?;
    }
    root.present()
        .map_err(|e| anyhow!("{e}"))
        .with_context(|| format!("writing {}", path.display()))?;
    Ok(())
}

/// Sample range of the last complete steady cycle: impact to next impact.
pub fn last_cycle(sim: &Simulation) -> Option<(usize, usize)> {
    let c = sim.run.cycles.len().checked_sub(1)?;
    let cyc = &sim.run.cycles[c];
    let dt = sim.run.truth.dt_s;
    let i1 = (cyc.t_impact_s / dt).round() as usize;
    let i0 = ((cyc.t_impact_s - cyc.period_s) / dt).round() as usize;
    Some((i0.saturating_sub(20), (i1 + 20).min(sim.run.truth.len())))
}

/// One figure per catalogued effect at its default magnitude.
pub fn effect_figures(dir: &Path, supply_bar: f64) -> Result<Vec<PathBuf>> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let mut base = SimConfig::nominal(supply_bar);
    base.solver.duration_s = 0.4;
    base.sensors.enabled = false;
    let nominal = simulate(&base)?;
    let (n0, n1) = last_cycle(&nominal).ok_or_else(|| anyhow!("nominal run has no complete cycle"))?;
    let mut files = Vec::new();
    for name in EFFECT_NAMES {
        let mut cfg = base.clone();
        cfg.effects.apply_spec(name)?;
        let with = simulate(&cfg)?;
        let (w0, w1) = last_cycle(&with).ok_or_else(|| anyhow!("{name}: no complete cycle"))?;
        let tn: Vec<f64> = (n0..n1)
            .map(|i| (i - n0) as f64 * base.solver.output_step_s * 1e3)
            .collect();
        let tw: Vec<f64> = (w0..w1)
            .map(|i| (i - w0) as f64 * base.solver.output_step_s * 1e3)
            .collect();
        let pair = |label: &str, nom: &[f64], eff: &[f64], scale: f64, lim: Option<(f64, f64)>| Panel {
            y_label: label.to_string(),
            series: vec![
                Series {
                    label: "nominal".into(),
                    color: NOMINAL,
                    x: &tn,
                    y: nom[n0..n1].iter().map(|v| v * scale).collect(),
                },
                Series {
                    label: name.into(),
                    color: EFFECT,
                    x: &tw,
                    y: eff[w0..w1].iter().map(|v| v * scale).collect(),
                },
            ],
            y_limits: lim,
        };
        let panels = [
            pair(
                "rear p, bar",
                &nominal.measured.p_rear_pa,
                &with.measured.p_rear_pa,
                1e-5,
                None,
            ),
            pair(
                "front p, bar",
                &nominal.measured.p_front_pa,
                &with.measured.p_front_pa,
                1e-5,
                None,
            ),
            pair(
                "accel, m/s²",
                &nominal.measured.accel_mps2,
                &with.measured.accel_mps2,
                1.0,
                Some((-800.0, 800.0)),
            ),
            pair(
                "velocity, m/s",
                &nominal.run.truth.v_mps,
                &with.run.truth.v_mps,
                1.0,
                None,
            ),
        ];
        let params = effect_params_text(&cfg.effects, name)?;
        let path = dir.join(format!("effect-{name}.png"));
        stacked_png(
            &path,
            &format!("{name}:{params} vs nominal, {supply_bar} bar"),
            "time since impact, ms",
            &panels,
            1100,
            900,
        )?;
        files.push(path);
    }
    Ok(files)
}

/// `key=value` pairs of an effect's parameters, short enough for a title.
pub fn effect_params_text(effects: &hammer_sim::Effects, name: &str) -> Result<String> {
    let value = serde_json::to_value(effects)?;
    let Some(obj) = value.get(name).and_then(|v| v.as_object()) else {
        return Ok(String::new());
    };
    Ok(obj
        .iter()
        .map(|(k, v)| match v.as_f64() {
            Some(x) if x != 0.0 && !(1e-3..1e5).contains(&x.abs()) => format!("{k}={x:.3e}"),
            Some(x) => format!("{k}={}", (x * 1e4).round() / 1e4),
            None => format!("{k}={v}"),
        })
        .collect::<Vec<_>>()
        .join(","))
}
