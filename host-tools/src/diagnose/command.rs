//! `hammer diagnose` and `hammer diagnose-bench`.

use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};

use anyhow::{bail, Context, Result};
use clap::Args;
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

use super::bench::{render, run_case_with, summarize, BenchOptions, CaseResult, PlantFor};
use super::case_log::{CaseLog, Done};
use super::engine::{diagnose_with, Options};
use super::input::{read_request, DiagnoseError, Request};
use super::model::{Builtin, FmuPlant, Plant};
use super::output::{summary, write_all};
use hammer_sim::SimConfig;
use hammer_variants::Structure;
use std::sync::Arc;

#[derive(Args, Debug)]
pub struct DiagnoseArgs {
    /// A measured trace (project trace format, CSV + optional sidecar), or a
    /// folder `hammer commission` wrote (every trace in it, all fitted
    /// unless `--fit-on` names some); repeatable. A trace's supply pressure
    /// comes from the sidecar or from a `--supply-bar` given right after it.
    #[arg(long, value_name = "TRACE", required = true)]
    pub measured: Vec<PathBuf>,
    /// Gauge supply pressure of the preceding `--measured`, bar.
    #[arg(long, value_name = "BAR", value_parser = crate::cli::supply_bar)]
    pub supply_bar: Vec<f64>,
    /// A record of the same hammer when it was known sound: a trace
    /// (repeatable; its supply pressure like `--measured`'s) or the folder
    /// `hammer commission` wrote. The measured traces are then diagnosed as
    /// a change from it, which cancels the model's form error. Every
    /// operating point of the measured traces needs one.
    #[arg(long, value_name = "TRACE|DIR")]
    pub reference: Vec<PathBuf>,
    /// Diagnose against a commissioning record although the board was
    /// recalibrated since (its calibration differs from the measured
    /// traces'): the change then includes the recalibration's.
    #[arg(long)]
    pub allow_stale_reference: bool,
    /// Fit on these traces (repeatable; default: the first); the other
    /// operating points, and the later half of the fitted traces' cycles, are held out.
    #[arg(long, value_name = "TRACE")]
    pub fit_on: Vec<PathBuf>,
    /// TOML file of the nominal model: [hammer], [valve], [contact], [sensors], [estimator].
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Relative standard deviation of the nominal parameters the model is
    /// unsure of (valve, ports, dead volumes, contact): a real hammer's are
    /// known to about ±20 %; they are recalibrated within it.
    #[arg(long, default_value_t = hammer_sim::params::NOMINAL_UNCERTAINTY)]
    pub nominal_uncertainty: f64,
    /// Directory for report.json, report.md and the figures.
    #[arg(long)]
    pub out: PathBuf,
    /// Fit a model of your own instead of the built-in simulator: an FMI
    /// 2.0 co-simulation FMU with a linux64 binary (docs/your-model.md).
    /// `--config` still describes the measured hammer (geometry, sensors).
    #[arg(long, value_name = "FMU")]
    pub model: Option<PathBuf>,
    /// The FMU's model map (default: `X.map.toml` beside `X.fmu`, as `hammer fmu` writes it).
    #[arg(long, value_name = "MAP", requires = "model")]
    pub model_map: Option<PathBuf>,
    /// The longest one run of the FMU may take, s (then its process is stopped and the diagnosis ends).
    #[arg(long, value_name = "S", default_value_t = 60.0, requires = "model")]
    pub model_time_limit: f64,
    /// Simulations side by side, and so the most FMU instances alive at
    /// once: a tool's runtime licence may draw a seat for each
    /// (docs/your-model.md). The verdict is the same on any number
    /// [default: the machine's cores].
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u16).range(1..))]
    pub threads: Option<u16>,
}

