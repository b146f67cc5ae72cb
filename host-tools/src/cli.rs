//! The `hammer` command line: one binary, one subcommand per job.

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::{bail, Context, Result};
use clap::{Args, Parser, Subcommand};

use hammer_sim::{simulate_to_file, SimulateError};
use hammer_sim::{SimConfig, EFFECT_NAMES};
use hammer_trace::config::{load_toml, ConfigError};
use hammer_trace::trace::{write_csv, write_sidecar};

/// The highest gauge supply pressure a command takes, bar. Pneumatic
/// hammers run on compressed-air networks of 4–10 bar (the paper runs
/// 4–7) and no pneumatic tool is rated near 25 bar; a larger number is a
/// typing or unit mistake (psi: 4 bar is 58 psi; kPa: 400).
pub const SUPPLY_BAR_MAX: f64 = 25.0;

/// The parser of every `--supply-bar` (and of the other flags that give a
/// supply pressure): one place refuses what no hammer runs at, a value
/// that is not a number, negative (gauge pressure below vacuum is not a
/// supply) or beyond [`SUPPLY_BAR_MAX`], before any file is opened.
pub fn supply_bar(text: &str) -> Result<f64, String> {
    let v: f64 = text
        .trim()
        .parse()
        .map_err(|_| format!("`{text}` is not a number of bar"))?;
    if !v.is_finite() || !(0.0..=SUPPLY_BAR_MAX).contains(&v) {
        return Err(format!(
            "{text} is not a gauge supply pressure: allowed 0 ..= {SUPPLY_BAR_MAX} bar (pneumatic hammers run at 4–10 bar; give bar, not psi or kPa)"
        ));
    }
    Ok(v)
}

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
    /// Live dashboard of a device: current cycle, rolling charts, alarms, link
    /// health; auto-reconnects; optional logs (decoded CSV, raw frames).
    Monitor(crate::monitor::MonitorArgs),
    /// Feed a raw-frame log (`frames.bin` from `monitor --log`) back through the dashboard.
    /// A damaged recording is shown as far as it goes, then exits 2 naming the bad frames' byte offsets.
    Replay(crate::monitor::ReplayArgs),
    /// Watch a fleet from an MQTT broker alone: one line per cycle report
    /// and per device state change, from hammer/<site>/# (docs/fleet.md).
    MqttTail(crate::mqtt::TailArgs),
    /// Ask a device for the raw samples of the next N cycles and write them in
    /// the project's trace format (CSV + sidecar).
    Capture(CaptureArgs),
    /// Record the hammer when it is known sound: raw cycles at each supply
    /// pressure, with the board's calibration and firmware, into a folder
    /// that `hammer diagnose --reference DIR` reads changes against.
    Commission(crate::commission::CommissionArgs),
    /// Plots (PNG) and an HTML page for a trace: one cycle, the run, and for a
    /// simulated trace the estimate against the truth.
    Report(crate::report::ReportArgs),
    /// Configuration files: `hammer config check FILE`.
    #[command(subcommand)]
    Config(ConfigCommand),
    /// The whole chain with no hardware: a simulated hammer streamed into the
    /// firmware (emulated board under QEMU, or the app natively if QEMU is
    /// missing), its reports on the dashboard or, with --headless, as lines.
    Demo(crate::demo::DemoArgs),
    /// The emulated board at the full 100 kS/s × 3 for minutes of hammer
    /// time: every report checked against the host estimator, and the
    /// board's overruns, lost frames, CPU duty and worst latency.
    Soak(crate::soak::SoakArgs),
    /// Calibrate a board's pressure channels (zero at atmosphere, span
    /// against a reference you apply and type in) and its accelerometer's
    /// zero at rest; the board stores the result.
    Calibrate(crate::calibrate::CalibrateArgs),
    /// Flash the reference firmware through a debug probe (probe-rs),
    /// verify and reset; the board's stored state is kept. --dry-run
    /// prints the plan without a probe.
    Flash(crate::flash::FlashArgs),
    /// A board's first-boot checks at rest (vented, supply off): each
    /// channel in its idle range, 10 s of sampling without loss at the
    /// configured rate. Exits non-zero when a check fails.
    Selftest(crate::selftest::SelftestArgs),
    /// Run the estimator (the firmware's no_std crate) over a trace and print
    /// one record per impact cycle: friction (N), impact energy (J) with and
    /// without friction, frequency (Hz), wear index (J), each with its
    /// expanded uncertainty, and quality flags.
    Estimate(EstimateArgs),
    /// The performance sheet over supply pressure from traces at several
    /// operating points: friction per phase, energy with and without friction,
    /// frequency, power, the fitted friction law, the model's curves, the
    /// paper's Table 3; HTML, PNG and CSV.
    BenchSheet(crate::bench_sheet::BenchSheetArgs),
    /// Convert a recorder's file (delimited text with a mapping, NI TDMS,
    /// MATLAB MAT v5, multi-channel WAV, Parquet) to the project's trace;
    /// prints what it understood (channels, units, rate, duration, ranges,
    /// gaps, rails) and keeps it in the sidecar. Every command that takes a
    /// trace reads these files directly too (with --map or [import]).
    Import(crate::import::ImportArgs),
    /// Sim-to-real gap diagnosis: where the nominal model misses the measured
    /// traces (signal × stage), which catalogued effect explains it (fitted,
    /// ranked, with evidence), and how far the gap shrinks on held-out data.
    Diagnose(crate::diagnose::command::DiagnoseArgs),
    /// Blind benchmark of the diagnosis: cases with a hidden effect (or none,
    /// or two) from a perturbed generator; prints the confusion matrix,
    /// parameter errors and the held-out shrink.
    DiagnoseBench(crate::diagnose::command::BenchArgs),
    /// Export the simulator as an FMI 2.0 co-simulation FMU for x86_64
    /// Linux (parameters: every value of the config and every effect with
    /// its switch), with its model map beside it (docs/your-model.md);
    /// `hammer fmu check my.fmu` is the pre-flight of a bench engineer's FMU.
    Fmu(crate::fmu_cmd::FmuArgs),
}

