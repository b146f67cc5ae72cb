//! Golden bytes (an accidental wire change fails here), round trips, and a
//! decoder that meets garbage.

use hammer_wire::*;

fn frame<T: serde::Serialize>(m: &T) -> Vec<u8> {
    let mut buf = [0u8; MAX_FRAME];
    let n = encode(m, &mut buf).unwrap();
    buf[..n].to_vec()
}

fn hex(b: &[u8]) -> String {
    b.iter().map(|x| format!("{x:02x}")).collect()
}

fn sample_report() -> CycleReport {
    CycleReport {
        seq: 7,
        t_impact_us: 500_000,
        period_s: 0.047,
        frequency_hz: 21.25,
        friction_n: 10.25,
        friction_stroke_n: 10.0,
        friction_backhaul_n: 10.5,
        friction_uncertainty_n: 1.0,
        friction_stroke_uncertainty_n: 1.5,
        friction_backhaul_uncertainty_n: 1.5,
        impact_velocity_mps: 2.5,
        impact_velocity_frictionless_mps: 2.75,
        impact_energy_j: 3.5,
        impact_energy_frictionless_j: 4.25,
        impact_energy_uncertainty_j: 0.125,
        impact_energy_frictionless_uncertainty_j: 0.125,
        friction_work_j: 0.875,
        friction_work_ratio: 0.125,
        stroke_m: 0.04375,
        peak_rear_pa: 327_000.0,
        peak_front_pa: 231_000.0,
        accel_zero_shift_mps2: 0.0,
        wear_index_j: 6.125,
        wear_remaining_fraction: 1.0,
        remaining_life_cycles: 1.0e7,
        drift_score: 0.0,
        calibration_hash: sample_config().calibration_hash(),
        front_feed_s: 0.0015,
        front_feed_uncertainty_s: 0.0001,
        front_feed_x_m: 0.04375,
        front_feed_p_rear_pa: 312_500.0,
        front_feed_p_front_pa: 12_500.0,
        front_closed_exponent: 1.375,
        front_closed_exponent_uncertainty: 0.0625,
        front_feed_area_m2: 2.5e-5,
        front_feed_area_uncertainty_m2: 2.5e-6,
        rear_feed_s: 0.0175,
        rear_feed_uncertainty_s: 0.0002,
        rear_feed_x_m: 0.0125,
        rear_feed_p_rear_pa: 25_000.0,
        rear_feed_p_front_pa: 187_500.0,
        rear_closed_exponent: 1.25,
        rear_closed_exponent_uncertainty: 0.125,
        rear_feed_area_m2: 3.0e-5,
        rear_feed_area_uncertainty_m2: 3.0e-6,
        flags: Flags(0x0800),
    }
}

/// Protocol 5's `Report` frame of [`sample_report`] (before the chambers).
const PROTOCOL5_REPORT_FRAME: &str = "000a0107a0c21e1283403d0103aa410103244101032041010328410103803f0103c03f0103c03f010320400103304001036040010388400101023e0101023e0103603f0101063e3333333d04ab9f4804966148010101010103c4400107803f8096184b0101010cb398ca8f0a80100c19e07200";

fn channel(zero_code: f32, scale: f32, gain_uncertainty: f32, offset_uncertainty: f32) -> ChannelCalibration {
    ChannelCalibration {
        zero_code,
        scale,
        full_scale_code: 4095,
        gain_uncertainty,
        offset_uncertainty,
    }
}

