//! `--log DIR`: what a bench run leaves behind.
//!
//! - `cycles.csv`: one row per report the dashboard interpreted, every field
//!   of [`Report`] at full precision, with the host's arrival time (RFC 3339
//!   and Unix seconds) beside the device's `t_impact_s`.
//! - `link.log`: one line per link event (connects, disconnects with the
//!   outage's start and end, handshake, protocol mismatch, sequence gaps,
//!   frame errors, rejections, alarms), each starting with an RFC 3339 time.
//! - `frames.bin`: every byte received, as it arrived, for `hammer replay`.
//!   An 8-byte magic `HMFRAMES`, then records, all little-endian:
//!   `[u64 host_time_us][u32 len][len bytes]`, host time in microseconds
//!   since the Unix epoch. `len` = [`OPENED`] marks a (re)connect and
//!   [`LOST`] a disconnect; no bytes follow a marker. Chunks are at most
//!   [`MAX_CHUNK`] bytes, so anything longer is corruption.
//!
//! Existing files are appended to (a second run adds a new connection to
//! frames.bin; a line torn by a crash or a full disk is cut back first).
//! The directory is created 0700 and the files 0600, opened without
//! following symlinks; a directory another user owns or can write is
//! refused ([`crate::private_files`]). Everything is flushed every [`FLUSH_EVERY`] and on each
//! disconnect, so a crash loses at most that much.
//!
//! Size cap (`--log-max-mb`, [`DEFAULT_MAX_MB`] by default, over the three
//! files together, what they held before included): a device flooding the
//! link filled 774 MB in 20 s. When the next write would pass the cap,
//! logging *stops* rather than rotating: frames.bin stays one replayable
//! recording from its start, and nothing already logged is deleted. The stop
//! is never silent: link.log gets a line saying so (written past the cap),
//! from then on what is not logged is counted ([`Unlogged`]: received bytes,
//! reports, link.log lines), the counts ride in the link statistics the
//! dashboard and headless output show, and a last line in link.log gives
//! the totals when the monitor stops. The two notice lines are the only
//! bytes past the cap.

use std::fs::File;
use std::io::{self, BufWriter, Read, Write};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use hammer_wire::{CycleReport, DeviceMsg};

use super::event::{describe, rfc3339, Event, Limiter, Stamped};

pub const MAGIC: &[u8; 8] = b"HMFRAMES";
pub const OPENED: u32 = 0xFFFF_FFFF;
pub const LOST: u32 = 0xFFFF_FFFE;
pub const MAX_CHUNK: u32 = 1 << 20;
pub const FLUSH_EVERY: Duration = Duration::from_millis(500);
/// Default size cap of the three log files together, in MB (10^6 bytes).
pub const DEFAULT_MAX_MB: f64 = 256.0;

/// The columns of cycles.csv before the report's: the host's arrival time.
pub const HOST_COLUMNS: [&str; 2] = ["host_time", "host_unix_s"];

/// cycles.csv's header: the host's columns, then every report column
/// ([`crate::records::columns`], the one table of report fields).
pub fn cycles_header() -> String {
    HOST_COLUMNS.join(",") + "," + &crate::records::csv_header()
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Marker {
    Opened,
    Lost,
}

/// One record of frames.bin.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Record {
    Bytes { t_us: u64, bytes: Vec<u8> },
    Marker { t_us: u64, marker: Marker },
}

/// What the size cap kept out of the logs.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Unlogged {
    /// Received bytes not in frames.bin.
    pub bytes: u64,
    /// Reports not in cycles.csv.
    pub reports: u64,
    /// Lines not in link.log.
    pub lines: u64,
}

pub struct Logger {
    dir: PathBuf,
    cycles: BufWriter<File>,
    link: BufWriter<File>,
    frames: BufWriter<File>,
    last_flush: Instant,
    frame_errors: Limiter,
    /// Sequence gaps and restarts: a stream running backwards makes one per report.
    seq_events: Limiter,
    max_bytes: u64,
    /// What the three files hold, counting what they held before.
    size_bytes: u64,
    capped: bool,
    /// The cap notice, until the reader has passed it on to the screen.
    news: Option<String>,
    unlogged: Unlogged,
}

/// A binary log, appended to: owner-only, never through a symlink.
fn append(path: &Path) -> io::Result<(File, u64)> {
    let f = crate::private_files::open_append(path)?;
    let len = f.metadata()?.len();
    Ok((f, len))
}

