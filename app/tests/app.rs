//! The app on the host: commands, capture, and the async tasks over an
//! in-memory link, fed with a simulated hammer.

use embassy_futures::select::{select, select4, Either};
use embassy_sync::blocking_mutex::raw::NoopRawMutex;
use embassy_sync::pipe::Pipe;
use embassy_sync::zerocopy_channel;
use hammer_app::chambers::{Block, Pipeline, READER_BLOCKS};
use hammer_app::{
    link_rx, link_tx, reading, sampling, ChamberReader, Clock, LinkRx, LinkSamples, LinkTx, Monitor, Overrun,
    ReaderRoom, SampleSource, Shared,
};
use hammer_estimator::{Config, CycleReport, Estimator, Flags, RawSample};
use hammer_sim::simulate::simulate;
use hammer_sim::SimConfig;
use hammer_wire::*;

fn codes(bar: f64, seconds: f64) -> Vec<RawSample> {
    let mut cfg = SimConfig::nominal(bar);
    cfg.solver.duration_s = seconds;
    cfg.effects.apply_spec("coulomb_friction").unwrap();
    let sim = simulate(&cfg).unwrap();
    let est = cfg.estimator_config(None).unwrap();
    // Compared as wire bytes: the unknown supply pressure is a NaN.
    assert_eq!(
        config_hash(&DeviceConfig::from(&est)),
        config_hash(&DeviceConfig::from(&Config::default())),
        "simulator sensors = device defaults"
    );
    sim.measured.codes
}

fn monitor() -> Box<Monitor> {
    Box::new(Monitor::new(Config::default(), "host-test").unwrap())
}

/// A monitor asked for a one-cycle capture and fed `samples`, with what
/// it sent on the way (the capture's chunks not yet taken).
fn captured(samples: &[RawSample]) -> (Box<Monitor>, Vec<DeviceMsg>) {
    let mut m = monitor();
    let mut out = vec![];
    let mut emit = |msg| out.push(msg);
    m.on_command(HostMsg::StartCapture { cycles: 1 }, 0, &mut emit);
    m.on_samples(samples, &mut emit);
    (m, out)
}

#[test]
fn reports_are_the_estimators_and_a_capture_reassembles_one_cycle() {
    let samples = codes(5.0, 0.6);
    let (mut m, mut out) = captured(&samples);
    let mut emit = |msg| out.push(msg);
    while let Some(c) = m.next_capture_chunk() {
        emit(c);
    }
    let mut est = Estimator::new(Config::default()).unwrap();
    let mut expected = vec![];
    est.push_block(&samples, |r| expected.push(r));
    let reports: Vec<CycleReport> = out
        .iter()
        .filter_map(|m| if let DeviceMsg::Report(r) = m { Some(*r) } else { None })
        .collect();
    assert_eq!(reports, expected);
    assert!(matches!(out[0], DeviceMsg::Ack(CommandKind::StartCapture)));
    // The capture: from the first reported impact to the next, contiguous, equal to the input.
    let chunks: Vec<&CaptureChunk> = out
        .iter()
        .filter_map(|m| if let DeviceMsg::Capture(c) = m { Some(c) } else { None })
        .collect();
    let total = chunks[0].total as usize;
    let mut got = vec![];
    for c in &chunks {
        assert_eq!(c.offset as usize, got.len());
        got.extend(c.samples.iter().map(|&s| RawSample::from(s)));
    }
    assert_eq!(got.len(), total);
    // The capture starts at the first impact seen after it was armed (here
    // the stream's first, which opens the first reported cycle) and holds
    // that cycle plus the tail with its closing impact (reports[0]'s).
    let closing = (reports[0].t_impact_s() * 1e5).round() as i64;
    let period = (reports[0].period_s * 1e5).round() as i64;
    let start = samples
        .windows(got.len())
        .position(|w| w == got.as_slice())
        .expect("capture is a slice of the input") as i64;
    assert!(
        (start - (closing - period)).abs() <= 1,
        "start {start}, impact {}",
        closing - period
    );
    let want = period + hammer_app::monitor::CAPTURE_TAIL as i64;
    assert!(
        (total as i64 - want).abs() <= 2,
        "{total} vs one period {period} + tail"
    );
}