fn sample_config() -> DeviceConfig {
    DeviceConfig {
        sample_rate_hz: 100_000.0,
        piston_mass_kg: 0.625,
        bore_diameter_m: 0.0325,
        rod_diameter_m: 0.0125,
        inclination_deg: -15.0,
        rear: channel(372.25, 268.5, 0.008, 1000.0),
        front: channel(372.25, 268.5, 0.008, 1000.0),
        accel: channel(2047.5, 0.976_5, 0.005, 1.0),
        impact_threshold_mps2: 1000.0,
        blank_before_s: 2e-4,
        blank_after_s: 1.5e-3,
        min_period_s: 0.02,
        max_period_s: 0.5,
        accel_zero_shift_tau_s: 0.5,
        coverage_factor: 2.0,
        supply_pressure_pa: f32::NAN,
        wear_budget_j: 5.0e7,
        baseline_cycles: 50,
        cusum_k: 0.5,
        cusum_h: 10.0,
        travel_m: 0.0625,
        rear_dead_m3: 1.5e-5,
        front_dead_m3: 2.0e-5,
        rear_outlet_m: 0.03125,
        front_outlet_m: 0.015625,
        pressure_group_delay_s: 4e-6,
    }
}

/// A frame's checked body (the message's postcard bytes), from its hex.
fn unframe(hex: &str) -> Vec<u8> {
    let mut raw: Vec<u8> = (0..hex.len() / 2)
        .map(|i| u8::from_str_radix(&hex[2 * i..2 * i + 2], 16).unwrap())
        .collect();
    let body = &mut raw[1..];
    let end = body.iter().position(|&b| b == 0).unwrap();
    let n = hammer_wire::cobs::decode_in_place(&mut body[..end]).unwrap();
    body[..n - 4].to_vec()
}

/// `c` without what protocol 5 added: protocol 4's layout.
fn protocol4(c: &DeviceConfig) -> DeviceConfigV4 {
    let mut buf = [0u8; MAX_FRAME];
    let n = postcard::to_slice(c, &mut buf).unwrap().len();
    // The six f32s protocol 5 appended, 4 bytes each (postcard writes f32 as is).
    postcard::from_bytes(&buf[..n - 24]).unwrap()
}

const GOLDEN_CONFIG_FRAME: &str = "0002050450c347010b203fb81e053dcdcc4c3c010370c10420ba430a408643ff1f6f12033c01037a440420ba430a408643ff1f6f12033c01037a440ef0ff44e7fb793fff1f0ad7a33b0103803f010f7a4417b75139a69bc43a0ad7a33c0101023f0101023f010102400108c07f20bc3e4c320101023f01032041010b803d82a87b37acc5a7370101023d010b803cbd37863699b880fc00";
const GOLDEN_SET_CONFIG_FRAME: &str = "0002020450c347010b203fb81e053dcdcc4c3c010370c10420ba430a408643ff1f6f12033c01037a440420ba430a408643ff1f6f12033c01037a440ef0ff44e7fb793fff1f0ad7a33b0103803f010f7a4417b75139a69bc43a0ad7a33c0101023f0101023f010102400108c07f20bc3e4c320101023f01032041010b803d82a87b37acc5a7370101023d010b803cbd3786362a9c850d00";
/// Protocol 4's `Config` frame of the same configuration (before the chambers).
const PROTOCOL4_CONFIG_FRAME: &str = "0002050450c347010b203fb81e053dcdcc4c3c010370c10420ba430a408643ff1f6f12033c01037a440420ba430a408643ff1f6f12033c01037a440ef0ff44e7fb793fff1f0ad7a33b0103803f010f7a4417b75139a69bc43a0ad7a33c0101023f0101023f010102400108c07f20bc3e4c320101023f0107204125d6285200";
const GOLDEN_CONFIG_HASH: u32 = 1_601_889_007;
/// Checked independently: Python's `zlib.crc32(struct.pack('<ffHff', ...) × 3)`.
const GOLDEN_CALIBRATION_HASH: u32 = 2_717_027_379;

