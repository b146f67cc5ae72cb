//! Reading what an older protocol sent, for a host that replays a
//! recording (`hammer replay` of a `frames.bin`); a live link still refuses
//! an older device at the handshake.
//!
//! - Protocol 6 added the chambers' characteristics to the `Report`
//!   (`hammer_types::CycleReportV5` is 4 and 5's): an older report reads
//!   with them NaN and flagged unread.
//! - Protocol 5 extended `DeviceConfig` with the chambers
//!   (`hammer_types::DeviceConfigV4`): a protocol-4 `Config` reads with the
//!   chambers given.
//!
//! Every other message reads as it is.

use crate::{CycleReportV5, DeviceConfig, DeviceConfigV4, DeviceMsg};

/// The protocols [`device_msg`] reads besides the current one.
pub const READABLE_OLDER: [u16; 2] = [4, 5];

/// `DeviceMsg::Report`'s and `Config`'s variant indices (postcard writes
/// each as one byte).
const REPORT_INDEX: u8 = 1;
const CONFIG_INDEX: u8 = 5;

/// The message a frame's checked body holds, sent in `protocol`; a
/// protocol-4 configuration with `chambers`' chambers. `None`: not a
/// message of that protocol.
pub fn device_msg(body: &[u8], protocol: u16, chambers: &DeviceConfig) -> Option<DeviceMsg> {
    let older = READABLE_OLDER.contains(&protocol);
    // An older report is shorter than a current one, so it never reads as
    // one; it is read as what it was.
    if let (true, Some((&REPORT_INDEX, rest))) = (older, body.split_first()) {
        if let Some(r) = whole::<CycleReportV5>(rest) {
            return Some(DeviceMsg::Report(r.into_current()));
        }
    }
    if let Some(m) = whole::<DeviceMsg>(body) {
        return Some(m);
    }
    match (protocol, body.split_first()) {
        (4, Some((&CONFIG_INDEX, rest))) => {
            whole::<DeviceConfigV4>(rest).map(|c| DeviceMsg::Config(c.with_chambers_of(chambers)))
        }
        _ => None,
    }
}

fn whole<'a, T: serde::Deserialize<'a>>(bytes: &'a [u8]) -> Option<T> {
    match postcard::take_from_bytes::<T>(bytes) {
        Ok((m, [])) => Some(m),
        _ => None,
    }
}
