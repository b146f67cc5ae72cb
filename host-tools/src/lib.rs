//! Host side of hammer-monitor: the `hammer` command line over the crates
//! below it (the trace format `hammer-trace`, the simulator `hammer-sim`, the
//! second model family `hammer-variants`, the diagnosis `hammer-diagnose`,
//! the fleet sinks `hammer-fleet`, the device link `hammer-link`, the wire
//! and the app).
//!
//! Module map (each row uses only the rows above it and the crates below):
//! - re-exported from the crates below, so their paths read as before:
//!   [`numfmt`] (`hammer-trace`: numbers for people); [`records`],
//!   [`parquet_files`], [`influx`], [`private_files`], [`tls`], [`mqtt`]
//!   (`hammer-fleet`: the fleet sinks); [`client`], [`stimulus`],
//!   [`emulator`] (`hammer-link`: the device link);
//! - [`chart`]: the one chart model and renderer;
//! - [`board`]: the firmware's app natively;
//! - [`import`], [`estimate`], [`report`], [`bench_sheet`], [`plot`]: offline:
//!   recorders' files converted, per-cycle records, the report page, the
//!   performance sheet over supply pressure, the effect figures;
//! - [`chambers`]: the chamber characteristics against their truth on both model families;
//! - [`diagnose`]: `hammer diagnose` and `diagnose-bench` over `hammer-diagnose`
//!   (re-exported in it), and the report for people;
//! - [`drift`]: the chamber characteristics of every live report read
//!   against the hammer's commissioning record (`hammer_diagnose::record`);
//! - [`flash`], [`capture`], [`calibrate`], [`selftest`], [`demo`], [`soak`], [`monitor`]: live: raw captures, calibration, the
//!   no-hardware demo, the full-rate soak, the dashboard, logs and replay;
//! - [`commission`]: the hammer's reference record, from the board's raw captures and reports;
//! - [`fmu_cmd`]: `hammer fmu`: the export, the pre-flight and speed of a
//!   foreign FMU (`hammer-fmu`'s import), its hidden worker process;
//! - [`cli`]: the subcommands, thin over the above.

#[macro_use]
mod stdout;

pub mod bench_sheet;
pub mod board;
pub mod calibrate;
pub mod capture;
pub mod chambers;
pub mod chart;
pub mod cli;
pub mod commission;
pub mod demo;
pub mod diagnose;
pub mod drift;
pub mod estimate;
pub mod flash;
pub mod fmu_cmd;
pub mod import;
pub mod monitor;
pub mod plot;
pub mod report;
pub mod selftest;
pub mod soak;

pub use hammer_fleet::{influx, mqtt, parquet_files, private_files, records, tls};
pub use hammer_link::{client, emulator, relay, stimulus};
pub use hammer_trace::numfmt;
