//! Files only their owner can read, opened so another local user cannot
//! redirect them: what the MQTT outage buffer and the monitor's logs are
//! written with.
//!
//! A directory is created 0700 and used only if it is a real directory (not
//! a symlink), owned by this user and writable by no one else: in a
//! directory another user can write, they could plant a symlink or a forged
//! record. Files are created 0600 and opened with `O_NOFOLLOW`; temporary
//! files are created exclusively under a fresh name, so a planted name makes
//! the create fail instead of following it.
//!
//! [`write_complete`] is the one way a file is written whole or not at all
//! (Parquet files, `--out`): a temporary file beside it, renamed over it
//! once complete, removed when anything fails.

use std::fs::{File, OpenOptions};
use std::io::{self, Read, Seek, SeekFrom};
use std::os::unix::fs::{DirBuilderExt, MetadataExt, OpenOptionsExt, PermissionsExt};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

use anyhow::{bail, Context, Result};

/// This process's effective user id.
pub fn euid() -> u32 {
    // SAFETY: geteuid has no preconditions and cannot fail.
    unsafe { libc::geteuid() }
}

/// The user's state directory: `$XDG_STATE_HOME`, else `~/.local/state`
/// (the XDG base directory specification), if either is known.
pub fn state_dir() -> Option<PathBuf> {
    let abs = |v: std::ffi::OsString| Some(PathBuf::from(v)).filter(|p| p.is_absolute());
    std::env::var_os("XDG_STATE_HOME")
        .and_then(abs)
        .or_else(|| std::env::var_os("HOME").and_then(abs).map(|h| h.join(".local/state")))
}

/// Creates `dir` (and its parents) 0700 if missing, then checks it is
/// private: a directory, not a symlink, owned by this user, writable by no
/// one else. The error says which.
pub fn ensure_private_dir(dir: &Path) -> Result<()> {
    if std::fs::symlink_metadata(dir).is_err() {
        std::fs::DirBuilder::new()
            .recursive(true)
            .mode(0o700)
            .create(dir)
            .with_context(|| format!("creating {}", dir.display()))?;
    }
    check_private_dir(dir)
}

/// Whether `dir` is private (see [`ensure_private_dir`]).
pub fn check_private_dir(dir: &Path) -> Result<()> {
    let m = std::fs::symlink_metadata(dir).with_context(|| format!("{}", dir.display()))?;
    if m.file_type().is_symlink() {
        bail!("{} is a symbolic link", dir.display());
    }
    if !m.is_dir() {
        bail!("{} is not a directory", dir.display());
    }
    if m.uid() != euid() {
        bail!("{} belongs to another user (uid {})", dir.display(), m.uid());
    }
    if m.mode() & 0o022 != 0 {
        bail!(
            "{} is writable by other users (mode {:o})",
            dir.display(),
            m.mode() & 0o777
        );
    }
    if m.mode() & 0o077 != 0 {
        // Ours and not writable by others, but readable: make it private.
        std::fs::set_permissions(dir, std::fs::Permissions::from_mode(0o700))
            .with_context(|| format!("making {} private", dir.display()))?;
    }
    Ok(())
}

/// A fresh private directory under the system's temporary directory,
/// created exclusively (never one that existed before).
pub fn fresh_private_dir(stem: &str) -> Result<PathBuf> {
    let base = std::env::temp_dir();
    for k in 0..100u32 {
        let nanos = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.subsec_nanos());
        let dir = base.join(format!("{stem}-{}-{}-{nanos:x}{k}", euid(), std::process::id()));
        match std::fs::DirBuilder::new().mode(0o700).create(&dir) {
            Ok(()) => return Ok(dir),
            Err(e) if e.kind() == io::ErrorKind::AlreadyExists => continue,
            Err(e) => return Err(e).with_context(|| format!("creating {}", dir.display())),
        }
    }
    bail!("no fresh directory could be created in {}", base.display())
}

/// Opens `path` for appending, created 0600, without following a symlink.
pub fn open_append(path: &Path) -> io::Result<File> {
    OpenOptions::new()
        .create(true)
        .append(true)
        .mode(0o600)
        .custom_flags(libc::O_NOFOLLOW)
        .open(path)
}

/// Opens `path` for reading without following a symlink.
pub fn open_read(path: &Path) -> io::Result<File> {
    OpenOptions::new().read(true).custom_flags(libc::O_NOFOLLOW).open(path)
}

/// Opens a text file for appending (0600, no symlinks) and cuts back a
/// torn last line (a crash or a full disk mid-write) so the next line
/// starts on a line of its own. Returns the file and its length.
pub fn open_append_whole_lines(path: &Path) -> io::Result<(File, u64, u64)> {
    let mut f = OpenOptions::new()
        .create(true)
        .read(true)
        .append(true)
        .mode(0o600)
        .custom_flags(libc::O_NOFOLLOW)
        .open(path)?;
    let len = f.metadata()?.len();
    let torn = torn_tail(&mut f, len)?;
    if torn > 0 {
        f.set_len(len - torn)?;
    }
    Ok((f, len - torn, torn))
}

/// Bytes after the last newline of a file of `len` bytes.
fn torn_tail(f: &mut File, len: u64) -> io::Result<u64> {
    let mut end = len;
    let mut buf = [0u8; 4096];
    while end > 0 {
        let start = end.saturating_sub(buf.len() as u64);
        let n = (end - start) as usize;
        f.seek(SeekFrom::Start(start))?;
        f.read_exact(&mut buf[..n])?;
        if let Some(i) = buf[..n].iter().rposition(|&b| b == b'\n') {
            return Ok(len - (start + i as u64 + 1));
        }
        end = start;
    }
    Ok(len)
}

