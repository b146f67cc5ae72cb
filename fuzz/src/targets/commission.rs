//! A commissioning record (`commission.json`) read by the one reader every
//! command uses (`hammer_diagnose::record::Folder::open`), in a folder
//! made once per thread with what a copied folder may hold: captures with
//! and without sidecars at 4 and 7 bar, a link inside the folder, a link
//! out of it, a FIFO, a folder named like a capture, a sidecar that links
//! out, and another record's folder beside it. Invariants: no panic, no
//! hang; an accepted record has an operating point, every capture is a
//! regular file inside the folder once resolved and listed once, each
//! sidecar agrees with its point.
//!
//! The record is parsed and checked as `Folder::open` does past reading
//! the file (`Record::parse`, then `Folder::of`): no file is written per
//! input.

use std::cell::RefCell;
use std::collections::HashSet;
use std::path::{Path, PathBuf};

use hammer_diagnose::record::{Folder, Record, RECORD_FILE, SUPPLY_AGREE_BAR};

use super::{bit, Target};

pub const TARGET: Target = Target {
    name: "commission",
    run,
    dict: &[
        b"{",
        b"}",
        b"[",
        b"]",
        b"\"",
        b",",
        b"..",
        b"../",
        b"./",
        b"//",
        b"/etc/passwd",
        b"\"points\":",
        b"\"supply_bar\":",
        b"\"traces\":",
        b"\"calibration_hash\":",
        b"4660",
        b"4.004",
        b"5.5",
        b"7",
        b"4.0bar/",
        b"cycle-000.csv",
        b"cycle-001.csv",
        b"alias.csv",
        b"out.csv",
        b"fifo.csv",
        b"dir.csv",
        b"side-out.csv",
        b"../other/4.0bar/cycle-000.csv",
        b"\"reports\":",
        b"reports.csv",
        b"4.0bar/reports.csv",
    ],
    seeds,
};

/// The record's calibration, stated by the 4 bar capture's sidecar.
const HASH: u32 = 0x1234;

/// The captures of the folder and the pressure their sidecars state.
const SIDECARS: [(&str, f64); 2] = [("4.0bar/cycle-000", 4.0), ("7.0bar/cycle-000", 7.0)];

/// A thread's folder (`rec/`, beside `other/` and `outside/` in `base`).
struct Fixture {
    base: PathBuf,
    rec: PathBuf,
    /// `rec` resolved.
    root: PathBuf,
}

thread_local! {
    static FIXTURE: RefCell<Option<Fixture>> = const { RefCell::new(None) };
}

fn fixture() -> Fixture {
    let base = std::env::temp_dir()
        .join(format!(
            "hammer-fuzz-commission-{}-{:?}",
            std::process::id(),
            std::thread::current().id()
        ))
        .to_string_lossy()
        .replace(['(', ')'], "");
    let base = PathBuf::from(base);
    let _ = std::fs::remove_dir_all(&base);
    let rec = base.join("rec");
    let write = |p: &Path, text: &str| {
        std::fs::create_dir_all(p.parent().expect("a parent")).expect("fixture folder");
        std::fs::write(p, text).expect("fixture file");
    };
    let trace = "t_s,p_rear_pa,p_front_pa,accel_mps2\n0,0,0,0\n0.00001,0,0,0\n";
    for (stem, bar) in SIDECARS {
        write(&rec.join(format!("{stem}.csv")), trace);
        let side = format!(
            r#"{{"format":"hammer-trace","version":2,"supply_pressure_bar":{bar},"source":"device","calibration_hash":{HASH}}}"#
        );
        write(&rec.join(format!("{stem}.json")), &side);
    }
    write(&rec.join("4.0bar/cycle-001.csv"), trace);
    // A point's reports, with its sidecar as `hammer commission` writes it.
    write(&rec.join("4.0bar/reports.csv"), "seq,valid,flags\n");
    write(
        &rec.join("4.0bar/reports.json"),
        &format!(
            r#"{{"format":"hammer-trace","version":2,"supply_pressure_bar":4,"source":"device","calibration_hash":{HASH}}}"#
        ),
    );
    write(&base.join("outside/secret.csv"), trace);
    write(&base.join("outside/side.json"), r#"{"supply_pressure_bar": 4}"#);
    write(&base.join("other/4.0bar/cycle-000.csv"), trace);
    write(&rec.join("4.0bar/side-out.csv"), trace);
    std::fs::create_dir_all(rec.join("4.0bar/dir.csv")).expect("fixture folder");
    #[cfg(unix)]
    {
        use std::os::unix::fs::symlink;
        let _ = symlink("cycle-000.csv", rec.join("4.0bar/alias.csv"));
        let _ = symlink(base.join("outside/secret.csv"), rec.join("4.0bar/out.csv"));
        let _ = symlink(base.join("outside/side.json"), rec.join("4.0bar/side-out.json"));
        let _ = std::process::Command::new("mkfifo")
            .arg(rec.join("4.0bar/fifo.csv"))
            .status();
    }
    let root = rec.canonicalize().expect("fixture resolves");
    Fixture { base, rec, root }
}

impl Drop for Fixture {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.base);
    }
}

