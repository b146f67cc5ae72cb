//! The reader thread, which owns the port, and [`Ingest`], the decoding core
//! it shares with `hammer replay`.

use std::collections::VecDeque;
use std::io::{self, Read};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{SyncSender, TrySendError};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use hammer_wire::{DecodeError, DeviceMsg, HostMsg};

use crate::client::{hello, hello_reply, write_frame, Inbound, Incoming, SeqCheck};

use super::drift::Watch;
use super::event::{now_us, Event, LinkStats, Stamped};
use super::export::DeviceExport;
use super::log::{Logger, Marker};
use super::{Connector, Port};

/// Pause between attempts to reopen a lost port.
pub const RETRY: Duration = Duration::from_millis(500);
/// Pause between unanswered `Hello`s: a board that was just plugged in (or a
/// QEMU that just accepted) may miss the first.
pub const HELLO_RETRY: Duration = Duration::from_secs(1);
/// Messages kept while the handshake has not said whether they can be read.
const HELD_CAP: usize = 256;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Handshake {
    Pending,
    Done,
    /// The device speaks this other protocol version.
    Mismatch(u16),
}

/// Bytes in, events out: the client's [`Inbound`] core (framing) and
/// [`SeqCheck`] (report sequence) plus the handshake's verdict, the held messages and the
/// link counters. Knows nothing of ports or clocks, so a replay of the
/// recorded bytes yields the same events as the live link.
pub struct Ingest {
    inbound: Inbound,
    /// What one read completed, before it is interpreted.
    arrived: Vec<Incoming>,
    stats: LinkStats,
    handshake: Handshake,
    held: VecDeque<DeviceMsg>,
    seq: SeqCheck,
    lost_at_us: Option<u64>,
    opened_before: bool,
    /// A replay reads a recording made in an older protocol this host can
    /// still read (`hammer_wire::legacy`); a live link refuses the device.
    older_readable: bool,
}

impl Default for Ingest {
    fn default() -> Self {
        Self::new()
    }
}

impl Ingest {
    pub fn new() -> Self {
        Self {
            inbound: Inbound::new(),
            arrived: Vec::new(),
            stats: LinkStats::default(),
            handshake: Handshake::Pending,
            held: VecDeque::new(),
            seq: SeqCheck::default(),
            lost_at_us: None,
            opened_before: false,
            older_readable: false,
        }
    }

    /// The core `hammer replay` uses: as [`Ingest::new`], and a recording
    /// whose device spoke an older protocol this host can read
    /// (`hammer_wire::legacy::READABLE_OLDER`) is read in it.
    pub fn for_replay() -> Self {
        Self {
            older_readable: true,
            ..Self::new()
        }
    }

    pub fn stats(&self) -> &LinkStats {
        &self.stats
    }

    pub fn handshake(&self) -> Handshake {
        self.handshake
    }

    /// Stream offset where the frame now being received began.
    pub fn frame_start(&self) -> u64 {
        self.inbound.frame_start()
    }

    /// Bytes of a frame that has begun but not ended yet (at the end of a
    /// recording: a frame that never ended).
    pub fn pending_bytes(&self) -> u64 {
        self.inbound.bytes() - self.inbound.frame_start()
    }

    /// A new connection: a fresh decoder (a frame cut by the disconnect must
    /// not swallow the first new one) and a new handshake; counters go on.
    pub fn opened(&mut self, t_us: u64, port: String, emit: &mut dyn FnMut(Stamped)) {
        self.inbound.reopen();
        self.inbound.read_as(hammer_wire::PROTOCOL_VERSION);
        self.handshake = Handshake::Pending;
        self.held.clear();
        if self.opened_before {
            self.stats.reconnects = self.stats.reconnects.saturating_add(1);
        }
        self.opened_before = true;
        self.stats.connected = true;
        let lost_at_us = self.lost_at_us.take();
        emit(Stamped {
            t_us,
            event: Event::Connected {
                port,
                reconnects: self.stats.reconnects,
                lost_at_us,
                outage_us: lost_at_us.map(|l| t_us.saturating_sub(l)),
            },
        });
        emit(Stamped {
            t_us,
            event: Event::Stats(self.stats),
        });
    }

    pub fn lost(&mut self, t_us: u64, port: String, reason: String, emit: &mut dyn FnMut(Stamped)) {
        self.stats.connected = false;
        self.lost_at_us = Some(t_us);
        emit(Stamped {
            t_us,
            event: Event::Disconnected { port, reason },
        });
        emit(Stamped {
            t_us,
            event: Event::Stats(self.stats),
        });
    }

