//! The firmware under emulation: QEMU boots the emulated board (the same app
//! as the reference board), the test feeds the ADC codes of simulated traces
//! into it, through its ADC model at the full rate or as frames over its
//! UART, and the reports that come back must equal the host estimator's on
//! the same samples, bit for bit.
//!
//! Needs `qemu-system-arm` and the emulated firmware built
//! (`cargo xtask ci` does both; `.ci/run` installs QEMU).

use std::time::Duration;

use hammer_app::chambers::{Pipeline, ReaderRoom};
use hammer_estimator::{Config, RawSample};
use hammer_host::client::Client;
use hammer_host::emulator::{firmware_elf, Emulator, Icount};
use hammer_host::stimulus::Stimulus;
use hammer_sim::estimation::to_codes;
use hammer_sim::simulate::simulate;
use hammer_sim::SimConfig;
use hammer_wire::stimulus::BLOCK_SETS;
use hammer_wire::*;

const T: Duration = Duration::from_secs(20);

fn boot() -> (Emulator, Client<std::net::TcpStream>) {
    let mut emu = Emulator::start(&firmware_elf(), false).expect("QEMU and the emulated firmware");
    let link = connect(&mut emu);
    (emu, link)
}

/// Connects to the board's UART and shakes hands. Like a host tool, it retries:
/// a fresh connection can be reset while QEMU starts, or wait in its listen
/// queue until the previous connection is fully closed.
fn connect(emu: &mut Emulator) -> Client<std::net::TcpStream> {
    for _ in 0..10 {
        let stream = emu.connect(T).expect("connect to the board's UART");
        let mut link = Client::new(stream);
        match link.handshake(Duration::from_secs(10)) {
            Ok(_) => return link,
            Err(e) => eprintln!("handshake failed ({e}); reconnecting"),
        }
        std::thread::sleep(Duration::from_millis(200));
    }
    panic!("no handshake with the emulated board");
}

fn status(link: &mut Client<std::net::TcpStream>) -> Status {
    link.send(&HostMsg::GetStatus).unwrap();
    let (s, _) = link
        .recv_until(T, |m| if let DeviceMsg::Status(s) = m { Some(*s) } else { None })
        .unwrap();
    s.expect("status")
}

/// Polls the status until the device has processed `n` samples.
fn wait_samples(link: &mut Client<std::net::TcpStream>, n: u64) -> Status {
    let deadline = std::time::Instant::now() + T;
    loop {
        let s = status(link);
        if s.samples >= n || std::time::Instant::now() > deadline {
            return s;
        }
        std::thread::sleep(Duration::from_millis(50));
    }
}

fn codes(bar: f64, seconds: f64, seed: u64) -> Vec<RawSample> {
    let mut cfg = SimConfig::nominal(bar);
    cfg.solver.duration_s = seconds;
    cfg.seed = seed;
    cfg.effects.apply_spec("coulomb_friction").unwrap();
    let sim = simulate(&cfg).unwrap();
    sim.measured.codes
}

/// Streams samples as numbered blocks; returns everything the device said.
fn stream(link: &mut Client<std::net::TcpStream>, samples: &[RawSample], next_block: &mut u32) -> Vec<DeviceMsg> {
    let mut got = vec![];
    for (i, chunk) in samples.chunks(BLOCK_SAMPLES).enumerate() {
        let block = SampleBlock {
            seq: *next_block,
            samples: chunk.iter().map(|s| [s.rear, s.front, s.accel]).collect(),
        };
        *next_block += 1;
        link.send(&HostMsg::Samples(block)).unwrap();
        if i % 64 == 0 {
            while let Some(m) = link.recv(Duration::ZERO).unwrap() {
                got.push(m);
            }
        }
    }
    got
}

/// Waits for the last chunk of a capture; returns every capture chunk in `got` and after it.
fn finish_capture(link: &mut Client<std::net::TcpStream>, mut got: Vec<DeviceMsg>) -> Vec<CaptureChunk> {
    let (_, more) = link
        .recv_until(T, |m| {
            matches!(m, DeviceMsg::Capture(c) if c.offset as usize + c.samples.len() == c.total as usize).then_some(())
        })
        .unwrap();
    got.extend(more);
    got.iter()
        .filter_map(|m| {
            if let DeviceMsg::Capture(c) = m {
                Some(c.clone())
            } else {
                None
            }
        })
        .collect()
}