/// The bytes of these frames are the protocol. If a test here fails, the
/// wire format changed: bump PROTOCOL_VERSION (unless, like the leading
/// delimiter, decoders of both versions still read each other's frames),
/// update docs/wire-protocol.md, and only then update the snapshot.
#[test]
fn golden_frames() {
    assert_eq!(PROTOCOL_VERSION, 6);
    assert_eq!(
        hex(&frame(&HostMsg::Hello { protocol_version: 1 })),
        "000106016922de3600"
    );
    assert_eq!(hex(&frame(&HostMsg::GetStatus)), "000605021b68a200");
    let block = SampleBlock {
        seq: 3,
        samples: heapless::Vec::from_slice(&[[1, 2, 4095], [0, 65535, 2048]]).unwrap(),
    };
    assert_eq!(
        hex(&frame(&HostMsg::Samples(block))),
        "00080903020102ff1f0affff0380102979e9e100"
    );
    assert_eq!(
        hex(&frame(&DeviceMsg::Report(sample_report()))),
        "000a0107a0c21e1283403d0103aa410103244101032041010328410103803f0103c03f0103c03f010320400103304001036040010388400101023e0101023e0103603f0101063e3333333d04ab9f4804966148010101010103c4400107803f8096184b01010116b398ca8f0aa69bc43a17b7d1383333333d80969848045043460103b03f0117803d17b7d137acc52736295c8f3c17b75139cdcc4c3c0450c346041b37480103a03f0101103e82a8fb379c5349368010987f602400"
    );
    // Protocol 6 appended the chambers' characteristics (18 f32) before the
    // flags, now a u32 written as the same varint: the report's bytes are
    // protocol 5's with those 72 bytes before the flags. A protocol-5
    // report (a recording's) reads with the chambers NaN and flagged unread.
    let p5 = unframe(PROTOCOL5_REPORT_FRAME);
    let p6 = unframe(&hex(&frame(&DeviceMsg::Report(sample_report()))));
    assert_eq!(p6.len(), p5.len() + 72);
    assert_eq!(
        &p6[..p5.len() - 2],
        &p5[..p5.len() - 2],
        "all but the flags' two varint bytes"
    );
    assert_eq!(&p6[p6.len() - 2..], &p5[p5.len() - 2..], "the flags");
    let old = hammer_wire::legacy::device_msg(&p5, 5, &sample_config()).expect("a protocol-5 report reads");
    let DeviceMsg::Report(old) = old else { panic!("{old:?}") };
    let mut expected = sample_report();
    expected.mark_chambers_unread();
    assert_eq!(format!("{old:?}"), format!("{expected:?}"));
    assert!(old.flags.contains(Flags::CHAMBERS_UNREAD | Flags::ACCEL_ZERO_SHIFT));
    // A configuration, both ways (`Config` answers `GetConfig`, `SetConfig` carries one).
    assert_eq!(hex(&frame(&DeviceMsg::Config(sample_config()))), GOLDEN_CONFIG_FRAME);
    assert_eq!(
        hex(&frame(&HostMsg::SetConfig(sample_config()))),
        GOLDEN_SET_CONFIG_FRAME
    );
    assert_eq!(config_hash(&sample_config()), GOLDEN_CONFIG_HASH);
    // Protocol 5 appended the chambers and the pressures' group delay: the
    // configuration's bytes are protocol 4's, then those six f32s.
    let v4 = protocol4(&sample_config());
    let mut b4 = [0u8; MAX_FRAME];
    let mut b5 = [0u8; MAX_FRAME];
    let (b4, b5) = (
        postcard::to_slice(&v4, &mut b4).unwrap(),
        postcard::to_slice(&sample_config(), &mut b5).unwrap(),
    );
    assert_eq!(&b5[..b4.len()], &b4[..]);
    assert_eq!(&b5[b4.len()..b4.len() + 4], &0.0625f32.to_le_bytes());
    assert_eq!(config_hash(&v4.with_chambers_of(&sample_config())), GOLDEN_CONFIG_HASH);
    // The frozen protocol-4 layout is what protocol 4 sent: its frame's
    // payload is the variant's index and those bytes, then the CRC.
    let mut old: Vec<u8> = (0..PROTOCOL4_CONFIG_FRAME.len() / 2)
        .map(|i| u8::from_str_radix(&PROTOCOL4_CONFIG_FRAME[2 * i..2 * i + 2], 16).unwrap())
        .collect();
    let body = &mut old[1..];
    let end = body.iter().position(|&b| b == 0).unwrap();
    let n = hammer_wire::cobs::decode_in_place(&mut body[..end]).unwrap();
    assert_eq!(body[0], 5, "DeviceMsg::Config's index");
    assert_eq!(&body[1..n - 4], b4);
    // Protocol 3 added the calibration's hash to every report; protocol 4
    // made the impact time integer µs (0.5 s: varint a0 c2 1e after the seq).
    assert_eq!(sample_config().calibration_hash(), GOLDEN_CALIBRATION_HASH);
    let rej = DeviceMsg::Rejected {
        command: CommandKind::Unknown,
        reason: RejectReason::CorruptFrame,
    };
    assert_eq!(hex(&frame(&rej)), "0008080a0439a4d00c00");
    // A status after a watchdog reset (protocol 2 added the cause and the stack, 3 VDDA).
    let status = Status {
        uptime_us: 1_000_000,
        samples: 100_000,
        protocol_version: 2,
        firmware_version: [0, 1, 0],
        config_hash: 0x20DC_CE35,
        reset_cause: ResetCause::Watchdog {
            overdue: Duty::Sampling,
        },
        stack_used_bytes: 18_292,
        stack_reserved_bytes: 32_768,
        vdda_v: 3.3,
        ..Default::default()
    };
    assert_eq!(
        hex(&frame(&DeviceMsg::Status(status))),
        "000802c0843da08d0601010101010101010101010101010202020107b59cf38602010ff48e0180800233335340b25b9ba100"
    );
}

