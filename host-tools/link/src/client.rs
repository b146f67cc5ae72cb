//! The host's one protocol client: frames in and out over any byte stream (a
//! serial port, the emulated board's TCP socket, a pipe), the handshake with
//! its version check, commands and their `Ack`/`Rejected`, and the decoded
//! device messages with frame-error and report-sequence accounting.
//!
//! Two layers, so every tool reads the link the same way:
//! - [`Inbound`], sans-IO: bytes in, [`Incoming`] out (a message, or a frame
//!   error with where its frame began): the host's one decoder. [`SeqCheck`]
//!   is its one report-sequence check, applied where messages are accepted.
//! - [`Client`], blocking over a stream: `hammer demo`, `hammer capture` and
//!   the end-to-end tests. The monitor's reader thread owns its port itself
//!   (it logs every raw byte, reconnects, and shares its event core with
//!   `hammer replay`), and drives the same [`Inbound`] and [`SeqCheck`] with
//!   [`hello`], [`hello_reply`] and [`write_frame`].

use std::collections::VecDeque;
use std::io::{self, Read, Write};
use std::time::{Duration, Instant};

use hammer_wire::{
    encode, CommandKind, DecodeError, Decoder, DecoderStats, DeviceInfo, DeviceMsg, HostMsg, RejectReason, MAX_FRAME,
    PROTOCOL_VERSION,
};

/// Pause between unanswered `Hello`s in [`Client::handshake`]: the board may still be booting.
pub const HANDSHAKE_RETRY: Duration = Duration::from_secs(2);

#[derive(Debug, thiserror::Error)]
pub enum ClientError {
    #[error(transparent)]
    Io(#[from] io::Error),
    #[error("device speaks protocol {device}, this tool {PROTOCOL_VERSION}: update one of them")]
    ProtocolMismatch { device: u16 },
    #[error("no answer to the handshake in {} s", .0.as_secs())]
    NoHandshake(Duration),
    #[error("no answer to {command:?} in {} s", .timeout.as_secs())]
    Timeout { command: CommandKind, timeout: Duration },
    #[error("the device rejected {command:?}: {reason:?}")]
    Rejected { command: CommandKind, reason: RejectReason },
}

/// The handshake's opening message.
pub fn hello() -> HostMsg {
    HostMsg::Hello {
        protocol_version: PROTOCOL_VERSION,
    }
}

/// What a message says about the handshake: `None` if nothing, `Ok` for a
/// device of this protocol, `Err(device's version)` for another protocol (a
/// `Hello` of another version, or the device rejecting ours).
pub fn hello_reply(m: &DeviceMsg) -> Option<Result<&DeviceInfo, u16>> {
    match m {
        DeviceMsg::Hello(info) if info.protocol_version != PROTOCOL_VERSION => Some(Err(info.protocol_version)),
        DeviceMsg::Hello(info) => Some(Ok(info)),
        DeviceMsg::Rejected {
            command: CommandKind::Hello,
            reason: RejectReason::ProtocolMismatch { device },
        } => Some(Err(*device)),
        _ => None,
    }
}

/// Which command a host message is, as the device names it in `Ack` and `Rejected`.
pub fn command_kind(msg: &HostMsg) -> CommandKind {
    match msg {
        HostMsg::Hello { .. } => CommandKind::Hello,
        HostMsg::GetConfig => CommandKind::GetConfig,
        HostMsg::SetConfig(_) => CommandKind::SetConfig,
        HostMsg::Tare { .. } => CommandKind::Tare,
        HostMsg::StartCapture { .. } => CommandKind::StartCapture,
        HostMsg::GetStatus => CommandKind::GetStatus,
        HostMsg::ResetWear => CommandKind::ResetWear,
        HostMsg::GetWear => CommandKind::GetWear,
        HostMsg::RestoreWear(_) => CommandKind::RestoreWear,
        HostMsg::Samples(_) => CommandKind::Samples,
        HostMsg::MeasureCodes { .. } => CommandKind::MeasureCodes,
    }
}

/// The device's verdict on `command`, if `m` is one: `Ok` for its `Ack`, `Err` for its `Rejected`.
pub fn reply_to(command: CommandKind, m: &DeviceMsg) -> Option<Result<(), RejectReason>> {
    match m {
        DeviceMsg::Ack(c) if *c == command => Some(Ok(())),
        DeviceMsg::Rejected { command: c, reason } if *c == command => Some(Err(*reason)),
        _ => None,
    }
}

/// One frame out. No `flush`: on a serial port that is `tcdrain`, waiting
/// for the device to take the bytes, which a stalled board never does.
pub fn write_frame<W: Write + ?Sized>(w: &mut W, msg: &HostMsg) -> io::Result<()> {
    let mut buf = [0u8; MAX_FRAME];
    let n = encode(msg, &mut buf).map_err(|_| io::Error::new(io::ErrorKind::InvalidInput, "message too large"))?;
    w.write_all(&buf[..n])
}

/// A report sequence number that was not the previous one plus one.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SeqGap {
    pub expected: u32,
    pub got: u32,
}