#[derive(Args, Debug)]
pub struct BenchArgs {
    /// Number of cases (each twelve: the eight effects, two controls, two pairs).
    #[arg(long, default_value_t = 24)]
    pub cases: usize,
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Operating points of every case, bar (the first and last are fitted).
    #[arg(long, value_delimiter = ',', default_value = "4,5.5,7")]
    pub points: Vec<f64>,
    /// Length of each generated trace, s.
    #[arg(long, default_value_t = 1.0)]
    pub duration: f64,
    /// Half-width of the uniform jitter of the generator's nominal parameters
    /// [default: 0.03, 0.1 with --structural].
    #[arg(long)]
    pub jitter: Option<f64>,
    /// Write bench.json (every case) and bench.txt here.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Measure hammers of the second model family (valve, ports, chambers,
    /// supply, anvil or sensors differ in form from the diagnosis' model);
    /// the default jitter becomes ±10 %.
    #[arg(long)]
    pub structural: bool,
    /// Instead of cases: the catalogue's isolability matrix from the model
    /// alone (each effect at its default in the model, every effect fitted).
    #[arg(long, conflicts_with = "structural")]
    pub isolability: bool,
    /// Give each case a record of the same hammer without the effect at
    /// every point, and diagnose the change from it (`diagnose --reference`).
    #[arg(long, conflicts_with = "isolability")]
    pub reference: bool,
    /// Diagnose every case with this FMU instead of the built-in model
    /// (`diagnose --model`); the cases are generated as without it.
    #[arg(long, value_name = "FMU", conflicts_with = "isolability")]
    pub model: Option<PathBuf>,
    /// The FMU's model map (default: `X.map.toml` beside `X.fmu`).
    #[arg(long, value_name = "MAP", requires = "model")]
    pub model_map: Option<PathBuf>,
    /// The longest one run of the FMU may take, s.
    #[arg(long, value_name = "S", default_value_t = 60.0, requires = "model")]
    pub model_time_limit: f64,
    /// Check each single of the model's own form against its truth: would
    /// the hammer's true nominal values and effect, in the model, pass the
    /// rule that names it? Where not, a `none` is the features' ceiling.
    #[arg(long, conflicts_with_all = ["structural", "model"])]
    pub oracle: bool,
    /// Cases side by side, one thread and one FMU instance each (with
    /// `--isolability`, simulations side by side) [default: the machine's
    /// cores].
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u16).range(1..))]
    pub threads: Option<u16>,
    /// Go on with the run whose cases `--out DIR` logged (`DIR/cases.jsonl`):
    /// only the cases it lacks are run. The options must be the run's own;
    /// `--cases` may grow. Without it, a new log replaces an old one.
    #[arg(long, requires = "out", conflicts_with = "isolability")]
    pub resume: bool,
}

/// Pairs every `--supply-bar` of the raw command line with the `--measured`
/// or `--reference` before it (clap keeps the lists apart): the measured
/// traces' pressures, then the references'.
fn supply_bars_by_position(
    raw: &[String],
    n_measured: usize,
    n_reference: usize,
) -> (Vec<Option<f64>>, Vec<Option<f64>>) {
    let mut out = (vec![None; n_measured], vec![None; n_reference]);
    // The trace a `--supply-bar` belongs to: (is a reference, index).
    let mut current: Option<(bool, usize)> = None;
    let (mut measured, mut reference) = (0usize, 0usize);
    let mut it = raw.iter().peekable();
    while let Some(a) = it.next() {
        let (flag, inline) = match a.split_once('=') {
            Some((f, v)) if f.starts_with("--") => (f, Some(v.to_string())),
            _ => (a.as_str(), None),
        };
        match flag {
            "--measured" | "--reference" => {
                let is_ref = flag == "--reference";
                let n = if is_ref { &mut reference } else { &mut measured };
                current = Some((is_ref, *n));
                *n += 1;
                if inline.is_none() {
                    it.next();
                }
            }
            "--supply-bar" => {
                let v = inline.or_else(|| it.next().cloned());
                if let (Some((is_ref, i)), Some(v)) = (current, v.and_then(|v| v.parse::<f64>().ok())) {
                    let list = if is_ref { &mut out.1 } else { &mut out.0 };
                    if let Some(slot) = list.get_mut(i) {
                        *slot = Some(v);
                    }
                }
            }
            _ => {}
        }
    }
    out
}

fn progress_bar(len: u64, template: &str) -> ProgressBar {
    if !std::io::stderr().is_terminal() {
        return ProgressBar::with_draw_target(Some(len), ProgressDrawTarget::hidden());
    }
    let pb = ProgressBar::with_draw_target(Some(len), ProgressDrawTarget::stderr());
    if let Ok(style) = ProgressStyle::with_template(template) {
        pb.set_style(style);
    }
    pb
}