    /// Bytes as they arrived at `t_us`.
    pub fn feed(&mut self, t_us: u64, bytes: &[u8], emit: &mut dyn FnMut(Stamped)) {
        self.stats.bytes += bytes.len() as u64;
        let mut arrived = std::mem::take(&mut self.arrived);
        self.inbound.feed(bytes, &mut |i| arrived.push(i));
        for i in arrived.drain(..) {
            match i {
                Incoming::Msg(m) => {
                    self.stats.frames += 1;
                    self.stats.last_frame_us = Some(t_us);
                    self.message(t_us, m, emit);
                }
                Incoming::FrameError { kind, frame_start } => {
                    let c = match kind {
                        DecodeError::Crc => &mut self.stats.crc_errors,
                        DecodeError::Cobs => &mut self.stats.cobs_errors,
                        DecodeError::Message => &mut self.stats.decode_errors,
                        DecodeError::Oversize => &mut self.stats.oversize,
                    };
                    *c += 1;
                    let total = self.stats.frame_errors();
                    emit(Stamped {
                        t_us,
                        event: Event::FrameError {
                            kind,
                            total,
                            stream_offset: frame_start,
                        },
                    });
                }
            }
        }
        self.arrived = arrived; // its capacity, for the next read
        emit(Stamped {
            t_us,
            event: Event::Stats(self.stats),
        });
    }

    fn message(&mut self, t_us: u64, m: DeviceMsg, emit: &mut dyn FnMut(Stamped)) {
        // A recording of an older device: read in its own protocol.
        let older = matches!(&m, DeviceMsg::Hello(i) if i.protocol_version != hammer_wire::PROTOCOL_VERSION
            && self.older_readable && self.inbound.read_as(i.protocol_version));
        let reply = match (&m, hello_reply(&m)) {
            (DeviceMsg::Hello(info), Some(Err(_))) if older => Some(Ok(info)),
            (_, r) => r,
        };
        match reply {
            Some(Err(device)) => {
                self.held.clear();
                if self.handshake != Handshake::Mismatch(device) {
                    self.handshake = Handshake::Mismatch(device);
                    emit(Stamped {
                        t_us,
                        event: Event::VersionMismatch { device },
                    });
                }
                return;
            }
            Some(Ok(info)) => {
                let first = self.handshake != Handshake::Done;
                self.handshake = Handshake::Done;
                emit(Stamped {
                    t_us,
                    event: Event::Device(info.clone()),
                });
                if first {
                    while let Some(h) = self.held.pop_front() {
                        self.interpret(t_us, h, emit);
                    }
                }
                return;
            }
            None => {}
        }
        match self.handshake {
            Handshake::Done => self.interpret(t_us, m, emit),
            Handshake::Pending => {
                if self.held.len() >= HELD_CAP {
                    self.held.pop_front();
                    self.stats.unhandshaken_dropped += 1;
                }
                self.held.push_back(m);
            }
            Handshake::Mismatch(_) => {}
        }
    }

    fn interpret(&mut self, t_us: u64, m: DeviceMsg, emit: &mut dyn FnMut(Stamped)) {
        if let DeviceMsg::Report(r) = &m {
            if let Some(gap) = self.seq.next(r.seq) {
                self.stats.seq_gaps += 1;
                self.stats.lost_reports += gap.lost();
                emit(Stamped {
                    t_us,
                    event: Event::SeqGap {
                        expected: gap.expected,
                        got: gap.got,
                    },
                });
            }
            self.stats.reports += 1;
        }
        emit(Stamped {
            t_us,
            event: Event::Msg(m),
        });
    }
}

/// Starts the thread that owns the port until `stop` is set.
pub fn spawn(
    connector: Box<dyn Connector>,
    logger: Option<Logger>,
    export: Option<DeviceExport>,
    drift: Option<Watch>,
    tx: SyncSender<Stamped>,
    stop: Arc<AtomicBool>,
) -> io::Result<JoinHandle<()>> {
    let mut r = Reader {
        connector,
        out: Outputs { logger, export },
        tx,
        stop,
        ingest: Ingest::new(),
        ui_dropped: 0,
        drift,
    };
    std::thread::Builder::new()
        .name("monitor-reader".into())
        .spawn(move || r.run())
}

