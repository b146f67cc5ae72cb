//! A fleet of emulated boards in one monitor, exported: `hammer demo
//! --devices 2 --headless --parquet DIR --influx FILE` prints each board's
//! reports as `[device]` lines, and the Parquet dataset and the line
//! protocol hold every one of them once, with the printed numbers. Needs
//! QEMU and the emulated firmware (`cargo xtask firmware`).

use std::collections::BTreeMap;
use std::path::Path;
use std::process::Command;

use hammer_estimator::fields::{Value, FIELDS};
use hammer_host::influx;
use hammer_host::parquet_files;

/// (seq, t_impact_s, friction_n) of a report line.
fn parse_report(line: &str) -> Option<(u32, f64, f64)> {
    let w: Vec<&str> = line.split_whitespace().collect();
    let at = |k: &str| w.iter().position(|x| *x == k).map(|i| w[i + 1]);
    Some((
        at("cycle")?.parse().ok()?,
        at("t")?.parse().ok()?,
        at("friction")?.parse().ok()?,
    ))
}

fn files(dir: &Path, out: &mut Vec<std::path::PathBuf>) {
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.is_dir() {
            files(&p, out);
        } else {
            out.push(p);
        }
    }
}

#[test]
fn two_boards_print_and_export_every_report_once_with_the_same_numbers() {
    let dir = std::env::temp_dir().join(format!("hammer-fleet-test-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let (pq, lp) = (dir.join("pq"), dir.join("cycles.lp"));
    let out = Command::new(env!("CARGO_BIN_EXE_hammer"))
        .args(["demo", "--headless", "--devices", "2", "--cycles", "15"])
        .args([
            "--parquet",
            pq.to_str().unwrap(),
            "--influx",
            lp.to_str().unwrap(),
            "--site",
            "ci",
        ])
        .output()
        .unwrap();
    let (stdout, stderr) = (
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr),
    );
    assert!(out.status.success(), "{stdout}\n{stderr}");
    // Printed: per device, seq → (t, friction).
    let mut printed: BTreeMap<String, BTreeMap<u32, (f64, f64)>> = BTreeMap::new();
    for l in stdout.lines() {
        let Some((device, rest)) = l.strip_prefix('[').and_then(|l| l.split_once("] ")) else {
            panic!("a line without its device: {l}");
        };
        if let Some((seq, t, f)) = parse_report(rest) {
            assert!(
                printed
                    .entry(device.to_string())
                    .or_default()
                    .insert(seq, (t, f))
                    .is_none(),
                "{device} printed cycle {seq} twice"
            );
        }
    }
    assert_eq!(
        printed.keys().collect::<Vec<_>>(),
        ["demo1-4.0bar", "demo2-7.0bar"],
        "{stdout}"
    );
    for (device, reports) in &printed {
        assert!(reports.len() >= 15, "{device}: {} reports", reports.len());
        let seqs: Vec<u32> = reports.keys().copied().collect();
        assert_eq!(seqs, (0..seqs.len() as u32).collect::<Vec<_>>(), "{device}: no gap");
    }
    // The paper's friction grows with the supply pressure: 10.27 N at 4 bar, 16.7 N at 7.
    let mean_friction = |d: &str| {
        let r = &printed[d];
        r.values().skip(2).map(|v| v.1).sum::<f64>() / (r.len() - 2) as f64
    };
    assert!(
        (mean_friction("demo1-4.0bar") - 10.27).abs() < 1.5,
        "{}",
        mean_friction("demo1-4.0bar")
    );
    assert!(
        (mean_friction("demo2-7.0bar") - 16.7).abs() < 2.0,
        "{}",
        mean_friction("demo2-7.0bar")
    );

    // Parquet: every printed report once, the same numbers.
    let mut paths = vec![];
    files(&pq, &mut paths);
    let seq_i = FIELDS.iter().position(|f| f.name == "seq").unwrap();
    let t_i = FIELDS.iter().position(|f| f.name == "t_impact_s").unwrap();
    let f_i = FIELDS.iter().position(|f| f.name == "friction_n").unwrap();
    let mut stored: BTreeMap<String, BTreeMap<u32, (f64, f64)>> = BTreeMap::new();
    for p in &paths {
        let partition = p
            .parent()
            .unwrap()
            .parent()
            .unwrap()
            .file_name()
            .unwrap()
            .to_string_lossy()
            .into_owned();
        for row in parquet_files::read(p).unwrap() {
            assert_eq!(partition, format!("device={}", row.device));
            assert!(row.host_time_us.is_some());
            let Value::U32(seq) = row.values[seq_i] else { panic!() };
            let v = (row.values[t_i].as_f64(), row.values[f_i].as_f64());
            assert!(
                stored.entry(row.device.clone()).or_default().insert(seq, v).is_none(),
                "stored twice"
            );
        }
    }
    for (device, reports) in &printed {
        for (seq, (t, f)) in reports {
            let (ts, fs) = stored[device][seq];
            assert!(
                (ts - t).abs() < 1e-6 && (fs - f).abs() < 0.006,
                "{device} #{seq}: {ts} {fs} vs {t} {f}"
            );
        }
        // A report past the last printed one may have been exported before the demo stopped.
        assert!(stored[device].len() >= reports.len());
    }

    // Line protocol: the same, tagged.
    let text = std::fs::read_to_string(&lp).unwrap();
    let mut lines: BTreeMap<String, BTreeMap<u32, f64>> = BTreeMap::new();
    for l in text.lines() {
        let p = influx::parse(l).unwrap();
        assert_eq!(p.measurement, influx::MEASUREMENT);
        let tag = |k: &str| p.tags.iter().find(|(n, _)| n == k).map(|(_, v)| v.clone());
        assert_eq!(tag("site").as_deref(), Some("ci"));
        let field = |k: &str| p.fields.iter().find(|(n, _)| n == k).map(|(_, v)| v.clone()).unwrap();
        let seq: u32 = field("seq").trim_end_matches('i').parse().unwrap();
        let device = tag("device").unwrap();
        assert!(
            lines
                .entry(device)
                .or_default()
                .insert(seq, field("friction_n").parse().unwrap())
                .is_none(),
            "a line twice"
        );
    }
    for (device, reports) in &printed {
        for (seq, (_, f)) in reports {
            assert!((lines[device][seq] - f).abs() < 0.006, "{device} #{seq}");
        }
    }
    assert!(
        stderr.contains("0 not written") && stderr.contains("0 not delivered"),
        "{stderr}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn ports_are_named_from_their_paths_or_by_the_user() {
    use hammer_host::monitor::{device_name, named_port};
    assert_eq!(named_port("/dev/ttyACM0"), ("ttyACM0".into(), "/dev/ttyACM0".into()));
    assert_eq!(named_port("rig4=/dev/ttyACM1"), ("rig4".into(), "/dev/ttyACM1".into()));
    assert_eq!(
        named_port("tcp:127.0.0.1:4000"),
        ("tcp_127.0.0.1_4000".into(), "tcp:127.0.0.1:4000".into())
    );
    assert_eq!(device_name("a b/c d"), "c_d");
    // Two devices of one name would share logs and partitions: refused.
    let out = Command::new(env!("CARGO_BIN_EXE_hammer"))
        .args([
            "monitor",
            "--headless",
            "--port",
            "x=tcp:127.0.0.1:1",
            "--port",
            "x=tcp:127.0.0.1:2",
        ])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("two devices are named \"x\""));
}

/// The Grafana dashboard in docs/ asks only for what the line protocol
/// writes: its measurement, its tags, fields of the report's table.
#[test]
fn the_grafana_dashboard_queries_the_line_protocol_schema() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../docs/grafana/hammer-fleet.json");
    let d: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
    let panels = d["panels"].as_array().unwrap();
    let mut plotted = vec![];
    for p in panels {
        for t in p["targets"].as_array().unwrap() {
            let q = t["query"].as_str().unwrap();
            assert!(q.contains(&format!("FROM \"{}\"", influx::MEASUREMENT)), "{q}");
            assert!(q.contains("GROUP BY time($__interval), \"device\""), "{q}");
            let field = q.split('"').nth(1).unwrap();
            assert!(FIELDS.iter().any(|f| f.name == field), "{field} is not a report field");
            plotted.push(field.to_string());
        }
    }
    for needed in ["friction_n", "impact_energy_j", "frequency_hz", "wear_index_j"] {
        assert!(plotted.iter().any(|f| f == needed), "the dashboard lacks {needed}");
    }
}
