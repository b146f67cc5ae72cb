//! What the diagnosis is given (the measured traces and their roles), how it
//! reports progress, and what it refuses. Apart from the engine so the
//! stages that read the inputs need not import the engine that runs them.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use hammer_sim::estimation::sensors_for;
use hammer_sim::simulate::{read_simulated_sidecar, Sidecar};
use hammer_sim::SimConfig;
use hammer_trace::config::load_toml;
use hammer_trace::trace::Trace;

use crate::record::{is_record, Folder};

/// One measured trace and its role.
#[derive(Debug, Clone)]
pub struct MeasuredInput {
    pub label: String,
    pub supply_bar: f64,
    pub trace: Trace,
    /// Part of the fit set (its later half of cycles is still held out).
    pub fit: bool,
}

#[derive(Debug, thiserror::Error)]
pub enum DiagnoseError {
    #[error("no measured trace given")]
    NoInput,
    #[error("{0}: no complete impact cycle found (is the accelerometer connected, does the hammer run?)")]
    NoCycles(String),
    #[error("{0}: supply pressure unknown: give it in the sidecar or with --supply-bar after the trace")]
    NoPressure(String),
    #[error("the nominal model does not run at {0} bar: {1}")]
    Model(f64, String),
    #[error("no reference record at {0} bar: with references, every operating point needs one")]
    NoReference(f64),
    /// The model failed in a way that ends the diagnosis (a foreign model
    /// that crashed, hung or could not be loaded): the plant's own message.
    #[error("{0}")]
    Plant(String),
}

impl DiagnoseError {
    /// A trace that holds no complete cycle (a hammer that does not run).
    pub fn is_no_cycles(&self) -> bool {
        matches!(self, DiagnoseError::NoCycles(_))
    }
}

/// Progress: (done, total, what is running).
pub type Progress<'a> = &'a (dyn Fn(usize, usize, &str) + Sync);

/// One trace (any format `hammer_trace::import` reads, through the
/// config's `[import]`) with its sidecar; its supply pressure from `bar`
/// (the command line, a script's argument), the sidecar, or the mapping.
/// Not yet part of the fit set (the caller decides).
pub fn read_input(
    path: &Path,
    bar: Option<f64>,
    map: Option<&hammer_trace::import::ImportMap>,
) -> Result<(MeasuredInput, Option<Sidecar>)> {
    let (trace, _, _) =
        hammer_trace::import::read_trace(path, map).with_context(|| format!("reading {}", path.display()))?;
    let sidecar = read_simulated_sidecar(path).with_context(|| format!("reading the sidecar of {}", path.display()))?;
    let supply_bar = bar
        .or_else(|| sidecar.as_ref().and_then(|s| s.supply_pressure_bar))
        .or_else(|| map.and_then(|m| m.supply_pressure_bar))
        .with_context(|| {
            format!(
                "{}: supply pressure unknown: not in its sidecar; give --supply-bar BAR right after it",
                path.display()
            )
        })?;
    let (lo, hi) = hammer_sim::params::SUPPLY_BAR_RANGE;
    hammer_trace::config::check_range("--supply-bar", supply_bar, lo, hi)?;
    let input = MeasuredInput {
        label: path.display().to_string(),
        supply_bar,
        trace,
        fit: false,
    };
    Ok((input, sidecar))
}

/// What the force balance takes as known of a hammer, by its `[hammer]`
/// keys: the piston's mass, bore and rod (the estimator's geometry) and the
/// impact position (its travel). The diagnosis recalibrates the nominal
/// values it is unsure of and reads the form's error in the rest; these it
/// cannot.
const KNOWN: [&str; 4] = [
    "piston_mass_kg",
    "bore_diameter_m",
    "rod_diameter_m",
    "impact_position_m",
];

