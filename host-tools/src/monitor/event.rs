//! What the reader (or a replay) tells the screen and the logs, stamped with
//! the host time the bytes arrived. One wording of each event, shared by the
//! event panel, headless output and `link.log`.

use std::time::{SystemTime, UNIX_EPOCH};

use hammer_wire::{config_hash, DecodeError, DeviceInfo, DeviceMsg, PROTOCOL_VERSION};

/// Host-side link counters. Sent as a whole snapshot, so a screen that
/// skipped events still shows the right totals.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct LinkStats {
    pub connected: bool,
    pub bytes: u64,
    /// Frames that decoded to a message.
    pub frames: u64,
    pub crc_errors: u64,
    pub cobs_errors: u64,
    /// Intact frames that are no known message.
    pub decode_errors: u64,
    pub oversize: u64,
    /// Report sequence numbers that were not the previous one plus one.
    pub seq_gaps: u64,
    /// Reports missing in those gaps (where the numbers tell).
    pub lost_reports: u64,
    pub reports: u64,
    pub reconnects: u32,
    /// Messages dropped before the handshake told whether they can be read.
    pub unhandshaken_dropped: u64,
    pub last_frame_us: Option<u64>,
    /// What the log size cap kept out of the logs (filled in by the reader,
    /// which owns the logger).
    pub unlogged: super::log::Unlogged,
}

impl LinkStats {
    pub fn frame_errors(&self) -> u64 {
        self.crc_errors + self.cobs_errors + self.decode_errors + self.oversize
    }
}

#[derive(Debug, Clone, PartialEq)]
pub enum Event {
    /// The port could not be opened (sent once per outage, not every retry).
    ConnectFailed {
        port: String,
        error: String,
    },
    /// The link is open. `outage_us` is how long it was down (not on the first connect).
    Connected {
        port: String,
        reconnects: u32,
        lost_at_us: Option<u64>,
        outage_us: Option<u64>,
    },
    Disconnected {
        port: String,
        reason: String,
    },
    /// The handshake answered with our protocol version: data can be read.
    Device(DeviceInfo),
    /// The device speaks another protocol: nothing more is interpreted.
    VersionMismatch {
        device: u16,
    },
    /// A message from a device that passed the handshake.
    Msg(DeviceMsg),
    FrameError {
        kind: DecodeError,
        total: u64,
        /// Where the bad frame began in the received byte stream (every
        /// connection's bytes end to end, as frames.bin records them), so a
        /// replay can name the spot in the file.
        stream_offset: u64,
    },
    SeqGap {
        expected: u32,
        got: u32,
    },
    Stats(LinkStats),
    /// A window of raw captures read against the commissioning record
    /// (`--reference`: [`crate::drift`]).
    Drift(Box<crate::drift::Drift>),
    /// Anything else worth a line: handshake retries, logging trouble, replay notes.
    Note(String),
    /// A replay reached the end of its file.
    End,
}

#[derive(Debug, Clone, PartialEq)]
pub struct Stamped {
    /// Host time, microseconds since the Unix epoch.
    pub t_us: u64,
    pub event: Event,
}

impl Stamped {
    pub fn now(event: Event) -> Self {
        Self { t_us: now_us(), event }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum Severity {
    Info,
    Warn,
    Error,
}

pub fn now_us() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_micros().min(u64::MAX as u128) as u64)
}

pub fn decode_error_name(e: DecodeError) -> &'static str {
    match e {
        DecodeError::Crc => "CRC mismatch",
        DecodeError::Cobs => "bad COBS (truncated or corrupted frame)",
        DecodeError::Message => "undecodable message",
        DecodeError::Oversize => "oversize frame",
    }
}

pub fn board_name(info: &DeviceInfo) -> String {
    String::from_utf8_lossy(&info.board).into_owned()
}

pub fn firmware_version(v: [u8; 3]) -> String {
    format!("{}.{}.{}", v[0], v[1], v[2])
}