pub fn run(args: &DiagnoseArgs) -> Result<()> {
    let raw: Vec<String> = std::env::args().collect();
    let (mut bars, ref_bars) = supply_bars_by_position(&raw, args.measured.len(), args.reference.len());
    if bars.iter().all(Option::is_none) && args.supply_bar.len() == args.measured.len() && args.reference.is_empty() {
        bars = args.supply_bar.iter().map(|b| Some(*b)).collect();
    }
    let read = read_request(&Request {
        measured: args.measured.iter().cloned().zip(bars).collect(),
        reference: args.reference.iter().cloned().zip(ref_bars).collect(),
        fit_on: args.fit_on.clone(),
        config: args.config.clone(),
        allow_stale_reference: args.allow_stale_reference,
    })?;
    for w in &read.warnings {
        eprintln!("warning: {w}");
    }
    let (inputs, references, base) = (read.inputs, read.references, read.base);
    let opts = Options {
        nominal_uncertainty: args.nominal_uncertainty,
        ..options(args.threads, true)
    };
    let pb = progress_bar(1, "{spinner} diagnose [{bar:30}] {pos}/{len} {msg} ({elapsed})");
    let plant: Arc<dyn Plant> = match &args.model {
        Some(fmu) => Arc::new(open_plant(
            fmu,
            args.model_map.as_deref(),
            opts.threads,
            args.model_time_limit,
        )?),
        None => Arc::new(Builtin::new(base.clone())),
    };

    let outcome = diagnose_with(&inputs, &references, &base, plant, &opts, &|done, total, what| {
        pb.set_length(total as u64);
        pb.set_position(done as u64);
        pb.set_message(what.to_string());
    })
    .map_err(|e| name_the_model(e, args.model.as_deref()))?;
    pb.finish_and_clear();
    let written = write_all(&args.out, &outcome)?;
    print!("{}", summary(&outcome.report));
    println!(
        "wrote {} ({} simulations on {} thread{}, {:.1} s)",
        written
            .iter()
            .map(|p| p.display().to_string())
            .collect::<Vec<_>>()
            .join(", "),
        outcome.report.simulations,
        opts.threads,
        if opts.threads == 1 { "" } else { "s" },
        outcome.report.elapsed_s
    );
    Ok(())
}

/// The diagnosis' options on `threads` (default: the machine's cores),
/// keeping the waveforms for the figures or not.
fn options(threads: Option<u16>, figures: bool) -> Options {
    let defaults = Options::default();
    Options {
        threads: threads.map_or(defaults.threads, usize::from),
        figures,
        ..defaults
    }
}

/// A nominal model that does not run is the FMU's to answer for: the
/// error names it where the model's own message does not (the
/// diagnosis' own finding, a run that holds no impact cycle, names no
/// file).
fn name_the_model(e: DiagnoseError, fmu: Option<&Path>) -> anyhow::Error {
    match (&e, fmu) {
        (DiagnoseError::Model(_, why), Some(fmu)) if !why.contains(&fmu.display().to_string()) => {
            anyhow::anyhow!("FMU {}: {e}", fmu.display())
        }
        _ => e.into(),
    }
}

/// A user's FMU with its map as the diagnosis' model, in at most
/// `threads` worker processes.
fn open_plant(fmu: &Path, model_map: Option<&Path>, threads: usize, time_limit_s: f64) -> Result<FmuPlant> {
    let (model, _) = crate::fmu_cmd::open_model(fmu, model_map, threads, time_limit_s)?;
    FmuPlant::new(model).map_err(|e| anyhow::anyhow!("FMU {}: {e}", fmu.display()))
}