#[test]
fn every_message_round_trips() {
    let msgs = [
        DeviceMsg::Report(sample_report()),
        DeviceMsg::Status(Status {
            uptime_us: 123,
            samples: 99,
            rx_crc_errors: 2,
            config_hash: 0xDEAD_BEEF,
            reset_cause: ResetCause::Fault {
                pc: 0x0800_1234,
                cfsr: 0x0000_8200,
            },
            ..Default::default()
        }),
        DeviceMsg::Alarm(Alarm {
            kind: AlarmKind::DriftOn,
            cycle_seq: 9,
            flags: Flags(1 << 13),
            drift_score: 11.5,
        }),
        DeviceMsg::Capture(CaptureChunk {
            capture_id: 1,
            offset: 64,
            total: 4700,
            samples: heapless::Vec::from_slice(&[[1, 2, 3]; 32]).unwrap(),
        }),
        DeviceMsg::Ack(CommandKind::Tare),
        DeviceMsg::Config(DeviceConfig {
            supply_pressure_pa: 4e5,
            ..sample_config()
        }),
    ];
    for m in msgs {
        let f = frame(&m);
        assert!(f.len() <= MAX_FRAME, "{} bytes", f.len());
        let mut d = Decoder::<MAX_FRAME>::new();
        let mut got = None;
        for &b in &f {
            if let Some(r) = d.push::<DeviceMsg>(b) {
                got = Some(r.unwrap());
            }
        }
        assert_eq!(got.unwrap(), m);
    }
    // The largest host message fits too.
    let block = SampleBlock {
        seq: u32::MAX,
        samples: heapless::Vec::from_slice(&[[65535; 3]; BLOCK_SAMPLES]).unwrap(),
    };
    assert!(frame(&HostMsg::Samples(block)).len() <= MAX_FRAME);
}

#[test]
fn the_decoder_resynchronises_after_garbage_and_counts_it() {
    let good = frame(&HostMsg::GetConfig);
    let mut stream = Vec::new();
    stream.extend_from_slice(&[0x13, 0x37, 0xff, 0x42]); // noise before the first delimiter
    stream.push(0);
    stream.extend_from_slice(&good);
    let mut corrupt = good.clone();
    corrupt[2] ^= 0x40; // one flipped bit
    stream.extend_from_slice(&corrupt);
    stream.extend_from_slice(&[0xAA; 1000]); // an oversized run
    stream.push(0);
    stream.extend_from_slice(&good[..good.len() / 2]); // truncated frame: a bad frame of its own…
    stream.extend_from_slice(&good); // …ended by the next one's leading delimiter, which survives
    stream.extend_from_slice(&good);
    let mut d = Decoder::<MAX_FRAME>::new();
    let mut ok = 0;
    let mut bad = 0;
    for b in stream {
        match d.push::<HostMsg>(b) {
            Some(Ok(HostMsg::GetConfig)) => ok += 1,
            Some(Ok(other)) => panic!("{other:?}"),
            Some(Err(_)) => bad += 1,
            None => {}
        }
    }
    assert_eq!(ok, 3);
    assert_eq!(bad, 4);
    let s = d.stats;
    assert_eq!(s.frames, 3);
    assert_eq!(s.oversize, 1);
    assert_eq!(s.cobs_errors + s.crc_errors + s.message_errors, 3);
}