fn reports(msgs: &[DeviceMsg]) -> Vec<CycleReport> {
    msgs.iter()
        .filter_map(|m| if let DeviceMsg::Report(r) = m { Some(*r) } else { None })
        .collect()
}

fn wire_bytes(r: &CycleReport) -> Vec<u8> {
    postcard::to_allocvec(r).unwrap()
}

/// The board at the full rate: `samples` through its ADC model (see
/// `tests/full_rate.rs`), guest time counted in instructions.
fn boot_full_rate(samples: &[RawSample]) -> (Emulator, Stimulus, Client<std::net::TcpStream>) {
    let stimulus = Stimulus::create().unwrap();
    assert!(stimulus.push(samples, &std::sync::atomic::AtomicBool::new(false)));
    stimulus.finish();
    let mut emu = Emulator::start_with(&firmware_elf(), Some(Icount::m4_at_125_mips(false)), Some(&stimulus))
        .expect("QEMU and the emulated firmware");
    let link = connect(&mut emu);
    (emu, stimulus, link)
}

#[test]
fn reports_from_the_emulated_board_equal_the_host_estimator_bit_for_bit() {
    for (i, bar) in [4.0, 6.0, 7.0].into_iter().enumerate() {
        let samples = codes(bar, 0.45, 20 + i as u64);
        let (_emu, _stimulus, mut link) = boot_full_rate(&samples);
        link.send(&HostMsg::GetConfig).unwrap();
        let (cfg, mut got) = link
            .recv_until(T, |m| if let DeviceMsg::Config(c) = m { Some(*c) } else { None })
            .unwrap();
        // A fresh board runs the default configuration, which the host's
        // estimator then takes as it is (not through the wire's f32s).
        let on_wire = |c: &DeviceConfig| postcard::to_allocvec(c).unwrap();
        assert_eq!(
            on_wire(&cfg.expect("config")),
            on_wire(&DeviceConfig::from(&Config::default()))
        );
        let device_cfg = Config::default();
        // The ADC delivers whole DMA halves: the tail short of one never comes.
        let delivered = samples.len() / BLOCK_SETS as usize * BLOCK_SETS as usize;
        // The host's copy of the board's pipeline: the estimator, then the
        // chambers' reader (the last report waits for samples that never come).
        let mut host = Pipeline::new(device_cfg, Box::new(ReaderRoom::new())).unwrap();
        let mut expected = vec![];
        host.push_block(&samples[..delivered], &mut |r| expected.push(r));
        assert!(host.counters().read >= 3, "{bar} bar: {:?}", host.counters());

        let last_seq = expected.last().unwrap().seq;
        let (done, more) = link
            .recv_until(T, |m| {
                matches!(m, DeviceMsg::Report(r) if r.seq == last_seq).then_some(())
            })
            .unwrap();
        got.extend(more);
        assert!(done.is_some(), "{bar} bar: last report arrived");
        let device = reports(&got);
        assert_eq!(device.len(), expected.len(), "{bar} bar: no report lost");
        for (k, (d, h)) in device.iter().zip(&expected).enumerate() {
            assert_eq!(d.seq, k as u32, "sequence numbers continuous");
            assert_eq!(
                wire_bytes(d),
                wire_bytes(h),
                "{bar} bar, cycle {k}: device {d:?} vs host {h:?}"
            );
        }
        assert!(device.iter().skip(1).all(|r| r.is_valid()), "{bar} bar: valid reports");
        let s = wait_samples(&mut link, delivered as u64);
        assert_eq!(s.samples, delivered as u64);
        assert_eq!(s.dropped_samples, 0);
        assert_eq!(s.frames_dropped, 0);
        assert_eq!(
            s.rx_crc_errors + s.rx_cobs_errors + s.rx_decode_errors + s.rx_oversize,
            0
        );
        println!("{bar} bar: {} reports identical to the host's", device.len());
    }
}

