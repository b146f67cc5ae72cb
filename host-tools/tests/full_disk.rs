//! Sinks on a full disk (a 200 KiB tmpfs): every sink reports its loss
//! with exact counts and the run exits non-zero; no torn line and no
//! temporary file remains; once there is room again the next run appends
//! cleanly; `estimate --out` on the full disk leaves no file and names it.
//! Needs root to mount a tmpfs; elsewhere the test says so and skips.

use std::path::{Path, PathBuf};
use std::process::Command;

use hammer_host::{influx, parquet_files};

/// A tmpfs mounted for the test, unmounted when dropped.
struct Tmpfs(PathBuf);

impl Tmpfs {
    fn mount(dir: &Path, size: &str) -> Option<Self> {
        std::fs::create_dir_all(dir).unwrap();
        let ok = Command::new("mount")
            .args(["-t", "tmpfs", "-o", &format!("size={size}"), "tmpfs"])
            .arg(dir)
            .status()
            .is_ok_and(|s| s.success());
        if !ok {
            eprintln!(
                "SKIPPED: cannot mount a tmpfs at {} (needs root and mount permission)",
                dir.display()
            );
            return None;
        }
        Some(Self(dir.to_path_buf()))
    }

    fn resize(&self, size: &str) {
        let ok = Command::new("mount")
            .args(["-o", &format!("remount,size={size}")])
            .arg(&self.0)
            .status()
            .unwrap();
        assert!(ok.success());
    }
}

impl Drop for Tmpfs {
    fn drop(&mut self) {
        let _ = Command::new("umount").arg(&self.0).status();
    }
}

fn hammer(args: &[&str]) -> (bool, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_hammer")).args(args).output().unwrap();
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

fn all_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for e in std::fs::read_dir(dir).into_iter().flatten().flatten() {
        let p = e.path();
        if p.is_dir() {
            all_files(&p, out);
        } else {
            out.push(p);
        }
    }
}

/// The number after `prefix` in `text`.
fn count_after(text: &str, prefix: &str) -> u64 {
    let at = text
        .find(prefix)
        .unwrap_or_else(|| panic!("{prefix:?} not in:\n{text}"))
        + prefix.len();
    text[at..]
        .split(|c: char| !c.is_ascii_digit())
        .next()
        .unwrap()
        .parse()
        .unwrap()
}

#[test]
fn a_full_disk_is_reported_with_exact_counts_and_leaves_nothing_torn() {
    let dir = std::env::temp_dir().join(format!("hammer-full-disk-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    // A trace for `estimate`, written where there is room.
    let trace = dir.join("trace.csv");
    let (ok, _, err) = hammer(&[
        "simulate",
        "--supply-bar",
        "4",
        "--duration",
        "0.5",
        "--out",
        trace.to_str().unwrap(),
    ]);
    assert!(ok, "{err}");
    let Some(disk) = Tmpfs::mount(&dir.join("disk"), "200k") else {
        return;
    };
    let pq = disk.0.join("pq");
    let lp = disk.0.join("influx.lp");
    let (pq_s, lp_s) = (pq.to_str().unwrap(), lp.to_str().unwrap());
    let (ok, stdout, stderr) = hammer(&[
        "demo",
        "--headless",
        "--native",
        "--cycles",
        "400",
        "--parquet",
        pq_s,
        "--influx",
        lp_s,
    ]);
    println!(
        "{}",
        stderr
            .lines()
            .filter(|l| l.contains("written"))
            .collect::<Vec<_>>()
            .join("\n")
    );
    assert!(!ok, "a run that lost data exits non-zero:\n{stderr}");
    assert!(stderr.contains("not every report reached its destination"), "{stderr}");
    let printed = stdout.lines().filter(|l| l.starts_with("cycle ")).count() as u64;
    assert!(printed >= 400, "{stdout}");
    // Exact counts: what the file holds is what the summary says, whole lines only.
    let written = count_after(&stderr, "influx: ");
    let failed = count_after(&stderr, "lines written, ");
    assert!(failed > 0, "the disk was full: {stderr}");
    assert_eq!(written + failed, printed, "every report counted once: {stderr}");
    let text = std::fs::read_to_string(&lp).unwrap();
    assert!(text.is_empty() || text.ends_with('\n'), "no torn last line");
    assert_eq!(text.lines().count() as u64, written, "the count is exact");
    for l in text.lines() {
        influx::parse(l).unwrap();
    }
    let rows = count_after(&stderr, "parquet: ");
    let not_written = count_after(&stderr, "files, ");
    assert_eq!(rows + not_written, printed, "{stderr}");
    let mut files = vec![];
    all_files(&disk.0, &mut files);
    let temporaries: Vec<&PathBuf> = files.iter().filter(|p| p.to_string_lossy().ends_with(".tmp")).collect();
    assert!(temporaries.is_empty(), "temporary files left: {temporaries:?}");
    let parquet_rows: usize = files
        .iter()
        .filter(|p| p.extension().is_some_and(|e| e == "parquet"))
        .map(|p| parquet_files::read(p).unwrap().len())
        .sum();
    assert_eq!(
        parquet_rows as u64, rows,
        "every Parquet file whole, with the rows counted"
    );

    // `estimate --out` on the disk filled to its last byte: an error naming
    // the file, and no file.
    {
        use std::io::Write;
        let mut filler = std::fs::File::create(disk.0.join("filler")).unwrap();
        while filler.write_all(&[0u8; 4096]).is_ok() {}
        while filler.write_all(&[0u8; 1]).is_ok() {}
    }
    let out = disk.0.join("cycles.parquet");
    let (ok, _, err) = hammer(&[
        "estimate",
        trace.to_str().unwrap(),
        "--format",
        "parquet",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(!ok, "no room: {err}");
    assert!(err.contains(out.to_str().unwrap()), "{err}");
    assert!(!out.exists(), "--out is complete or absent");
    std::fs::remove_file(disk.0.join("filler")).unwrap();
    let mut files = vec![];
    all_files(&disk.0, &mut files);
    assert!(
        !files.iter().any(|p| p.to_string_lossy().ends_with(".tmp")),
        "{files:?}"
    );

    // Room again: the next run appends whole lines after the ones there.
    disk.resize("4m");
    let (ok, _, stderr) = hammer(&["demo", "--headless", "--native", "--cycles", "20", "--influx", lp_s]);
    assert!(ok, "{stderr}");
    let more = count_after(&stderr, "influx: ");
    let text = std::fs::read_to_string(&lp).unwrap();
    assert_eq!(text.lines().count() as u64, written + more);
    for l in text.lines() {
        influx::parse(l).unwrap();
    }
    drop(disk);
    let _ = std::fs::remove_dir_all(&dir);
}