/// The host asks for the next capture as soon as the last chunk reaches it;
/// the link task may not have called for a chunk again by then (it stops
/// while the outgoing queue is nearly full), so the capture must end with its
/// last chunk, not one call later. (`hammer commission` was refused `Busy`
/// between two captures under load.)
#[test]
fn the_next_capture_is_accepted_as_soon_as_the_last_chunk_leaves() {
    let (mut m, mut out) = captured(&codes(5.0, 0.6));
    let mut last = None;
    while let Some(DeviceMsg::Capture(c)) = m.next_capture_chunk() {
        if c.offset as usize + c.samples.len() >= c.total as usize {
            last = Some(c);
            break;
        }
    }
    assert!(last.is_some(), "the capture completed");
    out.clear();
    let mut emit = |msg| out.push(msg);
    m.on_command(HostMsg::StartCapture { cycles: 1 }, 0, &mut emit);
    assert_eq!(out, vec![DeviceMsg::Ack(CommandKind::StartCapture)]);
    assert_eq!(m.next_capture_chunk(), None, "nothing left of the first capture");
}

#[test]
fn commands_are_applied_or_rejected_with_a_reason() {
    let mut m = monitor();
    let mut out = vec![];
    let mut emit = |msg| out.push(msg);
    m.on_command(HostMsg::Hello { protocol_version: 99 }, 0, &mut emit);
    assert_eq!(
        out[0],
        DeviceMsg::Rejected {
            command: CommandKind::Hello,
            reason: RejectReason::ProtocolMismatch {
                device: PROTOCOL_VERSION
            }
        }
    );
    assert!(matches!(&out[1], DeviceMsg::Hello(i) if i.protocol_version == PROTOCOL_VERSION));
    out.clear();
    let mut bad = DeviceConfig::from(&Config::default());
    bad.sample_rate_hz = 0.0;
    let mut emit = |msg| out.push(msg);
    m.on_command(HostMsg::SetConfig(bad), 0, &mut emit);
    m.on_command(
        HostMsg::RestoreWear(WearBlob {
            bytes: heapless::Vec::from_slice(&[1, 2, 3]).unwrap(),
        }),
        0,
        &mut emit,
    );
    m.on_command(HostMsg::StartCapture { cycles: 0 }, 0, &mut emit);
    assert_eq!(
        out,
        vec![
            DeviceMsg::Rejected {
                command: CommandKind::SetConfig,
                reason: RejectReason::InvalidConfig
            },
            DeviceMsg::Rejected {
                command: CommandKind::RestoreWear,
                reason: RejectReason::BadWearState
            },
            DeviceMsg::Rejected {
                command: CommandKind::StartCapture,
                reason: RejectReason::Busy
            },
        ]
    );
    assert_eq!(m.counters.rejected_commands, 4);

    // Tare: a moving hammer is refused, a resting one zeroes the offsets.
    out.clear();
    let mut emit = |msg| out.push(msg);
    m.on_command(HostMsg::Tare { samples: 2000 }, 0, &mut emit);
    m.on_samples(&codes(5.0, 0.2)[..2000], &mut emit);
    assert_eq!(
        out.last().unwrap(),
        &DeviceMsg::Rejected {
            command: CommandKind::Tare,
            reason: RejectReason::TareNotAtRest
        }
    );
    out.clear();
    let mut emit = |msg| out.push(msg);
    m.on_command(HostMsg::Tare { samples: 2000 }, 0, &mut emit);
    // At rest the chambers are at atmosphere: code 372 of the default range
    // (-1 to 10 bar gauge). The estimator may still report on the running
    // stretch before it; the tare's answer is an Ack.
    let rest: Vec<RawSample> = (0..2000)
        .map(|i| RawSample {
            rear: 371 + (i % 3) as u16,
            front: 374,
            accel: 2052,
        })
        .collect();
    m.on_samples(&rest, &mut emit);
    let answers: Vec<_> = out
        .iter()
        .filter(|m| matches!(m, DeviceMsg::Ack(_) | DeviceMsg::Rejected { .. }))
        .collect();
    assert_eq!(answers, vec![&DeviceMsg::Ack(CommandKind::Tare)]);
    assert!((m.config().rear.zero_code - 372.0).abs() < 0.01 && (m.config().accel.zero_code - 2052.0).abs() < 0.01);

    // Wear state: out and back in.
    let blob = m.wear_blob();
    out.clear();
    let mut emit = |msg| out.push(msg);
    m.on_command(HostMsg::RestoreWear(blob), 0, &mut emit);
    assert_eq!(out, vec![DeviceMsg::Ack(CommandKind::RestoreWear)]);
}

