//! The outage buffer: messages kept while the broker is away, one
//! checksummed record a line in a file private to the user, replayed in
//! order once it is back (see the parent module's docs).

use std::collections::VecDeque;
use std::fs::File;
use std::io::{Read, Write};
use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use serde::{Deserialize, Serialize};
use serde_json::Value;

use super::Kind;

/// One message, as queued and as buffered on disk.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub(super) struct Message {
    pub(super) kind: Kind,
    /// The payload without `historical`, which is decided when it is sent.
    pub(super) body: Value,
}

impl Message {
    pub(super) fn payload(&self, historical: bool) -> Vec<u8> {
        let mut body = self.body.clone();
        if let Some(m) = body.as_object_mut() {
            m.insert("historical".into(), historical.into());
        }
        serde_json::to_vec(&body).unwrap_or_default()
    }
}

/// The outage buffer: a queue in memory, mirrored record by record on disk.
///
/// A record is a line `<crc32 of the JSON, 8 hex digits> <JSON>`: a record
/// damaged on disk (a flipped digit, garbage, a line cut by a crash or a
/// full disk) fails its checksum and is skipped and counted, never sent as
/// data; the intact ones around it are replayed. A file that cannot be read
/// at all is renamed aside and a new one started. Without a usable file the
/// buffer keeps to memory, and says so.
pub(super) struct Buffer {
    pub(super) path: PathBuf,
    pub(super) file: Option<File>,
    pub(super) queue: VecDeque<(Message, usize)>,
    pub(super) bytes: usize,
    pub(super) cap: usize,
    /// The file still holds messages taken out of the queue.
    pub(super) stale: bool,
}

/// What opening a buffer found wrong: damaged records skipped, a file set aside.
#[derive(Debug, Default)]
pub(super) struct Damage {
    pub(super) records: u64,
    pub(super) notes: Vec<String>,
}

/// One record's line, newline included.
pub(super) fn record(m: &Message) -> Result<String> {
    let json = serde_json::to_string(m)?;
    Ok(format!("{:08x} {json}\n", crc32fast::hash(json.as_bytes())))
}

/// A record's message, if the line is whole and its checksum holds.
pub(super) fn parse_record(line: &[u8]) -> Option<Message> {
    let (crc, json) = (line.get(..8)?, line.get(9..)?);
    if line[8] != b' ' {
        return None;
    }
    let crc = u32::from_str_radix(std::str::from_utf8(crc).ok()?, 16).ok()?;
    (crc32fast::hash(json) == crc)
        .then(|| serde_json::from_slice(json).ok())
        .flatten()
}

impl Buffer {
    pub(super) fn open(path: &Path, cap: usize) -> (Self, Damage) {
        let mut damage = Damage::default();
        let mut queue = VecDeque::new();
        let mut bytes = 0;
        let mut read = Vec::new();
        let readable = match crate::private_files::open_read(path) {
            Ok(mut f) => f.read_to_end(&mut read).map(|_| true),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(false),
            Err(e) => Err(e),
        };
        match readable {
            Ok(_) => {
                let mut lines: Vec<&[u8]> = read.split(|&b| b == b'\n').collect();
                // What follows the last newline: nothing, or a record cut short.
                let tail = lines.pop().unwrap_or_default();
                for line in lines.into_iter().chain((!tail.is_empty()).then_some(tail)) {
                    match parse_record(line) {
                        Some(m) => {
                            bytes += line.len() + 1;
                            queue.push_back((m, line.len() + 1));
                        }
                        None if line.is_empty() => {}
                        None => damage.records += 1,
                    }
                }
            }
            Err(e) => {
                let aside = path.with_extension(format!(
                    "jsonl.unreadable-{}",
                    std::time::SystemTime::now()
                        .duration_since(std::time::UNIX_EPOCH)
                        .map_or(0, |d| d.as_secs())
                ));
                match std::fs::rename(path, &aside) {
                    Ok(()) => damage.notes.push(format!(
                        "the outage buffer {} could not be read ({e}): set aside as {}; a new one is started",
                        path.display(),
                        aside.display()
                    )),
                    Err(e2) => damage.notes.push(format!(
                        "the outage buffer {} could not be read ({e}) nor set aside ({e2})",
                        path.display()
                    )),
                }
            }
        }
        if damage.records > 0 {
            damage.notes.push(format!(
                "{} damaged records in the outage buffer {} skipped; {} intact ones kept for replay",
                damage.records,
                path.display(),
                queue.len()
            ));
        }
        let mut b = Self {
            path: path.to_path_buf(),
            file: None,
            queue,
            bytes,
            cap,
            stale: false,
        };
        // The file from now on holds exactly the intact records.
        let reopened = if damage.records > 0 {
            b.rewrite()
        } else {
            crate::private_files::open_append(path)
                .map(|f| b.file = Some(f))
                .with_context(|| format!("opening {}", path.display()))
        };
        if let Err(e) = reopened {
            damage.notes.push(format!(
                "the outage buffer {} cannot be written ({e:#}): buffering in memory only",
                path.display()
            ));
        }
        (b, damage)
    }

