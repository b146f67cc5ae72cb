//! The hardware-independent monitoring app: sampling → estimator → telemetry,
//! command handling and status, written against the small traits in
//! [`board`]. The firmware binaries are thin board layers around it.
#![no_std]
#![forbid(unsafe_code)]
#![allow(async_fn_in_trait)]

pub mod board;
pub mod monitor;
pub mod tasks;

pub use board::{Clock, LinkRx, LinkTx, Overrun, SampleSource};
pub use monitor::{Monitor, CAPTURE_SAMPLES, FIRMWARE_VERSION};
pub use tasks::{link_rx, link_tx, sampling, LinkSamples, Shared};