/// An in-memory byte link: one pipe each way.
struct PipeRx<'a>(&'a Pipe<NoopRawMutex, 4096>);
struct PipeTx<'a>(&'a Pipe<NoopRawMutex, 4096>);
impl LinkRx for PipeRx<'_> {
    async fn read(&mut self, buf: &mut [u8]) -> usize {
        self.0.read(buf).await
    }
}
impl LinkTx for PipeTx<'_> {
    async fn write_all(&mut self, bytes: &[u8]) {
        self.0.write_all(bytes).await
    }
}
struct FakeClock(std::cell::Cell<u64>);
impl Clock for FakeClock {
    fn now_us(&self) -> u64 {
        let t = self.0.get() + 10;
        self.0.set(t);
        t
    }
}

/// The link's samples; `1` says whether the board holds them while its
/// reader has no free block (`SampleSource::holds_samples`).
struct Samples<'a>(LinkSamples<'a, NoopRawMutex>, bool);
impl SampleSource for Samples<'_> {
    async fn read(&mut self, buf: &mut [RawSample]) -> Result<usize, Overrun> {
        self.0.read(buf).await
    }
    fn holds_samples(&self) -> bool {
        self.1
    }
}

/// How the device's tasks are run by [`over_a_link`].
#[derive(Clone, Copy)]
struct Run {
    /// The stream's block left out on the way, if any.
    lost: Option<usize>,
    /// The board's source holds its samples.
    hold: bool,
    /// The reader starts only once its blocks have all been full for this
    /// many rounds of the tasks, as a reader's thread waits its turn on a
    /// busy host.
    late_rounds: u32,
}

