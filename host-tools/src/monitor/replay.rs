//! `hammer replay`: a recorded frames.bin through the same decoding core and
//! the same dashboard, paced by the recorded host times.
//!
//! A damaged recording (bad frames, a frame that never ended, a cut-short or
//! garbled file) is still shown as far as it goes, but the command then fails
//! (exit 2) saying how many frames were bad and at which byte of the file: a
//! script that replays recordings must not take a damaged one for a clean one.

use std::fs::File;
use std::io::{BufReader, IsTerminal};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{self, SyncSender};
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use hammer_wire::DecodeError;

use super::app::App;
use super::event::{decode_error_name, Event, Stamped};
use super::log::{FrameReader, Marker, Record};
use super::reader::Ingest;
use super::{ReplayArgs, UiOptions};

/// A replay waits at most this long (real time) between two records: an
/// idle hour in the recording is not sat through.
pub const MAX_PAUSE: Duration = Duration::from_secs(5);
const HISTORY_S: f64 = 300.0;

fn frames_path(p: &Path) -> PathBuf {
    if p.is_dir() {
        p.join("frames.bin")
    } else {
        p.to_path_buf()
    }
}

pub fn run(args: &ReplayArgs) -> Result<()> {
    if !(args.speed.is_finite() && args.speed >= 0.0) {
        bail!(
            "--speed must be 0 (as fast as possible) or a positive factor, not {}",
            args.speed
        );
    }
    let path = frames_path(&args.log);
    let file = File::open(&path).with_context(|| format!("cannot open {}", path.display()))?;
    let frames = FrameReader::new(BufReader::new(file)).with_context(|| path.display().to_string())?;
    let headless = args.headless || !std::io::stdout().is_terminal();
    let (tx, rx) = mpsc::sync_channel(4096);
    let stop = Arc::new(AtomicBool::new(false));
    let speed = args.speed;
    let name = path.display().to_string();
    let player = {
        let stop = stop.clone();
        let name = name.clone();
        std::thread::Builder::new()
            .name("monitor-replay".into())
            .spawn(move || play(frames, &name, speed, &tx, &stop))?
    };
    let mut app = App::new(name, false, HISTORY_S);
    let opts = UiOptions {
        headless,
        exit_after_reports: None,
        live: false,
    };
    let result = super::show(&mut app, &rx, opts);
    stop.store(true, Ordering::Relaxed);
    drop(rx);
    let damage = player.join().unwrap_or_else(|_| Damage {
        file_error: Some("the replay thread panicked".into()),
        ..Damage::default()
    });
    result?;
    match damage.summary() {
        Some(text) => bail!("{}: {text}", path.display()),
        None => Ok(()),
    }
}

/// Bad frames whose offsets are listed; the rest are only counted.
const LISTED: usize = 5;

/// What was wrong with a recording, with file offsets.
#[derive(Debug, Default)]
pub struct Damage {
    pub bad_frames: u64,
    /// (file offset of the bad frame's first byte, why), the first [`LISTED`].
    pub first: Vec<(u64, DecodeError)>,
    /// (file offset, length) of a frame the recording ends in the middle of.
    pub unterminated: Option<(u64, u64)>,
    /// The file itself is damaged (a garbled record, a cut-short end).
    pub file_error: Option<String>,
}

impl Damage {
    /// One sentence for the user, or `None` for a clean recording.
    pub fn summary(&self) -> Option<String> {
        let mut parts = Vec::new();
        if self.bad_frames > 0 {
            let listed: Vec<String> = self
                .first
                .iter()
                .map(|(at, kind)| format!("{} at byte {at}", decode_error_name(*kind)))
                .collect();
            let more = self.bad_frames - self.first.len() as u64;
            parts.push(format!(
                "{} bad frame{} ({}{})",
                self.bad_frames,
                if self.bad_frames == 1 { "" } else { "s" },
                listed.join(", "),
                if more > 0 {
                    format!(", {more} more")
                } else {
                    String::new()
                }
            ));
        }
        if let Some((at, len)) = self.unterminated {
            parts.push(format!(
                "the recording ends inside a frame ({len} bytes from byte {at})"
            ));
        }
        if let Some(e) = &self.file_error {
            parts.push(e.clone());
        }
        (!parts.is_empty()).then(|| format!("damaged recording: {}", parts.join("; ")))
    }
}

