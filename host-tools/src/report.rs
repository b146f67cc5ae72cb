//! `hammer report`: the estimator's view of one trace as PNG figures and a
//! self-contained HTML page (no external assets), for a person to read.
//!
//! The estimator runs exactly as in `hammer estimate` (same configuration
//! path, same code). The figures add what the per-cycle records cannot show:
//! one cycle's signals with the stroke/backhaul split, the run's trends with
//! their uncertainty, and, for a simulated trace, the estimate against the
//! simulator's truth.

use std::fmt::Write as _;
use std::io::IsTerminal as _;
use std::ops::Range;
use std::path::{Path, PathBuf};
use std::sync::Once;
use std::time::Duration;

use anyhow::{anyhow, bail, Context, Result};
use hammer_estimator::{Config, CycleReport};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use plotters::coord::Shift;
use plotters::prelude::*;

use crate::plot::{Panel, Series, BLUE, EFFECT, NOMINAL};
use hammer_sim::estimation::open_for_estimation;
use hammer_sim::simulate::{Sidecar, SimulationInfo};
use hammer_sim::{CycleTruth, SimConfig};
use hammer_trace::config::load_toml;
use hammer_trace::trace::Trace;

/// A report cycle and a truth cycle are the same impact when their impact
/// times agree this closely (two samples at 100 kS/s).
pub const MATCH_TOLERANCE_S: f64 = 20e-6;

pub const CYCLE_PNG: &str = "cycle.png";
pub const RUN_PNG: &str = "run.png";
pub const TRUTH_PNG: &str = "truth.png";
pub const INDEX_HTML: &str = "index.html";

/// Pixel sizes of the figures (the tests read them back from the PNG header).
pub const CYCLE_SIZE: (u32, u32) = (1100, 900);
pub const RUN_SIZE: (u32, u32) = (1100, 1000);
pub const TRUTH_SIZE: (u32, u32) = (1100, 800);

const ORANGE: RGBColor = RGBColor(255, 127, 14);
const GREEN: RGBColor = RGBColor(44, 160, 44);

/// Runs with more cycles than this draw plain lines, without a dot per cycle.
const MAX_DOTTED_CYCLES: usize = 60;

/// Margin around the cycle window so both blanked shocks are visible, s.
const CYCLE_MARGIN_S: f64 = 2e-3;

/// Write an HTML report with PNG figures of a trace: one cycle with its
/// stroke/backhaul split, the run's per-cycle estimates, and for a simulated
/// trace the estimate against the simulator's truth.
#[derive(clap::Args, Debug)]
pub struct ReportArgs {
    /// Trace in the project's format (CSV, SI units, gauge pressures). Its sidecar
    /// JSON beside it (same name, extension .json) is read if present: the operating
    /// point and, for a simulated trace, the per-cycle truth the estimate is compared with.
    pub input: PathBuf,
    /// Directory for index.html and the PNG figures (created if missing; files of
    /// the same names are overwritten).
    #[arg(long)]
    pub out: PathBuf,
    /// Gauge supply pressure, bar: the operating point of the drift baseline
    /// (default: the sidecar's; unknown means binning by peak rear pressure).
    #[arg(long)]
    pub supply_bar: Option<f64>,
    /// TOML file: [hammer] geometry, [sensors.*] calibration ranges, [estimator] thresholds
    /// and accuracy (default: the paper's hammer on the reference bench; a simulator's
    /// sidecar supplies its own hammer and sensors).
    #[arg(long)]
    pub config: Option<PathBuf>,
}

