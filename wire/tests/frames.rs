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

fn sample_report() -> Report {
    Report {
        seq: 7,
        t_impact_s: 0.5,
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
        flags: 0x0800,
    }
}

/// The bytes of these frames are the protocol. If a test here fails, the
/// wire format changed: bump PROTOCOL_VERSION, update docs/wire-protocol.md,
/// and only then update the snapshot.
#[test]
fn golden_frames() {
    assert_eq!(PROTOCOL_VERSION, 1);
    assert_eq!(hex(&frame(&HostMsg::Hello { protocol_version: 1 })), "0106016922de3600");
    assert_eq!(hex(&frame(&HostMsg::GetStatus)), "0605021b68a200");
    let block = SampleBlock {
        seq: 3,
        samples: heapless::Vec::from_slice(&[[1, 2, 4095], [0, 65535, 2048]]).unwrap(),
    };
    assert_eq!(
        hex(&frame(&HostMsg::Samples(block))),
        "080903020102ff1f0affff0380102979e9e100"
    );
    assert_eq!(
        hex(&frame(&DeviceMsg::Report(sample_report()))),
        "030107010101010107e03f1283403d0103aa410103244101032041010328410103803f0103c03f0103c03f010320400103304001036040010388400101023e0101023e0103603f0101063e3333333d04ab9f4804966148010101010103c4400107803f8096184b0101010780101b7be5f800"
    );
    let rej = DeviceMsg::Rejected {
        command: CommandKind::Unknown,
        reason: RejectReason::CorruptFrame,
    };
    assert_eq!(hex(&frame(&rej)), "08080a0439a4d00c00");
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
            ..Default::default()
        }),
        DeviceMsg::Alarm(Alarm {
            kind: AlarmKind::DriftOn,
            cycle_seq: 9,
            flags: 1 << 13,
            drift_score: 11.5,
        }),
        DeviceMsg::Capture(CaptureChunk {
            capture_id: 1,
            offset: 64,
            total: 4700,
            samples: heapless::Vec::from_slice(&[[1, 2, 3]; 32]).unwrap(),
        }),
        DeviceMsg::Ack(CommandKind::Tare),
        DeviceMsg::Config(DeviceConfig::from(&hammer_estimator::Config {
            supply_pressure_pa: 4e5,
            ..Default::default()
        })),
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
    corrupt[1] ^= 0x40; // one flipped bit
    stream.extend_from_slice(&corrupt);
    stream.extend_from_slice(&[0xAA; 1000]); // an oversized run
    stream.push(0);
    stream.extend_from_slice(&good[..good.len() / 2]); // truncated frame…
    stream.extend_from_slice(&good); // …swallowed into the next one: one bad frame, then nothing lost after
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
    assert_eq!(ok, 2);
    assert_eq!(bad, 4);
    let s = d.stats;
    assert_eq!(s.frames, 2);
    assert_eq!(s.oversize, 1);
    assert_eq!(s.cobs_errors + s.crc_errors + s.message_errors, 3);
}

#[test]
fn estimator_reports_and_configs_convert_without_loss() {
    let c = hammer_estimator::Config::default();
    let wire = DeviceConfig::from(&c);
    let back = wire.to_config(&c);
    assert_eq!(back.rear, c.rear);
    assert_eq!(back.accel_spec, c.accel_spec);
    assert_eq!(back.sample_rate_hz, c.sample_rate_hz);
    assert!(back.validate().is_ok());
    assert_ne!(wire.hash(), 0);
    let mut other = wire;
    other.blank_after_s = 2e-3;
    assert_ne!(other.hash(), wire.hash());
}
