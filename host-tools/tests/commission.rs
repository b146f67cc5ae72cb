//! Commissioning and the diagnosis against it, as a bench engineer runs
//! them: `hammer commission --demo --native` records the firmware's app at
//! 4 and 7 bar, the same board is recorded again with a hidden valve delay,
//! and `hammer diagnose --reference DIR` names it from the front chamber's
//! feed. (The same runs on QEMU's emulated board in about 5 minutes,
//! measured in docs/diagnosis.md; the test takes the native app.)

use std::path::{Path, PathBuf};
use std::process::Command;

fn hammer(args: &[&str]) -> (i32, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_hammer"))
        .args(args)
        .output()
        .expect("runs");
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

fn tmp_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("hammer-commission-test-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    dir
}

fn commission(out: &Path, effect: Option<&str>) {
    let mut args = vec![
        "commission",
        "--demo",
        "--native",
        "--supply-bar",
        "4",
        "--supply-bar",
        "7",
        "--cycles",
        "30",
    ];
    if let Some(e) = effect {
        args.extend(["--effect", e]);
    }
    args.extend(["--out", out.to_str().unwrap()]);
    let (code, stdout, stderr) = hammer(&args);
    assert_eq!(code, 0, "{stdout}\n{stderr}");
    assert!(
        stdout.contains("30 cycles captured and") && stdout.contains("reported at 7 bar"),
        "{stdout}"
    );
}

/// The record says what it was made with, and a later recalibration makes
/// it stale: refused unless told.
#[test]
fn a_valve_delay_is_named_against_the_commissioning_record_and_a_stale_one_is_refused() {
    let reference = tmp_dir("ref");
    let measured = tmp_dir("meas");
    commission(&reference, None);
    commission(&measured, Some("valve_delay:tau_s=0.0015"));

    let record: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(reference.join("commission.json")).unwrap()).unwrap();
    assert_eq!(record["format"], "hammer-commission");
    assert!(
        record["firmware_version"]
            .as_str()
            .is_some_and(|v| v.split('.').count() == 3),
        "{record}"
    );
    let points = record["points"].as_array().unwrap();
    assert_eq!(points.len(), 2);
    assert_eq!(points[1]["supply_bar"], 7.0);
    assert_eq!(points[0]["traces"].as_array().unwrap().len(), 30);
    let side: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(reference.join("4.0bar/cycle-000.json")).unwrap()).unwrap();
    assert_eq!(side["calibration_hash"], record["calibration_hash"]);
    assert_eq!(side["supply_pressure_bar"], 4.0);

    let out = tmp_dir("diag");
    let (code, stdout, stderr) = hammer(&[
        "diagnose",
        "--measured",
        measured.to_str().unwrap(),
        "--reference",
        reference.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{stdout}\n{stderr}");
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap();
    assert_eq!(report["verdict"]["effects"][0], "valve_delay", "{stdout}");
    let tau = report["verdict"]["params"]["tau_s"].as_f64().unwrap();
    assert!((1.2e-3..=1.8e-3).contains(&tau), "tau {tau} s\n{stdout}");
    // The evidence is the front chamber's feed, later than in the record.
    let front = report["chambers"]
        .as_array()
        .unwrap()
        .iter()
        .find(|c| c["feature"] == "front_feed_s")
        .unwrap();
    assert!(front["z"].as_f64().unwrap() >= 3.0, "{front}");
    // The table gives the hammer's own values beside the change: the
    // record's onset (the emulated board's hammer is the model's, so about
    // the nominal model's), and a change of about the delay (the model's
    // port moves 1.0–1.2 τ, docs/estimator.md).
    let value = |k: &str| front[k].as_f64().unwrap_or(f64::NAN);
    let change = value("measured") - value("nominal");
    assert!((1.2e-3..=2.0e-3).contains(&change), "change {change} s: {front}");
    assert!((value("reference") - value("nominal")).abs() < 0.3e-3, "{front}");
    assert!(value("recalibrated").is_finite(), "{front}");
    let md = std::fs::read_to_string(out.join("report.md")).unwrap();
    assert!(md.contains("| quantity | reference record | now | change |"), "{md}");

    // A recalibration since: the measured folder (its record and every
    // capture, which must agree) carries another hash.
    let rehash = |path: &Path| {
        let mut v: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
        v["calibration_hash"] = serde_json::json!(12345);
        std::fs::write(path, v.to_string()).unwrap();
    };
    rehash(&measured.join("commission.json"));
    for point in ["4.0bar", "7.0bar"] {
        for e in std::fs::read_dir(measured.join(point)).unwrap() {
            let p = e.unwrap().path();
            if p.extension().is_some_and(|x| x == "json") {
                rehash(&p);
            }
        }
    }
    let args = [
        "diagnose",
        "--measured",
        measured.to_str().unwrap(),
        "--reference",
        reference.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ];
    let (code, _, stderr) = hammer(&args);
    assert_ne!(code, 0);
    assert!(
        stderr.contains("stale") && stderr.contains("--allow-stale-reference"),
        "{stderr}"
    );
    let mut told = args.to_vec();
    told.push("--allow-stale-reference");
    let (code, stdout, stderr) = hammer(&told);
    assert_eq!(code, 0, "{stdout}\n{stderr}");
    assert!(stderr.contains("stale"), "{stderr}");
    for d in [reference, measured, out] {
        let _ = std::fs::remove_dir_all(d);
    }
}

/// A fleet read against a record of three operating points (issue 47):
/// the emulated board is commissioned at 4, 5.5 and 7 bar (QEMU, its
/// hammer sampled at the full rate), then `hammer demo --devices 3` runs
/// one emulated board at each pressure with a hidden 1.5 ms valve delay.
/// No board's configuration holds its supply pressure: each is read
/// against the record's point at its own pressure (the demo's link knows
/// it), from its reports. Every front feed drifts later by about the delay
/// (true shift 1.3–1.5 ms at 4 bar, 1.8 at 7 on the model;
/// docs/estimator.md), beyond its uncertainty, and every board raises the
/// alarm.
#[test]
fn a_fleet_reads_each_board_against_the_records_point_at_its_own_pressure() {
    if !hammer_host::demo::emulated_board_available(false) {
        eprintln!("skipped: no emulated board (CI builds it and installs qemu-system-arm)");
        return;
    }
    let dir = tmp_dir("fleet");
    let reference = dir.join("ref");
    let (code, stdout, stderr) = hammer(&[
        "commission",
        "--demo",
        "--supply-bar",
        "4",
        "--supply-bar",
        "5.5",
        "--supply-bar",
        "7",
        "--cycles",
        "10",
        "--out",
        reference.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{stdout}\n{stderr}");
    let out = Command::new(env!("CARGO_BIN_EXE_hammer"))
        .args(["demo", "--headless", "--devices", "3", "--supply-bar", "4"])
        .args([
            "--cycles",
            "200",
            "--drift-cycles",
            "10",
            "--effect",
            "valve_delay:tau_s=0.0015",
        ])
        .arg("--reference")
        .arg(&reference)
        .output()
        .expect("runs");
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(out.status.success(), "{stdout}\n{stderr}");
    for (device, bar) in [("demo1-4.0bar", "4"), ("demo2-5.5bar", "5.5"), ("demo3-7.0bar", "7")] {
        let lines: Vec<&str> = stdout
            .lines()
            .filter(|l| l.starts_with(&format!("[{device}]")) && l.contains("drift since commissioning"))
            .collect();
        assert!(
            lines.len() >= 3,
            "{device}: {} drift lines\n{stdout}\n{stderr}",
            lines.len()
        );
        for l in &lines {
            assert!(l.contains(&format!("at {bar} bar")), "{l}");
            // "front_feed_s +1.514±0.032 ms"
            let v = l.split("front_feed_s ").nth(1).expect("front feed drift");
            let (shift, rest) = v.split_once('±').expect("±");
            let u: f64 = rest.split_whitespace().next().unwrap().parse().unwrap();
            let shift: f64 = shift.parse().unwrap();
            assert!((1.0..2.2).contains(&shift) && u < 0.3 && shift > u, "{l}");
        }
        assert!(
            lines.last().unwrap().contains("front_feed_s") && lines.last().unwrap().contains("ALARM"),
            "{device}: {}",
            lines.last().unwrap()
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// A commissioning folder as `hammer commission` lays it out, made from
/// simulated captures (cheaper than the demo board): `points` gives each
/// point's supply pressure, the captures' paths as the record lists them,
/// and the pressure the captures are simulated at (their sidecars say it).
/// Only paths of the form `<bar>bar/cycle-NNN.csv` are simulated.
fn simulated_record(dir: &Path, points: &[(f64, &[&str], f64)]) {
    std::fs::create_dir_all(dir).unwrap();
    for (_, traces, sim_bar) in points {
        for t in traces.iter().filter(|t| t.contains("bar/cycle-")) {
            let path = dir.join(t);
            if path.exists() {
                continue;
            }
            std::fs::create_dir_all(path.parent().unwrap()).unwrap();
            let (code, _, stderr) = hammer(&[
                "simulate",
                "--supply-bar",
                &sim_bar.to_string(),
                "--duration",
                "0.2",
                "--seed",
                "1",
                "--out",
                path.to_str().unwrap(),
            ]);
            assert_eq!(code, 0, "{stderr}");
        }
    }
    write_record(dir, points);
}

fn write_record(dir: &Path, points: &[(f64, &[&str], f64)]) {
    let points: Vec<serde_json::Value> = points
        .iter()
        .map(|(bar, traces, _)| serde_json::json!({"supply_bar": bar, "traces": traces}))
        .collect();
    let record = serde_json::json!({
        "format": "hammer-commission", "version": 1, "firmware_version": "0.1.0",
        "board": "sim", "calibration_hash": 0x1234, "points": points,
    });
    std::fs::write(dir.join("commission.json"), record.to_string()).unwrap();
}

/// `hammer` with `args`, killed (and the test failed) if it has not
/// finished within `seconds`: a refused FIFO must not hang it.
fn hammer_within(args: &[&str], seconds: u64) -> (i32, String, String) {
    use std::io::Read;
    let mut child = Command::new(env!("CARGO_BIN_EXE_hammer"))
        .args(args)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("runs");
    let start = std::time::Instant::now();
    let status = loop {
        if let Some(s) = child.try_wait().unwrap() {
            break s;
        }
        if start.elapsed().as_secs() >= seconds {
            let _ = child.kill();
            let _ = child.wait();
            panic!("hammer {args:?} still running after {seconds} s");
        }
        std::thread::sleep(std::time::Duration::from_millis(50));
    };
    let (mut out, mut err) = (String::new(), String::new());
    child.stdout.take().unwrap().read_to_string(&mut out).unwrap();
    child.stderr.take().unwrap().read_to_string(&mut err).unwrap();
    (status.code().unwrap_or(-1), out, err)
}

/// Each command that reads a record (`diagnose --reference` and
/// `--measured`, `monitor --reference`) refuses `dir` with exit 2 and an
/// error containing every one of `says`, without hanging and without the
/// first line of /etc/passwd (`root:`).
fn refused_everywhere(dir: &Path, measured: &Path, says: &[&str]) {
    let d = dir.to_str().unwrap();
    let m = measured.to_str().unwrap();
    let out = dir.with_extension("out");
    let o = out.to_str().unwrap();
    for args in [
        vec!["diagnose", "--measured", m, "--reference", d, "--out", o],
        vec!["diagnose", "--measured", d, "--out", o],
        vec!["monitor", "--port", "tcp:127.0.0.1:9", "--headless", "--reference", d],
    ] {
        let (code, stdout, stderr) = hammer_within(&args, 60);
        assert_eq!(code, 2, "{args:?}\n{stdout}\n{stderr}");
        for s in says {
            assert!(stderr.contains(s), "{args:?}: not `{s}` in\n{stderr}");
        }
        assert!(!stderr.contains("root:") && !stderr.contains("panicked"), "{stderr}");
        assert!(!out.join("report.json").exists(), "{args:?} wrote a report");
    }
}

/// A record's captures are relative paths inside its folder, regular files
/// listed once (issue 48, item 7): `../../../../etc/shadow`, an absolute
/// path, a symbolic link to /etc/passwd, a path or a link into another
/// record's folder and a FIFO (in place of a capture or of its sidecar) are
/// refused by name, never opened.
#[test]
fn a_record_is_confined_to_its_folder() {
    let base = tmp_dir("confined");
    let good = base.join("good");
    simulated_record(&good, &[(4.0, &["4.0bar/cycle-000.csv"], 4.0)]);
    let other = base.join("other");
    simulated_record(&other, &[(4.0, &["4.0bar/cycle-000.csv"], 4.0)]);
    let measured = good.join("4.0bar/cycle-000.csv");
    // The good record is read (and not refused by the checks below).
    let (code, stdout, stderr) = hammer_within(
        &[
            "diagnose",
            "--measured",
            measured.to_str().unwrap(),
            "--reference",
            good.to_str().unwrap(),
            "--out",
            base.join("good.out").to_str().unwrap(),
        ],
        120,
    );
    assert_eq!(code, 0, "{stdout}\n{stderr}");

    let bad = base.join("bad");
    let cases: [(&str, &[&str]); 5] = [
        ("../../../../etc/shadow", &["`..`"]),
        ("/etc/passwd", &["absolute path"]),
        ("../other/4.0bar/cycle-000.csv", &["`..`"]),
        ("4.0bar/passwd.csv", &["passwd.csv", "outside the commissioning folder"]),
        ("4.0bar/linked.csv", &["linked.csv", "outside the commissioning folder"]),
    ];
    simulated_record(&bad, &[(4.0, &["4.0bar/cycle-000.csv"], 4.0)]);
    std::os::unix::fs::symlink("/etc/passwd", bad.join("4.0bar/passwd.csv")).unwrap();
    std::os::unix::fs::symlink(other.join("4.0bar/cycle-000.csv"), bad.join("4.0bar/linked.csv")).unwrap();
    for (path, says) in cases {
        write_record(&bad, &[(4.0, &["4.0bar/cycle-000.csv", path], 4.0)]);
        let mut says = says.to_vec();
        says.extend(["commission.json", path]);
        refused_everywhere(&bad, &measured, &says);
    }
    // A FIFO as a capture, then as a capture's sidecar.
    let fifo = |p: &Path| {
        let ok = Command::new("mkfifo").arg(p).status().expect("mkfifo").success();
        assert!(ok, "mkfifo {}", p.display());
    };
    fifo(&bad.join("4.0bar/fifo.csv"));
    write_record(&bad, &[(4.0, &["4.0bar/cycle-000.csv", "4.0bar/fifo.csv"], 4.0)]);
    refused_everywhere(&bad, &measured, &["fifo.csv", "not a regular file"]);
    let side = bad.join("4.0bar/cycle-000.json");
    std::fs::remove_file(&side).unwrap();
    fifo(&side);
    write_record(&bad, &[(4.0, &["4.0bar/cycle-000.csv"], 4.0)]);
    refused_everywhere(&bad, &measured, &["cycle-000.json", "not a regular file"]);
    // The record itself a link to /etc/passwd.
    std::fs::remove_file(bad.join("commission.json")).unwrap();
    std::os::unix::fs::symlink("/etc/passwd", bad.join("commission.json")).unwrap();
    refused_everywhere(
        &bad,
        &measured,
        &["commission.json", "outside the commissioning folder"],
    );
    let _ = std::fs::remove_dir_all(&base);
}

/// A record without an operating point (issue 48, item 8) was ignored by
/// `diagnose --reference`, which then read the model alone: refused by
/// every command, as the monitor already did.
#[test]
fn a_record_without_points_is_refused() {
    let base = tmp_dir("empty");
    let dir = base.join("ref");
    simulated_record(&dir, &[(4.0, &["4.0bar/cycle-000.csv"], 4.0)]);
    write_record(&dir, &[]);
    refused_everywhere(
        &dir,
        &dir.join("4.0bar/cycle-000.csv"),
        &["commission.json", "no operating point"],
    );
    let _ = std::fs::remove_dir_all(&base);
}

/// The record's supply pressure and calibration hash agree with its
/// captures' sidecars (issue 48, item 9): a point relabelled 4 → 5.5 bar
/// (τ = 0.78 ms read where the truth was 1.5) and a capture of another
/// calibration are refused, naming the sidecar and both values.
#[test]
fn a_record_agrees_with_its_captures_sidecars() {
    let base = tmp_dir("agree");
    let dir = base.join("ref");
    simulated_record(&dir, &[(5.5, &["4.0bar/cycle-000.csv"], 4.0)]);
    let measured = dir.join("4.0bar/cycle-000.csv");
    refused_everywhere(&dir, &measured, &["cycle-000.json", "5.5 bar", "4 bar"]);
    // Within the stated tolerance the record's pressure stands.
    write_record(&dir, &[(4.004, &["4.0bar/cycle-000.csv"], 4.0)]);
    let (code, stdout, stderr) = hammer_within(
        &[
            "diagnose",
            "--measured",
            measured.to_str().unwrap(),
            "--reference",
            dir.to_str().unwrap(),
            "--out",
            base.join("out").to_str().unwrap(),
        ],
        120,
    );
    assert_eq!(code, 0, "{stdout}\n{stderr}");
    write_record(&dir, &[(4.0, &["4.0bar/cycle-000.csv"], 4.0)]);
    let side_path = dir.join("4.0bar/cycle-000.json");
    let mut side: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&side_path).unwrap()).unwrap();
    side["calibration_hash"] = serde_json::json!(0xbeef);
    std::fs::write(&side_path, side.to_string()).unwrap();
    refused_everywhere(&dir, &measured, &["cycle-000.json", "00001234", "0000beef"]);
    let _ = std::fs::remove_dir_all(&base);
}

/// Two supply pressures that name one point folder (issue 48, item 10:
/// `--supply-bar 4 --supply-bar 4.04` wrote both into `4.0bar/`, losing
/// the 4 bar captures) are refused before any capture, among the arguments
/// and against a folder's recorded points; a record that lists one file
/// for two points, by one name or two, is refused by the reader.
#[test]
fn point_folders_never_collide() {
    let base = tmp_dir("collide");
    let dir = base.join("ref");
    let d = dir.to_str().unwrap();
    let commission = |bars: &[&str]| {
        let mut args = vec!["commission", "--demo", "--native", "--cycles", "1", "--out", d];
        for b in bars {
            args.extend(["--supply-bar", b]);
        }
        hammer_within(&args, 60)
    };
    let (code, stdout, stderr) = commission(&["4", "4.04"]);
    assert_eq!(code, 2, "{stdout}\n{stderr}");
    assert!(stderr.contains("4.0bar") && stderr.contains("4.04"), "{stderr}");
    assert!(!dir.join("4.0bar").exists(), "captured before refusing");

    simulated_record(&dir, &[(4.0, &["4.0bar/cycle-000.csv"], 4.0)]);
    let before = std::fs::read(dir.join("4.0bar/cycle-000.csv")).unwrap();
    let (code, stdout, stderr) = commission(&["4.04"]);
    assert_eq!(code, 2, "{stdout}\n{stderr}");
    assert!(stderr.contains("4.0bar") && stderr.contains("4 bar point"), "{stderr}");
    assert_eq!(std::fs::read(dir.join("4.0bar/cycle-000.csv")).unwrap(), before);

    let measured = dir.join("4.0bar/cycle-000.csv");
    write_record(
        &dir,
        &[
            (4.0, &["4.0bar/cycle-000.csv"], 4.0),
            (4.004, &["4.0bar/cycle-000.csv"], 4.0),
        ],
    );
    refused_everywhere(&dir, &measured, &["commission.json", "listed twice"]);
    std::os::unix::fs::symlink("cycle-000.csv", dir.join("4.0bar/alias.csv")).unwrap();
    write_record(
        &dir,
        &[
            (4.0, &["4.0bar/cycle-000.csv"], 4.0),
            (4.004, &["4.0bar/alias.csv"], 4.0),
        ],
    );
    refused_everywhere(&dir, &measured, &["alias.csv", "same file"]);
    let _ = std::fs::remove_dir_all(&base);
}