/// A text log, appended to as [`append`], a line torn by a crash or a full
/// disk cut back first so the next run's lines stay whole.
fn append_lines(path: &Path) -> io::Result<(File, u64)> {
    let (f, len, _torn) = crate::private_files::open_append_whole_lines(path)?;
    Ok((f, len))
}

impl Logger {
    /// Logs into `dir` until the three files hold `max_bytes` together.
    /// The directory is created 0700 and the files 0600; a directory
    /// another user owns or can write is refused (they could plant links).
    pub fn open(dir: &Path, max_bytes: u64) -> io::Result<Self> {
        crate::private_files::ensure_private_dir(dir).map_err(|e| io::Error::other(format!("{e:#}")))?;
        let (cycles, cycles_len) = append_lines(&dir.join("cycles.csv"))?;
        let (frames, frames_len) = append(&dir.join("frames.bin"))?;
        let (link, link_len) = append_lines(&dir.join("link.log"))?;
        let mut l = Self {
            dir: dir.to_path_buf(),
            cycles: BufWriter::new(cycles),
            link: BufWriter::new(link),
            frames: BufWriter::with_capacity(64 * 1024, frames),
            last_flush: Instant::now(),
            frame_errors: Limiter::new(20),
            seq_events: Limiter::new(20),
            max_bytes,
            size_bytes: cycles_len + frames_len + link_len,
            capped: false,
            news: None,
            unlogged: Unlogged::default(),
        };
        let t = super::event::now_us();
        // Without its header a file is unreadable: the header or nothing.
        let header = cycles_header();
        if cycles_len == 0 && l.admit(t, header.len() as u64 + 1)? {
            writeln!(l.cycles, "{header}")?;
        }
        if frames_len == 0 && l.admit(t, MAGIC.len() as u64)? {
            l.frames.write_all(MAGIC)?;
        }
        l.line(
            super::event::now_us(),
            &format!("monitor started, hammer {}", env!("CARGO_PKG_VERSION")),
        )?;
        l.flush()?;
        Ok(l)
    }

    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// What the cap has kept out so far.
    pub fn unlogged(&self) -> Unlogged {
        self.unlogged
    }

    /// The cap notice, once, for the screen.
    pub fn take_news(&mut self) -> Option<String> {
        self.news.take()
    }

    /// Whether `n` more bytes fit under the cap; the first refusal stops
    /// logging and says so in link.log.
    fn admit(&mut self, t_us: u64, n: u64) -> io::Result<bool> {
        if self.capped {
            return Ok(false);
        }
        if self.size_bytes + n <= self.max_bytes {
            self.size_bytes += n;
            return Ok(true);
        }
        self.capped = true;
        let text = format!(
            "logging stopped: the logs reached their size cap of {} MB (--log-max-mb); \
             from here on received bytes, reports and link events are counted, not logged",
            self.max_bytes as f64 / 1e6
        );
        writeln!(self.link, "{} {text}", rfc3339(t_us))?;
        self.news = Some(text);
        Ok(false)
    }

    pub fn raw(&mut self, t_us: u64, bytes: &[u8]) -> io::Result<()> {
        for chunk in bytes.chunks(MAX_CHUNK as usize) {
            if !self.admit(t_us, 12 + chunk.len() as u64)? {
                self.unlogged.bytes += chunk.len() as u64;
                continue;
            }
            self.frames.write_all(&t_us.to_le_bytes())?;
            self.frames.write_all(&(chunk.len() as u32).to_le_bytes())?;
            self.frames.write_all(chunk)?;
        }
        Ok(())
    }

    /// Markers carry no data: past the cap they go unrecorded (and uncounted).
    pub fn marker(&mut self, t_us: u64, m: Marker) -> io::Result<()> {
        if !self.admit(t_us, 12)? {
            return Ok(());
        }
        self.frames.write_all(&t_us.to_le_bytes())?;
        let code = match m {
            Marker::Opened => OPENED,
            Marker::Lost => LOST,
        };
        self.frames.write_all(&code.to_le_bytes())
    }

    fn line(&mut self, t_us: u64, text: &str) -> io::Result<()> {
        let line = format!("{} {text}\n", rfc3339(t_us));
        if !self.admit(t_us, line.len() as u64)? {
            self.unlogged.lines += 1;
            return Ok(());
        }
        self.link.write_all(line.as_bytes())
    }