/// Means over the valid cycles: what the report's summary table shows.
/// NaN where there is no valid cycle.
#[derive(Debug, Clone, PartialEq)]
pub struct Summary {
    pub cycles: usize,
    pub valid_cycles: usize,
    pub friction_mean_n: f64,
    /// Cycle-to-cycle standard deviation of the friction.
    pub friction_sd_n: f64,
    /// Mean expanded uncertainty the estimator states per cycle.
    pub friction_uncertainty_n: f64,
    pub energy_mean_j: f64,
    pub energy_sd_j: f64,
    pub energy_uncertainty_j: f64,
    /// What a friction-blind method (earlier studies) would report.
    pub energy_frictionless_mean_j: f64,
    pub frequency_mean_hz: f64,
    /// Stroke friction work over impact energy.
    pub friction_work_ratio: f64,
    /// Wear index after the last cycle (cumulative friction work).
    pub wear_index_j: f64,
    /// How often each flag was raised, in the estimator's flag order.
    pub flag_counts: Vec<(&'static str, usize)>,
}

/// The simulator's truth over the matched valid cycles, and the estimate's mean error.
#[derive(Debug, Clone, PartialEq)]
pub struct TruthSummary {
    pub matched_cycles: usize,
    pub friction_n: f64,
    pub friction_error_n: f64,
    pub energy_j: f64,
    pub energy_error_j: f64,
    pub frequency_hz: f64,
    pub frequency_error_hz: f64,
    pub friction_work_ratio: f64,
}

/// Writes the report of `args.input` into `args.out`; returns the files written
/// (figures first, index.html last).
pub fn run(args: &ReportArgs) -> Result<Vec<PathBuf>> {
    let pb = progress_bar(6);
    let result = write_report(args, &pb);
    pb.finish_and_clear();
    result
}

/// A stage counter on a terminal; hidden when stderr is piped or redirected so
/// logs and CI output stay clean.
fn progress_bar(stages: u64) -> ProgressBar {
    if !std::io::stderr().is_terminal() {
        return ProgressBar::with_draw_target(Some(stages), ProgressDrawTarget::hidden());
    }
    let pb = ProgressBar::with_draw_target(Some(stages), ProgressDrawTarget::stderr());
    if let Ok(style) = ProgressStyle::with_template("{spinner} report [{bar:20}] {pos}/{len} {msg} ({elapsed})") {
        pb.set_style(style.progress_chars("=> "));
    }
    // Reading a long trace is one call with no progress of its own: the spinner shows it is alive.
    pb.enable_steady_tick(Duration::from_millis(120));
    pb
}

/// Starts the next stage: the position counts the stages already done.
fn stage(pb: &ProgressBar, msg: &'static str) {
    if !pb.message().is_empty() {
        pb.inc(1);
    }
    pb.set_message(msg);
}

fn write_report(args: &ReportArgs, pb: &ProgressBar) -> Result<Vec<PathBuf>> {
    stage(pb, "reading trace");
    let a = analyse(args, pb)?;
    std::fs::create_dir_all(&args.out).with_context(|| format!("creating {}", args.out.display()))?;
    let out = |name: &str| args.out.join(name);
    stage(pb, "drawing cycle.png");
    cycle_figure(&a, &out(CYCLE_PNG))?;
    let mut files = vec![out(CYCLE_PNG)];
    stage(pb, "drawing run.png");
    run_figure(&a, &out(RUN_PNG))?;
    files.push(out(RUN_PNG));
    stage(pb, "drawing truth.png");
    let matched = a.truth().map(|t| match_truth(&a.reports, t, a.t0_s()));
    if let Some(m) = matched.as_ref().filter(|m| !m.is_empty()) {
        truth_figure(&a, m, &out(TRUTH_PNG))?;
        files.push(out(TRUTH_PNG));
    }
    stage(pb, "writing index.html");
    let figures: Vec<&str> = files.iter().filter_map(|f| f.file_name()?.to_str()).collect();
    let html = html_page(&a, matched.as_deref(), &figures);
    std::fs::write(out(INDEX_HTML), html).with_context(|| format!("writing {}", out(INDEX_HTML).display()))?;
    files.push(out(INDEX_HTML));
    Ok(files)
}

// ---------------------------------------------------------------------------
// Estimation

/// Where the supply pressure of the report came from.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Supply {
    Flag(f64),
    Sidecar(f64),
    Unknown,
}

impl Supply {
    fn bar(self) -> Option<f64> {
        match self {
            Supply::Flag(b) | Supply::Sidecar(b) => Some(b),
            Supply::Unknown => None,
        }
    }
}