/// What a device's events are written to: the logs and the exports.
struct Outputs {
    logger: Option<Logger>,
    export: Option<DeviceExport>,
}

struct Reader {
    connector: Box<dyn Connector>,
    out: Outputs,
    tx: SyncSender<Stamped>,
    stop: Arc<AtomicBool>,
    ingest: Ingest,
    ui_dropped: u64,
    /// The drift since commissioning (`--reference`), read from the reports.
    drift: Option<Watch>,
}

/// The logs and exports first (they must not miss anything), then the
/// screen, which may lag: it is never waited for, and what it missed is counted.
fn deliver(out: &mut Outputs, tx: &SyncSender<Stamped>, ui_dropped: &mut u64, mut ev: Stamped) {
    if let Some(note) = out.export.as_mut().and_then(|x| x.event(&ev)) {
        let _ = tx.try_send(Stamped {
            t_us: ev.t_us,
            event: Event::Note(note),
        });
    }
    let logger = &mut out.logger;
    if let Some(l) = logger {
        if let Event::Stats(s) = &mut ev.event {
            s.unlogged = l.unlogged();
        }
        if let Err(e) = l.event(&ev) {
            give_up_logging(logger, tx, e);
        }
    }
    if let Some(news) = logger.as_mut().and_then(Logger::take_news) {
        let _ = tx.try_send(Stamped {
            t_us: ev.t_us,
            event: Event::Note(news),
        });
    }
    match tx.try_send(ev) {
        Ok(()) => {}
        Err(TrySendError::Full(_)) => *ui_dropped += 1,
        Err(TrySendError::Disconnected(_)) => {}
    }
}

fn give_up_logging(logger: &mut Option<Logger>, tx: &SyncSender<Stamped>, e: io::Error) {
    *logger = None;
    let _ = tx.try_send(Stamped::now(Event::Note(format!("logging stopped: {e}"))));
}

impl Reader {
    fn stopped(&self) -> bool {
        self.stop.load(Ordering::Relaxed)
    }

    fn emit(&mut self, ev: Stamped) {
        deliver(&mut self.out, &self.tx, &mut self.ui_dropped, ev);
    }

    fn marker(&mut self, t_us: u64, m: Marker) {
        if let Some(l) = &mut self.out.logger {
            if let Err(e) = l.marker(t_us, m) {
                give_up_logging(&mut self.out.logger, &self.tx, e);
            }
        }
    }

    fn sleep(&mut self, d: Duration) {
        let until = Instant::now() + d;
        while !self.stopped() {
            let Some(left) = until.checked_duration_since(Instant::now()) else {
                break;
            };
            std::thread::sleep(left.min(Duration::from_millis(50)));
            self.flush_due();
        }
    }

    fn flush_due(&mut self) {
        if let Some(l) = &mut self.out.logger {
            if let Err(e) = l.flush_if_due() {
                give_up_logging(&mut self.out.logger, &self.tx, e);
            }
        }
    }

    fn run(&mut self) {
        let mut outage_reported = false;
        while !self.stopped() {
            match self.connector.connect() {
                Ok(port) => {
                    outage_reported = false;
                    let name = self.connector.describe();
                    let t = now_us();
                    self.marker(t, Marker::Opened);
                    let (out, tx, dropped) = (&mut self.out, &self.tx, &mut self.ui_dropped);
                    self.ingest
                        .opened(t, name.clone(), &mut |ev| deliver(out, tx, dropped, ev));
                    let reason = self.session(port);
                    let t = now_us();
                    self.marker(t, Marker::Lost);
                    let (out, tx, dropped) = (&mut self.out, &self.tx, &mut self.ui_dropped);
                    self.ingest
                        .lost(t, name, reason, &mut |ev| deliver(out, tx, dropped, ev));
                    if let Some(l) = &mut self.out.logger {
                        let _ = l.flush();
                    }
                }
                Err(e) => {
                    if !outage_reported {
                        outage_reported = true;
                        let ev = Stamped::now(Event::ConnectFailed {
                            port: self.connector.describe(),
                            error: e.to_string(),
                        });
                        self.emit(ev);
                    }
                }
            }
            self.sleep(RETRY);
        }
        if let Some(l) = &mut self.out.logger {
            let _ = l.flush();
        }
    }