    /// Reports go to cycles.csv, news to link.log.
    pub fn event(&mut self, ev: &Stamped) -> io::Result<()> {
        match &ev.event {
            Event::Msg(DeviceMsg::Report(r)) => {
                let row = csv_row(ev.t_us, r);
                if !self.admit(ev.t_us, row.len() as u64 + 1)? {
                    self.unlogged.reports += 1;
                    return Ok(());
                }
                writeln!(self.cycles, "{row}")
            }
            Event::FrameError { .. } => match self.frame_errors.allow(ev.t_us) {
                Some(held) => {
                    if held > 0 {
                        self.line(ev.t_us, &format!("({held} more frame errors not listed)"))?;
                    }
                    match describe(&ev.event) {
                        Some((_, text)) => self.line(ev.t_us, &text),
                        None => Ok(()),
                    }
                }
                None => Ok(()),
            },
            Event::SeqGap { .. } => match self.seq_events.allow(ev.t_us) {
                Some(held) => {
                    if held > 0 {
                        self.line(ev.t_us, &format!("({held} more sequence gaps or restarts not listed)"))?;
                    }
                    match describe(&ev.event) {
                        Some((_, text)) => self.line(ev.t_us, &text),
                        None => Ok(()),
                    }
                }
                None => Ok(()),
            },
            Event::Stats(_) => Ok(()),
            Event::Disconnected { .. } => {
                if let Some((_, text)) = describe(&ev.event) {
                    self.line(ev.t_us, &text)?;
                }
                self.flush()
            }
            e => match describe(e) {
                Some((_, text)) => self.line(ev.t_us, &text),
                None => Ok(()),
            },
        }
    }

    pub fn flush_if_due(&mut self) -> io::Result<()> {
        if self.last_flush.elapsed() >= FLUSH_EVERY {
            self.flush()?;
        }
        Ok(())
    }

    pub fn flush(&mut self) -> io::Result<()> {
        self.last_flush = Instant::now();
        self.frames.flush()?;
        self.cycles.flush()?;
        self.link.flush()
    }
}

impl Drop for Logger {
    fn drop(&mut self) {
        let t = super::event::now_us();
        if !self.capped {
            let _ = self.line(t, "monitor stopped");
        } else {
            let u = self.unlogged;
            let _ = writeln!(
                self.link,
                "{} monitor stopped; not logged after the size cap: {} received bytes, {} reports, {} link.log lines",
                rfc3339(t),
                u.bytes,
                u.reports,
                u.lines
            );
        }
        let _ = self.flush();
    }
}

/// One cycles.csv row; every report field prints the shortest text that reads back to the same number.
pub fn csv_row(t_us: u64, r: &CycleReport) -> String {
    format!(
        "{},{}.{:06},{}",
        rfc3339(t_us),
        t_us / 1_000_000,
        t_us % 1_000_000,
        crate::records::csv_record(r)
    )
}

/// Reads frames.bin record by record; bounded memory whatever the file holds.
pub struct FrameReader<R> {
    r: R,
    offset: u64,
}

#[derive(Debug, thiserror::Error)]
pub enum FrameFileError {
    #[error("not a frames.bin (no HMFRAMES header)")]
    NotFrames,
    #[error("corrupt record at byte {offset}: length {len} (longest chunk is {MAX_CHUNK})")]
    Corrupt { offset: u64, len: u32 },
    #[error("the last record is cut short at byte {offset} (recording interrupted?)")]
    Truncated { offset: u64 },
    #[error(transparent)]
    Io(#[from] io::Error),
}

impl<R> FrameReader<R> {
    /// File offset of the next record (after one, where its bytes ended).
    pub fn offset(&self) -> u64 {
        self.offset
    }
}

impl<R: Read> FrameReader<R> {
    pub fn new(mut r: R) -> Result<Self, FrameFileError> {
        let mut magic = [0u8; 8];
        match read_full(&mut r, &mut magic)? {
            8 if &magic == MAGIC => Ok(Self { r, offset: 8 }),
            _ => Err(FrameFileError::NotFrames),
        }
    }

