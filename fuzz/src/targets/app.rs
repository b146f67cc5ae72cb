//! The firmware app's command handling and sample path, fed what a host (or
//! a line gone wrong) can send: frames through the decoder as the link task
//! does, or — to get past the CRC — message bytes straight into postcard.
//! Invariants: no panic; every message the device sends fits a frame; the
//! status it reports stays consistent (no more invalid cycles than cycles).

use hammer_app::monitor::LinkCounters;
use hammer_app::Monitor;
use hammer_estimator::{Config, RawSample};
use hammer_wire::{
    encode, DecodeError, Decoder, DeviceConfig, DeviceMsg, HostMsg, RejectReason, SampleBlock, BLOCK_SAMPLES,
    MAX_FRAME, PROTOCOL_VERSION,
};

use super::{bit, Target};

pub const TARGET: Target = Target {
    name: "app",
    run,
    dict: &[b"\x00", b"\x01", b"\x09", b"\x02", b"\xff\xff"],
    seeds,
};

/// The device side of one fuzz input.
struct Device {
    mon: Monitor,
    expected_seq: Option<u32>,
    now_us: u64,
    sig: u64,
}

impl Device {
    fn new() -> Self {
        Self {
            mon: Monitor::new(Config::default(), "fuzz").expect("the default configuration is valid"),
            expected_seq: None,
            now_us: 0,
            sig: 0,
        }
    }

    fn apply(&mut self, m: HostMsg) {
        let mut sig = 0;
        let mut out = |d: DeviceMsg| {
            let mut buf = [0u8; MAX_FRAME];
            encode(&d, &mut buf).expect("every device message fits a frame");
            sig |= bit(message_code(&d));
        };
        match m {
            HostMsg::Samples(block) => {
                // As the emulated board's sample source: a sequence gap is an overrun.
                if let Some(exp) = self.expected_seq {
                    if block.seq != exp {
                        let lost = block.seq.wrapping_sub(exp).min(1 << 20) * BLOCK_SAMPLES as u32;
                        self.mon.on_overrun(lost);
                        self.sig |= bit(40);
                    }
                }
                self.expected_seq = Some(block.seq.wrapping_add(1));
                let raw: Vec<RawSample> = block.samples.iter().map(|&c| RawSample::from(c)).collect();
                self.mon.on_samples(&raw, &mut out);
                self.now_us += raw.len() as u64 * 10;
            }
            cmd => self.mon.on_command(cmd, self.now_us, &mut out),
        }
        while let Some(d) = self.mon.next_capture_chunk() {
            out(d);
        }
        self.now_us += 100;
        self.sig |= sig;
    }

    fn bad_frame(&mut self, e: DecodeError) {
        let reason = match e {
            DecodeError::Oversize => RejectReason::Oversize,
            _ => RejectReason::CorruptFrame,
        };
        self.mon.on_bad_frame(reason, &mut |d| {
            let mut buf = [0u8; MAX_FRAME];
            encode(&d, &mut buf).expect("a rejection fits a frame");
        });
        self.sig |= bit(41);
    }

    fn finish(self) -> u64 {
        let st = self.mon.status(self.now_us, 0, 0, LinkCounters::default());
        assert!(st.invalid_cycles <= st.cycles, "{st:?}");
        let mut buf = [0u8; MAX_FRAME];
        encode(&DeviceMsg::Status(st), &mut buf).expect("the status fits a frame");
        self.sig
    }
}

fn run(data: &[u8]) -> u64 {
    let Some((&mode, rest)) = data.split_first() else {
        return 0;
    };
    let mut dev = Device::new();
    if mode & 1 == 0 {
        let mut dec = Decoder::<MAX_FRAME>::new();
        for &b in rest {
            match dec.push::<HostMsg>(b) {
                Some(Ok(m)) => dev.apply(m),
                Some(Err(e)) => dev.bad_frame(e),
                None => {}
            }
        }
    } else {
        let mut bytes = rest;
        while let Ok((m, tail)) = postcard::take_from_bytes::<HostMsg>(bytes) {
            dev.apply(m);
            if tail.len() == bytes.len() {
                break;
            }
            bytes = tail;
        }
        dev.sig |= bit(42);
    }
    dev.finish()
}