fn run(data: &[u8]) -> u64 {
    FIXTURE.with(|f| {
        let mut f = f.borrow_mut();
        let f = f.get_or_insert_with(fixture);
        let read = std::str::from_utf8(data)
            .map_err(|_| anyhow::anyhow!("not UTF-8"))
            .and_then(|t| Record::parse(t, RECORD_FILE))
            .and_then(|r| Folder::of(&f.rec, r, RECORD_FILE));
        match read {
            Ok(folder) => {
                check(f, &folder);
                bit(0) | bit(1 + folder.points.len().min(6) as u32) | bit(8 + folder.traces().count().min(8) as u32)
            }
            Err(e) => {
                let m = format!("{e:#}");
                assert!(!m.contains("panicked"), "{m}");
                let c = [
                    "`..`",
                    "absolute",
                    "outside the commissioning folder",
                    "not a regular file",
                    "listed twice",
                    "same file",
                    "no operating point",
                    "lists no capture",
                    "gauge pressure",
                    "sidecar",
                    "not JSON",
                    "cut short",
                    "fields and types",
                    "format",
                    "version",
                    "No such file",
                    "UTF-8",
                ]
                .iter()
                .position(|k| m.contains(k))
                .unwrap_or(17);
                bit(20 + c as u32)
            }
        }
    })
}

/// An accepted record's captures and reports: regular files inside the
/// folder once resolved, each once, never the file outside, their sidecars
/// agreeing.
fn check(f: &Fixture, folder: &Folder) {
    assert!(!folder.points.is_empty(), "a record without a point accepted");
    let mut seen = HashSet::new();
    let reports = folder
        .points
        .iter()
        .flat_map(|p| p.reports.iter().map(|r| (r.as_path(), p.supply_bar)));
    for (trace, bar) in folder.traces().chain(reports) {
        let real = trace.canonicalize().expect("an accepted capture resolves");
        assert!(real.starts_with(&f.root), "{} leads out of the folder", trace.display());
        assert!(
            std::fs::metadata(&real).expect("metadata").is_file(),
            "{}",
            trace.display()
        );
        assert!(seen.insert(real.clone()), "{} listed twice", trace.display());
        for (stem, side_bar) in SIDECARS {
            if real == f.root.join(format!("{stem}.csv")) {
                assert!((bar - side_bar).abs() <= SUPPLY_AGREE_BAR, "{stem} at {bar} bar");
            }
        }
    }
    assert_eq!(
        folder.record.calibration_hash, HASH,
        "a capture of another calibration accepted"
    );
}

fn record(points: &str) -> Vec<u8> {
    format!(
        r#"{{"format":"hammer-commission","version":1,"firmware_version":"0.1.0","board":"fuzz","calibration_hash":{HASH},"points":{points}}}"#
    )
    .into_bytes()
}

/// The record as `hammer commission` writes it, and the issue's
/// reproductions (issue 48, items 7–10).
fn seeds() -> Vec<Vec<u8>> {
    let r = Record {
        format: hammer_diagnose::record::RECORD_FORMAT.into(),
        version: hammer_diagnose::record::RECORD_VERSION,
        firmware_version: "0.1.0".into(),
        board: "fuzz".into(),
        calibration_hash: HASH,
        points: vec![
            hammer_diagnose::record::PointRecord {
                supply_bar: 4.0,
                traces: vec!["4.0bar/cycle-000.csv".into(), "4.0bar/cycle-001.csv".into()],
                reports: None,
            },
            hammer_diagnose::record::PointRecord {
                supply_bar: 7.0,
                traces: vec!["7.0bar/cycle-000.csv".into()],
                reports: None,
            },
        ],
    };
    vec![
        serde_json::to_vec_pretty(&r).expect("serialises"),
        record("[]"),
        record(r#"[{"supply_bar":4,"traces":["../../../../etc/shadow"]}]"#),
        record(r#"[{"supply_bar":4,"traces":["/etc/passwd"]}]"#),
        record(r#"[{"supply_bar":4,"traces":["4.0bar/out.csv","4.0bar/alias.csv"]}]"#),
        record(r#"[{"supply_bar":4,"traces":["../other/4.0bar/cycle-000.csv"]}]"#),
        record(r#"[{"supply_bar":4,"traces":["4.0bar/fifo.csv","4.0bar/dir.csv","4.0bar/side-out.csv"]}]"#),
        record(r#"[{"supply_bar":5.5,"traces":["4.0bar/cycle-000.csv"]}]"#),
        record(r#"[{"supply_bar":5.5,"traces":["4.0bar/alias.csv"]}]"#),
        // A point's reports: a missing file, a capture named twice, a path out.
        record(r#"[{"supply_bar":4,"traces":["4.0bar/cycle-000.csv"],"reports":"4.0bar/reports.csv"}]"#),
        record(r#"[{"supply_bar":4,"traces":["4.0bar/cycle-000.csv"],"reports":"4.0bar/cycle-000.csv"}]"#),
        record(r#"[{"supply_bar":4,"traces":["4.0bar/cycle-000.csv"],"reports":"../other/reports.csv"}]"#),
        record(
            r#"[{"supply_bar":4,"traces":["4.0bar/cycle-000.csv"]},{"supply_bar":4.04,"traces":["4.0bar/alias.csv"]}]"#,
        ),
    ]
}
