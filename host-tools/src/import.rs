//! `hammer import`: a recorder's file (delimited text, TDMS, MAT v5, WAV,
//! Parquet) converted to the project's trace, with what was understood
//! printed and kept in the sidecar. The reading itself is
//! `hammer_trace::import`, the same path every command opens traces by.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::{bail, Result};
use clap::Args;

use hammer_sim::SimConfig;
use hammer_trace::import::inspect::{stats, Stats};
use hammer_trace::import::{read_trace, Understood};
use hammer_trace::trace::{sidecar_path, write_csv, write_sidecar, Sidecar};

#[derive(Args, Debug)]
pub struct ImportArgs {
    /// The recorder's file: delimited text, NI TDMS, MATLAB MAT v5, WAV or Parquet.
    pub input: PathBuf,
    /// Trace to write (the project's CSV); its sidecar goes beside it (.json).
    #[arg(long)]
    pub out: PathBuf,
    #[command(flatten)]
    pub mapping: MapArgs,
    /// Gauge supply pressure of the recording, bar (for the sidecar).
    #[arg(long, value_parser = crate::cli::supply_bar)]
    pub supply_bar: Option<f64>,
}

/// Where a command finds what a recorder's file means.
#[derive(Args, Debug, Clone, Default)]
pub struct MapArgs {
    /// TOML file with the `[import]` table (columns, units, gauge/absolute,
    /// sign, delimiter, decimal comma, preamble, sample rate;
    /// docs/trace-format.md). Overrides the config's `[import]`.
    #[arg(long, value_name = "FILE.toml")]
    pub map: Option<PathBuf>,
    /// TOML file: [hammer] geometry, [sensors.*] ranges, [estimator] settings, [import] mapping.
    #[arg(long)]
    pub config: Option<PathBuf>,
}

impl MapArgs {
    /// The configuration with `--map`'s table in place of the config's `[import]`.
    pub fn load(&self) -> Result<SimConfig> {
        Ok(hammer_sim::estimation::config_with_map(
            self.config.as_deref(),
            self.map.as_deref(),
        )?)
    }
}

pub fn run(args: &ImportArgs) -> Result<String> {
    if sidecar_path(&args.out) == args.out {
        bail!(
            "--out {}: the sidecar would overwrite the trace; use .csv",
            args.out.display()
        );
    }
    if args.out.extension().is_none_or(|e| e != "csv") {
        bail!(
            "--out {}: the project's trace is a CSV: give a name ending in .csv",
            args.out.display()
        );
    }
    let cfg = args.mapping.load()?;
    let map = cfg.import.as_ref();
    let (trace, understood, embedded) = read_trace(&args.input, map)?;
    let st = stats(&trace);
    let supply = args.supply_bar.or(map.and_then(|m| m.supply_pressure_bar)).or_else(|| {
        embedded
            .as_deref()
            .and_then(|t| serde_json::from_str::<serde_json::Value>(t).ok())
            .and_then(|v| v.get("supply_pressure_bar").and_then(|b| b.as_f64()))
    });
    write_csv(&args.out, &trace)?;
    let mut sidecar: Sidecar = Sidecar::new(supply, "import");
    sidecar.import = Some(serde_json::json!({
        "input": args.input.display().to_string(),
        "understood": understood,
        "stats": st,
    }));
    write_sidecar(&args.out, &sidecar)?;
    let mut s = summary(&args.input, &understood, &st);
    let _ = writeln!(
        s,
        "wrote {} and {}",
        args.out.display(),
        sidecar_path(&args.out).display()
    );
    Ok(s)
}

/// What was understood, for people.
pub fn summary(input: &Path, u: &Understood, st: &Stats) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "{}: {}", input.display(), u.format.name());
    if let (Some(d), Some(dec)) = (&u.delimiter, &u.decimal) {
        let d = if d == "\t" { "tab".to_string() } else { format!("`{d}`") };
        let _ = write!(s, "  text: delimiter {d}, decimal `{dec}`");
        match u.header_line {
            Some(h) => {
                let _ = writeln!(s, ", header on line {h}");
            }
            None => {
                let _ = writeln!(s, ", no header");
            }
        }
    }
    for sig in &u.signals {
        let _ = write!(s, "  {:<8} <- {} [{}]", sig.signal, sig.column, sig.unit);
        if let Some(r) = &sig.reference {
            let _ = write!(s, " {r}");
        }
        if sig.sign < 0.0 {
            let _ = write!(s, ", inverted");
        }
        if let Some(fs) = sig.full_scale {
            let _ = write!(s, ", full scale {fs}");
        }
        let _ = writeln!(s);
    }
    let _ = writeln!(
        s,
        "  {} samples at {:.6} kS/s, {:.6} s; {} gap(s), {} samples missing",
        st.samples,
        st.sample_rate_hz / 1e3,
        st.duration_s,
        st.gaps,
        st.missing_samples
    );
    for c in &st.channels {
        let (unit, k) = if c.name.ends_with("_pa") {
            ("bar", 1e-5)
        } else {
            ("m/s²", 1.0)
        };
        let _ = write!(s, "  {:<11} {:.4} … {:.4} {unit}", c.name, c.min * k, c.max * k);
        for r in &c.rails {
            let _ = write!(
                s,
                "; rail at {:.4} {unit}: {} samples ({:.1} %) in {} runs",
                r.value * k,
                r.samples,
                100.0 * r.samples as f64 / st.samples as f64,
                r.runs
            );
        }
        let _ = writeln!(s);
    }
    if st.looks_absolute {
        let _ = writeln!(
            s,
            "  warning: both chambers stay above {:.1} bar: the pressures look absolute; the estimator reads gauge (set absolute = true under [import.p_rear] and [import.p_front])",
            hammer_trace::import::inspect::ABSOLUTE_MIN_GAUGE_PA / 1e5
        );
    }
    s
}

/// The configuration a trace-taking command uses (`--config`, `--map`).
pub fn config_with_map(config: Option<&Path>, map: Option<&Path>) -> Result<SimConfig> {
    MapArgs {
        map: map.map(Path::to_path_buf),
        config: config.map(Path::to_path_buf),
    }
    .load()
}