pub fn bench(args: &BenchArgs) -> Result<()> {
    if args.points.is_empty() {
        bail!("--points: give at least one operating point");
    }
    for &p in &args.points {
        hammer_trace::config::check_range("--points", p, 0.5, 20.0)?;
    }
    if args.isolability {
        return isolability(args);
    }
    let jitter = args.jitter.unwrap_or(BenchOptions::default_jitter(args.structural));
    hammer_trace::config::check_range("--jitter", jitter, 0.0, 0.5)?;
    hammer_trace::config::check_range("--duration", args.duration, 0.3, 60.0)?;
    let opts = BenchOptions {
        cases: args.cases,
        seed: args.seed,
        points: args.points.clone(),
        duration_s: args.duration,
        jitter,
        structural: args.structural,
        reference: args.reference,
        // A record must add evidence, never subtract it: the benchmark
        // shows every case beside its diagnosis against the model alone.
        alone_beside: args.reference,
        model: None,
        oracle: args.oracle,
    };
    let diag = options(args.threads, false);
    let workers = diag.threads.clamp(1, args.cases.max(1));
    let fmu = match &args.model {
        Some(fmu) => Some(open_plant(
            fmu,
            args.model_map.as_deref(),
            workers,
            args.model_time_limit,
        )?),
        None => None,
    };
    let opts = BenchOptions {
        model: fmu.as_ref().and_then(|p| p.identity()),
        ..opts
    };
    // Each case's drawn structure goes to an FMU that takes it as
    // parameters (the second family's); any other FMU runs as it is.
    let plant_for = |structure: Option<&Structure>| -> Arc<dyn Plant> {
        match (&fmu, structure) {
            (Some(f), Some(s)) => Arc::new(f.with_fixed(f.structure_settings(s))),
            (Some(f), None) => Arc::new(f.with_fixed(Vec::new())),
            (None, _) => Arc::new(Builtin::new(SimConfig::default())),
        }
    };
    let plant_for: Option<PlantFor> = fmu.as_ref().map(|_| &plant_for as PlantFor);
    // Each finished case is logged as it finishes, so a long run can go on
    // where it was stopped (`--resume`).
    let (log, mut done) = match &args.out {
        Some(dir) => {
            let (log, done) = CaseLog::open(dir, &opts, args.resume)?;
            (Some(log), done)
        }
        None => (None, Done::default()),
    };
    let todo: Vec<usize> = (0..args.cases).filter(|i| !done.contains(*i)).collect();
    if let Some(log) = &log {
        if args.resume {
            eprintln!(
                "{}: {} of {} cases done, {} to run",
                log.path().display(),
                args.cases - todo.len(),
                args.cases,
                todo.len()
            );
        }
    }
    let pb = progress_bar(
        args.cases as u64,
        "diagnose-bench [{bar:30}] {pos}/{len} {msg} ({elapsed}, eta {eta})",
    );
    pb.set_position((args.cases - todo.len()) as u64);
    let results = run_cases(&todo, &opts, &diag, workers, plant_for, log.as_ref(), &pb);
    let mut cases: Vec<CaseResult> = Vec::new();
    let mut not_run = Vec::new();
    for (i, r) in results {
        match r {
            Ok(c) => cases.push(c),
            // A generated hammer that does not run: the case is not a test
            // of the diagnosis. Said, and left out of the counts.
            Err(e) if is_no_cycles(&e) => {
                pb.println(format!("case {i} not run: {e:#}"));
                not_run.push((i, format!("{e:#}")));
            }
            Err(e) => return Err(e.context(format!("case {i}"))),
        }
    }
    pb.finish_and_clear();
    // The logged cases of this run's range, with the new ones, in order.
    done.cases.retain(|i, _| *i < args.cases);
    cases.extend(done.cases.into_values());
    cases.sort_by_key(|c| c.index);
    not_run.extend(done.not_run.into_iter().filter(|(i, _)| *i < args.cases));
    not_run.sort_by_key(|(i, _)| *i);
    if not_run.len() * 10 > args.cases {
        bail!(
            "{} of {} cases could not be generated: {:?}",
            not_run.len(),
            args.cases,
            not_run
        );
    }
    let s = summarize(&opts, cases, not_run);
    let text = render(&s);
    print!("{text}");
    if let Some(dir) = &args.out {
        write_result(dir, "bench", &s, &text)?;
    }
    Ok(())
}

/// A generated hammer that does not run: not a test of the diagnosis.
fn is_no_cycles(e: &anyhow::Error) -> bool {
    e.downcast_ref::<DiagnoseError>()
        .is_some_and(DiagnoseError::is_no_cycles)
}

