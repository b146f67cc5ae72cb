//! Parquet written by `hammer` read by a standard engine: DuckDB (Python)
//! reads the hive-partitioned dataset and `hammer estimate --format parquet`
//! with the columns and numbers the CSV has. Without DuckDB the Rust reader
//! checks alone run, and the test says so; under CI (`CI` set, `.ci/run`
//! installs DuckDB) a missing DuckDB fails it.

use std::path::Path;
use std::process::Command;
use std::time::Duration;

use hammer_estimator::fields::FIELDS;
use hammer_estimator::CycleReport;
use hammer_host::parquet_files::{read, PartitionedWriter};

fn duckdb() -> bool {
    let ok = Command::new("python3")
        .args(["-c", "import duckdb"])
        .status()
        .is_ok_and(|s| s.success());
    if !ok {
        assert!(
            std::env::var_os("CI").is_none(),
            "CI is set but Python's duckdb is missing (.ci/run installs it)"
        );
        eprintln!("SKIPPED the DuckDB half: `python3 -m pip install duckdb` to run it");
    }
    ok
}

fn python(script: &str, dir: &Path) -> String {
    let out = Command::new("python3")
        .args(["-c", script])
        .current_dir(dir)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    String::from_utf8(out.stdout).unwrap()
}

#[test]
fn duckdb_reads_a_two_device_dataset_row_for_row() {
    let dir = std::env::temp_dir().join(format!("hammer-pq-e2e-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let t0 = 1_764_000_000_000_000i64;
    // Every other report with its chambers unread (NaN), the others read.
    let reports: Vec<CycleReport> = (0..300u32)
        .map(|k| {
            let mut r = CycleReport {
                seq: k,
                t_impact_us: u64::from(k) * 47_000,
                friction_n: 10.0 + k as f32 * 0.01,
                impact_energy_j: 4.5,
                calibration_hash: 0x7b78_6e0f,
                front_feed_s: 1.57e-3,
                ..Default::default()
            };
            if k % 2 == 1 {
                r.mark_chambers_unread();
            }
            r
        })
        .collect();
    {
        let mut w = PartitionedWriter::with_limits(&dir, 128, Duration::from_secs(60)).unwrap();
        for (k, r) in reports.iter().enumerate() {
            let t = t0 + k as i64 * 47_000;
            w.push("rig-4bar", t, r).unwrap();
            w.push("rig-7bar", t + 10, &CycleReport { friction_n: 16.7, ..*r })
                .unwrap();
        }
        assert_eq!(w.stats().rows_failed, 0);
    }
    // The Rust reader: every report once per device.
    let mut n = 0;
    for device in ["rig-4bar", "rig-7bar"] {
        let part = dir.join(format!("device={device}"));
        for date in std::fs::read_dir(&part).unwrap() {
            for f in std::fs::read_dir(date.unwrap().path()).unwrap() {
                for row in read(&f.unwrap().path()).unwrap() {
                    let r = &reports[row.host_time_us.map(|t| ((t - t0) / 47_000) as usize).unwrap()];
                    let expected = if device == "rig-7bar" {
                        CycleReport { friction_n: 16.7, ..*r }
                    } else {
                        *r
                    };
                    assert!(row.holds(&expected), "{row:?}");
                    n += 1;
                }
            }
        }
    }
    assert_eq!(n, 600);
    if !duckdb() {
        return;
    }
    let out = python(
        "import duckdb\n\
         q = \"select device, count(*), count(distinct seq), min(seq), max(seq), round(avg(friction_n), 4), \
         min(calibration_hash), bool_and(valid), count(*) filter (where isnan(front_feed_s)), \
         count(*) filter (where flags like '%chambers_unread%'), \
         round(avg(front_feed_s) filter (where not isnan(front_feed_s)) * 1000, 3), isnan(avg(front_feed_s)) \
         from read_parquet('**/*.parquet', hive_partitioning=true) \
         group by device order by device\"\n\
         for r in duckdb.sql(q).fetchall(): print(*r)\n\
         print(len(duckdb.sql(\"describe select * from read_parquet('**/*.parquet', hive_partitioning=true)\").fetchall()))",
        &dir,
    );
    let lines: Vec<&str> = out.lines().collect();
    // The unread chambers are NaN to DuckDB (docs/fleet.md says how to aggregate them).
    assert_eq!(
        lines[0], "rig-4bar 300 300 0 299 11.495 2071490063 True 150 150 1.57 True",
        "{out}"
    );
    assert_eq!(
        lines[1], "rig-7bar 300 300 0 299 16.7 2071490063 True 150 150 1.57 True",
        "{out}"
    );
    // device, host_time, the fields, valid, flags, and the date partition.
    assert_eq!(lines[2], (FIELDS.len() + 5).to_string(), "{out}");
    let _ = std::fs::remove_dir_all(&dir);
}