    /// The next record, `Ok(None)` at a clean end of file.
    pub fn next_record(&mut self) -> Result<Option<Record>, FrameFileError> {
        let start = self.offset;
        let mut head = [0u8; 12];
        match read_full(&mut self.r, &mut head)? {
            0 => return Ok(None),
            12 => {}
            _ => return Err(FrameFileError::Truncated { offset: start }),
        }
        let t_us = u64::from_le_bytes(head[..8].try_into().unwrap_or_default());
        let len = u32::from_le_bytes(head[8..].try_into().unwrap_or_default());
        self.offset += 12;
        let marker = match len {
            OPENED => Some(Marker::Opened),
            LOST => Some(Marker::Lost),
            _ => None,
        };
        if let Some(marker) = marker {
            return Ok(Some(Record::Marker { t_us, marker }));
        }
        if len > MAX_CHUNK {
            return Err(FrameFileError::Corrupt { offset: start, len });
        }
        let mut bytes = vec![0u8; len as usize];
        if read_full(&mut self.r, &mut bytes)? != bytes.len() {
            return Err(FrameFileError::Truncated { offset: start });
        }
        self.offset += u64::from(len);
        Ok(Some(Record::Bytes { t_us, bytes }))
    }
}

fn read_full(r: &mut impl Read, buf: &mut [u8]) -> io::Result<usize> {
    let mut n = 0;
    while n < buf.len() {
        match r.read(&mut buf[n..]) {
            Ok(0) => break,
            Ok(k) => n += k,
            Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
    Ok(n)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_bin_round_trips_and_reports_damage() {
        let dir = std::env::temp_dir().join(format!("hammer-monitor-log-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        {
            let mut l = Logger::open(&dir, 1 << 20).unwrap();
            l.marker(5, Marker::Opened).unwrap();
            l.raw(6, b"abc").unwrap();
            l.marker(7, Marker::Lost).unwrap();
        }
        let bytes = std::fs::read(dir.join("frames.bin")).unwrap();
        let mut r = FrameReader::new(&bytes[..]).unwrap();
        assert_eq!(
            r.next_record().unwrap(),
            Some(Record::Marker {
                t_us: 5,
                marker: Marker::Opened
            })
        );
        assert_eq!(
            r.next_record().unwrap(),
            Some(Record::Bytes {
                t_us: 6,
                bytes: b"abc".to_vec()
            })
        );
        assert!(matches!(r.next_record().unwrap(), Some(Record::Marker { t_us: 7, .. })));
        assert_eq!(r.next_record().unwrap(), None);

        let mut r = FrameReader::new(&bytes[..bytes.len() - 14]).unwrap();
        r.next_record().unwrap();
        assert!(matches!(r.next_record(), Err(FrameFileError::Truncated { offset: 20 })));
        let mut bad = bytes.clone();
        bad[28..32].copy_from_slice(&(MAX_CHUNK + 1).to_le_bytes());
        let mut r = FrameReader::new(&bad[..]).unwrap();
        r.next_record().unwrap();
        assert!(matches!(
            r.next_record(),
            Err(FrameFileError::Corrupt { offset: 20, .. })
        ));
        assert!(matches!(
            FrameReader::new(&b"nonsense"[..]),
            Err(FrameFileError::NotFrames)
        ));
        let header = std::fs::read_to_string(dir.join("cycles.csv")).unwrap();
        assert_eq!(header.trim_end(), cycles_header());
        // Owner-only, and a line torn by a crash is cut back before the next run appends.
        use std::os::unix::fs::PermissionsExt;
        let mode = |p: &Path| std::fs::metadata(p).unwrap().permissions().mode() & 0o777;
        assert_eq!(mode(&dir), 0o700);
        for f in ["cycles.csv", "frames.bin", "link.log"] {
            assert_eq!(mode(&dir.join(f)), 0o600, "{f}");
        }
        let mut torn = std::fs::read(dir.join("link.log")).unwrap();
        let whole = torn.len();
        torn.extend_from_slice(b"2026-11-27T05:00:00Z half a li");
        std::fs::write(dir.join("link.log"), &torn).unwrap();
        drop(Logger::open(&dir, 1 << 20).unwrap());
        let text = std::fs::read_to_string(dir.join("link.log")).unwrap();
        assert!(!text.contains("half a li") && text.len() > whole, "{text}");
        assert!(text.lines().all(|l| l.starts_with("20")), "{text}");
        // A log directory other users can write is refused.
        std::fs::set_permissions(&dir, std::fs::Permissions::from_mode(0o777)).unwrap();
        let e = Logger::open(&dir, 1 << 20).err().expect("refused");
        assert!(e.to_string().contains("writable by other users"), "{e}");
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn the_size_cap_stops_logging_says_so_and_counts_what_it_kept_out() {
        let dir = std::env::temp_dir().join(format!("hammer-monitor-log-cap-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let cap = 4_000;
        let u = {
            let mut l = Logger::open(&dir, cap).unwrap();
            assert_eq!(l.take_news(), None);
            for i in 0..100 {
                l.raw(i, &[0xAB; 100]).unwrap();
            }
            let report = Stamped {
                t_us: 200,
                event: Event::Msg(DeviceMsg::Report(CycleReport::default())),
            };
            l.event(&report).unwrap();
            l.line(201, "a link event").unwrap();
            let news = l.take_news().expect("the cap is news");
            assert!(news.contains("size cap of 0.004 MB"), "{news}");
            assert_eq!(l.take_news(), None, "once");
            l.unlogged()
        };
        assert_eq!((u.reports, u.lines), (1, 1));
        let bin = std::fs::read(dir.join("frames.bin")).unwrap();
        let mut r = FrameReader::new(&bin[..]).unwrap();
        let mut logged = 0;
        while let Some(rec) = r.next_record().unwrap() {
            if let Record::Bytes { bytes, .. } = rec {
                logged += bytes.len() as u64;
            }
        }
        assert_eq!(logged + u.bytes, 100 * 100, "every received byte is logged or counted");
        let link = std::fs::read_to_string(dir.join("link.log")).unwrap();
        let notices: usize = link
            .lines()
            .filter(|l| l.contains("logging stopped") || l.contains("not logged after the size cap"))
            .map(|l| l.len() + 1)
            .sum();
        let total: u64 = ["frames.bin", "cycles.csv", "link.log"]
            .iter()
            .map(|f| std::fs::metadata(dir.join(f)).unwrap().len())
            .sum();
        assert!(total <= cap + notices as u64, "{total} bytes under a cap of {cap}");
        assert!(total > cap - 200, "the cap is used, {total} bytes");
        assert!(
            link.contains(&format!(
                "not logged after the size cap: {} received bytes, 1 reports, 1 link.log lines",
                u.bytes
            )),
            "{link}"
        );
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn csv_rows_have_a_value_per_column() {
        // The layout cycles.csv had before the columns came from the table of report fields,
        // plus the calibration hash (protocol 3) and the chambers' characteristics (protocol 6).
        assert_eq!(
            cycles_header(),
            "host_time,host_unix_s,seq,t_impact_s,period_s,frequency_hz,friction_n,\
friction_stroke_n,friction_backhaul_n,friction_uncertainty_n,friction_stroke_uncertainty_n,\
friction_backhaul_uncertainty_n,impact_velocity_mps,impact_velocity_frictionless_mps,impact_energy_j,\
impact_energy_frictionless_j,impact_energy_uncertainty_j,impact_energy_frictionless_uncertainty_j,\
friction_work_j,friction_work_ratio,stroke_m,peak_rear_pa,peak_front_pa,accel_zero_shift_mps2,wear_index_j,\
wear_remaining_fraction,remaining_life_cycles,drift_score,calibration_hash,\
front_feed_s,front_feed_uncertainty_s,front_feed_x_m,front_feed_p_rear_pa,front_feed_p_front_pa,\
front_closed_exponent,front_closed_exponent_uncertainty,front_feed_area_m2,front_feed_area_uncertainty_m2,\
rear_feed_s,rear_feed_uncertainty_s,rear_feed_x_m,rear_feed_p_rear_pa,rear_feed_p_front_pa,\
rear_closed_exponent,rear_closed_exponent_uncertainty,rear_feed_area_m2,rear_feed_area_uncertainty_m2,valid,flags"
        );
        // Unread chambers: NaN, which a CSV reader (pandas, NumPy, Rust) reads back as NaN.
        let mut unread = CycleReport::default();
        unread.mark_chambers_unread();
        let row = csv_row(1_700_000_000_123_456, &unread);
        assert!(
            row.ends_with(&format!("{}true,chambers_unread", "NaN,".repeat(18))),
            "{row}"
        );
        let row = csv_row(1_700_000_000_123_456, &CycleReport::default());
        assert_eq!(row.split(',').count(), cycles_header().split(',').count());
        assert!(
            row.starts_with("2023-11-14T22:13:20.123456Z,1700000000.123456,0,"),
            "{row}"
        );
    }
}