#[test]
fn the_firmware_survives_garbage_oversize_frames_bad_commands_and_reconnects() {
    let (mut emu, mut link) = boot();
    let before = status(&mut link);

    // Garbage: random bytes ending in a delimiter.
    let mut x = 0x1234_5678u32;
    let garbage: Vec<u8> = (0..300)
        .map(|_| {
            x ^= x << 13;
            x ^= x >> 17;
            x ^= x << 5;
            (x % 251 + 1) as u8
        })
        .chain([0])
        .collect();
    link.send_raw(&garbage).unwrap();
    // A frame with one corrupted byte.
    let mut frame = [0u8; MAX_FRAME];
    let n = encode(&HostMsg::GetConfig, &mut frame).unwrap();
    frame[2] ^= 0x10;
    link.send_raw(&frame[..n]).unwrap();
    // An oversized frame.
    link.send_raw(&[0x42; 1000]).unwrap();
    link.send_raw(&[0]).unwrap();
    // A well-formed but invalid command.
    let mut bad = DeviceConfig::from(&Config::default());
    bad.sample_rate_hz = -5.0;
    link.send(&HostMsg::SetConfig(bad)).unwrap();
    let (rej, seen) = link
        .recv_until(T, |m| {
            matches!(
                m,
                DeviceMsg::Rejected {
                    command: CommandKind::SetConfig,
                    reason: RejectReason::InvalidConfig
                }
            )
            .then_some(())
        })
        .unwrap();
    assert!(rej.is_some(), "invalid config rejected");
    let after = status(&mut link);
    let corrupt = after.rx_crc_errors + after.rx_cobs_errors + after.rx_decode_errors
        - (before.rx_crc_errors + before.rx_cobs_errors + before.rx_decode_errors);
    assert_eq!(corrupt, 2, "garbage and the corrupted frame counted: {after:?}");
    assert_eq!(after.rx_oversize - before.rx_oversize, 1);
    assert!(after.rejected_commands > before.rejected_commands);
    let rejections = seen
        .iter()
        .filter(|m| {
            matches!(
                m,
                DeviceMsg::Rejected {
                    command: CommandKind::Unknown,
                    ..
                }
            )
        })
        .count();
    assert!(rejections >= 2, "the device says what it rejected: {seen:?}");

    // The host disconnects mid-stream and comes back: the firmware kept running.
    let samples = codes(5.0, 0.3, 7);
    let mut next = 0;
    let half = samples.len() / 2;
    stream(&mut link, &samples[..half], &mut next);
    let s0 = wait_samples(&mut link, half as u64);
    assert_eq!(s0.samples, half as u64);
    drop(link);
    std::thread::sleep(Duration::from_millis(300));
    assert!(emu.is_running());
    let mut link = connect(&mut emu);
    let s1 = status(&mut link);
    assert!(s1.uptime_us > s0.uptime_us, "no reboot");
    assert_eq!(s1.samples, half as u64, "the device kept its state over the reconnect");
    stream(&mut link, &samples[half..], &mut next);
    let s2 = wait_samples(&mut link, samples.len() as u64);
    assert_eq!(s2.samples, samples.len() as u64);
    assert_eq!(s2.dropped_samples, 0);
}