/// Everything the report is drawn from.
struct Analysis {
    /// The input's file name: the page shows no machine-specific path.
    name: String,
    config_file: Option<String>,
    trace: Trace,
    sidecar: Option<Sidecar>,
    supply: Supply,
    cfg: Config,
    reports: Vec<CycleReport>,
}

impl Analysis {
    /// Report times count from the first sample; trace and truth times do not.
    fn t0_s(&self) -> f64 {
        self.trace.t_s.first().copied().unwrap_or(0.0)
    }

    fn simulation(&self) -> Option<&SimulationInfo> {
        self.sidecar.as_ref()?.simulation.as_ref()
    }

    fn truth(&self) -> Option<&[CycleTruth]> {
        self.simulation().map(|s| s.cycles.as_slice()).filter(|c| !c.is_empty())
    }
}

/// Reads the trace and runs the estimator over it, configured exactly as
/// `hammer estimate` does (config file, then the sidecar's hammer and sensors).
fn analyse(args: &ReportArgs, pb: &ProgressBar) -> Result<Analysis> {
    let file: SimConfig = match &args.config {
        Some(p) => load_toml(p)?,
        None => SimConfig::default(),
    };
    // The reader's message already names the path and the OS error; as an anyhow
    // chain it would print the OS error twice.
    let input = open_for_estimation(&args.input, &file, args.supply_bar).map_err(|e| anyhow!("{e}"))?;
    let supply = match (args.supply_bar, input.supply_bar) {
        (Some(b), _) => Supply::Flag(b),
        (None, Some(b)) => Supply::Sidecar(b),
        (None, None) => Supply::Unknown,
    };
    let (trace, sidecar, cfg) = (input.trace, input.sidecar, input.config);
    stage(pb, "estimating");
    let reports = hammer_sim::estimation::run(&input.codes, cfg)?;
    let name = file_name(&args.input);
    if !reports.iter().any(|r| r.is_cycle()) {
        bail!(
            "{name}: no complete impact cycle in {} samples ({:.3} s): a cycle needs two impacts \
             (acceleration below −{} m/s²) at most {} s apart{}",
            trace.len(),
            trace.len() as f64 * trace.dt_s,
            cfg.impact_threshold_mps2,
            cfg.max_period_s,
            no_impact_note(&reports)
        );
    }
    Ok(Analysis {
        name,
        config_file: args.config.as_deref().map(file_name),
        trace,
        sidecar,
        supply,
        cfg,
        reports,
    })
}

fn file_name(p: &Path) -> String {
    p.file_name()
        .map_or_else(|| p.display().to_string(), |n| n.to_string_lossy().into_owned())
}

fn mean(xs: impl Iterator<Item = f64>) -> f64 {
    let (n, s) = xs.fold((0usize, 0.0), |(n, s), x| (n + 1, s + x));
    if n == 0 {
        f64::NAN
    } else {
        s / n as f64
    }
}

/// Sample standard deviation (n − 1); 0 for a single value, NaN for none.
fn sd(xs: &[f64]) -> f64 {
    if xs.is_empty() {
        return f64::NAN;
    }
    let m = mean(xs.iter().copied());
    let ss: f64 = xs.iter().map(|x| (x - m).powi(2)).sum();
    (ss / (xs.len() as f64 - 1.0).max(1.0)).sqrt()
}

