//! `hammer fmu`: the export (`--out X.fmu`), the pre-flight of a foreign
//! FMU (`check`), its speed against the built-in path (`speed`), a
//! source-code FMU built for this platform (`compile`), and the
//! hidden worker process that runs a foreign FMU (`worker`, started by
//! `hammer_fmu::import`, never by hand).

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result};
use clap::{Args, Subcommand};

use hammer_fmu::import::{cycling, FmuModel, ModelMap, WorkerCommand};
use hammer_sim::SimConfig;
use hammer_trace::config::load_toml;

#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum FmuFamily {
    Hammer,
    Variants,
}

#[derive(Args, Debug)]
#[command(args_conflicts_with_subcommands = true, subcommand_negates_reqs = true)]
pub struct FmuArgs {
    #[command(subcommand)]
    pub action: Option<FmuAction>,
    /// The FMU to write; the model map goes beside it (`X.fmu` → `X.map.toml`).
    #[arg(long, required = true)]
    pub out: Option<PathBuf>,
    /// TOML file whose values become the FMU's start values (with
    /// `--family variants`: `[params]`, `[structure]`, `[supply]`,
    /// `[effects.*]`, `seed`, `duration_s`).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Which model: the built-in simulator, or hammer-variants' second family.
    #[arg(long, value_enum, default_value = "hammer")]
    pub family: FmuFamily,
    /// The FMU's shared library (default: $HAMMER_FMU_LIB, else
    /// libhammer_fmu.so beside this program; `cargo build --release -p hammer-fmu`).
    #[arg(long)]
    pub lib: Option<PathBuf>,
}

#[derive(Subcommand, Debug)]
pub enum FmuAction {
    /// Pre-flight of an FMU for the diagnosis: loads it, checks the model
    /// map against its description, runs one short simulation, and says
    /// which catalogue effects the diagnosis can name with it.
    Check(RunArgs),
    /// Times runs of the FMU against the built-in simulator's path at the
    /// same supply pressure and duration, and what a diagnosis costs.
    Speed(SpeedArgs),
    /// Builds a linux64 binary from a source-code FMU's sources with the
    /// system's C compiler ($CC, else cc; $CXX, else c++, for C++) and
    /// writes the FMU with it.
    Compile(CompileArgs),
    /// The worker process that runs a foreign FMU (started by the import).
    #[command(hide = true)]
    Worker,
}

#[derive(Args, Debug)]
pub struct RunArgs {
    /// The FMU (FMI 2.0 co-simulation, linux64 binary).
    pub fmu: PathBuf,
    /// The model map (default: `X.map.toml` beside `X.fmu`, as `hammer fmu` writes it).
    #[arg(long)]
    pub model_map: Option<PathBuf>,
    /// Gauge supply pressure of the run, bar.
    #[arg(long, default_value_t = 5.0, value_parser = crate::cli::supply_bar)]
    pub supply_bar: f64,
    /// Simulated time of the run, s.
    #[arg(long, default_value_t = 1.0)]
    pub duration: f64,
    /// The longest one call into the FMU may take, s (then its process is stopped).
    #[arg(long, default_value_t = 60.0)]
    pub time_limit: f64,
}

#[derive(Args, Debug)]
pub struct CompileArgs {
    /// The source-code FMU (FMI 2.0 co-simulation, with `sources/`).
    pub fmu: PathBuf,
    /// The FMU to write (default: `X.linux64.fmu` beside `X.fmu`; never
    /// the FMU itself).
    #[arg(long)]
    pub out: Option<PathBuf>,
}

#[derive(Args, Debug)]
pub struct SpeedArgs {
    #[command(flatten)]
    pub run: RunArgs,
    /// Runs to time (the first, which starts the worker, is not counted).
    #[arg(long, default_value_t = 5)]
    pub runs: usize,
    /// Simulations per diagnosis to cost (docs/diagnosis.md: 416 with two
    /// points fitted and two held out, 1002 with four fitted; each run
    /// 0.45 s simulated: give --duration 0.45).
    #[arg(long, value_delimiter = ',', default_values_t = [416usize, 1002])]
    pub per_diagnosis: Vec<usize>,
}

