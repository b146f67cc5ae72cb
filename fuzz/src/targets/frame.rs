//! The frame decoder against arbitrary bytes, as the host meets a noisy
//! line and the device meets a host gone wrong. Invariants: no panic; every
//! byte accounted for (good frames + discarded + delimiters = input); a
//! decoded frame is exactly the canonical encoding of its message (no false
//! frame out of noise).

use hammer_wire::{encode, Decoder, DeviceMsg, HostMsg, MAX_FRAME};
use serde::de::DeserializeOwned;
use serde::Serialize;

use super::{bit, Target};

pub const TARGET: Target = Target {
    name: "frame",
    run,
    dict: &[b"\x00", b"\x00\x00", b"\x01", b"\xff"],
    seeds,
};

fn run(data: &[u8]) -> u64 {
    decode_all::<DeviceMsg>(data, device_variant) | decode_all::<HostMsg>(data, host_variant) << 32
}

fn decode_all<T: DeserializeOwned + Serialize>(data: &[u8], variant: fn(&T) -> u32) -> u64 {
    let mut dec = Decoder::<MAX_FRAME>::new();
    let mut sig = 0;
    let (mut good, mut zeros, mut start) = (0usize, 0usize, 0usize);
    let input = data.iter().copied().chain(core::iter::once(0));
    for (i, b) in input.enumerate() {
        match dec.push::<T>(b) {
            Some(Ok(m)) => {
                let mut buf = [0u8; MAX_FRAME];
                let n = encode(&m, &mut buf).expect("a decoded message encodes again");
                let frame = if i < data.len() {
                    &data[start..=i]
                } else {
                    &data[start..]
                };
                let original: Vec<u8> = frame.iter().copied().chain((i == data.len()).then_some(0)).collect();
                // `original` starts after the previous delimiter, which was
                // this frame's leading one (or the start of the input).
                assert_eq!(
                    &buf[1..n],
                    &original[..],
                    "a decoded frame is its message's canonical encoding"
                );
                good += i - start;
                sig |= bit(variant(&m));
            }
            Some(Err(e)) => sig |= bit(16 + e as u32),
            None => {}
        }
        if b == 0 {
            zeros += 1;
            start = i + 1;
        }
    }
    let s = dec.stats;
    assert_eq!(
        good + s.discarded_bytes as usize + zeros,
        data.len() + 1,
        "every byte is in a good frame, discarded, or a delimiter: {s:?}"
    );
    sig
}

fn device_variant(m: &DeviceMsg) -> u32 {
    match m {
        DeviceMsg::Hello(_) => 0,
        DeviceMsg::Report(_) => 1,
        DeviceMsg::Status(_) => 2,
        DeviceMsg::Capture(_) => 3,
        DeviceMsg::Alarm(_) => 4,
        DeviceMsg::Config(_) => 5,
        DeviceMsg::Wear(_) => 6,
        DeviceMsg::Ack(_) => 7,
        DeviceMsg::Rejected { .. } => 8,
        DeviceMsg::CodeStats { .. } => 9,
    }
}

fn host_variant(m: &HostMsg) -> u32 {
    match m {
        HostMsg::Hello { .. } => 0,
        HostMsg::GetConfig => 1,
        HostMsg::SetConfig(_) => 2,
        HostMsg::Tare { .. } => 3,
        HostMsg::StartCapture { .. } => 4,
        HostMsg::GetStatus => 5,
        HostMsg::ResetWear => 6,
        HostMsg::GetWear => 7,
        HostMsg::RestoreWear(_) => 8,
        HostMsg::Samples(_) => 9,
        HostMsg::MeasureCodes { .. } => 10,
    }
}

/// A device's real output (a short run of the app on simulated samples) and
/// every host command, as frames; one input per message kind and one
/// stream of all of them.
fn seeds() -> Vec<Vec<u8>> {
    let mut frames: Vec<Vec<u8>> = super::app::device_session().into_iter().map(|m| framed(&m)).collect();
    frames.extend(super::app::host_commands().iter().map(framed));
    let mut out: Vec<Vec<u8>> = Vec::new();
    for f in &frames {
        if !out.contains(f) {
            out.push(f.clone());
        }
    }
    out.truncate(24);
    out.push(frames.concat().into_iter().take(crate::mutate::MAX_INPUT).collect());
    out
}

pub(crate) fn framed<T: Serialize>(m: &T) -> Vec<u8> {
    let mut buf = [0u8; MAX_FRAME];
    let n = encode(m, &mut buf).expect("fits a frame");
    buf[..n].to_vec()
}
