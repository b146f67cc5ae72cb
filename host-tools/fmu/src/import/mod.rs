//! A bench engineer's FMU, run by the project (issue 46): what the
//! diagnosis will call in place of its built-in model.
//!
//! Module map (data flows down the list):
//! - [`units`]: the units a foreign signal may come in, to SI gauge;
//! - [`map`]: `map.toml`, the model map (read here, written by `hammer fmu`);
//! - [`archive`]: the `.fmu` zip unpacked into a private directory;
//! - [`describe`]: modelDescription.xml (identity, capabilities, variables);
//! - [`check`]: the map against the description (unknown, unsettable, missing);
//! - [`compile`]: a source-code FMU built for this platform (`hammer fmu compile`);
//! - [`fmi2`]: the foreign library called (worker process only);
//! - [`worker`]: the worker process's loop and the pipe protocol;
//! - [`pool`]: the host's worker processes (time limit, crash, reuse);
//! - [`model`]: [`FmuModel`], the one API: a supply pressure, settings and a
//!   duration in, SI gauge signals or a typed [`FmuError`] out;
//! - [`cycling`]: whether a run reached steady cycling.

pub mod archive;
pub mod check;
pub mod compile;
pub mod cycling;
pub mod describe;
pub mod fmi2;
pub mod map;
pub mod model;
pub mod pool;
pub mod units;
pub mod worker;

use std::path::PathBuf;

pub use map::ModelMap;
pub use model::{FmuModel, Identity, Options, Signals};
pub use pool::WorkerCommand;

/// What failed, for a caller that acts on it (the CLI prints the message).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FailKind {
    /// The file is missing or unreadable.
    Open,
    /// Not a zip, or a damaged one.
    NotZip,
    /// modelDescription.xml missing or not what the import runs.
    Description,
    /// No binary for this platform, or it does not load.
    NoBinary,
    /// A source-code FMU's sources did not compile or link.
    Compile,
    /// The binary lacks an FMI function the import calls.
    MissingFunction,
    /// The map does not fit the FMU (or a setting names no parameter).
    Map,
    /// fmi2Instantiate or the initialisation failed.
    Instantiate,
    /// fmi2DoStep (or a get or set) failed.
    Step,
    /// An output was NaN or infinite.
    NonFinite,
    /// The run never reached steady cycling.
    NotCycling,
    /// A call did not return within the time limit.
    Timeout,
    /// The FMU's process ended (crash, abort, exit).
    Crashed,
    /// The worker or its protocol failed (not the FMU's doing).
    Worker,
}

/// An FMU's failure: which FMU, what kind, what exactly.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FmuError {
    pub fmu: PathBuf,
    pub kind: FailKind,
    pub detail: String,
}

impl std::fmt::Display for FmuError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "FMU {}: {}", self.fmu.display(), self.detail)
    }
}

impl std::error::Error for FmuError {}