/// xorshift64: a reproducible noise source without another dependency.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        self.0
    }

    fn below(&mut self, n: u64) -> u64 {
        self.next() % n
    }
}

/// Line noise right before a frame: the frame must survive every time, the
/// noise must be counted as one bad frame, and every byte must be accounted
/// for. Without the leading delimiter the same streams lose every such frame.
#[test]
fn the_frame_right_after_line_noise_survives() {
    const TRIALS: usize = 20_000;
    let msgs = [
        HostMsg::GetStatus,
        HostMsg::Hello { protocol_version: 1 },
        HostMsg::Tare { samples: 4096 },
        HostMsg::Samples(SampleBlock {
            seq: 9,
            samples: heapless::Vec::from_slice(&[[7, 4095, 2048]; BLOCK_SAMPLES]).unwrap(),
        }),
    ];
    let frames: Vec<Vec<u8>> = msgs.iter().map(frame).collect();
    let mut rng = Rng(0x9E37_79B9_7F4A_7C15);
    let mut d = Decoder::<MAX_FRAME>::new();
    let mut legacy = Decoder::<MAX_FRAME>::new();
    let (mut survived, mut legacy_survived, mut noise_bytes, mut frame_bytes) = (0, 0, 0u32, 0u32);
    for _ in 0..TRIALS {
        let noise: Vec<u8> = (0..1 + rng.below(64)).map(|_| 1 + rng.below(255) as u8).collect();
        let k = rng.below(msgs.len() as u64) as usize;
        let f = &frames[k];
        noise_bytes += noise.len() as u32;
        frame_bytes += f.len() as u32;
        let mut got = Vec::new();
        for &b in noise.iter().chain(f) {
            if let Some(r) = d.push::<HostMsg>(b) {
                got.push(r);
            }
        }
        assert_eq!(got.len(), 2, "noise {noise:02x?} then frame {k}: {got:?}");
        assert!(got[0].is_err(), "noise decoded as a frame: {noise:02x?}");
        if got[1].as_ref() == Ok(&msgs[k]) {
            survived += 1;
        }
        // The same stream in the old framing: no leading delimiter.
        for &b in noise.iter().chain(&f[1..]) {
            if let Some(Ok(m)) = legacy.push::<HostMsg>(b) {
                legacy_survived += u32::from(m == msgs[k]);
            }
        }
    }
    assert_eq!(survived, TRIALS, "frames decoded right after noise");
    assert_eq!(legacy_survived, 0, "the old framing loses them all");
    let s = d.stats;
    assert_eq!(s.frames as usize, TRIALS);
    assert_eq!((s.cobs_errors + s.crc_errors + s.message_errors) as usize, TRIALS);
    assert_eq!(s.oversize, 0);
    // Every byte is noise (discarded) or a good frame's, none of them double-counted.
    assert_eq!(s.discarded_bytes, noise_bytes, "exactly the noise is discarded");
    assert!(frame_bytes as usize > 2 * TRIALS);
}

/// The configuration hash tells configurations apart (the estimator's
/// mapping to and from `Config` is tested in `hammer_estimator::device`).
#[test]
fn the_config_hash_tells_configs_apart() {
    let wire = sample_config();
    assert_ne!(config_hash(&wire), 0);
    let mut other = wire;
    other.blank_after_s = 2e-3;
    assert_ne!(config_hash(&other), config_hash(&wire));
}