#[test]
fn a_raw_capture_of_one_cycle_round_trips_into_the_trace_format() {
    let (_emu, mut link) = boot();
    let samples = codes(5.0, 0.5, 9);
    link.send(&HostMsg::StartCapture { cycles: 1 }).unwrap();
    let (ack, _) = link
        .recv_until(T, |m| (*m == DeviceMsg::Ack(CommandKind::StartCapture)).then_some(()))
        .unwrap();
    assert!(ack.is_some());
    let mut next = 0;
    let got = stream(&mut link, &samples, &mut next);
    let chunks = finish_capture(&mut link, got);
    let codes_back = hammer_host::capture::assemble(&chunks).expect("complete capture");
    assert!(
        codes_back.len() > 4000,
        "one full cycle at 100 kS/s: {} sample-sets",
        codes_back.len()
    );
    // It is a contiguous slice of what was streamed…
    let sent: Vec<[u16; 3]> = samples.iter().map(|s| [s.rear, s.front, s.accel]).collect();
    let start = sent
        .windows(codes_back.len())
        .position(|w| w == codes_back.as_slice())
        .expect("slice of the input");
    // …written as a trace and read back, it gives the same codes.
    let cfg = Config::default();
    let (trace, side) = hammer_host::capture::to_trace(&codes_back, &cfg, Some(5.0));
    let dir = std::env::temp_dir().join(format!("hammer-capture-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("capture.csv");
    hammer_trace::trace::write_csv(&path, &trace).unwrap();
    hammer_trace::trace::write_sidecar(&path, &side).unwrap();
    let back = hammer_trace::trace::read_csv(&path).unwrap();
    let recoded = to_codes(&back, &cfg);
    assert_eq!(recoded.len(), codes_back.len());
    assert!(recoded
        .iter()
        .zip(&codes_back)
        .all(|(a, b)| [a.rear, a.front, a.accel] == *b));
    assert_eq!(
        hammer_trace::trace::read_sidecar(&path).unwrap().unwrap().source,
        "device"
    );
    println!("capture: {} sample-sets from sample {start}", codes_back.len());
}

/// One-cycle raw captures from the emulated board, `n` of them, while it is
/// fed a hammer with the paper's friction at `bar`; each becomes a trace.
fn captures(bar: f64, n: usize, seed: u64) -> Vec<hammer_trace::trace::Trace> {
    let (_emu, mut link) = boot();
    let mut cfg = SimConfig::nominal(bar);
    cfg.solver.duration_s = 0.4 + 0.12 * n as f64;
    cfg.seed = seed;
    cfg.effects.apply_spec("coulomb_friction").unwrap();
    let sim = simulate(&cfg).unwrap();
    // The start-up from rest is not what a bench records: begin at 0.25 s.
    let samples = &sim.codes()[25_000..];
    let mut next = 0;
    let mut out = Vec::new();
    // Lock the estimator onto the cycle first.
    stream(&mut link, &samples[..10_000], &mut next);
    let mut at = 10_000;
    while out.len() < n && at < samples.len() {
        link.send(&HostMsg::StartCapture { cycles: 1 }).unwrap();
        let end = (at + 10_000).min(samples.len());
        let got = stream(&mut link, &samples[at..end], &mut next);
        at = end;
        let chunks = finish_capture(&mut link, got);
        if let Ok(codes) = hammer_host::capture::assemble(&chunks) {
            out.push(hammer_host::capture::to_trace(&codes, &Config::default(), Some(bar)).0);
        }
    }
    out
}

#[test]
fn the_diagnosis_names_friction_from_the_boards_raw_captures() {
    use hammer_host::diagnose::engine::{diagnose, MeasuredInput, Options};
    let mut inputs = Vec::new();
    for (bar, seed) in [(4.0, 31), (7.0, 32)] {
        let traces = captures(bar, 3, seed);
        assert_eq!(traces.len(), 3, "three captures at {bar} bar");
        for (k, trace) in traces.into_iter().enumerate() {
            inputs.push(MeasuredInput {
                label: format!("capture {k} at {bar} bar"),
                supply_bar: bar,
                trace,
                fit: true,
            });
        }
    }
    let opts = Options {
        figures: false,
        ..Options::default()
    };
    let r = diagnose(&inputs, &SimConfig::default(), &opts, &|_, _, _| {})
        .expect("diagnosis of the captures")
        .report;
    println!("{:?}: {} {}", r.verdict.effects, r.verdict.reason, r.verdict.params);
    for i in &r.inputs {
        assert_eq!(i.cycles, 1, "a capture is one complete cycle: {i:?}");
    }
    assert_eq!(r.verdict.effects, vec!["coulomb_friction"]);
    let p = &r.verdict.params;
    let force = |bar: f64| p["f0_n"].as_f64().unwrap() + p["k_n_per_bar"].as_f64().unwrap() * bar;
    assert!((force(4.0) - 10.27).abs() < 0.1 * 10.27, "{}", force(4.0));
    assert!((force(7.0) - 16.7).abs() < 0.1 * 16.7, "{}", force(7.0));
}
