//! A user's FMU as the diagnosis' model, from Python (issue 46): the same
//! import as `hammer diagnose --model`, with this Python as its worker.
//!
//! Why this Python and not the `hammer` binary: the CLI runs each FMU in
//! worker processes of itself (`hammer fmu worker`), so that a foreign
//! library's crash or hang costs an error, never the host. A wheel has no
//! `hammer` binary to start, but it has an interpreter that can import
//! this module: the worker is `python -c "…_native.fmu_worker()"`, the
//! same loop (`hammer_fmu::import::worker::serve`) behind the same pipe.

use std::path::PathBuf;
use std::sync::Arc;

use hammer_diagnose::model::{FmuPlant, Plant};
use hammer_fmu::import::{FmuModel, WorkerCommand};
use pyo3::prelude::*;

/// The worker command: this interpreter, serving [`fmu_worker`].
pub(crate) fn python_worker(py: Python<'_>) -> PyResult<WorkerCommand> {
    let program: String = py.import("sys")?.getattr("executable")?.extract()?;
    if program.is_empty() {
        return Err(pyo3::exceptions::PyRuntimeError::new_err(
            "model=: this Python does not know its own executable (sys.executable is empty), so it cannot start the FMU's worker process",
        ));
    }
    Ok(WorkerCommand {
        program: PathBuf::from(program),
        args: vec![
            "-c".into(),
            "import sys; from hammer_monitor import _native; sys.exit(_native.fmu_worker())".into(),
        ],
        env: Vec::new(),
    })
}

/// The FMU at `fmu` with its map as a diagnosis' plant, in at most
/// `threads` worker processes started by `worker`.
pub(crate) fn open_plant(
    fmu: &std::path::Path,
    model_map: Option<&std::path::Path>,
    threads: usize,
    time_limit_s: f64,
    worker: WorkerCommand,
) -> anyhow::Result<Arc<dyn Plant>> {
    let (model, _) =
        FmuModel::open_mapped(fmu, model_map, threads, time_limit_s, worker).map_err(anyhow::Error::msg)?;
    let plant = FmuPlant::new(model).map_err(|e| anyhow::anyhow!("FMU {}: {e}", fmu.display()))?;
    Ok(Arc::new(plant))
}

/// The worker's loop on this process's standard input and output, until
/// the host closes the pipe; the exit code for `sys.exit`. The GIL is let
/// go while it serves: a pythonfmu FMU takes it for its own Python code.
#[pyfunction]
pub(crate) fn fmu_worker(py: Python<'_>) -> i32 {
    py.detach(hammer_fmu::import::worker::serve)
}