#[derive(Args, Debug)]
pub struct CaptureArgs {
    /// Device: a serial port path, `auto`, or `tcp:HOST:PORT` (the emulated board).
    #[arg(long, default_value = "auto")]
    pub port: String,
    /// Capture a demo board instead of a device: the firmware (QEMU or native)
    /// fed with a simulated hammer at this gauge supply pressure, bar.
    #[arg(long, value_name = "SUPPLY_BAR", conflicts_with = "port", value_parser = supply_bar)]
    pub demo: Option<f64>,
    /// Impact cycles to record (the device holds one full cycle at 100 kS/s).
    #[arg(long, default_value_t = 1)]
    pub cycles: u8,
    /// Gauge supply pressure to write in the sidecar, bar (unknown if omitted).
    #[arg(long, value_parser = supply_bar)]
    pub supply_bar: Option<f64>,
    /// Trace to write (CSV); its sidecar goes beside it with extension .json.
    /// A name ending in `.parquet` writes one Parquet file instead: the
    /// trace's columns, the raw ADC codes, the sidecar in its metadata.
    #[arg(long)]
    pub out: PathBuf,
}

#[derive(Subcommand, Debug)]
pub enum ConfigCommand {
    /// Validate a hammer/sensor/estimator TOML file: every error names the
    /// field and its allowed range; prints the resolved configuration.
    Check { file: PathBuf },
}

/// `hammer estimate`'s output. Every format names a report field by the
/// same unit-suffixed name (`friction_n`, `wear_index_j`, ...), from the one
/// table of report fields (`hammer_types::FIELDS`; docs/trace-format.md).
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum Format {
    /// One JSON object per cycle: every field, `valid`, `flags` (an array of names).
    Jsonl,
    /// One row per cycle: every field at full precision, `valid`, `flags`
    /// (names joined by `|`, `-` when none): cycles.csv's columns after its host time.
    Csv,
    /// The main fields (friction and energy ± their uncertainty) and a summary line.
    Table,
    /// The CSV's columns as one Parquet file (zstd; `device` is the trace's
    /// file name, `host_time` null): to `--out`, or to a redirected stdout.
    Parquet,
}

#[derive(Args, Debug)]
pub struct EstimateArgs {
    /// Trace: the project's CSV (its sidecar JSON is read if present), or a
    /// recorder's file (delimited text, TDMS, MAT v5, WAV, Parquet) read through --map / [import].
    pub trace: PathBuf,
    /// Gauge supply pressure, bar: the operating point of the drift baseline
    /// (default: the sidecar's; unknown means binning by peak rear pressure).
    #[arg(long, value_parser = supply_bar)]
    pub supply_bar: Option<f64>,
    /// TOML file: [hammer] geometry, [sensors.*] calibration ranges, [estimator] thresholds and accuracy,
    /// [import] what a recorder's file means.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// TOML file with the `[import]` table for a recorder's file (overrides the config's).
    #[arg(long, value_name = "FILE.toml")]
    pub map: Option<PathBuf>,
    #[arg(long, value_enum, default_value_t = Format::Table)]
    pub format: Format,
    /// Write to this file instead of standard output.
    #[arg(long, value_name = "FILE")]
    pub out: Option<PathBuf>,
}