/// The summary over the valid cycles of `reports`.
pub fn summarize(reports: &[CycleReport]) -> Summary {
    let valid: Vec<&CycleReport> = reports.iter().filter(|r| r.is_valid()).collect();
    let col = |f: fn(&CycleReport) -> f32| valid.iter().map(|r| f(r) as f64).collect::<Vec<f64>>();
    let avg = |f: fn(&CycleReport) -> f32| mean(col(f).into_iter());
    let flag_counts = hammer_estimator::Flags::NAMES
        .iter()
        .map(|&(flag, name)| (name, reports.iter().filter(|r| r.flags.contains(flag)).count()))
        .filter(|&(_, n)| n > 0)
        .collect();
    Summary {
        cycles: reports.len(),
        valid_cycles: valid.len(),
        friction_mean_n: avg(|r| r.friction_n),
        friction_sd_n: sd(&col(|r| r.friction_n)),
        friction_uncertainty_n: avg(|r| r.friction_uncertainty_n),
        energy_mean_j: avg(|r| r.impact_energy_j),
        energy_sd_j: sd(&col(|r| r.impact_energy_j)),
        energy_uncertainty_j: avg(|r| r.impact_energy_uncertainty_j),
        energy_frictionless_mean_j: avg(|r| r.impact_energy_frictionless_j),
        frequency_mean_hz: avg(|r| r.frequency_hz),
        friction_work_ratio: avg(|r| r.friction_work_ratio),
        wear_index_j: reports.last().map_or(f64::NAN, |r| r.wear_index_j as f64),
        flag_counts,
    }
}

/// A report cycle and the simulator's truth of the same impact.
#[derive(Debug, Clone, Copy)]
pub struct Matched<'a> {
    pub report: &'a CycleReport,
    pub truth: &'a CycleTruth,
}

/// Pairs every report with the truth cycle whose impact lies within
/// [`MATCH_TOLERANCE_S`]; `t0_s` is the trace's first sample time (report
/// times count from it, truth times do not).
pub fn match_truth<'a>(reports: &'a [CycleReport], truth: &'a [CycleTruth], t0_s: f64) -> Vec<Matched<'a>> {
    reports
        .iter()
        .filter_map(|r| {
            let t = r.t_impact_s + t0_s;
            let truth = truth.iter().find(|c| (c.t_impact_s - t).abs() <= MATCH_TOLERANCE_S)?;
            Some(Matched { report: r, truth })
        })
        .collect()
}

/// Truth means and mean errors over the matched cycles whose estimate is valid.
pub fn truth_summary(matched: &[Matched]) -> TruthSummary {
    let valid: Vec<&Matched> = matched.iter().filter(|m| m.report.is_valid()).collect();
    let avg = |f: &dyn Fn(&Matched) -> f64| mean(valid.iter().map(|m| f(m)));
    let energy_j = avg(&|m| m.truth.impact_energy_j);
    TruthSummary {
        matched_cycles: valid.len(),
        friction_n: avg(&|m| m.truth.friction_cycle_n),
        friction_error_n: avg(&|m| m.report.friction_n as f64 - m.truth.friction_cycle_n),
        energy_j,
        energy_error_j: avg(&|m| m.report.impact_energy_j as f64 - m.truth.impact_energy_j),
        frequency_hz: avg(&|m| m.truth.frequency_hz),
        frequency_error_hz: avg(&|m| m.report.frequency_hz as f64 - m.truth.frequency_hz),
        friction_work_ratio: avg(&|m| m.truth.friction_work_stroke_j) / energy_j,
    }
}

// ---------------------------------------------------------------------------
// Drawing: the plot module's panels plus the marks a report needs

/// A shaded x interval (the blanked shock).
struct Span {
    x0: f64,
    x1: f64,
    color: RGBColor,
    label: Option<String>,
}

/// A dashed vertical marker (the turning point).
struct VLine {
    x: f64,
    color: RGBColor,
    label: Option<String>,
}

/// A shaded band around a line (an expanded uncertainty); its line's legend
/// entry names it.
struct Band<'a> {
    color: RGBColor,
    x: &'a [f64],
    lo: Vec<f64>,
    hi: Vec<f64>,
}

/// Crosses: values that are not estimates (flagged cycles), kept visible but
/// out of the lines and the autoscale.
struct Crosses<'a> {
    /// None: another set of crosses in the panel already names them.
    label: Option<String>,
    color: RGBColor,
    x: &'a [f64],
    y: Vec<f64>,
}