impl SeqGap {
    /// Reports missing in the gap (where the numbers tell: none if the count went back).
    pub fn lost(&self) -> u64 {
        u64::from(self.got.saturating_sub(self.expected))
    }
}

/// Checks report sequence numbers for gaps.
#[derive(Debug, Clone, Copy, Default)]
pub struct SeqCheck {
    last: Option<u32>,
}

impl SeqCheck {
    pub fn next(&mut self, seq: u32) -> Option<SeqGap> {
        let gap = self
            .last
            .map(|p| p.wrapping_add(1))
            .and_then(|expected| (seq != expected).then_some(SeqGap { expected, got: seq }));
        self.last = Some(seq);
        gap
    }
}

/// What arrived on the link, in order.
#[derive(Debug, Clone, PartialEq)]
pub enum Incoming {
    Msg(DeviceMsg),
    /// A frame that did not decode; `frame_start` is the stream offset where it began.
    FrameError {
        kind: DecodeError,
        frame_start: u64,
    },
}

/// The host's decoding core: frames and byte offsets. Knows nothing of ports or clocks.
pub struct Inbound {
    dec: Decoder<MAX_FRAME>,
    /// The protocol the bytes are read in: this host's, or an older one a
    /// replayed recording's handshake named ([`Inbound::read_as`]).
    protocol: u16,
    /// The chambers an older protocol's configuration is read with.
    chambers: hammer_wire::DeviceConfig,
    /// Bytes fed so far.
    bytes: u64,
    /// Stream offset just after the last delimiter: where the frame now being
    /// received began.
    frame_start: u64,
}

impl Default for Inbound {
    fn default() -> Self {
        Self::new()
    }
}

impl Inbound {
    pub fn new() -> Self {
        Self {
            dec: Decoder::new(),
            protocol: PROTOCOL_VERSION,
            chambers: hammer_wire::DeviceConfig::from(&hammer_estimator::Config::default()),
            bytes: 0,
            frame_start: 0,
        }
    }

    /// Reads what follows as `protocol` sent it, if this host can
    /// (`hammer_wire::legacy::READABLE_OLDER`); an older configuration
    /// gets the default chambers (the paper's hammer). False: it cannot.
    pub fn read_as(&mut self, protocol: u16) -> bool {
        let readable = protocol == PROTOCOL_VERSION || hammer_wire::legacy::READABLE_OLDER.contains(&protocol);
        if readable {
            self.protocol = protocol;
        }
        readable
    }

    /// A new connection: a frame cut by the disconnect must not swallow the
    /// first new one.
    pub fn reopen(&mut self) {
        self.dec = Decoder::new();
        self.frame_start = self.bytes;
    }

    pub fn stats(&self) -> DecoderStats {
        self.dec.stats
    }

    /// Bytes fed so far.
    pub fn bytes(&self) -> u64 {
        self.bytes
    }

    /// Stream offset where the frame now being received began.
    pub fn frame_start(&self) -> u64 {
        self.frame_start
    }

    /// Feeds bytes as they arrived; `out` sees what they completed, in order.
    pub fn feed(&mut self, bytes: &[u8], out: &mut dyn FnMut(Incoming)) {
        let first = self.bytes;
        self.bytes += bytes.len() as u64;
        for (i, &b) in bytes.iter().enumerate() {
            let (protocol, chambers) = (self.protocol, &self.chambers);
            match self
                .dec
                .push_with(b, |body| hammer_wire::legacy::device_msg(body, protocol, chambers))
            {
                None => {}
                Some(Ok(m)) => out(Incoming::Msg(m)),
                Some(Err(kind)) => out(Incoming::FrameError {
                    kind,
                    frame_start: self.frame_start,
                }),
            }
            if b == 0 {
                self.frame_start = first + i as u64 + 1;
            }
        }
    }
}