    /// Reads until the port goes away; returns why it ended.
    fn session(&mut self, mut port: Box<dyn Port>) -> String {
        let mut buf = vec![0u8; 4096];
        let mut hello_at: Option<Instant> = None;
        let mut hellos = 0u32;
        let mut config_asked = false;
        let mut reported_drops = 0u64;
        if let Some(w) = self.drift.as_mut() {
            w.reconnected();
        }
        loop {
            if self.stopped() {
                return "monitor stopped".into();
            }
            match self.ingest.handshake() {
                Handshake::Pending if hello_at.is_none_or(|t| t.elapsed() >= HELLO_RETRY) => {
                    if hellos == 3 {
                        self.emit(Stamped::now(Event::Note(format!(
                            "no answer to Hello after {hellos} tries; still asking every {} s",
                            HELLO_RETRY.as_secs()
                        ))));
                    }
                    match write_frame(&mut port, &hello()) {
                        Ok(()) => {}
                        // A device that does not read yet: ask again next time.
                        Err(e) if matches!(e.kind(), io::ErrorKind::TimedOut | io::ErrorKind::WouldBlock) => {}
                        Err(e) => return format!("cannot send Hello: {e}"),
                    }
                    hellos += 1;
                    hello_at = Some(Instant::now());
                }
                Handshake::Done if !config_asked => {
                    config_asked = true;
                    match write_frame(&mut port, &HostMsg::GetConfig) {
                        Ok(()) => {}
                        Err(e) if matches!(e.kind(), io::ErrorKind::TimedOut | io::ErrorKind::WouldBlock) => {
                            config_asked = false;
                        }
                        Err(e) => return format!("cannot send GetConfig: {e}"),
                    }
                }
                _ => {}
            }
            match port.read(&mut buf) {
                Ok(0) => return "end of stream (the device closed the link)".into(),
                Ok(n) => {
                    let t = now_us();
                    if let Some(l) = &mut self.out.logger {
                        if let Err(e) = l.raw(t, &buf[..n]) {
                            give_up_logging(&mut self.out.logger, &self.tx, e);
                        }
                    }
                    let (out, tx, dropped) = (&mut self.out, &self.tx, &mut self.ui_dropped);
                    let watch = &mut self.drift;
                    self.ingest.feed(t, &buf[..n], &mut |ev| {
                        // What the drift reads of an event follows it.
                        let follow = watch.as_mut().map(|w| w.see(&ev)).unwrap_or_default();
                        let t_us = ev.t_us;
                        deliver(out, tx, dropped, ev);
                        for event in follow {
                            deliver(out, tx, dropped, Stamped { t_us, event });
                        }
                    });
                }
                Err(e) if matches!(e.kind(), io::ErrorKind::WouldBlock | io::ErrorKind::TimedOut) => {}
                Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
                Err(e) => return format!("read error: {e}"),
            }
            if self.ui_dropped > reported_drops {
                // Once the queue has room again: say how much the screen skipped.
                let n = self.ui_dropped - reported_drops;
                let note = Stamped::now(Event::Note(format!(
                    "the screen fell behind and skipped {n} events (logs are complete)"
                )));
                if self.tx.try_send(note).is_ok() {
                    reported_drops = self.ui_dropped;
                }
            }
            self.flush_due();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::client::fixtures::{frame, info, report};
    use hammer_wire::PROTOCOL_VERSION;

    fn hello(v: u16) -> DeviceMsg {
        DeviceMsg::Hello(info(v))
    }

    fn run(ingest: &mut Ingest, msgs: &[DeviceMsg]) -> Vec<Event> {
        let mut out = vec![];
        for m in msgs {
            ingest.feed(1, &frame(m), &mut |e| out.push(e.event));
        }
        out.into_iter().filter(|e| !matches!(e, Event::Stats(_))).collect()
    }

    #[test]
    fn reports_before_the_handshake_wait_for_its_verdict() {
        let mut i = Ingest::new();
        let ev = run(&mut i, &[report(0), report(1)]);
        assert!(ev.is_empty(), "{ev:?}");
        let ev = run(&mut i, &[hello(PROTOCOL_VERSION), report(3)]);
        assert!(matches!(ev[0], Event::Device(_)));
        assert_eq!(ev[1], Event::Msg(report(0)));
        assert_eq!(ev[2], Event::Msg(report(1)));
        assert_eq!(ev[3], Event::SeqGap { expected: 2, got: 3 });
        assert_eq!(i.stats().seq_gaps, 1);
        assert_eq!(i.stats().lost_reports, 1);
    }

    /// A recording made with a protocol-4 board (before the chambers joined
    /// the configuration) replays: its reports as they were (the chambers
    /// unread, as protocol 5's), its `Config`
    /// (the frame protocol 4 sent, pinned in `wire/tests/frames.rs` then)
    /// with the default chambers; a live link refuses that board.
    #[test]
    fn a_replayed_protocol_4_recording_is_read_in_its_protocol() {
        const V4_CONFIG: &str = "0002050450c347010b203fb81e053dcdcc4c3c010370c10420ba430a408643ff1f6f12033c01037a440420ba430a408643ff1f6f12033c01037a440ef0ff44e7fb793fff1f0ad7a33b0103803f010f7a4417b75139a69bc43a0ad7a33c0101023f0101023f010102400108c07f20bc3e4c320101023f0107204125d6285200";
        let v4: Vec<u8> = (0..V4_CONFIG.len() / 2)
            .map(|k| u8::from_str_radix(&V4_CONFIG[2 * k..2 * k + 2], 16).unwrap())
            .collect();
        let stream = |i: &mut Ingest| {
            let mut out = vec![];
            // Protocol 4's reports are protocol 5's.
            let old = |seq| {
                protocol5_report(&hammer_wire::CycleReport {
                    seq,
                    ..Default::default()
                })
            };
            for bytes in [frame(&hello(4)), v4.clone(), old(0), old(1)] {
                i.feed(1, &bytes, &mut |e| out.push(e.event));
            }
            out.into_iter()
                .filter(|e| !matches!(e, Event::Stats(_)))
                .collect::<Vec<_>>()
        };
        let ev = stream(&mut Ingest::for_replay());
        assert!(matches!(&ev[0], Event::Device(i) if i.protocol_version == 4), "{ev:?}");
        let Event::Msg(DeviceMsg::Config(c)) = &ev[1] else {
            panic!("{ev:?}")
        };
        // The recorded board's own settings, the default chambers added.
        assert_eq!((c.piston_mass_kg, c.inclination_deg, c.cusum_h), (0.625, -15.0, 10.0));
        let default = hammer_wire::DeviceConfig::from(&hammer_estimator::Config::default());
        assert_eq!(
            (c.front_dead_m3, c.pressure_group_delay_s),
            (default.front_dead_m3, default.pressure_group_delay_s)
        );
        let unread = |m: DeviceMsg| match m {
            DeviceMsg::Report(mut r) => {
                r.mark_chambers_unread();
                Event::Msg(DeviceMsg::Report(r))
            }
            m => Event::Msg(m),
        };
        assert_eq!(&ev[2..], &[unread(report(0)), unread(report(1))]);
        // Live, the same bytes are a board of another protocol: not read
        // (its configuration and reports do not even decode in this one).
        let ev = stream(&mut Ingest::new());
        assert!(
            matches!(
                ev[..],
                [
                    Event::VersionMismatch { device: 4 },
                    Event::FrameError { .. },
                    Event::FrameError { .. },
                    Event::FrameError { .. }
                ]
            ),
            "{ev:?}"
        );
        // A protocol this host cannot read is not read in a replay either.
        let mut i = Ingest::for_replay();
        let ev = run(&mut i, &[hello(3), report(0)]);
        assert_eq!(ev, vec![Event::VersionMismatch { device: 3 }]);
    }

    /// Frames `body` as it is (a message of another protocol's layout).
    fn raw_frame(body: &[u8]) -> Vec<u8> {
        struct Raw<'a>(&'a [u8]);
        impl serde::Serialize for Raw<'_> {
            fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
                use serde::ser::SerializeTuple;
                let mut t = s.serialize_tuple(self.0.len())?;
                for b in self.0 {
                    t.serialize_element(b)?;
                }
                t.end()
            }
        }
        let mut buf = [0u8; hammer_wire::MAX_FRAME];
        let n = hammer_wire::encode(&Raw(body), &mut buf).unwrap();
        buf[..n].to_vec()
    }

    /// `r` as a protocol-5 board sent it: this protocol's body without the
    /// chambers' 72 bytes, which lie just before the flags' varint
    /// (`wire/tests/frames.rs` pins that layout against protocol 5's frame).
    fn protocol5_report(r: &hammer_wire::CycleReport) -> Vec<u8> {
        let mut f = frame(&DeviceMsg::Report(*r));
        let end = f.len() - 1;
        let n = hammer_wire::cobs::decode_in_place(&mut f[1..end]).unwrap();
        let body = &f[1..1 + n - 4];
        let flags = (1..).find(|k| r.flags.0 >> (7 * k) == 0).unwrap();
        let chambers = body.len() - flags - 72..body.len() - flags;
        let v5: Vec<u8> = body[..chambers.start]
            .iter()
            .chain(&body[chambers.end..])
            .copied()
            .collect();
        raw_frame(&v5)
    }

    /// A recording made with a protocol-5 board (before the report carried
    /// the chambers' characteristics) replays: its reports with every field
    /// as sent, the chambers NaN and flagged `chambers_unread`; a live link
    /// refuses that board.
    #[test]
    fn a_replayed_protocol_5_recording_is_read_with_its_chambers_unread() {
        use hammer_wire::{CycleReport, Flags};
        let sent: Vec<CycleReport> = (0..2)
            .map(|seq| CycleReport {
                seq,
                t_impact_us: 47_000 * u64::from(seq + 1),
                friction_n: 10.25,
                friction_uncertainty_n: 1.125,
                impact_energy_j: 4.5,
                drift_score: 0.5,
                calibration_hash: 0xDEAD_BEEF,
                flags: Flags::ACCEL_ZERO_SHIFT,
                ..Default::default()
            })
            .collect();
        let config = hammer_wire::DeviceConfig::from(&hammer_estimator::Config::default());
        let stream = |i: &mut Ingest| {
            let mut out = vec![];
            let mut frames = vec![frame(&hello(5)), frame(&DeviceMsg::Config(config))];
            frames.extend(sent.iter().map(protocol5_report));
            for bytes in frames {
                i.feed(1, &bytes, &mut |e| out.push(e.event));
            }
            out.into_iter()
                .filter(|e| !matches!(e, Event::Stats(_)))
                .collect::<Vec<_>>()
        };
        let ev = stream(&mut Ingest::for_replay());
        assert!(matches!(&ev[0], Event::Device(i) if i.protocol_version == 5), "{ev:?}");
        // The configuration as it is (protocol 6 left it unchanged; NaN
        // supply pressure, so compared by its hash).
        let Event::Msg(DeviceMsg::Config(c)) = &ev[1] else {
            panic!("{ev:?}")
        };
        assert_eq!(hammer_wire::config_hash(c), hammer_wire::config_hash(&config));
        assert_eq!(ev.len(), 4, "{ev:?}");
        for (e, s) in ev[2..].iter().zip(&sent) {
            let Event::Msg(DeviceMsg::Report(r)) = e else {
                panic!("{ev:?}")
            };
            let mut expected = *s;
            expected.mark_chambers_unread();
            assert_eq!(*r, expected);
            assert!(r.front_feed_s.is_nan() && r.rear_feed_area_uncertainty_m2.is_nan());
            assert!(r.flags.contains(Flags::CHAMBERS_UNREAD | Flags::ACCEL_ZERO_SHIFT));
            assert!(r.is_valid(), "unread chambers do not invalidate a cycle");
        }
        // Live, a protocol-5 board is refused at its Hello, and its reports
        // (shorter than this protocol's) are not read as this protocol's.
        let ev = stream(&mut Ingest::new());
        assert!(matches!(ev[0], Event::VersionMismatch { device: 5 }), "{ev:?}");
        assert!(!ev.iter().any(|e| matches!(e, Event::Msg(_))), "{ev:?}");
    }

    #[test]
    fn another_protocol_stops_interpretation() {
        let mut i = Ingest::new();
        let ev = run(&mut i, &[report(0), hello(PROTOCOL_VERSION + 1), report(1)]);
        assert_eq!(
            ev,
            vec![Event::VersionMismatch {
                device: PROTOCOL_VERSION + 1
            }]
        );
        assert_eq!(i.stats().frames, 3);
    }

    #[test]
    fn errors_are_counted_by_kind() {
        let mut i = Ingest::new();
        let mut f = frame(&hello(PROTOCOL_VERSION));
        let mid = f.len() / 2;
        f[mid] ^= 0x01;
        let mut out = vec![];
        i.feed(1, &f, &mut |e| out.push(e.event));
        i.feed(1, &[0x42; 1000], &mut |e| out.push(e.event));
        i.feed(1, &[0], &mut |e| out.push(e.event));
        let s = *i.stats();
        assert_eq!(s.frames, 0);
        assert_eq!(s.crc_errors + s.cobs_errors, 1);
        assert_eq!(s.oversize, 1);
    }
}
