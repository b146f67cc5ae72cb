//! Host side of hammer-monitor: the hammer simulator, trace files and the
//! `hammer` command line.

#[macro_use]
mod stdout;

pub mod board;
pub mod capture;
pub mod chart;
pub mod cli;
pub mod client;
pub mod demo;
pub mod diagnose;
pub mod emulator;
pub mod estimate;
pub mod monitor;
pub mod numfmt;
pub mod plot;
pub mod records;
pub mod report;
