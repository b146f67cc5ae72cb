//! The hardware-independent monitoring app: sampling → estimator → telemetry,
//! command handling and status, written against the small traits in
//! [`board`]. The firmware binaries are thin board layers around it.
//!
//! Module map (data flows down the list):
//! - [`board`]: the four traits a board implements (samples, link out, link in, clock);
//! - [`tasks`]: the async tasks over those traits (sampling, the chambers'
//!   reading, link receive, link transmit) and the [`Shared`] state between them;
//! - [`monitor`]: the synchronous, sans-IO core: samples in, estimator,
//!   reports, alarms, captures and wear persistence out; commands applied;
//! - [`chambers`]: the chambers' characteristics read at each cycle's
//!   close into its report, which waits for them (a task below sampling);
//! - [`packed`]: sample-sets at 12 bits a code, for the capture buffer;
//! - [`persisted`]: the configuration record the boards store;
//! - [`reset`]: the reset cause as a board keeps it through a reset;
//! - [`sample_clock`]: sample-sets produced in an elapsed time;
//! - [`supervisor`]: the duties' check-ins, for a watchdog fed only while
//!   every duty is alive;
//! - [`supply`]: the ADC's reference voltage from the internal reference.
//!
//! How to add a board: implement the four traits of [`board`] over its
//! peripherals in a firmware binary (`firmware/src/main.rs` is the reference
//! board, `firmware/emulated/` the emulated one), spawn [`sampling`], [`reading`]
//! (below sampling's priority), [`link_rx`] and [`link_tx`] with one
//! [`Shared`], and add it to `cargo xtask firmware`.
//!
//! How to add a wire message: append a variant to `hammer_wire`'s `HostMsg`
//! or `DeviceMsg` (never reorder; see `docs/wire-protocol.md` for when to
//! bump `PROTOCOL_VERSION`), add its golden bytes in `wire/tests`, handle it
//! in [`Monitor::on_command`] or emit it from [`monitor`], and let the host's
//! one client (`host-tools/link/src/client.rs`) name it in `command_kind`.
#![no_std]
#![forbid(unsafe_code)]
#![allow(async_fn_in_trait)]

pub mod board;
pub mod chambers;
pub mod monitor;
pub mod packed;
pub mod persisted;
pub mod reset;
pub mod sample_clock;
pub mod supervisor;
pub mod supply;
pub mod tasks;

pub use board::{Clock, LinkRx, LinkTx, Overrun, Record, SampleSource, Store};
pub use chambers::{ChamberReader, ReaderRoom};
pub use monitor::{Monitor, CAPTURE_SAMPLES, FIRMWARE_VERSION};
pub use supervisor::{Duty, Supervisor, Watch};
pub use tasks::{link_rx, link_tx, persisting, reading, sampling, LinkSamples, Shared};