/// A framed, checksummed connection to a device.
pub struct Client<S> {
    stream: S,
    inbound: Inbound,
    seq: SeqCheck,
    pending: VecDeque<DeviceMsg>,
    /// Frames that failed to decode, in arrival order (for tests and logs).
    pub errors: Vec<DecodeError>,
    pub frames_sent: u64,
    /// Report sequence gaps seen, and the reports missing in them.
    pub seq_gaps: u64,
    pub lost_reports: u64,
}

impl<S: Read + Write> Client<S> {
    /// The stream must time out its reads (or return `WouldBlock`).
    pub fn new(stream: S) -> Self {
        Self {
            stream,
            inbound: Inbound::new(),
            seq: SeqCheck::default(),
            pending: Default::default(),
            errors: vec![],
            frames_sent: 0,
            seq_gaps: 0,
            lost_reports: 0,
        }
    }

    pub fn stream(&mut self) -> &mut S {
        &mut self.stream
    }

    pub fn stats(&self) -> DecoderStats {
        self.inbound.stats()
    }

    /// Frames that did not decode (garbage, corruption, oversize).
    pub fn frame_errors(&self) -> usize {
        self.errors.len()
    }

    pub fn send(&mut self, msg: &HostMsg) -> io::Result<()> {
        write_frame(&mut self.stream, msg)?;
        self.frames_sent += 1;
        Ok(())
    }

    /// Raw bytes, for fault injection.
    pub fn send_raw(&mut self, bytes: &[u8]) -> io::Result<()> {
        self.stream.write_all(bytes)
    }

    /// Feeds bytes read elsewhere (a reader thread, a log replay) into the decoder.
    pub fn feed(&mut self, bytes: &[u8]) {
        let (pending, errors, seq) = (&mut self.pending, &mut self.errors, &mut self.seq);
        let (gaps, lost) = (&mut self.seq_gaps, &mut self.lost_reports);
        self.inbound.feed(bytes, &mut |i| match i {
            Incoming::Msg(m) => {
                if let DeviceMsg::Report(r) = &m {
                    if let Some(g) = seq.next(r.seq) {
                        *gaps += 1;
                        *lost += g.lost();
                    }
                }
                pending.push_back(m)
            }
            Incoming::FrameError { kind, .. } => errors.push(kind),
        });
    }

    /// The next message, waiting at most `timeout`. `Ok(None)` on timeout.
    pub fn recv(&mut self, timeout: Duration) -> io::Result<Option<DeviceMsg>> {
        let deadline = Instant::now() + timeout;
        let mut buf = [0u8; 4096];
        loop {
            if let Some(m) = self.pending.pop_front() {
                return Ok(Some(m));
            }
            if Instant::now() >= deadline {
                return Ok(None);
            }
            match self.stream.read(&mut buf) {
                Ok(0) => return Err(io::Error::new(io::ErrorKind::UnexpectedEof, "link closed")),
                Ok(n) => self.feed(&buf[..n]),
                Err(e) if matches!(e.kind(), io::ErrorKind::WouldBlock | io::ErrorKind::TimedOut) => {}
                Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
                Err(e) => return Err(e),
            }
        }
    }

    /// The messages as they arrive, until none came for `idle`.
    pub fn messages(&mut self, idle: Duration) -> impl Iterator<Item = io::Result<DeviceMsg>> + '_ {
        std::iter::from_fn(move || self.recv(idle).transpose())
    }

    /// Waits for the first message `pick` accepts; others are returned too, in order.
    pub fn recv_until<T>(
        &mut self,
        timeout: Duration,
        mut pick: impl FnMut(&DeviceMsg) -> Option<T>,
    ) -> io::Result<(Option<T>, Vec<DeviceMsg>)> {
        let deadline = Instant::now() + timeout;
        let mut seen = vec![];
        while let Some(left) = deadline.checked_duration_since(Instant::now()) {
            match self.recv(left)? {
                Some(m) => {
                    if let Some(t) = pick(&m) {
                        seen.push(m);
                        return Ok((Some(t), seen));
                    }
                    seen.push(m);
                }
                None => break,
            }
        }
        Ok((None, seen))
    }

    /// Sends `msg` and waits for the first answer `pick` accepts (`None` on timeout).
    pub fn request<T>(
        &mut self,
        msg: &HostMsg,
        timeout: Duration,
        pick: impl FnMut(&DeviceMsg) -> Option<T>,
    ) -> io::Result<Option<T>> {
        self.send(msg)?;
        Ok(self.recv_until(timeout, pick)?.0)
    }

    /// Sends a command and waits for its `Ack`; returns every message up to it.
    pub fn command(&mut self, msg: &HostMsg, timeout: Duration) -> Result<Vec<DeviceMsg>, ClientError> {
        let command = command_kind(msg);
        self.send(msg)?;
        match self.recv_until(timeout, |m| reply_to(command, m))? {
            (Some(Ok(())), seen) => Ok(seen),
            (Some(Err(reason)), _) => Err(ClientError::Rejected { command, reason }),
            (None, _) => Err(ClientError::Timeout { command, timeout }),
        }
    }

    /// The handshake, retried: the board may still be booting. Returns who
    /// the device is and every message that came with the answer.
    pub fn handshake(&mut self, timeout: Duration) -> Result<(DeviceInfo, Vec<DeviceMsg>), ClientError> {
        let deadline = Instant::now() + timeout;
        while Instant::now() < deadline {
            self.send(&hello())?;
            let (reply, seen) = self.recv_until(HANDSHAKE_RETRY, |m| hello_reply(m).map(|r| r.cloned()))?;
            match reply {
                Some(Ok(info)) => return Ok((info, seen)),
                Some(Err(device)) => return Err(ClientError::ProtocolMismatch { device }),
                None => {}
            }
        }
        Err(ClientError::NoHandshake(timeout))
    }
}

