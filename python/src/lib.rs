//! `hammer_monitor._native`: the Python package's compiled core, thin over
//! the library crates the `hammer` CLI uses (one code path for both: a
//! number the package returns is the number the CLI prints).
//!
//! Module map:
//! - [`columns`]: numbers across the boundary (f64 columns as little-endian
//!   bytes, which numpy reads without a copy per element);
//! - [`interrupt`]: long calls run without the GIL and honour Ctrl-C;
//! - [`model`]: a user's FMU as the diagnosis' model, this Python its
//!   worker process;
//! - this file: the functions the Python layer (`hammer_monitor/__init__.py`)
//!   wraps into pyarrow Tables; every refusal is a `ValueError` carrying the
//!   CLI's message.

mod columns;
mod interrupt;
mod model;

use std::path::{Path, PathBuf};

use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict};

use hammer_diagnose::engine::{diagnose_against, diagnose_with, Options, PointWaves};
use hammer_diagnose::gap::CycleSignals;
use hammer_diagnose::input::{read_request, Request};
use hammer_estimator::CycleReport;
use hammer_sim::estimation::{
    config_with_map, estimate_trace, no_cycle_message, no_valid_message, stream_estimation, StreamSummary,
};
use hammer_sim::params::RunOverrides;
use hammer_sim::SimConfig;
use hammer_trace::import::columns::Channel;
use hammer_trace::import::trace_from_channels;

use columns::{from_le_bytes, trace_columns};
use interrupt::run_interruptible;

/// A refusal as Python sees it: the CLI's message (`error: …` without the prefix).
fn refused(e: impl std::fmt::Display) -> PyErr {
    PyValueError::new_err(e.to_string())
}

/// The project configuration (`config`) with a recorder's mapping (`map`), as `--config` and `--map` read them.
fn configuration(config: Option<&Path>, map: Option<&Path>) -> PyResult<SimConfig> {
    config_with_map(config, map).map_err(refused)
}

/// The columns of `hammer estimate --format csv`, in order.
#[pyfunction]
fn estimate_columns() -> Vec<String> {
    hammer_fleet::records::csv_header()
        .split(',')
        .map(String::from)
        .collect()
}

/// The records as `hammer estimate --format jsonl` prints them, with the
/// CLI's refusal when no cycle of them is valid (the Python layer warns
/// with it and still returns the flagged records, which say why), or its
/// refusal of a trace in which no impact cycle closed.
fn records(
    path: &Path,
    summary: &StreamSummary,
    reports: &[CycleReport],
) -> Result<(Vec<String>, Option<String>), String> {
    if let Some(message) = no_cycle_message(path, summary, reports) {
        return Err(message);
    }
    let lines = reports
        .iter()
        .map(|r| hammer_fleet::records::json_record(r).to_string())
        .collect();
    Ok((lines, no_valid_message(path, reports, &summary.config)))
}

/// Reads a trace file (every format the CLI reads) into named f64 columns.
#[pyfunction]
#[pyo3(signature = (path, map=None))]
fn read_trace(py: Python<'_>, path: PathBuf, map: Option<PathBuf>) -> PyResult<Py<PyDict>> {
    let cfg = configuration(None, map.as_deref())?;
    let trace = run_interruptible(py, move || {
        hammer_trace::import::read_trace(&path, cfg.import.as_ref())
            .map(|(trace, ..)| trace)
            .map_err(|e| e.to_string())
    })?
    .map_err(PyValueError::new_err)?;
    trace_columns(py, trace)
}

/// `hammer estimate --format jsonl` on a trace file: one JSON object per record.
#[pyfunction]
#[pyo3(signature = (path, config=None, map=None, supply_bar=None))]
fn estimate_file(
    py: Python<'_>,
    path: PathBuf,
    config: Option<PathBuf>,
    map: Option<PathBuf>,
    supply_bar: Option<f64>,
) -> PyResult<(Vec<String>, Option<String>)> {
    let file = configuration(config.as_deref(), map.as_deref())?;
    run_interruptible(py, move || {
        let mut reports = Vec::new();
        let summary = stream_estimation(&path, &file, supply_bar, |r| reports.push(r)).map_err(|e| e.to_string())?;
        records(&path, &summary, &reports)
    })?
    .map_err(PyValueError::new_err)
}

/// The estimator over arrays (f64, little-endian bytes of equal length):
/// time in s, gauge pressures in Pa, acceleration in m/s².
#[pyfunction]
#[pyo3(signature = (t_s, p_rear_pa, p_front_pa, accel_mps2, config=None, supply_bar=None))]
fn estimate_arrays(
    py: Python<'_>,
    t_s: &Bound<'_, PyBytes>,
    p_rear_pa: &Bound<'_, PyBytes>,
    p_front_pa: &Bound<'_, PyBytes>,
    accel_mps2: &Bound<'_, PyBytes>,
    config: Option<PathBuf>,
    supply_bar: Option<f64>,
) -> PyResult<(Vec<String>, Option<String>)> {
    let file = configuration(config.as_deref(), None)?;
    let channels = [
        ("t_s", t_s),
        ("p_rear_pa", p_rear_pa),
        ("p_front_pa", p_front_pa),
        ("accel_mps2", accel_mps2),
    ]
    .into_iter()
    .map(|(name, b)| Channel::new(name, from_le_bytes(b.as_bytes())))
    .collect();
    let trace = trace_from_channels("arrays", channels, None).map_err(refused)?;
    run_interruptible(py, move || {
        let (reports, summary) = estimate_trace(&trace, &file, supply_bar, "arrays").map_err(|e| e.to_string())?;
        records(Path::new("arrays"), &summary, &reports)
    })?
    .map_err(PyValueError::new_err)
}