fn message_code(m: &DeviceMsg) -> u32 {
    match m {
        DeviceMsg::Hello(_) => 0,
        DeviceMsg::Report(r) => 1 + !r.flags.is_empty() as u32,
        DeviceMsg::Status(_) => 3,
        DeviceMsg::Capture(_) => 4,
        DeviceMsg::Alarm(_) => 5,
        DeviceMsg::Config(_) => 6,
        DeviceMsg::Wear(_) => 7,
        DeviceMsg::Ack(k) => 8 + *k as u32,
        DeviceMsg::Rejected { command, .. } => 24 + *command as u32,
        // Between the Acks (8 + up to 11) and the rejections.
        DeviceMsg::CodeStats { .. } => 21,
    }
}

/// Sample blocks of a simulated hammer at 5 bar (about three cycles).
pub(crate) fn sample_blocks() -> Vec<SampleBlock> {
    use hammer_sim::estimation::{estimator_config, to_codes};
    use hammer_sim::SimConfig;
    let mut cfg = SimConfig::nominal(5.0);
    cfg.solver.duration_s = 0.16;
    let sim = hammer_sim::simulate::simulate(&cfg).expect("the nominal hammer simulates");
    let trace = sim.trace();
    let est = estimator_config(&cfg.hammer, &cfg.sensors, &cfg.estimator, 1.0 / trace.dt_s, Some(5.0))
        .expect("the nominal estimator configuration is valid");
    let codes = to_codes(&trace, &est);
    codes
        .chunks(BLOCK_SAMPLES)
        .enumerate()
        .map(|(i, c)| SampleBlock {
            seq: i as u32,
            samples: c.iter().map(|s| [s.rear, s.front, s.accel]).collect(),
        })
        .collect()
}

/// One of every host command.
pub(crate) fn host_commands() -> Vec<HostMsg> {
    let mon = Monitor::new(Config::default(), "seed").expect("valid");
    let blocks = sample_blocks();
    vec![
        HostMsg::Hello {
            protocol_version: PROTOCOL_VERSION,
        },
        HostMsg::GetConfig,
        HostMsg::SetConfig(DeviceConfig::from(&Config::default())),
        HostMsg::Tare { samples: 64 },
        HostMsg::StartCapture { cycles: 1 },
        HostMsg::GetStatus,
        HostMsg::ResetWear,
        HostMsg::GetWear,
        HostMsg::RestoreWear(mon.wear_blob()),
        HostMsg::Samples(blocks[0].clone()),
        HostMsg::MeasureCodes { samples: 64 },
    ]
}

/// What a device says in a short session: handshake, configuration, the
/// reports and captures of a simulated run, status, wear.
pub(crate) fn device_session() -> Vec<DeviceMsg> {
    let mut mon = Monitor::new(Config::default(), "seed").expect("valid");
    let mut out = Vec::new();
    for cmd in host_commands() {
        if !matches!(cmd, HostMsg::Samples(_) | HostMsg::Tare { .. }) {
            mon.on_command(cmd, 0, &mut |m| out.push(m));
        }
    }
    for b in sample_blocks() {
        let raw: Vec<RawSample> = b.samples.iter().map(|&c| RawSample::from(c)).collect();
        mon.on_samples(&raw, &mut |m| out.push(m));
        while let Some(m) = mon.next_capture_chunk() {
            out.push(m);
        }
    }
    out.push(DeviceMsg::Status(mon.status(1_000, 0, 0, LinkCounters::default())));
    out
}

/// A command session framed (mode byte 0) and the same as plain postcard
/// (mode byte 1): handshake, configuration, a capture over simulated samples.
fn seeds() -> Vec<Vec<u8>> {
    let cmds = host_commands();
    let mut session: Vec<HostMsg> = cmds
        .iter()
        .filter(|m| !matches!(m, HostMsg::Samples(_)))
        .cloned()
        .collect();
    session.retain(|m| !matches!(m, HostMsg::Tare { .. }));
    session.extend(sample_blocks().into_iter().take(120).map(HostMsg::Samples));
    let framed: Vec<u8> = std::iter::once(0u8)
        .chain(session.iter().flat_map(super::frame::framed))
        .take(crate::mutate::MAX_INPUT)
        .collect();
    let mut plain = vec![1u8];
    for m in &session {
        let mut buf = [0u8; MAX_FRAME];
        let bytes = postcard::to_slice(m, &mut buf).expect("fits");
        if plain.len() + bytes.len() > crate::mutate::MAX_INPUT {
            break;
        }
        plain.extend_from_slice(bytes);
    }
    let mut tare = vec![1u8];
    for m in [
        HostMsg::Tare { samples: 64 },
        HostMsg::Samples(sample_blocks()[0].clone()),
    ] {
        let mut buf = [0u8; MAX_FRAME];
        tare.extend_from_slice(postcard::to_slice(&m, &mut buf).expect("fits"));
    }
    vec![framed, plain, tare]
}