/// The device's tasks over an in-memory link, fed `samples` in blocks by a
/// host that sends a Hello and a line of garbage first, then asks for the
/// status until it has seen every sample sent and `want_reports` reports
/// (or a hundred times). What came back, and the blocks the reader lost.
fn over_a_link(samples: &[RawSample], run: Run, want_reports: usize) -> (Vec<DeviceMsg>, u32) {
    let blocks: Vec<&[RawSample]> = samples.chunks(BLOCK_SAMPLES).collect();
    let host_to_dev: Pipe<NoopRawMutex, 4096> = Pipe::new();
    let dev_to_host: Pipe<NoopRawMutex, 4096> = Pipe::new();
    let shared: Shared<NoopRawMutex> = Shared::new();
    let mut monitor = monitor();
    let clock = FakeClock(std::cell::Cell::new(0));
    let (mut rx, mut tx) = (PipeRx(&host_to_dev), PipeTx(&dev_to_host));
    let mut board_reader = ChamberReader::new(&Config::default(), Box::new(ReaderRoom::new()));
    let mut slots = vec![Block::EMPTY; READER_BLOCKS];
    let mut channel = zerocopy_channel::Channel::<NoopRawMutex, Block>::new(&mut slots);
    let (mut blocks_tx, mut blocks_rx) = channel.split();
    let device = select4(
        async {
            let mut src = Samples(LinkSamples::new(&shared), run.hold);
            sampling(&mut src, &mut monitor, &shared, &clock, &mut blocks_tx).await
        },
        async {
            let mut full_for = 0;
            core::future::poll_fn(|cx| {
                full_for = if blocks_rx.is_full() { full_for + 1 } else { 0 };
                if full_for >= run.late_rounds {
                    return core::task::Poll::Ready(());
                }
                cx.waker().wake_by_ref();
                core::task::Poll::Pending
            })
            .await;
            reading(&mut board_reader, &shared, &mut blocks_rx).await
        },
        link_rx(&mut rx, &shared),
        link_tx(&mut tx, &shared),
    );
    let sent: usize = blocks
        .iter()
        .enumerate()
        .filter(|(i, _)| Some(*i) != run.lost)
        .map(|(_, b)| b.len())
        .sum();
    let host = async {
        let mut frame = [0u8; MAX_FRAME];
        let mut send = async |m: &HostMsg| {
            let n = encode(m, &mut frame).unwrap();
            host_to_dev.write_all(&frame[..n]).await;
        };
        send(&HostMsg::Hello {
            protocol_version: PROTOCOL_VERSION,
        })
        .await;
        host_to_dev.write_all(&[0x55, 0x12, 0x00]).await; // garbage
        for (i, b) in blocks.iter().enumerate() {
            if Some(i) == run.lost {
                continue;
            }
            let block = SampleBlock {
                seq: i as u32,
                samples: b.iter().map(|s| [s.rear, s.front, s.accel]).collect(),
            };
            send(&HostMsg::Samples(block)).await;
        }
        // Samples and commands travel in separate queues: ask for the status
        // until it has seen every sample sent.
        let mut dec = Decoder::<MAX_FRAME>::new();
        let mut got = vec![];
        let mut buf = [0u8; 256];
        for _ in 0..100 {
            send(&HostMsg::GetStatus).await;
            loop {
                let n = dev_to_host.read(&mut buf).await;
                let mut status = None;
                for &b in &buf[..n] {
                    if let Some(Ok(m)) = dec.push::<DeviceMsg>(b) {
                        if let DeviceMsg::Status(s) = &m {
                            status = Some(s.samples);
                        }
                        got.push(m);
                    }
                }
                // Every sample seen, and every report read that can be.
                let reports = got.iter().filter(|m| matches!(m, DeviceMsg::Report(_))).count();
                match status {
                    Some(seen) if seen == sent as u64 && reports >= want_reports => return got,
                    Some(_) => break,
                    None => {}
                }
            }
        }
        got
    };
    let got = match embassy_futures::block_on(select(device, host)) {
        Either::First(_) => unreachable!("device tasks never return"),
        Either::Second(got) => got,
    };
    (
        got,
        shared.reader_blocks_dropped.load(std::sync::atomic::Ordering::Relaxed),
    )
}

fn reports(got: &[DeviceMsg]) -> Vec<CycleReport> {
    got.iter()
        .filter_map(|m| if let DeviceMsg::Report(r) = m { Some(*r) } else { None })
        .collect()
}

/// The host's reference: the estimator, then the chambers' reader, on the
/// same blocks (`lost` seen as a gap).
fn expected_reports(samples: &[RawSample], lost: Option<usize>) -> (Vec<CycleReport>, u32) {
    let mut host = Pipeline::new(Config::default(), Box::new(ReaderRoom::new())).unwrap();
    let mut expected = vec![];
    for (i, b) in samples.chunks(BLOCK_SAMPLES).enumerate() {
        if Some(i) == lost {
            host.push_gap(b.len() as u32);
        } else {
            host.push_block(b, &mut |r| expected.push(r));
        }
    }
    (expected, host.counters().read)
}

