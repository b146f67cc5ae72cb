//! Reading what an older protocol sent, for a host that replays a
//! recording (`hammer replay` of a `frames.bin`); a live link still refuses
//! an older device at the handshake.
//!
//! Protocol 4 differs from 5 only in `DeviceConfig`, which 5 extended with
//! the chambers (`hammer_types::DeviceConfigV4`): every other message reads
//! as it is, and a protocol-4 `Config` reads with the chambers given.

use crate::{DeviceConfig, DeviceConfigV4, DeviceMsg};

/// The protocols [`device_msg`] reads besides the current one.
pub const READABLE_OLDER: [u16; 1] = [4];

/// `DeviceMsg::Config`'s variant index (postcard writes it as one byte).
const CONFIG_INDEX: u8 = 5;

/// The message a frame's checked body holds, sent in `protocol`; a
/// protocol-4 configuration with `chambers`' chambers. `None`: not a
/// message of that protocol.
pub fn device_msg(body: &[u8], protocol: u16, chambers: &DeviceConfig) -> Option<DeviceMsg> {
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