/// `--effect`'s help: the catalogue's names, from the registry.
fn effect_help() -> String {
    format!(
        "Switch an effect on: NAME or NAME:key=value,... (repeatable). Effects: {}",
        EFFECT_NAMES.join(", ")
    )
}

#[derive(Args, Debug)]
#[command(allow_negative_numbers = true)]
pub struct SimulateArgs {
    /// Gauge supply pressure at the valve inlet, bar (the paper runs 4–7). Overrides the config.
    #[arg(long, value_parser = supply_bar)]
    pub supply_bar: Option<f64>,
    /// Simulated time, s (default 0.5, the paper's run length).
    #[arg(long)]
    pub duration: Option<f64>,
    // Help from the registry: `effect_help`.
    #[arg(long = "effect", value_name = "SPEC", help = effect_help())]
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
    /// Trace to write (CSV), row by row as the run goes (memory does not grow
    /// with --duration; disk does: about 18 MB per simulated second at 10e-6);
    /// the sidecar goes beside it with extension .json.
    #[arg(long)]
    pub out: Option<PathBuf>,
}

#[derive(Args, Debug)]
pub struct FiguresArgs {
    /// Directory for the PNG files (created if missing).
    #[arg(long, default_value = "docs/figures")]
    pub out: PathBuf,
    /// Gauge supply pressure, bar.
    #[arg(long, default_value_t = 4.0, value_parser = supply_bar)]
    pub supply_bar: f64,
}

impl SimulateArgs {
    /// Builds the configuration: defaults, then the file, then the flags. A
    /// refused value is named as the user gave it: the flag, or the file's key.
    pub fn config(&self) -> Result<SimConfig> {
        let mut cfg: SimConfig = match &self.config {
            Some(p) => load_toml(p)?,
            None => SimConfig::default(),
        };
        hammer_sim::params::RunOverrides {
            supply_bar: self.supply_bar,
            duration_s: self.duration,
            seed: self.seed,
            output_step_s: self.dt,
            rtol: self.rtol,
            ideal_sensors: self.ideal_sensors,
            effects: self.effects.clone(),
        }
        .apply(&mut cfg)?;
        cfg.validate().map_err(|e| self.in_user_terms(e))?;
        Ok(cfg)
    }

    /// The config key each value flag sets, and whether it was given.
    fn flags(&self) -> [(&'static str, &'static str, bool); 4] {
        [
            ("--supply-bar", "supply.pressure_bar", self.supply_bar.is_some()),
            ("--duration", "solver.duration_s", self.duration.is_some()),
            ("--dt", "solver.output_step_s", self.dt.is_some()),
            ("--rtol", "solver.rtol", self.rtol.is_some()),
        ]
    }

    fn in_user_terms(&self, e: ConfigError) -> anyhow::Error {
        if let ConfigError::OutOfRange { field, value, min, max } = &e {
            if let Some((flag, ..)) = self.flags().into_iter().find(|(_, key, given)| *given && key == field) {
                return anyhow::anyhow!("{flag} {value} is out of range: allowed {min} ..= {max}");
            }
        }
        match &self.config {
            Some(p) => anyhow::Error::new(e).context(p.display().to_string()),
            None => e.into(),
        }
    }
}

