//! `hammer replay`: a recorded frames.bin through the same decoding core and
//! the same dashboard, paced by the recorded host times.

use std::fs::File;
use std::io::{BufReader, IsTerminal};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{self, SyncSender};
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};

use super::app::App;
use super::event::{Event, Stamped};
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
    let _ = player.join();
    result
}

/// Reads the records and emits their events, in time. Blocks on a full
/// queue: a replay has all the time it wants, nothing may be skipped.
fn play<R: std::io::Read>(
    mut frames: FrameReader<R>,
    name: &str,
    speed: f64,
    tx: &SyncSender<Stamped>,
    stop: &AtomicBool,
) {
    let mut ingest = Ingest::new();
    let mut emit = |ev: Stamped| {
        let _ = tx.send(ev);
    };
    let start = Instant::now();
    let mut due = Duration::ZERO;
    let mut prev_t: Option<u64> = None;
    let mut last_t = 0u64;
    loop {
        if stop.load(Ordering::Relaxed) {
            return;
        }
        let rec = match frames.next_record() {
            Ok(Some(r)) => r,
            Ok(None) => break,
            Err(e) => {
                emit(Stamped {
                    t_us: last_t,
                    event: Event::Note(format!("replay stopped: {e}")),
                });
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
                    return;
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
            Record::Bytes { t_us, bytes } => ingest.feed(t_us, &bytes, &mut emit),
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
    emit(Stamped {
        t_us: last_t,
        event: Event::End,
    });
}
