//! The wire protocol shared by the firmware and the host tools, `no_std`.
//!
//! A frame is `0x00 ‖ COBS(postcard(message) ‖ CRC-32(postcard bytes)) ‖ 0x00`:
//! the UART has no integrity check of its own, COBS makes `0x00` a frame
//! boundary to resynchronise on after garbage, and the leading `0x00` ends
//! any garbage before a frame so that the frame itself survives. postcard is not self-describing, so any
//! change to a message's fields changes the bytes: [`PROTOCOL_VERSION`] is
//! exchanged in the handshake, and golden byte snapshots in the tests make an
//! accidental change fail CI. Policy: `docs/wire-protocol.md`.
//!
//! Module map: [`msg`] (every message; the report, flags and configuration
//! are `hammer_types`' own, carried as they are), [`frame`] (encode, and a
//! bounded decoder that counts what it throws away), [`legacy`] (an older
//! protocol's messages, for a replayed recording), [`cobs`], [`stimulus`]
//! (the emulated board's ADC samples, through memory shared with the host
//! instead of the link).
//!
//! How to add a message: append a variant to [`HostMsg`] or [`DeviceMsg`]
//! (never reorder or insert: an old peer would misread every later variant),
//! add its golden bytes to `wire/tests/frames.rs`, bump [`PROTOCOL_VERSION`]
//! if an old peer cannot ignore it, and follow the app's and the host
//! client's recipe (`app/src/lib.rs`).
#![no_std]
#![forbid(unsafe_code)]

pub mod cobs;
pub mod frame;
pub mod legacy;
pub mod msg;
pub mod stimulus;

pub use frame::{encode, DecodeError, Decoder, DecoderStats, EncodeError};
pub use msg::*;

/// Bumped on every change of any message's layout or meaning. Not bumped for
/// the leading delimiter: decoders of either framing read the other's frames
/// (an extra 0x00 is an empty frame, which they ignore), so a bump would only
/// make hosts and devices refuse each other needlessly.
pub const PROTOCOL_VERSION: u16 = 6;
/// Largest frame on the wire, both delimiters included. Bounds every buffer.
pub const MAX_FRAME: usize = 400;
/// Sample-sets per `Samples` or `Capture` block.
pub const BLOCK_SAMPLES: usize = 32;