/// A temporary file beside `target`, created exclusively (0600, no
/// symlinks) under a fresh name: `.<name>.<pid>.<n>.tmp`.
pub fn create_temp(target: &Path) -> io::Result<(PathBuf, File)> {
    create_temp_mode(target, 0o600)
}

/// Writes `path` whole or not at all: `fill` writes into a temporary file
/// beside it (created exclusively with `mode`, before the umask), which is
/// synced and renamed over `path`; on any failure the temporary file is
/// removed, `path` is left as it was, and the error names `path`.
pub fn write_complete(
    path: &Path,
    mode: u32,
    fill: impl FnOnce(&mut io::BufWriter<&mut File>) -> Result<()>,
) -> Result<()> {
    let (tmp, mut f) =
        create_temp_mode(path, mode).with_context(|| format!("creating a temporary file beside {}", path.display()))?;
    let result = (|| -> Result<()> {
        let mut w = io::BufWriter::new(&mut f);
        fill(&mut w)?;
        io::Write::flush(&mut w)?;
        drop(w);
        f.sync_all()?;
        std::fs::rename(&tmp, path)?;
        Ok(())
    })();
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result.with_context(|| format!("writing {} (nothing of it was kept)", path.display()))
}

fn create_temp_mode(target: &Path, mode: u32) -> io::Result<(PathBuf, File)> {
    static NEXT: AtomicU64 = AtomicU64::new(0);
    let dir = target.parent().unwrap_or(Path::new("."));
    let name = target
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    loop {
        let n = NEXT.fetch_add(1, Ordering::Relaxed);
        let tmp = dir.join(format!(".{name}.{}.{n}.tmp", std::process::id()));
        match OpenOptions::new()
            .write(true)
            .create_new(true)
            .mode(mode)
            .custom_flags(libc::O_NOFOLLOW)
            .open(&tmp)
        {
            Ok(f) => return Ok((tmp, f)),
            Err(e) if e.kind() == io::ErrorKind::AlreadyExists => continue,
            Err(e) => return Err(e),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Write;

    fn scratch(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("hammer-private-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        d
    }

    #[test]
    fn directories_are_made_private_and_shared_ones_refused() {
        let d = scratch("dirs");
        ensure_private_dir(&d.join("a/b")).unwrap();
        let mode = std::fs::metadata(d.join("a/b")).unwrap().mode() & 0o777;
        assert_eq!(mode, 0o700);
        std::fs::set_permissions(d.join("a/b"), std::fs::Permissions::from_mode(0o777)).unwrap();
        let e = ensure_private_dir(&d.join("a/b")).unwrap_err();
        assert!(format!("{e:#}").contains("writable by other users"), "{e:#}");
        std::os::unix::fs::symlink(d.join("a"), d.join("link")).unwrap();
        assert!(format!("{:#}", check_private_dir(&d.join("link")).unwrap_err()).contains("symbolic link"));
        let _ = std::fs::remove_dir_all(&d);
    }

    #[test]
    fn files_are_owner_only_never_followed_and_torn_lines_cut_back() {
        let d = scratch("files");
        ensure_private_dir(&d).unwrap();
        let victim = d.join("victim");
        std::fs::write(&victim, "keep me\n").unwrap();
        std::os::unix::fs::symlink(&victim, d.join("planted")).unwrap();
        assert!(open_append(&d.join("planted")).is_err(), "a symlink is not followed");
        assert!(open_append_whole_lines(&d.join("planted")).is_err());
        assert_eq!(std::fs::read_to_string(&victim).unwrap(), "keep me\n");

        let mut f = open_append(&d.join("log")).unwrap();
        f.write_all(b"one\ntwo\nthr").unwrap();
        drop(f);
        assert_eq!(std::fs::metadata(d.join("log")).unwrap().mode() & 0o777, 0o600);
        let (mut f, len, torn) = open_append_whole_lines(&d.join("log")).unwrap();
        assert_eq!((len, torn), (8, 3));
        f.write_all(b"three\n").unwrap();
        assert_eq!(std::fs::read_to_string(d.join("log")).unwrap(), "one\ntwo\nthree\n");

        // Whole or not at all: a failure leaves neither the file nor a temporary one.
        let e = write_complete(&d.join("out.bin"), 0o644, |w| {
            io::Write::write_all(w, b"half")?;
            anyhow::bail!("disk full")
        })
        .unwrap_err();
        assert!(format!("{e:#}").contains("out.bin"), "{e:#}");
        let names: Vec<String> = std::fs::read_dir(&d)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        assert!(
            !names.iter().any(|n| n.contains("out.bin")),
            "neither the file nor a temporary one: {names:?}"
        );
        write_complete(&d.join("out.bin"), 0o644, |w| Ok(io::Write::write_all(w, b"whole")?)).unwrap();
        assert_eq!(std::fs::read(d.join("out.bin")).unwrap(), b"whole");

        let (tmp, _) = create_temp(&d.join("buf.jsonl")).unwrap();
        let (tmp2, _) = create_temp(&d.join("buf.jsonl")).unwrap();
        assert_ne!(tmp, tmp2);
        assert_eq!(std::fs::metadata(&tmp).unwrap().mode() & 0o777, 0o600);
        let _ = std::fs::remove_dir_all(&d);
    }
}
