//! The host end of the wire protocol over any byte stream (a serial port, the
//! emulated board's TCP socket, a pipe).

use std::io::{self, Read, Write};
use std::time::{Duration, Instant};

use hammer_wire::{encode, DecodeError, Decoder, DecoderStats, DeviceMsg, HostMsg, MAX_FRAME};

/// A framed, checksummed connection to a device.
pub struct Link<S> {
    stream: S,
    dec: Decoder<MAX_FRAME>,
    pending: std::collections::VecDeque<DeviceMsg>,
    /// Frames that failed to decode, in arrival order (for tests and logs).
    pub errors: Vec<DecodeError>,
    pub frames_sent: u64,
}

impl<S: Read + Write> Link<S> {
    pub fn new(stream: S) -> Self {
        Self {
            stream,
            dec: Decoder::new(),
            pending: Default::default(),
            errors: vec![],
            frames_sent: 0,
        }
    }

    pub fn stream(&mut self) -> &mut S {
        &mut self.stream
    }

    pub fn stats(&self) -> DecoderStats {
        self.dec.stats
    }

    pub fn send(&mut self, msg: &HostMsg) -> io::Result<()> {
        let mut buf = [0u8; MAX_FRAME];
        let n = encode(msg, &mut buf).map_err(|_| io::Error::new(io::ErrorKind::InvalidInput, "message too large"))?;
        self.stream.write_all(&buf[..n])?;
        self.frames_sent += 1;
        Ok(())
    }

    /// Raw bytes, for fault injection.
    pub fn send_raw(&mut self, bytes: &[u8]) -> io::Result<()> {
        self.stream.write_all(bytes)
    }

    /// Feeds bytes read elsewhere (a reader thread, a log replay) into the decoder.
    pub fn feed(&mut self, bytes: &[u8]) {
        for &b in bytes {
            match self.dec.push::<DeviceMsg>(b) {
                Some(Ok(m)) => self.pending.push_back(m),
                Some(Err(e)) => self.errors.push(e),
                None => {}
            }
        }
    }

    /// The next message, waiting at most `timeout`. `Ok(None)` on timeout;
    /// the stream must have a read timeout set (or return `WouldBlock`).
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
}
