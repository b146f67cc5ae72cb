//! What the diagnosis is given (the measured traces and their roles), how it
//! reports progress, and what it refuses. Apart from the engine so the
//! stages that read the inputs need not import the engine that runs them.

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
