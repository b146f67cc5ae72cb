//! The bottom of hammer-monitor: one schema per wire concept, `no_std`.
//!
//! The types here are what the estimator produces, what the wire carries and
//! what the host shows, each defined once: the estimator, the wire crate, the
//! firmware and the host tools all use (or re-export) these, so a field added
//! to a report or a configuration appears everywhere at once and cannot drift
//! between a mirror and its original.
//!
//! - [`Flags`]: a cycle's quality flags, which of them invalidate a cycle
//!   ([`Flags::INVALIDATING`]) and which blame a sensor ([`Flags::SENSOR_FAULTS`]).
//! - [`CycleReport`]: what the estimator reports per cycle; the wire's `Report`.
//! - [`fields::FIELDS`]: the one table of a report's per-cycle fields (column
//!   name, unit, value) every rendering is driven by.
//! - [`Codes`] / [`RawSample`]: one sample-set of ADC codes.
//! - [`DeviceConfig`] / [`ChannelCalibration`]: the device's configuration on
//!   the wire (the estimator maps it to and from its runtime `Config`);
//!   [`DeviceConfigV4`], protocol 4's, to migrate a stored record.
//! - [`WEAR_STATE_BYTES`], [`crc32`]: the saved wear state's size and the CRC
//!   that checks it and every frame.
//!
//! serde derives only (no_std, no alloc): postcard on the device, JSON and
//! CSV on the host.
#![no_std]
#![forbid(unsafe_code)]

pub mod config;
pub mod crc;
pub mod fields;
pub mod flags;
pub mod report;
pub mod sample;

pub use config::{calibration_hash, ChannelCalibration, DeviceConfig, DeviceConfigV4};
pub use crc::crc32;
pub use fields::{Field, Value, FIELDS};
pub use flags::Flags;
pub use report::{CycleReport, CycleReportV5, FeedFields};
pub use sample::{Codes, RawSample};

/// Operating points the wear state remembers at once (bins of supply or peak rear pressure).
pub const MAX_BASELINES: usize = 8;
/// Size of the serialised wear state (`hammer_estimator::WearState::to_bytes`,
/// the wire's `WearBlob`): header, counters, then one 16-byte baseline per
/// operating point, then its CRC-32.
pub const WEAR_STATE_BYTES: usize = 16 + 8 + 4 + 4 + 4 + MAX_BASELINES * 16 + 4;
