//! Raw captures from a device, turned into the project's trace format.

use hammer_estimator::Config;
use hammer_wire::CaptureChunk;

use hammer_trace::trace::{Sidecar, Trace};

#[derive(Debug, thiserror::Error, PartialEq)]
pub enum CaptureError {
    #[error("capture {id}: chunk at offset {offset} where {expected} was expected (a chunk was lost)")]
    Gap { id: u16, offset: u32, expected: u32 },
    #[error("capture {id}: {got} of {total} sample-sets arrived")]
    Incomplete { id: u16, got: u32, total: u32 },
    #[error("capture chunks of different captures ({a} and {b})")]
    Mixed { a: u16, b: u16 },
    #[error("empty capture")]
    Empty,
}

/// Reassembles the chunks of one capture (in order, no gaps) into ADC codes.
pub fn assemble(chunks: &[CaptureChunk]) -> Result<Vec<[u16; 3]>, CaptureError> {
    let first = chunks.first().ok_or(CaptureError::Empty)?;
    let mut codes = Vec::with_capacity(first.total as usize);
    for c in chunks {
        if c.capture_id != first.capture_id {
            return Err(CaptureError::Mixed {
                a: first.capture_id,
                b: c.capture_id,
            });
        }
        if c.offset as usize != codes.len() {
            return Err(CaptureError::Gap {
                id: c.capture_id,
                offset: c.offset,
                expected: codes.len() as u32,
            });
        }
        codes.extend_from_slice(&c.samples);
    }
    if codes.len() != first.total as usize {
        return Err(CaptureError::Incomplete {
            id: first.capture_id,
            got: codes.len() as u32,
            total: first.total,
        });
    }
    Ok(codes)
}

/// ADC codes and the device's calibration → a trace (physical units, gauge
/// pressures) and its sidecar.
pub fn to_trace(codes: &[[u16; 3]], cfg: &Config, supply_bar: Option<f64>) -> (Trace, Sidecar) {
    let dt = 1.0 / cfg.sample_rate_hz as f64;
    let val = |cal: &hammer_estimator::ChannelCal, c: u16| cal.value(c) as f64;
    let trace = Trace {
        dt_s: dt,
        t_s: (0..codes.len()).map(|i| i as f64 * dt).collect(),
        p_rear_pa: codes.iter().map(|c| val(&cfg.rear, c[0])).collect(),
        p_front_pa: codes.iter().map(|c| val(&cfg.front, c[1])).collect(),
        accel_mps2: codes.iter().map(|c| val(&cfg.accel, c[2])).collect(),
        extra: Default::default(),
        gaps: Vec::new(),
    };
    let sidecar = Sidecar {
        calibration_hash: Some(cfg.calibration_hash()),
        ..Sidecar::new(supply_bar, "device")
    };
    (trace, sidecar)
}

/// Records `cycles` raw cycles from a device: asks for its configuration (the
/// calibration that turns codes into units), starts the capture and collects
/// the chunks until the capture is complete.
pub fn record<S: std::io::Read + std::io::Write>(
    client: &mut crate::client::Client<S>,
    cycles: u8,
    timeout: std::time::Duration,
) -> anyhow::Result<(Vec<[u16; 3]>, Config)> {
    record_armed(client, cycles, timeout, || {}, &mut Vec::new())
}

/// [`record`], calling `on_armed` once the device has acknowledged the
/// capture: a demo board's hammer is fed from then on, so that the samples
/// the capture needs never reach the board before the request does. The
/// reports that arrive beside the capture are added to `reports`.
pub fn record_armed<S: std::io::Read + std::io::Write>(
    client: &mut crate::client::Client<S>,
    cycles: u8,
    timeout: std::time::Duration,
    mut on_armed: impl FnMut(),
    reports: &mut Vec<hammer_estimator::CycleReport>,
) -> anyhow::Result<(Vec<[u16; 3]>, Config)> {
    use crate::client::reply_to;
    use hammer_wire::{CommandKind, DeviceMsg, HostMsg};
    let cfg = client.request(&HostMsg::GetConfig, timeout, |m| match m {
        DeviceMsg::Config(c) => Some(*c),
        DeviceMsg::Report(r) => {
            reports.push(*r);
            None
        }
        _ => None,
    })?;
    let cfg = cfg.ok_or_else(|| anyhow::anyhow!("the device did not send its configuration"))?;
    let cfg = Config::default().with_device(&cfg);
    client.send(&HostMsg::StartCapture { cycles })?;
    let mut chunks: Vec<CaptureChunk> = Vec::new();
    let deadline = std::time::Instant::now() + timeout;
    let mut acked = false;
    loop {
        let left = deadline
            .checked_duration_since(std::time::Instant::now())
            .unwrap_or_default();
        if left.is_zero() {
            anyhow::bail!(
                "capture timed out after {} s ({} chunks; is the hammer running?)",
                timeout.as_secs(),
                chunks.len()
            );
        }
        let Some(m) = client.recv(left)? else { continue };
        match reply_to(CommandKind::StartCapture, &m) {
            Some(Ok(())) => {
                if !acked {
                    on_armed();
                }
                acked = true;
            }
            Some(Err(reason)) => anyhow::bail!("the device refused the capture: {reason:?}"),
            None => {}
        }
        if let DeviceMsg::Report(r) = &m {
            reports.push(*r);
        }
        if let DeviceMsg::Capture(c) = m {
            let done = c.offset as usize + c.samples.len() >= c.total as usize;
            chunks.push(c);
            if done {
                break;
            }
        }
    }
    if !acked {
        anyhow::bail!("capture data arrived without the device acknowledging the request");
    }
    Ok((assemble(&chunks)?, cfg))
}