/// Where each recorded chunk's bytes sit in the file, from the decoder's
/// current frame on: maps stream offsets (which is what the decoder knows)
/// to file offsets (which is what a user can look at).
#[derive(Default)]
struct Chunks(Vec<(u64, u64)>);

impl Chunks {
    fn file_offset(&self, stream_offset: u64) -> u64 {
        match self.0.iter().rev().find(|(s, _)| *s <= stream_offset) {
            Some((s, f)) => f + (stream_offset - s),
            None => 0,
        }
    }

    /// Keeps only the chunks a frame that began at `frame_start` can lie in.
    fn forget_before(&mut self, frame_start: u64) {
        let keep = self.0.iter().rposition(|(s, _)| *s <= frame_start).unwrap_or(0);
        self.0.drain(..keep);
    }
}

/// Reads the records and emits their events, in time. Blocks on a full
/// queue: a replay has all the time it wants, nothing may be skipped.
fn play<R: std::io::Read>(
    mut frames: FrameReader<R>,
    name: &str,
    speed: f64,
    tx: &SyncSender<Stamped>,
    stop: &AtomicBool,
) -> Damage {
    let mut ingest = Ingest::for_replay();
    let mut damage = Damage::default();
    let mut chunks = Chunks::default();
    let mut emit = |ev: Stamped| {
        let _ = tx.send(ev);
    };
    let start = Instant::now();
    let mut due = Duration::ZERO;
    let mut prev_t: Option<u64> = None;
    let mut last_t = 0u64;
    loop {
        if stop.load(Ordering::Relaxed) {
            return damage;
        }
        let rec = match frames.next_record() {
            Ok(Some(r)) => r,
            Ok(None) => break,
            Err(e) => {
                emit(Stamped {
                    t_us: last_t,
                    event: Event::Note(format!("replay stopped: {e}")),
                });
                damage.file_error = Some(e.to_string());
                break;
            }
        };
        let t_us = match &rec {
            Record::Bytes { t_us, .. } | Record::Marker { t_us, .. } => *t_us,
        };
        if speed > 0.0 {
            if let Some(p) = prev_t {
                let gap = Duration::from_secs_f64(t_us.saturating_sub(p) as f64 * 1e-6 / speed);
                due += gap.min(MAX_PAUSE);
            }
            while let Some(left) = due.checked_sub(start.elapsed()) {
                if stop.load(Ordering::Relaxed) {
                    return damage;
                }
                if left.is_zero() {
                    break;
                }
                std::thread::sleep(left.min(Duration::from_millis(50)));
            }
        }
        prev_t = Some(t_us);
        last_t = last_t.max(t_us);
        match rec {
            Record::Bytes { t_us, bytes } => {
                chunks
                    .0
                    .push((ingest.stats().bytes, frames.offset() - bytes.len() as u64));
                ingest.feed(t_us, &bytes, &mut |ev| {
                    if let Event::FrameError {
                        kind, stream_offset, ..
                    } = ev.event
                    {
                        damage.bad_frames += 1;
                        if damage.first.len() < LISTED {
                            damage.first.push((chunks.file_offset(stream_offset), kind));
                        }
                    }
                    emit(ev)
                });
                chunks.forget_before(ingest.frame_start());
            }
            Record::Marker {
                t_us,
                marker: Marker::Opened,
            } => ingest.opened(t_us, format!("{name} (recorded link)"), &mut emit),
            Record::Marker {
                t_us,
                marker: Marker::Lost,
            } => ingest.lost(
                t_us,
                format!("{name} (recorded link)"),
                "recorded disconnect".into(),
                &mut emit,
            ),
        }
    }
    if ingest.pending_bytes() > 0 {
        damage.unterminated = Some((chunks.file_offset(ingest.frame_start()), ingest.pending_bytes()));
    }
    if let Some(text) = damage.summary() {
        emit(Stamped {
            t_us: last_t,
            event: Event::Note(text),
        });
    }
    emit(Stamped {
        t_us: last_t,
        event: Event::End,
    });
    damage
}