pub fn run(args: &FmuArgs) -> Result<()> {
    match &args.action {
        None => export(args),
        Some(FmuAction::Check(a)) => check(a),
        Some(FmuAction::Speed(a)) => speed(a),
        Some(FmuAction::Compile(a)) => compile(a),
        Some(FmuAction::Worker) => std::process::exit(hammer_fmu::import::worker::serve()),
    }
}

fn export(args: &FmuArgs) -> Result<()> {
    let out = args.out.as_ref().context("--out is required")?;
    let in_file = || args.config.as_ref().map_or(String::new(), |p| p.display().to_string());
    let model = match args.family {
        FmuFamily::Hammer => {
            let cfg: SimConfig = args
                .config
                .as_deref()
                .map_or_else(|| Ok(SimConfig::default()), load_toml)?;
            cfg.validate().with_context(in_file)?;
            hammer_fmu::Model::Hammer(cfg)
        }
        FmuFamily::Variants => {
            let cfg: hammer_fmu::VariantsConfig = args
                .config
                .as_deref()
                .map_or_else(|| Ok(Default::default()), load_toml)?;
            cfg.validate().map_err(anyhow::Error::msg).with_context(in_file)?;
            hammer_fmu::Model::Variants(cfg)
        }
    };
    let lib = hammer_fmu::find_library(args.lib.as_deref()).map_err(anyhow::Error::msg)?;
    let w = hammer_fmu::write_fmu(&model, &lib, out).map_err(anyhow::Error::msg)?;
    outln!(
        "wrote {} (FMI 2.0 co-simulation, linux64; {} parameters, {} outputs; GUID {}) and {}",
        w.fmu.display(),
        w.parameters,
        w.outputs,
        w.guid,
        w.map.display()
    );
    Ok(())
}

/// The FMU opened with its map (the given one, else the one beside it;
/// with neither it is opened without a map: loaded and instantiated, not run).
fn open(a: &RunArgs, threads: usize) -> Result<(FmuModel, PathBuf)> {
    if !(a.duration > 0.0 && a.duration.is_finite()) {
        anyhow::bail!("--duration must be positive seconds");
    }
    open_model(&a.fmu, a.model_map.as_deref(), threads, a.time_limit)
}

/// `fmu` opened with `model_map` (default: `X.map.toml` beside `X.fmu`,
/// if there is one) in at most `threads` worker processes, each call
/// limited to `time_limit_s`: what `fmu check` and `diagnose --model` share.
pub(crate) fn open_model(
    fmu: &std::path::Path,
    model_map: Option<&std::path::Path>,
    threads: usize,
    time_limit_s: f64,
) -> Result<(FmuModel, PathBuf)> {
    let worker = WorkerCommand::this_program().map_err(anyhow::Error::msg)?;
    FmuModel::open_mapped(fmu, model_map, threads, time_limit_s, worker).map_err(anyhow::Error::msg)
}

/// The map of an FMU opened with one, else the error that says how to give it.
fn need_map<'m>(model: &'m FmuModel, a: &RunArgs, map_path: &std::path::Path) -> Result<&'m ModelMap> {
    model.map().ok_or_else(|| {
        anyhow::anyhow!(
            "FMU {}: no model map (none given, none beside it at {}): it loads and instantiates, \
             but without a map nothing can be run or named; give --model-map (docs/your-model.md, \"Writing the map\")",
            a.fmu.display(),
            map_path.display()
        )
    })
}