    /// Appends; beyond the cap drops the oldest and returns how many. A
    /// failed write (a full disk) cuts the file back to its last whole
    /// record and keeps the message in memory: the error says so.
    pub(super) fn push_back(&mut self, m: Message) -> (u64, Option<anyhow::Error>) {
        let line = match record(&m) {
            Ok(l) => l,
            Err(e) => return (1, Some(e)),
        };
        let mut failed = None;
        if let Some(f) = self.file.as_mut() {
            let len = f.metadata().map(|m| m.len());
            if let Err(e) = f.write_all(line.as_bytes()) {
                if let Ok(len) = len {
                    let _ = f.set_len(len);
                }
                self.file = None;
                failed = Some(anyhow::Error::new(e).context(format!("writing {}", self.path.display())));
            }
        }
        self.bytes += line.len();
        self.queue.push_back((m, line.len()));
        let mut dropped = 0;
        while self.bytes > self.cap && self.queue.len() > 1 {
            let (_, n) = self.queue.pop_front().expect("non-empty");
            self.bytes -= n;
            dropped += 1;
        }
        if dropped > 0 {
            if let Err(e) = self.rewrite() {
                failed.get_or_insert(e);
            }
        }
        (dropped, failed)
    }

    /// Puts messages that were in flight back at the front, in order.
    pub(super) fn push_front_all(&mut self, ms: Vec<Message>) -> Result<()> {
        for m in ms.into_iter().rev() {
            let n = record(&m)?.len();
            self.bytes += n;
            self.queue.push_front((m, n));
        }
        self.rewrite()
    }

    pub(super) fn pop_front(&mut self) -> Option<Message> {
        let (m, n) = self.queue.pop_front()?;
        self.bytes -= n;
        self.stale = true;
        Some(m)
    }

    /// The file holds exactly the queue: written to a fresh temporary file
    /// (created exclusively, removed on failure), then renamed over it.
    pub(super) fn rewrite(&mut self) -> Result<()> {
        let (tmp, mut f) = crate::private_files::create_temp(&self.path)
            .with_context(|| format!("a temporary file beside {}", self.path.display()))?;
        let written = (|| -> Result<()> {
            let mut w = std::io::BufWriter::new(&mut f);
            for (m, _) in &self.queue {
                w.write_all(record(m)?.as_bytes())?;
            }
            w.flush()?;
            drop(w);
            f.sync_all()?;
            std::fs::rename(&tmp, &self.path)?;
            Ok(())
        })();
        if let Err(e) = written {
            let _ = std::fs::remove_file(&tmp);
            // The old file no longer matches the queue: memory only, until
            // a rewrite succeeds.
            self.file = None;
            return Err(e).with_context(|| format!("rewriting {}", self.path.display()));
        }
        self.file = Some(
            crate::private_files::open_append(&self.path)
                .with_context(|| format!("opening {}", self.path.display()))?,
        );
        self.stale = false;
        Ok(())
    }
}

/// The outage buffer's directory: `requested`, or by default the user's
/// own (`$XDG_STATE_HOME/hammer/mqtt-buffer`, `~/.local/state/…`), used
/// only if private to this user. Otherwise a fresh private one, and a note
/// saying why.
pub fn buffer_dir(requested: Option<&Path>) -> Result<(PathBuf, Option<String>)> {
    let wanted = match requested {
        Some(d) => d.to_path_buf(),
        None => match crate::private_files::state_dir() {
            Some(s) => s.join("hammer").join("mqtt-buffer"),
            None => std::env::temp_dir().join(format!("hammer-mqtt-buffer-{}", crate::private_files::euid())),
        },
    };
    match crate::private_files::ensure_private_dir(&wanted) {
        Ok(()) => Ok((wanted, None)),
        Err(e) => {
            let fresh = crate::private_files::fresh_private_dir("hammer-mqtt-buffer")?;
            let note = format!(
                "mqtt: the outage buffer directory is not used: {e:#} (another user could read or plant records there); \
                 buffering in {} instead",
                fresh.display()
            );
            Ok((fresh, Some(note)))
        }
    }
}