#[test]
fn tasks_over_a_link_report_reject_garbage_and_count_gaps() {
    let samples = codes(6.0, 0.4);
    // Block 5 of the stream is lost on the way: the host-side reference sees a gap there.
    let run = Run {
        lost: Some(5),
        hold: false,
        late_rounds: 0,
    };
    let (expected, read) = expected_reports(&samples, run.lost);
    // The last report waits for the 8 ms after its impact, which never come.
    assert!(read >= 5, "{read}");
    let (got, reader_dropped) = over_a_link(&samples, run, expected.len());
    // The garbage is answered by the receive task at once, the Hello by the
    // sampling task: their order may vary.
    assert!(got
        .iter()
        .any(|m| matches!(m, DeviceMsg::Hello(i) if i.board.as_slice() == b"host-test")));
    let rejected = DeviceMsg::Rejected {
        command: CommandKind::Unknown,
        reason: RejectReason::CorruptFrame,
    };
    assert_eq!(got.iter().filter(|m| **m == rejected).count(), 1);
    assert_eq!(
        reports(&got),
        expected,
        "device reports equal the host estimator's and reader's on the same samples"
    );
    let DeviceMsg::Status(s) = got.last().unwrap() else {
        unreachable!()
    };
    assert_eq!(s.rx_cobs_errors + s.rx_crc_errors + s.rx_decode_errors, 1);
    assert_eq!(s.dropped_samples, BLOCK_SAMPLES as u64);
    assert_eq!(s.adc_overruns, 1);
    assert_eq!(s.frames_dropped, 0);
    assert_eq!(s.samples as usize, samples.len() - BLOCK_SAMPLES);
    assert_eq!(reader_dropped, 0);
}

/// A reader that waits its turn (a native board's thread on a busy host),
/// here for longer than the stream takes to arrive: an ADC's blocks run on
/// past it and are lost to the reading, counted; a source that holds its
/// samples waits for it, and every cycle is read as the host's reference
/// reads it.
#[test]
fn a_late_reader_costs_readings_only_where_the_source_cannot_wait() {
    let samples = codes(6.0, 0.4);
    let (expected, read) = expected_reports(&samples, None);
    assert!(read >= 5, "{read}");
    let late = |hold| {
        let run = Run {
            lost: None,
            hold,
            late_rounds: 2_000,
        };
        over_a_link(&samples, run, expected.len())
    };
    let (got, reader_dropped) = late(false);
    let read_ones = |rs: &[CycleReport]| rs.iter().filter(|r| !r.flags.contains(Flags::CHAMBERS_UNREAD)).count();
    assert!(reader_dropped > 0, "{reader_dropped}");
    assert!(read_ones(&reports(&got)) < read_ones(&expected), "{:?}", reports(&got));
    let (got, reader_dropped) = late(true);
    assert_eq!(reader_dropped, 0);
    assert_eq!(reports(&got), expected);
}

/// The device's default configuration on the wire: the mapping from the
/// estimator's `Config` to `DeviceConfig` is part of what a host sees (the
/// `Config` reply, the hash in `Hello` and `Status`), so its bytes are pinned.
#[test]
fn the_default_config_on_the_wire_is_pinned() {
    let wire = DeviceConfig::from(&Config::default());
    let mut buf = [0u8; MAX_FRAME];
    let n = encode(&DeviceMsg::Config(wire), &mut buf).unwrap();
    let hex: String = buf[..n].iter().map(|x| format!("{x:02x}")).collect();
    assert_eq!(
        hex,
        "0002051050c347295c8f3f9eef273d4260e53c0101010fe922ba43654f8643ff1f6f12033c01117a44e922ba43654f8643ff1f6f12033c01037a440ef0ff44a10f7a3fff1f0ad7a33b0103803f1880bb4417b751386f12833a0ad7a33b8fc2f53d0ad7a33c010102400108c07f20bc3e4c320101023f011f2041f4fd543d07457337edeea6378fc2f53c0ad7a33c077e8536a7d1c4f800"
    );
    assert_eq!(config_hash(&wire), 1_530_825_681);
}