/// Refuses a trace whose sidecar states another hammer than the model's
/// (`config`: the `--config` file, `None` for the built-in default) in
/// what the force balance takes as known ([`KNOWN`]). Read against the
/// wrong piston mass or bore, the force balance's gap would be named as
/// effects (a 2 kg hammer came out as a gain error and friction).
pub fn same_hammer(trace: &Path, sidecar: Option<&Sidecar>, model: &SimConfig, config: Option<&Path>) -> Result<()> {
    let Some(stated) = sidecar.and_then(|s| s.simulation.as_ref()).map(|s| &s.config.hammer) else {
        return Ok(());
    };
    let d: Vec<String> = stated
        .differences(&model.hammer)
        .into_iter()
        .filter(|d| KNOWN.iter().any(|k| d.starts_with(&format!("{k} = "))))
        .collect();
    if d.is_empty() {
        return Ok(());
    }
    let model_is = match config {
        Some(c) => format!("--config {}", c.display()),
        None => "the built-in model (the paper's hammer; no --config)".into(),
    };
    bail!(
        "{}: its sidecar states another hammer than {model_is} ({}, sidecar vs model): give --config with this hammer's [hammer] values",
        trace.display(),
        d.join(", ")
    )
}

/// What a diagnosis is asked to read: measured traces or commissioning
/// folders, each with the supply pressure given after it (bar; `None`:
/// from its sidecar), the same for the references, the traces to fit on,
/// the nominal model's file.
#[derive(Debug, Clone, Default)]
pub struct Request {
    pub measured: Vec<(PathBuf, Option<f64>)>,
    pub reference: Vec<(PathBuf, Option<f64>)>,
    pub fit_on: Vec<PathBuf>,
    pub config: Option<PathBuf>,
    /// Read against a commissioning record made with another calibration.
    pub allow_stale_reference: bool,
}

/// A [`Request`] read: the inputs, the references, the nominal model (its
/// sensors from the first trace's sidecar when no file names them), and
/// warnings for the caller to show.
#[derive(Debug)]
pub struct Read {
    pub inputs: Vec<MeasuredInput>,
    pub references: Vec<MeasuredInput>,
    pub base: SimConfig,
    pub warnings: Vec<String>,
}