/// `hammer simulate`: the trace's columns (as its CSV holds them) and the
/// per-cycle truth as JSON.
#[pyfunction]
#[pyo3(signature = (supply_bar=None, duration_s=None, effects=Vec::new(), config=None, seed=None, output_step_s=None, rtol=None, ideal_sensors=false))]
#[allow(clippy::too_many_arguments)]
fn simulate(
    py: Python<'_>,
    supply_bar: Option<f64>,
    duration_s: Option<f64>,
    effects: Vec<String>,
    config: Option<PathBuf>,
    seed: Option<u64>,
    output_step_s: Option<f64>,
    rtol: Option<f64>,
    ideal_sensors: bool,
) -> PyResult<(Py<PyDict>, String)> {
    let mut cfg: SimConfig = match &config {
        Some(p) => hammer_trace::config::load_toml(p).map_err(refused)?,
        None => SimConfig::default(),
    };
    RunOverrides {
        supply_bar,
        duration_s,
        seed,
        output_step_s,
        rtol,
        ideal_sensors,
        effects,
    }
    .apply(&mut cfg)
    .map_err(refused)?;
    cfg.validate().map_err(|e| match &config {
        Some(p) => refused(format!("{}: {e}", p.display())),
        None => refused(e),
    })?;
    // The trace alone, built as the run goes: the whole simulation would
    // also keep the solver's truth and the ADC codes (about 4x the table).
    let (trace, info) = run_interruptible(py, move || {
        hammer_sim::simulate_trace(&cfg).map_err(|e| format!("simulation failed: {e}"))
    })?
    .map_err(PyValueError::new_err)?;
    let truth = serde_json::to_string(&info.cycles).map_err(refused)?;
    Ok((trace_columns(py, trace)?, truth))
}

/// `hammer diagnose` on traces: `report.json`'s content as JSON, and with
/// `figures` the waveforms the CLI draws (per operating point) as JSON.
#[pyfunction]
#[pyo3(signature = (measured, reference=Vec::new(), fit_on=Vec::new(), config=None, nominal_uncertainty=0.2, figures=false, model=None, model_map=None, model_time_limit_s=60.0, threads=None))]
#[allow(clippy::too_many_arguments)]
fn diagnose(
    py: Python<'_>,
    measured: Vec<(PathBuf, Option<f64>)>,
    reference: Vec<(PathBuf, Option<f64>)>,
    fit_on: Vec<PathBuf>,
    config: Option<PathBuf>,
    nominal_uncertainty: f64,
    figures: bool,
    model: Option<PathBuf>,
    model_map: Option<PathBuf>,
    model_time_limit_s: f64,
    threads: Option<i64>,
) -> PyResult<(String, Option<String>)> {
    let threads = match threads {
        Some(n) if n < 1 => return Err(PyValueError::new_err(format!("threads: at least 1, got {n}"))),
        n => n.map(|n| n as usize),
    };
    let worker = model.as_ref().map(|_| model::python_worker(py)).transpose()?;
    let run = move || -> anyhow::Result<(String, Option<String>)> {
        // The CLI's reading of its inputs (commissioning folders included).
        let read = read_request(&Request {
            measured,
            reference,
            fit_on,
            config,
            allow_stale_reference: false,
        })?;
        let (inputs, references, base) = (read.inputs, read.references, read.base);
        let defaults = Options::default();
        let opts = Options {
            nominal_uncertainty,
            figures,
            threads: threads.unwrap_or(defaults.threads),
            ..defaults
        };
        let quiet = |_: usize, _: usize, _: &str| {};
        let outcome = match (model, worker) {
            (Some(fmu), Some(worker)) => {
                let plant = model::open_plant(&fmu, model_map.as_deref(), opts.threads, model_time_limit_s, worker)?;
                diagnose_with(&inputs, &references, &base, plant, &opts, &quiet)?
            }
            _ => diagnose_against(&inputs, &references, &base, &opts, &quiet)?,
        };
        let report = serde_json::to_string(&outcome.report)?;
        let waves = figures.then(|| waves_json(&outcome.waves).to_string());
        Ok((report, waves))
    };
    run_interruptible(py, move || run().map_err(|e| format!("{e:#}")))?.map_err(PyValueError::new_err)
}

/// The figures' waveforms: per operating point, the time base, the stage of
/// each sample, and the measured, nominal and fitted mean cycles.
fn waves_json(waves: &[PointWaves]) -> serde_json::Value {
    let signals = |c: &CycleSignals| {
        serde_json::json!({
            "p_rear_pa": c.p_rear_pa, "p_front_pa": c.p_front_pa,
            "accel_mps2": c.accel_mps2, "velocity_mps": c.velocity_mps,
        })
    };
    waves
        .iter()
        .map(|w| {
            serde_json::json!({
                "supply_bar": w.supply_bar,
                "t_s": w.t_s,
                "stages": w.stages,
                "measured": signals(&w.measured),
                "nominal": signals(&w.nominal),
                "fitted": w.fitted.as_ref().map(signals),
            })
        })
        .collect()
}

#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(estimate_columns, m)?)?;
    m.add_function(wrap_pyfunction!(read_trace, m)?)?;
    m.add_function(wrap_pyfunction!(estimate_file, m)?)?;
    m.add_function(wrap_pyfunction!(estimate_arrays, m)?)?;
    m.add_function(wrap_pyfunction!(simulate, m)?)?;
    m.add_function(wrap_pyfunction!(diagnose, m)?)?;
    m.add_function(wrap_pyfunction!(model::fmu_worker, m)?)?;
    Ok(())
}