/// One panel of a report figure.
struct Chart<'a> {
    panel: Panel<'a>,
    bands: Vec<Band<'a>>,
    crosses: Vec<Crosses<'a>>,
    spans: Vec<Span>,
    vlines: Vec<VLine>,
    /// Text near the bottom of the panel, at an x position.
    notes: Vec<(f64, String)>,
    /// A thin line at y = 0 (where the velocity changes sign).
    zero_line: bool,
    /// A dot at each data point: per-cycle values are samples, not a curve.
    points: bool,
    legend: SeriesLabelPosition,
}

impl<'a> Chart<'a> {
    fn new(y_label: &str, series: Vec<Series<'a>>) -> Self {
        Chart {
            panel: Panel {
                y_label: y_label.to_string(),
                series,
                y_limits: None,
            },
            bands: Vec::new(),
            crosses: Vec::new(),
            spans: Vec::new(),
            vlines: Vec::new(),
            notes: Vec::new(),
            zero_line: false,
            points: false,
            legend: SeriesLabelPosition::UpperRight,
        }
    }
}

static FONT: Once = Once::new();

/// The plot module's font (DejaVu from the `dejavu` crate), registered here too
/// because its registration happens only inside `stacked_png`.
fn register_font() {
    FONT.call_once(|| {
        let _ = plotters::style::register_font("sans-serif", FontStyle::Normal, dejavu::sans::regular());
    });
}