pub fn run(cli: Cli) -> Result<()> {
    match cli.command {
        Command::Simulate(args) => {
            let cfg = args.config()?;
            if let Some(out) = args
                .out
                .as_ref()
                .filter(|o| hammer_trace::trace::sidecar_path(o) == **o)
            {
                bail!(
                    "--out {}: the sidecar would overwrite the trace; give the trace another extension (.csv)",
                    out.display()
                );
            }
            // Streamed: ten minutes of samples take no more memory than a second.
            let sim = simulate_to_file(&cfg, args.out.as_deref()).map_err(|e| match e {
                SimulateError::Solver(e) => anyhow::Error::new(e).context("simulation failed"),
                SimulateError::Output(e) => e.into(),
            })?;
            out!("{}", sim.summary());
            if let Some(out) = &args.out {
                outln!(
                    "wrote {} and {}",
                    out.display(),
                    hammer_trace::trace::sidecar_path(out).display()
                );
            }
            Ok(())
        }
        Command::Estimate(args) => estimate_cmd(&args),
        Command::BenchSheet(args) => {
            for f in crate::bench_sheet::run(&args)? {
                outln!("wrote {}", f.display());
            }
            Ok(())
        }
        Command::Import(args) => {
            out!("{}", crate::import::run(&args)?);
            Ok(())
        }
        Command::Diagnose(args) => crate::diagnose::command::run(&args),
        Command::DiagnoseBench(args) => crate::diagnose::command::bench(&args),
        Command::Demo(args) => crate::demo::run(&args),
        Command::Calibrate(args) => {
            let c = crate::calibrate::run(&args)?;
            outln!("{}", c.summary());
            Ok(())
        }
        Command::Flash(args) => crate::flash::run(&args),
        Command::Selftest(args) => {
            let checks = crate::selftest::run(&args)?;
            outln!("{}", crate::selftest::summary(&checks));
            if checks.iter().any(|c| !c.pass) {
                anyhow::bail!("the self-test failed");
            }
            Ok(())
        }
        Command::Soak(args) => {
            let soak = crate::soak::run(&args, true)?;
            outln!("{}", soak.summary());
            if !soak.clean() {
                anyhow::bail!("the soak lost samples, frames or reports, or a report differed from the host's");
            }
            Ok(())
        }
        Command::Config(ConfigCommand::Check { file }) => config_check(&file),
        Command::Monitor(args) => crate::monitor::run(&args),
        Command::Replay(args) => crate::monitor::replay(&args),
        Command::MqttTail(args) => crate::mqtt::tail(&args),
        Command::Capture(args) => capture_cmd(&args),
        Command::Commission(args) => crate::commission::run(&args),
        Command::Report(args) => {
            for f in crate::report::run(&args)? {
                outln!("wrote {}", f.display());
            }
            Ok(())
        }
        Command::Fmu(args) => crate::fmu_cmd::run(&args),
        Command::Figures(args) => {
            let files = crate::plot::effect_figures(&args.out, args.supply_bar)?;
            for f in files {
                outln!("wrote {}", f.display());
            }
            Ok(())
        }
    }
}

fn capture_cmd(args: &CaptureArgs) -> Result<()> {
    use crate::client::Client;
    let timeout = std::time::Duration::from_secs(120);
    let (codes, cfg, supply) = match args.demo {
        Some(bar) => {
            let demo = crate::demo::DemoArgs::for_capture(bar);
            let codes = crate::demo::hammer_codes(&demo, 0.25 + 0.06 * args.cycles as f64)?;
            let (board, read, write) = crate::demo::start_board(false, None, false)?;
            let writer = std::sync::Arc::new(std::sync::Mutex::new(write));
            let mut link = Client::new(crate::demo::SharedPort::new(read, writer.clone()));
            link.handshake(timeout)?;
            // Arm the capture before the hammer starts, then feed it.
            let feeder = std::thread::spawn({
                let writer = writer.clone();
                move || {
                    std::thread::sleep(std::time::Duration::from_millis(200));
                    crate::demo::feed(codes, writer, false, 1e5)
                }
            });
            let (codes, cfg) = crate::capture::record(&mut link, args.cycles, timeout)?;
            drop(board);
            let _ = feeder.join();
            (codes, cfg, Some(bar))
        }
        None => {
            let mut connector = crate::monitor::connector_for(&args.port)?;
            let port = connector
                .connect()
                .with_context(|| format!("opening {}", connector.describe()))?;
            let mut link = Client::new(port);
            link.handshake(std::time::Duration::from_secs(10))?;
            let (codes, cfg) = crate::capture::record(&mut link, args.cycles, timeout)?;
            (codes, cfg, args.supply_bar)
        }
    };
    let (trace, sidecar) = crate::capture::to_trace(&codes, &cfg, args.supply_bar.or(supply));
    let ms = codes.len() as f64 / cfg.sample_rate_hz as f64 * 1e3;
    if args.out.extension().is_some_and(|e| e == "parquet") {
        let sidecar = serde_json::to_string(&sidecar)?;
        crate::private_files::write_complete(&args.out, 0o644, |out| {
            crate::parquet_files::write_trace(out, &trace, &codes, &sidecar)
        })?;
        outln!(
            "captured {} sample-sets ({ms:.1} ms) into {}",
            codes.len(),
            args.out.display()
        );
        return Ok(());
    }
    write_csv(&args.out, &trace)?;
    write_sidecar(&args.out, &sidecar)?;
    outln!(
        "captured {} sample-sets ({ms:.1} ms) into {} and {}",
        codes.len(),
        args.out.display(),
        hammer_trace::trace::sidecar_path(&args.out).display()
    );
    Ok(())
}