/// The cases `todo` of `opts`, `workers` of them side by side, in case
/// order, each logged as it finishes.
fn run_cases(
    todo: &[usize],
    opts: &BenchOptions,
    diag: &Options,
    workers: usize,
    plant_for: Option<PlantFor>,
    log: Option<&CaseLog>,
    pb: &ProgressBar,
) -> Vec<(usize, Result<CaseResult>)> {
    // Cases side by side, one thread each: a case's diagnosis is the same
    // on any number of threads, and one thread a case keeps every core
    // busy where a case's own stages would leave one idle between them.
    let one = Options {
        threads: 1,
        ..diag.clone()
    };
    let next = AtomicUsize::new(0);
    let right = AtomicUsize::new(0);
    std::thread::scope(|scope| {
        let workers: Vec<_> = (0..workers)
            .map(|_| {
                scope.spawn(|| {
                    let mut done = Vec::new();
                    loop {
                        let Some(&i) = todo.get(next.fetch_add(1, Ordering::Relaxed)) else {
                            break done;
                        };
                        let r = run_case_with(opts, i, &one, plant_for);
                        if let Ok(c) = &r {
                            right.fetch_add(usize::from(c.correct), Ordering::Relaxed);
                        }
                        // A log that cannot be written costs the resume,
                        // not the run: said, and the run goes on.
                        let logged = match (&r, log) {
                            (Ok(c), Some(log)) => log.case(c),
                            (Err(e), Some(log)) if is_no_cycles(e) => log.not_run(i, &format!("{e:#}")),
                            _ => Ok(()),
                        };
                        if let Err(e) = logged {
                            pb.println(format!("case {i}: {e:#}"));
                        }
                        pb.set_message(format!("{} named right", right.load(Ordering::Relaxed)));
                        pb.inc(1);
                        done.push((i, r));
                    }
                })
            })
            .collect();
        let mut all: Vec<_> = workers
            .into_iter()
            .flat_map(|w| w.join().unwrap_or_else(|p| std::panic::resume_unwind(p)))
            .collect();
        all.sort_by_key(|(i, _)| *i);
        all
    })
}

/// `DIR/NAME.json` (every figure) and `DIR/NAME.txt` (what was printed).
fn write_result(dir: &Path, name: &str, value: &impl serde::Serialize, text: &str) -> Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let json = dir.join(format!("{name}.json"));
    std::fs::write(&json, serde_json::to_string_pretty(value)?)
        .with_context(|| format!("writing {}", json.display()))?;
    let txt = dir.join(format!("{name}.txt"));
    std::fs::write(&txt, text).with_context(|| format!("writing {}", txt.display()))?;
    Ok(())
}

fn isolability(args: &BenchArgs) -> Result<()> {
    let diag = options(args.threads, false);
    let rows = super::isolability::matrix(&args.points, args.duration, &diag)?;
    let text = super::isolability::render(&rows);
    print!("{text}");
    if let Some(dir) = &args.out {
        write_result(dir, "isolability", &rows, &text)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn supply_bars_follow_their_trace() {
        let raw: Vec<String> = [
            "hammer",
            "diagnose",
            "--measured",
            "a.csv",
            "--supply-bar",
            "4",
            "--measured=b.csv",
            "--measured",
            "c.csv",
            "--supply-bar=7",
            "--out",
            "d",
        ]
        .iter()
        .map(|s| s.to_string())
        .collect();
        assert_eq!(supply_bars_by_position(&raw, 3, 0).0, vec![Some(4.0), None, Some(7.0)]);
    }

    #[test]
    fn a_references_supply_bar_is_its_own() {
        let raw: Vec<String> = [
            "hammer",
            "diagnose",
            "--measured",
            "a.csv",
            "--supply-bar",
            "4",
            "--reference",
            "r.csv",
            "--supply-bar=7",
            "--measured=b.csv",
            "--reference=s.csv",
            "--supply-bar",
            "5.5",
        ]
        .iter()
        .map(|s| s.to_string())
        .collect();
        let (m, r) = supply_bars_by_position(&raw, 2, 2);
        assert_eq!(m, vec![Some(4.0), None]);
        assert_eq!(r, vec![Some(7.0), Some(5.5)]);
    }
}