fn plot_err(e: impl std::fmt::Display) -> anyhow::Error {
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
        for s in &c.panel.series {
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
    for s in &c.panel.series {
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
    if let Some((lo, hi)) = c.panel.y_limits {
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

/// Draws `charts` stacked vertically into a PNG of `size` pixels.
fn figure_png(path: &Path, title: &str, x_label: &str, charts: &[Chart], size: (u32, u32)) -> Result<()> {
    register_font();
    let root = BitMapBackend::new(path, size).into_drawing_area();
    root.fill(&WHITE).map_err(plot_err)?;
    // A long title (a long file name, a flagged cycle) gets a smaller font rather than clipped.
    let font = if title.chars().count() > 105 { 16 } else { 20 };
    let root = root.titled(title, ("sans-serif", font)).map_err(plot_err)?;
    let xr = x_range(charts);
    let areas = root.split_evenly((charts.len(), 1));
    for (i, (chart, area)) in charts.iter().zip(&areas).enumerate() {
        let last = i + 1 == charts.len();
        draw_chart(area, chart, xr, last.then_some(x_label))?;
    }
    root.present()
        .map_err(plot_err)
        .with_context(|| format!("writing {}", path.display()))
}

type Ctx<'c, 'b> = ChartContext<
    'c,
    BitMapBackend<'b>,
    Cartesian2d<plotters::coord::types::RangedCoordf64, plotters::coord::types::RangedCoordf64>,
>;

fn draw_chart(
    area: &DrawingArea<BitMapBackend<'_>, Shift>,
    c: &Chart,
    (x0, x1): (f64, f64),
    x_label: Option<&str>,
) -> Result<()> {
    let (y0, y1) = y_range(c);
    let mut ctx = ChartBuilder::on(area)
        .margin(8)
        .x_label_area_size(if x_label.is_some() { 36 } else { 20 })
        .y_label_area_size(70)
        .build_cartesian_2d(x0..x1, y0..y1)
        .map_err(plot_err)?;
    let mut mesh = ctx.configure_mesh();
    mesh.y_desc(c.panel.y_label.as_str())
        .label_style(("sans-serif", 13))
        .light_line_style(WHITE.mix(0.0));
    if let Some(l) = x_label {
        mesh.x_desc(l);
    }
    mesh.draw().map_err(plot_err)?;
    draw_spans(&mut ctx, c, (y0, y1))?;
    draw_bands(&mut ctx, c, (y0, y1))?;
    draw_lines(&mut ctx, c, (x0, x1), (y0, y1))?;
    draw_marks(&mut ctx, c, (y0, y1))?;
    ctx.configure_series_labels()
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK.mix(0.3))
        .label_font(("sans-serif", 13))
        .position(c.legend.clone())
        .draw()
        .map_err(plot_err)
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
    for s in &c.panel.series {
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
    let t_prev = r.t_impact_s - r.period_s as f64;
    let index = |t: f64| ((t / dt).floor().max(0.0) as usize).min(n - 1);
    let window = index(t_prev - CYCLE_MARGIN_S)..index(r.t_impact_s + CYCLE_MARGIN_S) + 1;
    let t_ms: Vec<f64> = window.clone().map(|i| (i as f64 * dt - t_prev) * 1e3).collect();
    let first = index(t_prev + a.cfg.blank_after_s as f64).max(window.start);
    let last = index(r.t_impact_s);
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

fn cycle_figure(a: &Analysis, path: &Path) -> Result<()> {
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
    accel.panel.y_limits = accel_limits(&accel.panel.series[0].y, &view.t_ms, &blanks);
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
    figure_png(path, &cycle_title(a, r), x_label, &charts, CYCLE_SIZE)
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
        r.t_impact_s + a.t0_s(),
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

/// A run panel: the valid values as a line, their uncertainty as a band, the
/// flagged ones as crosses.
fn run_chart<'a>(
    reports: &[CycleReport],
    k: f32,
    x: &'a [f64],
    y_label: &str,
    lines: &[(&str, RGBColor, fn(&CycleReport) -> f32, Option<fn(&CycleReport) -> f32>)],
) -> Chart<'a> {
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
        chart.panel.series.push(Series { label, color, x, y });
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

fn run_figure(a: &Analysis, path: &Path) -> Result<()> {
    let x: &[f64] = &a.reports.iter().map(|r| r.t_impact_s + a.t0_s()).collect::<Vec<f64>>();
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
    figure_png(path, &title, "impact time, s", &charts, RUN_SIZE)
}

fn truth_figure(a: &Analysis, matched: &[Matched], path: &Path) -> Result<()> {
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
    let truths: [(&str, fn(&CycleTruth) -> f64); 3] = [
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
        chart.panel.series.insert(0, line);
    }
    let title = format!(
        "{}: estimate vs simulator truth, {} cycles matched by impact time (±{:.0} µs)",
        a.name,
        matched.len(),
        MATCH_TOLERANCE_S * 1e6
    );
    figure_png(path, &title, "impact time, s", &charts, TRUTH_SIZE)
}

// ---------------------------------------------------------------------------
// index.html

/// `x` with `prec` decimals, or a dash where there is no number.
fn num(x: f64, prec: usize) -> String {
    if x.is_finite() {
        format!("{x:.prec$}")
    } else {
        "—".into()
    }
}

/// Signed, for errors; a value that rounds to zero shows as +0, not −0.
fn signed(x: f64, prec: usize) -> String {
    let scale = 10f64.powi(prec as i32);
    let x = (x * scale).round() / scale + 0.0;
    if x.is_finite() {
        format!("{x:+.prec$}")
    } else {
        "—".into()
    }
}

/// Escapes text for HTML element content and attribute values.
fn esc(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

const STYLE: &str = "body{font-family:system-ui,-apple-system,'DejaVu Sans',sans-serif;max-width:1140px;margin:2em auto;padding:0 1em;color:#222}\
table{border-collapse:collapse;margin:.5em 0 1.5em}\
th,td{border:1px solid #ccc;padding:.3em .7em;text-align:left;vertical-align:top}\
th{background:#f3f3f3}td.n{text-align:right;font-variant-numeric:tabular-nums}\
figure{margin:1.5em 0}img{max-width:100%;height:auto;border:1px solid #ddd}\
figcaption{color:#555;font-size:.92em;margin-top:.3em}.note{color:#555;font-size:.92em}";

fn html_page(a: &Analysis, matched: Option<&[Matched]>, figures: &[&str]) -> String {
    let mut h = String::new();
    let title = format!("hammer report: {}", esc(&a.name));
    let _ = write!(
        h,
        "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n<title>{title}</title>\n<style>{STYLE}</style>\n</head>\n<body>\n<h1>{title}</h1>\n"
    );
    let _ = writeln!(
        h,
        "<p class=\"note\">Generated by <code>hammer report</code> {}: the same estimator as the firmware and \
         <code>hammer estimate</code>. Uncertainties are expanded (k = {}).</p>",
        env!("CARGO_PKG_VERSION"),
        a.cfg.coverage_factor
    );
    h.push_str(&operating_point_html(a));
    h.push_str(&summary_html(&summarize(&a.reports), matched.map(truth_summary)));
    if matched.is_some_and(|m| m.is_empty()) {
        h.push_str("<p class=\"note\">The sidecar carries the simulator's truth, but no estimated cycle matched a simulated impact within 20 µs.</p>\n");
    }
    h.push_str("<h2>Figures</h2>\n");
    for f in figures {
        let _ = writeln!(
            h,
            "<figure>\n<img src=\"{}\" alt=\"{}\">\n<figcaption>{}</figcaption>\n</figure>",
            esc(f),
            esc(f),
            caption(f)
        );
    }
    h.push_str("</body>\n</html>\n");
    h
}

fn caption(file: &str) -> &'static str {
    match file {
        CYCLE_PNG => {
            "One steady cycle from the middle of the run: pressures, acceleration (limited to the flight \
            phase; the impacts leave its range) and the piston velocity integrated from the pressures with the \
            estimated friction, anchored at the reported impact velocity. Its zero crossing is the turning point \
            that splits backhaul and stroke; the shaded stretches around the impacts are blanked by the estimator."
        }
        RUN_PNG => {
            "Per-cycle estimates over the run with their expanded uncertainty bands. Flagged cycles are \
            not estimates: they are left out of the lines and marked ×."
        }
        TRUTH_PNG => "Estimate against the simulator's truth, cycle by cycle, matched by impact time (within 20 µs).",
        _ => "",
    }
}

fn row(h: &mut String, cells: &[String]) {
    h.push_str("<tr>");
    for (i, c) in cells.iter().enumerate() {
        let class = if i == 0 { "" } else { " class=\"n\"" };
        let _ = write!(h, "<td{class}>{c}</td>");
    }
    h.push_str("</tr>\n");
}

fn operating_point_html(a: &Analysis) -> String {
    let mut h = String::from("<h2>Operating point</h2>\n<table>\n");
    let supply = match a.supply {
        Supply::Flag(b) => format!("{b} bar (--supply-bar)"),
        Supply::Sidecar(b) => format!("{b} bar (sidecar)"),
        Supply::Unknown => "unknown: drift baseline binned by peak rear pressure".into(),
    };
    let source = a
        .sidecar
        .as_ref()
        .map_or("no sidecar".to_string(), |s| s.source.clone());
    let g = &a.cfg.geometry;
    let mut rows = vec![
        ("trace", esc(&a.name)),
        ("source", esc(&source)),
        ("supply pressure (gauge)", supply),
        (
            "samples",
            format!(
                "{} at {} kS/s ({:.3} s)",
                a.trace.len(),
                num(1e-3 / a.trace.dt_s, 1),
                a.trace.len() as f64 * a.trace.dt_s
            ),
        ),
        (
            "piston",
            format!(
                "{} kg, bore {} mm, rod {} mm, inclination {}°",
                g.piston_mass_kg,
                g.bore_diameter_m * 1e3,
                g.rod_diameter_m * 1e3,
                a.cfg.inclination_deg
            ),
        ),
        (
            "config file",
            a.config_file.as_deref().map_or("none (defaults)".into(), esc),
        ),
    ];
    if let Some(sim) = a.simulation() {
        let effects = if sim.active_effects.is_empty() {
            "none (nominal)".to_string()
        } else {
            sim.active_effects.join(", ")
        };
        rows.push(("simulated effects", esc(&effects)));
        rows.push(("simulation seed", sim.config.seed.to_string()));
    }
    for (k, v) in rows {
        let _ = writeln!(h, "<tr><th>{k}</th><td>{v}</td></tr>");
    }
    h.push_str("</table>\n");
    h
}

fn summary_html(s: &Summary, t: Option<TruthSummary>) -> String {
    let mut h = String::from("<h2>Summary</h2>\n<table>\n<tr><th>quantity (valid cycles)</th><th>estimate</th>");
    if t.is_some() {
        h.push_str("<th>simulator truth</th><th>mean error</th>");
    }
    h.push_str("</tr>\n");
    let flags = if s.flag_counts.is_empty() {
        String::new()
    } else {
        let list: Vec<String> = s.flag_counts.iter().map(|(n, c)| format!("{n} × {c}")).collect();
        format!(" (flags: {})", list.join(", "))
    };
    let truth = |f: &dyn Fn(&TruthSummary) -> (String, String)| match &t {
        Some(t) => {
            let (a, b) = f(t);
            vec![a, b]
        }
        None => vec![],
    };
    let mut add = |label: &str, est: String, truth: Vec<String>| {
        let mut cells = vec![label.to_string(), est];
        cells.extend(truth);
        row(&mut h, &cells);
    };
    add(
        "cycles",
        format!("{}{}", s.cycles, flags),
        truth(&|_| (String::new(), String::new())),
    );
    add(
        "valid cycles",
        s.valid_cycles.to_string(),
        truth(&|t| (format!("{} matched", t.matched_cycles), String::new())),
    );
    add(
        "friction, N: mean ± cycle-to-cycle sd [± U]",
        format!(
            "{} ± {} [± {}]",
            num(s.friction_mean_n, 3),
            num(s.friction_sd_n, 3),
            num(s.friction_uncertainty_n, 2)
        ),
        truth(&|t| (num(t.friction_n, 3), signed(t.friction_error_n, 3))),
    );
    add(
        "impact energy, J: mean ± sd [± U]",
        format!(
            "{} ± {} [± {}]",
            num(s.energy_mean_j, 4),
            num(s.energy_sd_j, 4),
            num(s.energy_uncertainty_j, 3)
        ),
        truth(&|t| {
            let rel = 100.0 * t.energy_error_j / t.energy_j;
            (
                num(t.energy_j, 4),
                format!("{} ({} %)", signed(t.energy_error_j, 4), signed(rel, 2)),
            )
        }),
    );
    let blind_excess = 100.0 * (s.energy_frictionless_mean_j / s.energy_mean_j - 1.0);
    add(
        "friction-blind impact energy, J",
        format!(
            "{} ({} % over the friction-aware)",
            num(s.energy_frictionless_mean_j, 4),
            signed(blind_excess, 1)
        ),
        truth(&|t| {
            let over = 100.0 * (s.energy_frictionless_mean_j / t.energy_j - 1.0);
            (String::new(), format!("{} % vs truth", signed(over, 1)))
        }),
    );
    add(
        "frequency, Hz",
        num(s.frequency_mean_hz, 3),
        truth(&|t| (num(t.frequency_hz, 3), signed(t.frequency_error_hz, 4))),
    );
    add(
        "stroke friction work / impact energy, %",
        num(100.0 * s.friction_work_ratio, 1),
        truth(&|t| {
            let err = 100.0 * (s.friction_work_ratio - t.friction_work_ratio);
            (num(100.0 * t.friction_work_ratio, 1), signed(err, 1))
        }),
    );
    add(
        "wear index after the last cycle, J",
        num(s.wear_index_j, 2),
        truth(&|_| (String::new(), String::new())),
    );
    h.push_str("</table>\n");
    h
}

/// What the estimator's no-impact records blame, for an error that would
/// otherwise only say "no cycle".
pub fn no_impact_note(reports: &[hammer_estimator::CycleReport]) -> String {
    let flags = reports
        .iter()
        .filter(|r| !r.is_cycle())
        .fold(hammer_estimator::Flags::default(), |f, r| f | r.flags);
    if reports.is_empty() {
        String::new()
    } else {
        format!(
            "; {} no-impact record(s) flagged {}",
            reports.len(),
            flags.names().collect::<Vec<_>>().join(",")
        )
    }
}