/// The file must parse (unknown keys are errors), the simulator's parameters
/// must be in range, and the estimator must accept the sensors and thresholds.
fn config_check(file: &std::path::Path) -> Result<()> {
    let cfg: SimConfig = load_toml(file)?;
    let in_file = || file.display().to_string();
    cfg.validate().with_context(in_file)?;
    let est = cfg
        .estimator_config(Some(cfg.supply.pressure_bar))
        .with_context(in_file)?;
    outln!("{}: ok", file.display());
    outln!(
        "  hammer: {} kg piston, bore {} mm, rod {} mm, supply {} bar, inclination {}°",
        cfg.hammer.piston_mass_kg,
        cfg.hammer.bore_diameter_m * 1e3,
        cfg.hammer.rod_diameter_m * 1e3,
        cfg.supply.pressure_bar,
        cfg.hammer.inclination_deg
    );
    let (r0, r1) = est.rear.range();
    let (a0, a1) = est.accel.range();
    outln!(
        "  sensors: pressure {:.2} … {:.2} bar, acceleration {:.0} … {:.0} m/s², {} kS/s",
        r0 / 1e5,
        r1 / 1e5,
        a0,
        a1,
        est.sample_rate_hz / 1e3
    );
    let ch = &est.chambers;
    outln!(
        "  chambers (the board's with `hammer calibrate --hammer-config`): travel {:.1} mm, dead volumes rear {:.2} front {:.2} cm³, outlets rear {:.1} front {:.1} mm, pressure delay {:.2} µs",
        est.geometry.travel_m * 1e3,
        ch.rear_dead_m3 * 1e6,
        ch.front_dead_m3 * 1e6,
        ch.rear_outlet_m * 1e3,
        ch.front_outlet_m * 1e3,
        ch.pressure_group_delay_s * 1e6
    );
    let active = cfg.effects.active();
    outln!(
        "  simulator effects: {}",
        if active.is_empty() {
            "none".to_string()
        } else {
            active.join(", ")
        }
    );
    Ok(())
}

fn estimate_cmd(args: &EstimateArgs) -> Result<()> {
    use crate::estimate::*;
    let file = crate::import::config_with_map(args.config.as_deref(), args.map.as_deref())?;
    // Streamed: an hour of samples takes no more memory than a second.
    let mut reports = Vec::new();
    let summary = hammer_sim::estimation::stream_estimation(&args.trace, &file, args.supply_bar, |r| reports.push(r))?;
    // No-impact records are printed like cycles (they name the suspected
    // channel), but a trace with no cycle at all is still an error.
    let no_cycle = hammer_sim::estimation::no_cycle_message(&args.trace, &summary, &reports);
    if reports.is_empty() {
        return Err(anyhow::anyhow!(no_cycle.unwrap_or_default()));
    }
    use std::io::{IsTerminal as _, Write as _};
    if args.out.is_none() && args.format == Format::Parquet && std::io::stdout().is_terminal() {
        anyhow::bail!("Parquet is binary: give --out FILE or redirect standard output")
    }
    // Rendered whole first: an --out file is then written complete or not at all.
    let mut out: Vec<u8> = Vec::new();
    match args.format {
        Format::Jsonl => {
            for r in &reports {
                writeln!(out, "{}", jsonl_record(r))?;
            }
        }
        Format::Csv => {
            writeln!(out, "{}", csv_header())?;
            for r in &reports {
                writeln!(out, "{}", csv_record(r))?;
            }
        }
        Format::Table => write!(out, "{}", table(&reports))?,
        Format::Parquet => {
            let device = args
                .trace
                .file_stem()
                .map_or_else(String::new, |s| s.to_string_lossy().into_owned());
            let rows: Vec<crate::parquet_files::Row> = reports
                .iter()
                .map(|r| crate::parquet_files::Row {
                    device: device.clone(),
                    host_time_us: None,
                    report: *r,
                })
                .collect();
            crate::parquet_files::write(&mut out, &rows)?;
        }
    }
    // A full disk or a closed pipe must not pass for success.
    match &args.out {
        Some(path) => crate::private_files::write_complete(path, 0o644, |w| Ok(w.write_all(&out)?))?,
        None => {
            let mut stdout = std::io::stdout().lock();
            stdout
                .write_all(&out)
                .and_then(|()| stdout.flush())
                .context("writing to standard output")?;
        }
    }
    if let Some(message) = no_cycle {
        return Err(anyhow::anyhow!(message));
    }
    if let Some(message) = hammer_sim::estimation::no_valid_message(&args.trace, &reports, &summary.config) {
        return Err(anyhow::anyhow!(message));
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
