//! The bottom of the host side: what every host tool reads and writes, and
//! nothing above it. It imports no simulator, diagnosis or CLI code, so the
//! file format cannot drift with them.
//!
//! Module map:
//! - [`trace`]: the trace CSV and its JSON sidecar (`docs/trace-format.md`);
//!   the sidecar's `simulation` object is opaque here (the simulator types it).
//! - [`rows`]: the CSV read row by row in bounded memory, with the time base and gaps;
//!   the time base works over any [`rows::RowSource`].
//! - [`import`]: recorders' files (delimited text with a mapping, TDMS, MAT v5,
//!   WAV, Parquet) as row sources; the one place a trace file is opened.
//! - [`config`]: configuration errors that name the field and its range, TOML loading.
//! - [`estimator_params`]: the `[estimator]` table of the project configuration.
//! - [`numfmt`]: numbers for people, the formatting rules every report shares
//!   (the diagnosis' text, the report page, the dashboard).

pub mod config;
pub mod estimator_params;
pub mod import;
pub mod numfmt;
pub mod rows;
pub mod trace;

pub use config::ConfigError;
pub use estimator_params::EstimatorParams;