/// The line for an event, or `None` for events that are not news (data, counters).
pub fn describe(ev: &Event) -> Option<(Severity, String)> {
    use Severity::*;
    Some(match ev {
        Event::ConnectFailed { port, error } => (Warn, format!("cannot open {port}: {error}; retrying every 0.5 s")),
        Event::Connected {
            port,
            reconnects,
            lost_at_us,
            outage_us,
        } => match (lost_at_us, outage_us) {
            (Some(lost), Some(gap)) => (
                Warn,
                format!(
                    "reconnected to {port} (reconnect {reconnects}): link was down {:.3} s, from {} to {}",
                    *gap as f64 * 1e-6,
                    rfc3339(*lost),
                    rfc3339(lost + gap)
                ),
            ),
            _ => (Info, format!("connected to {port}")),
        },
        Event::Disconnected { port, reason } => (Error, format!("disconnected from {port}: {reason}")),
        Event::Device(info) => (
            Info,
            format!(
                "device: board {}, firmware {}, protocol {}, config {:08x}",
                board_name(info),
                firmware_version(info.firmware_version),
                info.protocol_version,
                info.config_hash
            ),
        ),
        Event::VersionMismatch { device } => (
            Error,
            format!(
                "PROTOCOL MISMATCH: the device speaks protocol {device}, this host speaks {PROTOCOL_VERSION}; \
                 not interpreting its data (update the firmware or the host tools)"
            ),
        ),
        Event::FrameError { kind, total, .. } => (
            Warn,
            format!(
                "frame error: {} ({total} frame errors so far)",
                decode_error_name(*kind)
            ),
        ),
        Event::SeqGap { expected, got } => {
            if got > expected {
                (
                    Warn,
                    format!(
                        "report sequence gap: expected {expected}, got {got} ({} lost)",
                        got - expected
                    ),
                )
            } else {
                (
                    Warn,
                    format!("report sequence restarted: expected {expected}, got {got} (device reset?)"),
                )
            }
        }
        Event::Msg(DeviceMsg::Rejected { command, reason }) => {
            (Warn, format!("device rejected {command:?}: {reason:?}"))
        }
        Event::Msg(DeviceMsg::Alarm(a)) => (
            Error,
            format!(
                "alarm {:?} at cycle {} (drift score {:.2}, flags {})",
                a.kind,
                a.cycle_seq,
                a.drift_score,
                flag_list(a.flags)
            ),
        ),
        Event::Msg(DeviceMsg::Config(c)) => (
            Info,
            format!(
                "device config: {:.0} S/s, hash {:08x}",
                c.sample_rate_hz,
                config_hash(c)
            ),
        ),
        Event::Drift(d) => (if d.alarm() { Error } else { Info }, d.line()),
        Event::Note(s) => (Info, s.clone()),
        Event::End => (Info, "end of recording".into()),
        Event::Msg(_) | Event::Stats(_) => return None,
    })
}

pub use crate::records::flag_list;

/// RFC 3339 in UTC with microseconds, e.g. `2025-03-01T14:03:22.123456Z`.
pub fn rfc3339(t_us: u64) -> String {
    let secs = t_us / 1_000_000;
    let micros = t_us % 1_000_000;
    let (y, m, d) = civil_from_days((secs / 86_400) as i64);
    let s = secs % 86_400;
    format!(
        "{y:04}-{m:02}-{d:02}T{:02}:{:02}:{:02}.{micros:06}Z",
        s / 3600,
        s / 60 % 60,
        s % 60
    )
}

/// `HH:MM:SS` of the UTC day: short enough for the event panel.
pub fn clock(t_us: u64) -> String {
    let s = t_us / 1_000_000 % 86_400;
    format!("{:02}:{:02}:{:02}", s / 3600, s / 60 % 60, s % 60)
}

/// Days since 1970-01-01 to a proleptic Gregorian date (H. Hinnant's algorithm).
fn civil_from_days(z: i64) -> (i64, u32, u32) {
    let z = z + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z.rem_euclid(146_097);
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = (doy - (153 * mp + 2) / 5 + 1) as u32;
    let m = if mp < 10 { mp + 3 } else { mp - 9 } as u32;
    let y = yoe + era * 400 + i64::from(m <= 2);
    (y, m, d)
}

/// At most `per_s` lines a second of one kind, so line noise cannot flood a
/// log or a terminal; the rest are counted and summed up in the next line.
#[derive(Debug, Clone)]
pub struct Limiter {
    per_s: u32,
    window_us: u64,
    in_window: u32,
    suppressed: u64,
}

impl Limiter {
    pub fn new(per_s: u32) -> Self {
        Self {
            per_s,
            window_us: 0,
            in_window: 0,
            suppressed: 0,
        }
    }

    /// `Some(n)` when a line may be written now (`n` lines were suppressed before it).
    pub fn allow(&mut self, t_us: u64) -> Option<u64> {
        let window = t_us / 1_000_000;
        if window != self.window_us {
            self.window_us = window;
            self.in_window = 0;
        }
        if self.in_window < self.per_s {
            self.in_window += 1;
            Some(std::mem::take(&mut self.suppressed))
        } else {
            self.suppressed += 1;
            None
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use hammer_wire::Flags;

    #[test]
    fn rfc3339_matches_known_dates() {
        assert_eq!(rfc3339(0), "1970-01-01T00:00:00.000000Z");
        assert_eq!(rfc3339(951_782_400_000_001), "2000-02-29T00:00:00.000001Z");
        assert_eq!(rfc3339(1_735_689_599_999_999), "2024-12-31T23:59:59.999999Z");
        assert_eq!(clock(1_735_689_599_999_999), "23:59:59");
    }

    #[test]
    fn limiter_counts_what_it_holds_back() {
        let mut l = Limiter::new(2);
        assert_eq!(l.allow(10), Some(0));
        assert_eq!(l.allow(20), Some(0));
        assert_eq!(l.allow(30), None);
        assert_eq!(l.allow(40), None);
        assert_eq!(l.allow(1_000_001), Some(2));
    }

    #[test]
    fn flags_read_as_names() {
        assert_eq!(flag_list(Flags(0)), "-");
        assert_eq!(flag_list(Flags((1 << 13) | 1)), "rear_saturated|drift_alarm");
        // Every bit has a name now (no_impact took the last one).
        assert_eq!(flag_list(Flags(1 << 15)), "no_impact");
    }
}
