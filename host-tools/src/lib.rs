//! Host side of hammer-monitor: the `hammer` command line over the crates
//! below it (the trace format `hammer-trace`, the simulator `hammer-sim`, the
//! second model family `hammer-variants`, the wire and the app).
//!
//! Module map (each row uses only the rows above it and the crates below):
//! - [`numfmt`], [`chart`]: numbers for people, the one chart model and renderer;
//! - [`records`], [`parquet_files`], [`influx`]: every rendering of a cycle
//!   report, from `hammer_types::fields::FIELDS`: text, Parquet, line protocol;
//! - [`private_files`]: owner-only directories and files that do not follow
//!   symlinks (the outage buffer, the logs);
//! - [`tls`]: the one TLS client configuration (MQTT over TLS, InfluxDB over
//!   HTTPS) and handshake failures in words;
//! - [`client`]: the one protocol client (its sans-IO decoding core, the blocking client);
//! - [`board`], [`stimulus`], [`emulator`]: the firmware's app natively, the
//!   emulated board's ADC ring, and the board on QEMU's mps2-an386;
//! - [`import`], [`estimate`], [`report`], [`bench_sheet`], [`plot`]: offline:
//!   recorders' files converted, per-cycle records, the report page, the
//!   performance sheet over supply pressure, the effect figures;
//! - [`chambers`]: the chamber characteristics against their truth on both model families;
//! - [`diagnose`]: the sim-to-real gap diagnosis and its benchmarks;
//! - [`reference_record`], [`drift`]: the hammer's commissioning record, and
//!   the chamber characteristics of live captures read against it;
//! - [`flash`], [`capture`], [`calibrate`], [`selftest`], [`demo`], [`soak`], [`monitor`]: live: raw captures, calibration, the
//!   no-hardware demo, the full-rate soak, the dashboard, logs and replay;
//! - [`commission`]: the hammer's reference record, from the board's raw captures;
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
pub mod client;
pub mod commission;
pub mod demo;
pub mod diagnose;
pub mod drift;
pub mod emulator;
pub mod estimate;
pub mod flash;
pub mod import;
pub mod influx;
pub mod monitor;
pub mod mqtt;
pub mod numfmt;
pub mod parquet_files;
pub mod plot;
pub mod private_files;
pub mod records;
pub mod reference_record;
pub mod report;
pub mod selftest;
pub mod soak;
pub mod stimulus;
pub mod tls;
