//! `hammer report`: the estimator's view of one trace as PNG figures and a
//! self-contained HTML page (no external assets), for a person to read.
//!
//! The estimator runs exactly as in `hammer estimate` (same configuration
//! path, same code). The figures add what the per-cycle records cannot show:
//! one cycle's signals with the stroke/backhaul split, the run's trends with
//! their uncertainty, and, for a simulated trace, the estimate against the
//! simulator's truth.
//!
//! Modules: `analysis` runs the estimator and sums it up (no drawing),
//! `figures` draws the PNGs in the shared chart model, `html` writes the
//! page; this module is the command's glue.

mod analysis;
mod figures;
mod html;

use std::io::IsTerminal as _;
use std::path::PathBuf;
use std::time::Duration;

use anyhow::{Context, Result};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

pub use analysis::{match_truth, summarize, truth_summary, Matched, Summary, TruthSummary, MATCH_TOLERANCE_S};
pub use hammer_sim::estimation::{geometry_hint, no_impact_note};

pub const CYCLE_PNG: &str = "cycle.png";
pub const RUN_PNG: &str = "run.png";
pub const TRUTH_PNG: &str = "truth.png";
pub const INDEX_HTML: &str = "index.html";

/// Pixel sizes of the figures (the tests read them back from the PNG header).
pub const CYCLE_SIZE: (u32, u32) = (1100, 900);
pub const RUN_SIZE: (u32, u32) = (1100, 1000);
pub const TRUTH_SIZE: (u32, u32) = (1100, 800);

/// Write an HTML report with PNG figures of a trace: one cycle with its
/// stroke/backhaul split, the run's per-cycle estimates, and for a simulated
/// trace the estimate against the simulator's truth.
#[derive(clap::Args, Debug)]
pub struct ReportArgs {
    /// Trace in the project's format (CSV, SI units, gauge pressures), or a recorder's
    /// file (delimited text, TDMS, MAT v5, WAV, Parquet) read through --map / [import]. Its sidecar
    /// JSON beside it (same name, extension .json) is read if present: the operating
    /// point and, for a simulated trace, the per-cycle truth the estimate is compared with.
    pub input: PathBuf,
    /// Directory for index.html and the PNG figures (created if missing; files of
    /// the same names are overwritten).
    #[arg(long)]
    pub out: PathBuf,
    /// Gauge supply pressure, bar: the operating point of the drift baseline
    /// (default: the sidecar's; unknown means binning by peak rear pressure).
    #[arg(long, value_parser = crate::cli::supply_bar)]
    pub supply_bar: Option<f64>,
    /// TOML file: [hammer] geometry, [sensors.*] calibration ranges, [estimator] thresholds
    /// and accuracy (default: the paper's hammer on the reference bench; a simulator's
    /// sidecar supplies its own hammer and sensors).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// TOML file with the `[import]` table for a recorder's file (overrides the config's).
    #[arg(long, value_name = "FILE.toml")]
    pub map: Option<PathBuf>,
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
    let a = analysis::analyse(args, pb)?;
    std::fs::create_dir_all(&args.out).with_context(|| format!("creating {}", args.out.display()))?;
    let out = |name: &str| args.out.join(name);
    stage(pb, "drawing cycle.png");
    figures::cycle_figure(&a, &out(CYCLE_PNG))?;
    let mut files = vec![out(CYCLE_PNG)];
    stage(pb, "drawing run.png");
    figures::run_figure(&a, &out(RUN_PNG))?;
    files.push(out(RUN_PNG));
    stage(pb, "drawing truth.png");
    let matched = a.truth().map(|t| match_truth(&a.reports, t, a.t0_s()));
    if let Some(m) = matched.as_ref().filter(|m| !m.is_empty()) {
        figures::truth_figure(&a, m, &out(TRUTH_PNG))?;
        files.push(out(TRUTH_PNG));
    }
    stage(pb, "writing index.html");
    let figures: Vec<&str> = files.iter().filter_map(|f| f.file_name()?.to_str()).collect();
    let html = html::html_page(&a, matched.as_deref(), &figures);
    std::fs::write(out(INDEX_HTML), html).with_context(|| format!("writing {}", out(INDEX_HTML).display()))?;
    files.push(out(INDEX_HTML));
    Ok(files)
}