/// Device messages as a test device sends them, for the client's and the
/// monitor's tests (the `fixtures` feature, for the crates above).
#[cfg(any(test, feature = "fixtures"))]
pub mod fixtures {
    use hammer_wire::{encode, CycleReport, DeviceInfo, DeviceMsg, MAX_FRAME};

    pub fn frame(m: &DeviceMsg) -> Vec<u8> {
        let mut buf = [0u8; MAX_FRAME];
        let n = encode(m, &mut buf).unwrap();
        buf[..n].to_vec()
    }

    pub fn info(v: u16) -> DeviceInfo {
        DeviceInfo {
            protocol_version: v,
            firmware_version: [1, 2, 3],
            board: b"fake".iter().copied().collect(),
            config_hash: 7,
        }
    }

    pub fn report(seq: u32) -> DeviceMsg {
        DeviceMsg::Report(CycleReport {
            seq,
            ..Default::default()
        })
    }
}

#[cfg(test)]
mod tests {
    use super::fixtures::{frame, info, report};
    use super::*;
    use std::sync::{Arc, Mutex};

    /// A scripted device in memory: each host frame it decodes is answered
    /// with the bytes `script` returns; reads with nothing to say are
    /// `WouldBlock`, as a port with a read timeout.
    /// The bytes a fake device answers a host message with.
    type Script = Box<dyn FnMut(&HostMsg) -> Vec<u8>>;

    struct FakeDevice {
        dec: Decoder<MAX_FRAME>,
        out: VecDeque<u8>,
        script: Script,
        received: Arc<Mutex<Vec<HostMsg>>>,
    }

    impl FakeDevice {
        fn new(script: impl FnMut(&HostMsg) -> Vec<u8> + 'static) -> (Self, Arc<Mutex<Vec<HostMsg>>>) {
            let received = Arc::new(Mutex::new(vec![]));
            let dev = Self {
                dec: Decoder::new(),
                out: VecDeque::new(),
                script: Box::new(script),
                received: received.clone(),
            };
            (dev, received)
        }
    }

