//! `hammer-link`, the device link: how the host talks to a board, real or
//! emulated, apart from the CLI so a script or a test rig can drive a board
//! without the dashboard.
//!
//! Module map (each row uses only the rows above it and the crates below):
//! - [`client`]: the one protocol client (its sans-IO decoding core, the blocking client);
//! - [`stimulus`]: the emulated board's ADC ring (the PSRAM file QEMU maps);
//! - [`emulator`]: the board on QEMU's mps2-an386, fed through [`stimulus`];
//! - [`relay`]: a counting relay between a host tool and a board.

pub mod client;
pub mod emulator;
pub mod relay;
pub mod stimulus;