/// Reads what `req` names, as `hammer diagnose` and the Python package do:
/// a commissioning folder stands for all its traces (all fitted unless
/// `fit_on` says otherwise), and one recorded with another calibration
/// than the measured captures is refused as stale unless allowed.
pub fn read_request(req: &Request) -> Result<Read> {
    let mut base: SimConfig = match &req.config {
        Some(p) => load_toml(p)?,
        None => SimConfig::default(),
    };
    base.validate()?;
    let same = |a: &Path, b: &Path| a == b || a.canonicalize().ok().is_some_and(|x| b.canonicalize().ok() == Some(x));
    let mut inputs = Vec::new();
    let mut warnings = Vec::new();
    // The calibrations the measured traces were made with (device captures).
    let mut measured_hashes = Vec::new();
    for (path, bar) in &req.measured {
        let folder = is_record(path).then(|| Folder::open(path)).transpose()?;
        let traces = match &folder {
            Some(f) => {
                // Its captures were made with the record's calibration (checked).
                measured_hashes.push(f.record.calibration_hash);
                f.traces().map(|(p, b)| (p.to_path_buf(), Some(b))).collect()
            }
            None => vec![(path.clone(), *bar)],
        };
        // A folder's traces are one cycle each: all fitted unless told.
        let fit_folder = folder.is_some() && (req.fit_on.is_empty() || req.fit_on.iter().any(|f| same(f, path)));
        for (trace, bar) in traces {
            let (input, sidecar) = read_input(&trace, bar, base.import.as_ref())?;
            same_hammer(&trace, sidecar.as_ref(), &base, req.config.as_deref())?;
            if inputs.is_empty() && req.config.is_none() {
                base.sensors = sensors_for(sidecar.as_ref(), &base.sensors);
            }
            measured_hashes.extend(sidecar.as_ref().and_then(|s| s.calibration_hash));
            inputs.push(MeasuredInput {
                fit: fit_folder || req.fit_on.iter().any(|f| same(f, &trace)),
                ..input
            });
        }
    }
    let mut references = Vec::new();
    for (path, bar) in &req.reference {
        if !is_record(path) {
            let (input, sidecar) = read_input(path, *bar, base.import.as_ref())?;
            same_hammer(path, sidecar.as_ref(), &base, req.config.as_deref())?;
            references.push(input);
            continue;
        }
        let folder = Folder::open(path)?;
        let record = &folder.record;
        if let Some(h) = measured_hashes.iter().find(|&&h| h != record.calibration_hash) {
            let what = format!(
                "{} was commissioned with calibration {:08x}; the measured traces were recorded with {h:08x}: the board was recalibrated since, so the record is stale",
                path.display(),
                record.calibration_hash
            );
            if !req.allow_stale_reference {
                bail!("{what}. Commission again, or pass --allow-stale-reference to read the change against it anyway");
            }
            warnings.push(format!(
                "{what}; the change read includes the recalibration's (--allow-stale-reference)"
            ));
        }
        for (trace, bar) in folder.traces() {
            let (input, sidecar) = read_input(trace, Some(bar), base.import.as_ref())?;
            same_hammer(trace, sidecar.as_ref(), &base, req.config.as_deref())?;
            references.push(input);
        }
    }
    for f in &req.fit_on {
        if !req.measured.iter().any(|(m, _)| same(f, m)) && !inputs.iter().any(|i| same(f, Path::new(&i.label))) {
            bail!("--fit-on {}: not among the --measured traces", f.display());
        }
    }
    Ok(Read {
        inputs,
        references,
        base,
        warnings,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use hammer_sim::simulate_to_file;

    fn sidecar_of(cfg: &SimConfig) -> Sidecar {
        let mut c = cfg.clone();
        c.solver.duration_s = 0.01;
        simulate_to_file(&c, None).unwrap().sidecar()
    }

    /// Another piston mass is refused, naming the trace, the model and the
    /// field; a nominal value the diagnosis recalibrates (a dead volume) is
    /// not, nor is the same hammer, nor a trace with no simulated hammer.
    #[test]
    fn a_sidecar_of_another_hammer_is_refused_but_not_for_what_is_fitted() {
        let model = SimConfig::default();
        let trace = Path::new("m4.csv");
        let mut heavy = model.clone();
        heavy.hammer.piston_mass_kg = 2.0;
        let e = same_hammer(trace, Some(&sidecar_of(&heavy)), &model, None)
            .unwrap_err()
            .to_string();
        assert!(
            e.starts_with("m4.csv: ") && e.contains("piston_mass_kg = 2.0 vs 1.12"),
            "{e}"
        );
        assert!(e.contains("built-in model") && e.contains("--config"), "{e}");
        let mut jittered = model.clone();
        jittered.hammer.rear_dead_volume_m3 *= 1.1;
        jittered.hammer.outlet_cd *= 0.9;
        same_hammer(trace, Some(&sidecar_of(&jittered)), &model, None).unwrap();
        same_hammer(trace, Some(&sidecar_of(&model)), &model, None).unwrap();
        same_hammer(trace, None, &model, None).unwrap();
        same_hammer(trace, Some(&sidecar_of(&heavy)), &heavy, Some(Path::new("heavy.toml"))).unwrap();
        let mut short = model.clone();
        short.hammer.impact_position_m -= 0.005;
        let e = same_hammer(trace, Some(&sidecar_of(&short)), &model, None)
            .unwrap_err()
            .to_string();
        assert!(e.contains("impact_position_m = "), "{e}");
    }

    /// Every key the check compares is one of the hammer's: a renamed field
    /// must not drop out of the comparison unseen.
    #[test]
    fn the_known_fields_are_the_hammers() {
        let keys = serde_json::to_value(SimConfig::default().hammer).unwrap();
        for k in KNOWN {
            assert!(keys.get(k).is_some(), "{k}");
        }
    }
}
