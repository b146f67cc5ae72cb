//! What the diagnosis is given (the measured traces and their roles), how it
//! reports progress, and what it refuses. Apart from the engine so the
//! stages that read the inputs need not import the engine that runs them.

use std::path::Path;

use anyhow::{Context, Result};
use hammer_sim::simulate::{read_simulated_sidecar, Sidecar};
use hammer_trace::trace::Trace;

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
    hammer_trace::config::check_range("--supply-bar", supply_bar, 0.5, 20.0)?;
    let input = MeasuredInput {
        label: path.display().to_string(),
        supply_bar,
        trace,
        fit: false,
    };
    Ok((input, sidecar))
}