fn check(a: &RunArgs) -> Result<()> {
    let (model, map_path) = open(a, 1)?;
    let id = model.identity();
    let d = model.description();
    outln!(
        "FMU {}: {:?}, GUID {}, FMI {}, generated by {}; co-simulation, linux64 binary loaded and instantiated{}",
        a.fmu.display(),
        id.name,
        id.guid,
        id.fmi_version,
        id.generation_tool.as_deref().unwrap_or("(not said)"),
        if d.once_per_process {
            " (one instance per process: the pool runs one per worker process)"
        } else {
            ""
        }
    );
    let map = need_map(&model, a, &map_path)?;
    outln!(
        "map {} (sha256 {}): fits the FMU: {} signals, supply {} ({}, {}), {} nuisance parameters, {} fixed",
        map_path.display(),
        id.map_hash.as_deref().unwrap_or(""),
        map.outputs().len(),
        map.supply.variable(),
        map.supply.unit,
        match map.supply.pressure {
            hammer_fmu::import::map::Reference::Gauge => "gauge",
            hammer_fmu::import::map::Reference::Absolute => "absolute",
        },
        map.nuisance.len(),
        map.fixed.len()
    );
    outln!("what the diagnosis can name with it:");
    for (name, c) in map.coverage() {
        outln!("  {name:<22} {}", c.label());
    }
    let t0 = Instant::now();
    let s = model.run(a.supply_bar * 1e5, &[], a.duration)?;
    let took = t0.elapsed().as_secs_f64();
    let c = cycling::steady(&s).map_err(|e| hammer_fmu::import::FmuError {
        fmu: a.fmu.clone(),
        kind: hammer_fmu::import::FailKind::NotCycling,
        detail: format!("a run of {} s at {} bar: {e}", a.duration, a.supply_bar),
    })?;
    outln!(
        "run: {} s at {} bar in {took:.3} s ({} samples every {:.4} ms): steady cycling, {} cycles in its second half, period {:.2} ms (spread {:.2} %)",
        a.duration,
        a.supply_bar,
        s.p_rear_pa.len(),
        s.dt_s * 1e3,
        c.cycles,
        c.period_s * 1e3,
        c.spread * 100.0
    );
    Ok(())
}

fn compile(a: &CompileArgs) -> Result<()> {
    let out = a.out.clone().unwrap_or_else(|| a.fmu.with_extension("linux64.fmu"));
    let same = |p: &std::path::Path| std::fs::canonicalize(p).ok();
    if out == a.fmu || (same(&out).is_some() && same(&out) == same(&a.fmu)) {
        anyhow::bail!(
            "FMU {}: --out is the FMU itself; write the compiled one elsewhere",
            a.fmu.display()
        );
    }
    let c = hammer_fmu::import::compile::compile(&a.fmu, &out)?;
    outln!(
        "compiled {} source file(s) of {} ({}) with {} into {}; wrote {}",
        c.sources.len(),
        a.fmu.display(),
        c.sources.join(", "),
        c.linker,
        c.binary,
        c.out.display()
    );
    outln!(
        "next: hammer fmu check {} --model-map MAP (a map beside it is read as {})",
        c.out.display(),
        hammer_fmu::package::map_path(&c.out).display()
    );
    Ok(())
}

/// The built-in path's time for one run of `duration_s` at `supply_bar`.
fn builtin_run_s(supply_bar: f64, duration_s: f64) -> Result<f64> {
    let mut cfg = SimConfig::default();
    cfg.supply.pressure_bar = supply_bar;
    cfg.solver.duration_s = duration_s;
    let t0 = Instant::now();
    let run = hammer_sim::simulate_truth(&cfg)?;
    let took = t0.elapsed().as_secs_f64();
    std::hint::black_box(run);
    Ok(took)
}

fn speed(a: &SpeedArgs) -> Result<()> {
    let (model, map_path) = open(&a.run, 1)?;
    need_map(&model, &a.run, &map_path)?;
    let (bar, dur) = (a.run.supply_bar, a.run.duration);
    model.run(bar * 1e5, &[], dur)?;
    let runs = a.runs.max(1);
    let mut fmu = Vec::with_capacity(runs);
    let mut builtin = Vec::with_capacity(runs);
    for _ in 0..runs {
        let t0 = Instant::now();
        model.run(bar * 1e5, &[], dur)?;
        fmu.push(t0.elapsed().as_secs_f64());
        builtin.push(builtin_run_s(bar, dur)?);
    }
    let median = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let (f, b) = (median(&mut fmu), median(&mut builtin));
    outln!(
        "{} s at {bar} bar, median of {runs} runs: FMU {:.4} s per run ({:.3} s per simulated second), \
         built-in path {:.4} s ({:.3} s per simulated second): the FMU takes {:.2}× the built-in path",
        dur,
        f,
        f / dur,
        b,
        b / dur,
        f / b
    );
    for n in &a.per_diagnosis {
        outln!(
            "a diagnosis of {n} runs of {dur} s: FMU {:.1} s, built-in path {:.1} s on one thread (divide by the threads given)",
            *n as f64 * f,
            *n as f64 * b
        );
    }
    Ok(())
}
