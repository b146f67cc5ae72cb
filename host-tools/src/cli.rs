//! The `hammer` command line: one binary, one subcommand per job.

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::{Context, Result};
use clap::{Args, Parser, Subcommand};

use crate::config::load_toml;
use crate::sim::SimConfig;
use crate::simulate::simulate;
use crate::trace::{write_csv, write_sidecar};

#[derive(Parser, Debug)]
#[command(
    name = "hammer",
    version,
    about = "Monitoring tools for pneumatic impact hammers (SI units, gauge pressures)"
)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Subcommand, Debug)]
pub enum Command {
    /// Simulate the paper's pneumatic hammer and print a per-cycle summary;
    /// with --out, write the trace (CSV) and its sidecar (JSON).
    Simulate(SimulateArgs),
    /// Draw one PNG per catalogued effect: nominal vs with-effect over one steady cycle.
    Figures(FiguresArgs),
    /// Run the estimator (the firmware's no_std crate) over a trace and print
    /// one record per impact cycle: friction (N), impact energy (J) with and
    /// without friction, frequency (Hz), wear index (J), each with its
    /// expanded uncertainty, and quality flags.
    Estimate(EstimateArgs),
}

#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum Format {
    Jsonl,
    Csv,
    Table,
}

#[derive(Args, Debug)]
pub struct EstimateArgs {
    /// Trace in the project's format (CSV; its sidecar JSON is read if present).
    pub trace: PathBuf,
    /// Gauge supply pressure, bar: the operating point of the drift baseline
    /// (default: the sidecar's; unknown means binning by peak rear pressure).
    #[arg(long)]
    pub supply_bar: Option<f64>,
    /// TOML file: [hammer] geometry, [sensors.*] calibration ranges, [estimator] thresholds and accuracy.
    #[arg(long)]
    pub config: Option<PathBuf>,
    #[arg(long, value_enum, default_value_t = Format::Table)]
    pub format: Format,
}

#[derive(Args, Debug)]
#[command(allow_negative_numbers = true)]
pub struct SimulateArgs {
    /// Gauge supply pressure at the valve inlet, bar (the paper runs 4–7). Overrides the config.
    #[arg(long)]
    pub supply_bar: Option<f64>,
    /// Simulated time, s (default 0.5, the paper's run length).
    #[arg(long)]
    pub duration: Option<f64>,
    /// Switch an effect on: NAME or NAME:key=value,... (repeatable). Effects:
    /// coulomb_friction, viscous_friction, leakage, valve_delay, heat_transfer,
    /// supply_restriction, accel_zero_shift, pressure_gain_error.
    #[arg(long = "effect", value_name = "SPEC")]
    pub effects: Vec<String>,
    /// Seed of the sensor noise (same seed, same trace).
    #[arg(long)]
    pub seed: Option<u64>,
    /// TOML file with any of [hammer] [valve] [contact] [supply] [solver] [effects.*] [sensors.*].
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Output grid step, s (default 10e-6 = 100 kS/s).
    #[arg(long)]
    pub dt: Option<f64>,
    /// Relative tolerance of the integrator (default 1e-6).
    #[arg(long)]
    pub rtol: Option<f64>,
    /// Ideal sensors: no noise, bandwidth, clipping or quantisation.
    #[arg(long)]
    pub ideal_sensors: bool,
    /// Trace to write (CSV); the sidecar goes beside it with extension .json.
    #[arg(long)]
    pub out: Option<PathBuf>,
}

#[derive(Args, Debug)]
pub struct FiguresArgs {
    /// Directory for the PNG files (created if missing).
    #[arg(long, default_value = "docs/figures")]
    pub out: PathBuf,
    /// Gauge supply pressure, bar.
    #[arg(long, default_value_t = 4.0)]
    pub supply_bar: f64,
}

impl SimulateArgs {
    /// Builds the configuration: defaults, then the file, then the flags.
    pub fn config(&self) -> Result<SimConfig> {
        let mut cfg: SimConfig = match &self.config {
            Some(p) => load_toml(p)?,
            None => SimConfig::default(),
        };
        if let Some(v) = self.supply_bar {
            cfg.supply.pressure_bar = v;
        }
        if let Some(v) = self.duration {
            cfg.solver.duration_s = v;
        }
        if let Some(v) = self.seed {
            cfg.seed = v;
        }
        if let Some(v) = self.dt {
            cfg.solver.output_step_s = v;
        }
        if let Some(v) = self.rtol {
            cfg.solver.rtol = v;
        }
        if self.ideal_sensors {
            cfg.sensors.enabled = false;
        }
        for spec in &self.effects {
            cfg.effects.apply_spec(spec)?;
        }
        cfg.validate()?;
        Ok(cfg)
    }
}

pub fn run(cli: Cli) -> Result<()> {
    match cli.command {
        Command::Simulate(args) => {
            let cfg = args.config()?;
            let sim = simulate(&cfg).context("simulation failed")?;
            print!("{}", sim.summary());
            if let Some(out) = &args.out {
                write_csv(out, &sim.trace())?;
                write_sidecar(out, &sim.sidecar())?;
                println!(
                    "wrote {} and {}",
                    out.display(),
                    crate::trace::sidecar_path(out).display()
                );
            }
            Ok(())
        }
        Command::Estimate(args) => estimate_cmd(&args),
        Command::Figures(args) => {
            let files = crate::plot::effect_figures(&args.out, args.supply_bar)?;
            for f in files {
                println!("wrote {}", f.display());
            }
            Ok(())
        }
    }
}

fn estimate_cmd(args: &EstimateArgs) -> Result<()> {
    use crate::estimate::*;
    let file: SimConfig = match &args.config {
        Some(p) => load_toml(p)?,
        None => SimConfig::default(),
    };
    let trace = crate::trace::read_csv(&args.trace)?;
    let sidecar = crate::trace::read_sidecar(&args.trace)?;
    let supply = args.supply_bar.or(sidecar.as_ref().and_then(|s| s.supply_pressure_bar));
    let sensors = sensors_for(sidecar.as_ref(), &file.sensors);
    let hammer = sidecar
        .as_ref()
        .and_then(|s| s.simulation.as_ref())
        .map_or(file.hammer.clone(), |s| s.config.hammer.clone());
    let cfg = estimator_config(&hammer, &sensors, &file.estimator, 1.0 / trace.dt_s, supply)?;
    let reports = run(&to_codes(&trace, &cfg), cfg)?;
    let mut out = std::io::BufWriter::new(std::io::stdout().lock());
    use std::io::Write as _;
    match args.format {
        Format::Jsonl => {
            for r in &reports {
                writeln!(out, "{}", jsonl_record(r))?;
            }
        }
        Format::Csv => {
            writeln!(out, "{CSV_HEADER}")?;
            for r in &reports {
                writeln!(out, "{}", csv_record(r))?;
            }
        }
        Format::Table => write!(out, "{}", table(&reports))?,
    }
    Ok(())
}

pub fn main() -> ExitCode {
    match run(Cli::parse()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::from(2)
        }
    }
}