    impl Read for FakeDevice {
        fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
            if self.out.is_empty() {
                std::thread::sleep(Duration::from_millis(1));
                return Err(io::ErrorKind::WouldBlock.into());
            }
            let n = buf.len().min(self.out.len());
            for (b, o) in buf.iter_mut().zip(self.out.drain(..n)) {
                *b = o;
            }
            Ok(n)
        }
    }

    impl Write for FakeDevice {
        fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
            for &b in buf {
                if let Some(Ok(m)) = self.dec.push::<HostMsg>(b) {
                    let answer = (self.script)(&m);
                    self.out.extend(answer);
                    self.received.lock().unwrap().push(m);
                }
            }
            Ok(buf.len())
        }
        fn flush(&mut self) -> io::Result<()> {
            Ok(())
        }
    }

    #[test]
    fn a_good_handshake() {
        let (dev, received) = FakeDevice::new(|m| match m {
            HostMsg::Hello { .. } => [frame(&report(0)), frame(&DeviceMsg::Hello(info(PROTOCOL_VERSION)))].concat(),
            _ => vec![],
        });
        let mut c = Client::new(dev);
        let (i, seen) = c.handshake(Duration::from_secs(5)).unwrap();
        assert_eq!(i, info(PROTOCOL_VERSION));
        assert_eq!(seen, vec![report(0), DeviceMsg::Hello(info(PROTOCOL_VERSION))]);
        assert_eq!(*received.lock().unwrap(), vec![hello()]);
        assert_eq!(c.frame_errors(), 0);
    }

    #[test]
    fn a_device_of_another_protocol_is_refused() {
        let other = PROTOCOL_VERSION + 1;
        let (dev, _) = FakeDevice::new(move |m| match m {
            HostMsg::Hello { .. } => frame(&DeviceMsg::Rejected {
                command: CommandKind::Hello,
                reason: RejectReason::ProtocolMismatch { device: other },
            }),
            _ => vec![],
        });
        let err = Client::new(dev).handshake(Duration::from_secs(5)).unwrap_err();
        assert!(
            matches!(err, ClientError::ProtocolMismatch { device } if device == other),
            "{err:?}"
        );
        assert_eq!(
            err.to_string(),
            format!("device speaks protocol {other}, this tool {PROTOCOL_VERSION}: update one of them")
        );
        // A Hello of another version says the same.
        let (dev, _) = FakeDevice::new(move |_| frame(&DeviceMsg::Hello(info(other))));
        let err = Client::new(dev).handshake(Duration::from_secs(5)).unwrap_err();
        assert!(
            matches!(err, ClientError::ProtocolMismatch { device } if device == other),
            "{err:?}"
        );
    }

    #[test]
    fn a_silent_device_times_out() {
        let (dev, received) = FakeDevice::new(|_| vec![]);
        let mut c = Client::new(dev);
        let t = Instant::now();
        let err = c.command(&HostMsg::ResetWear, Duration::from_millis(100)).unwrap_err();
        assert!(t.elapsed() >= Duration::from_millis(100));
        assert!(
            matches!(
                err,
                ClientError::Timeout {
                    command: CommandKind::ResetWear,
                    ..
                }
            ),
            "{err:?}"
        );
        assert_eq!(*received.lock().unwrap(), vec![HostMsg::ResetWear]);
        let err = c.handshake(Duration::from_millis(100)).unwrap_err();
        assert_eq!(err.to_string(), "no answer to the handshake in 0 s");
    }

    #[test]
    fn commands_are_acked_or_rejected() {
        let (dev, _) = FakeDevice::new(|m| match m {
            HostMsg::ResetWear => [frame(&report(4)), frame(&DeviceMsg::Ack(CommandKind::ResetWear))].concat(),
            _ => frame(&DeviceMsg::Rejected {
                command: command_kind(m),
                reason: RejectReason::Busy,
            }),
        });
        let mut c = Client::new(dev);
        let seen = c.command(&HostMsg::ResetWear, Duration::from_secs(5)).unwrap();
        assert_eq!(seen, vec![report(4), DeviceMsg::Ack(CommandKind::ResetWear)]);
        let err = c
            .command(&HostMsg::Tare { samples: 10 }, Duration::from_secs(5))
            .unwrap_err();
        assert!(
            matches!(
                err,
                ClientError::Rejected {
                    command: CommandKind::Tare,
                    reason: RejectReason::Busy
                }
            ),
            "{err:?}"
        );
    }

    #[test]
    fn garbage_between_frames_counts_as_frame_errors_and_gaps_are_counted() {
        let (dev, _) = FakeDevice::new(|_| {
            let mut corrupt = frame(&report(2));
            let mid = corrupt.len() / 2;
            corrupt[mid] = corrupt[mid].wrapping_add(1).max(1); // any other byte but a delimiter
            [
                frame(&report(0)),
                b"\x13\x37garbage".to_vec(),
                frame(&report(1)),
                vec![0x42; 1000],
                frame(&report(2)),
                corrupt,
                frame(&report(5)),
            ]
            .concat()
        });
        let mut c = Client::new(dev);
        c.send(&HostMsg::GetStatus).unwrap();
        let got: Vec<DeviceMsg> = c.messages(Duration::from_millis(50)).map(Result::unwrap).collect();
        assert_eq!(got, vec![report(0), report(1), report(2), report(5)]);
        assert_eq!(c.frame_errors(), 3, "{:?}", c.errors);
        assert_eq!(c.errors[1], DecodeError::Oversize);
        assert_eq!((c.seq_gaps, c.lost_reports), (1, 2));
        assert_eq!(c.stats().frames, 4);
    }
}
