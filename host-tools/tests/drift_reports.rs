//! The drift since commissioning read from the board's reports alone
//! (issue 47): the emulated board (QEMU, sampling its simulated hammer at
//! the full rate through its ADC model) is commissioned sound at 4 and
//! 7 bar, then runs with a hidden 1.5 ms valve delay under `hammer monitor
//! --reference`. Between the monitor and the board sits a relay
//! (`hammer_link::relay`) that decodes every command the monitor sends, so
//! the test counts the `StartCapture`s: none.
//!
//! The drift the reports show is compared with the shift the monitor read
//! until now, from raw captures: the diagnosis' extractor on the captures
//! of the same board commissioned sound and commissioned delayed.

use std::path::{Path, PathBuf};
use std::process::Command;

use hammer_host::demo::{emulated_board_available, start_board, DemoArgs, FullRate};
use hammer_host::diagnose::engine::extractor_for;
use hammer_host::diagnose::record::Folder;
use hammer_host::drift::baseline::captured;
use hammer_host::drift::median;
use hammer_host::relay::Relay;
use hammer_sim::SimConfig;

const DELAY: &str = "valve_delay:tau_s=0.0015";

fn tmp_dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("hammer-drift-reports-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// `hammer commission --demo` at 4 and 7 bar on the emulated board.
fn commission(out: &Path, effect: Option<&str>) {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_hammer"));
    cmd.args(["commission", "--demo", "--supply-bar", "4", "--supply-bar", "7"])
        .args(["--cycles", "20", "--out"])
        .arg(out);
    if let Some(e) = effect {
        cmd.args(["--effect", e]);
    }
    let o = cmd.output().unwrap();
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{stdout}\n{}", String::from_utf8_lossy(&o.stderr));
    assert!(stdout.contains("reported at 7 bar"), "{stdout}");
}

/// The front feed's median over a record's captures at `bar`, read as the
/// monitor read captures before the board read its chambers.
fn captured_front_feed_s(dir: &Path, bar: f64) -> f64 {
    let folder = Folder::open(dir).unwrap();
    let extractor = extractor_for(&SimConfig::default());
    let point = folder
        .points
        .iter()
        .find(|p| (p.supply_bar - bar).abs() < 0.01)
        .unwrap();
    let feeds: Vec<f64> = captured(&extractor, point)
        .unwrap()
        .iter()
        .map(|r| r[0])
        .filter(|x| x.is_finite())
        .collect();
    assert!(
        feeds.len() >= 10,
        "{} cycles read from the captures at {bar} bar",
        feeds.len()
    );
    median(&feeds)
}

/// One drift line's window and front feed drift, ms: "… (10 cycles,
/// window 3): front_feed_s +1.514±0.032 ms ALARM, …".
fn window_and_front_feed(line: &str) -> (u32, f64, bool) {
    let window: u32 = line
        .split("window ")
        .nth(1)
        .and_then(|s| s.split(')').next())
        .and_then(|s| s.parse().ok())
        .unwrap_or_else(|| panic!("{line}"));
    let v = line.split("front_feed_s ").nth(1).unwrap_or_else(|| panic!("{line}"));
    let (shift, rest) = v.split_once('±').unwrap();
    let alarm = rest.split(',').next().unwrap().contains("ALARM");
    (window, shift.parse().unwrap(), alarm)
}

#[test]
fn a_valve_delay_is_found_from_the_reports_alone() {
    if !emulated_board_available(false) {
        eprintln!("skipped: no emulated board (CI builds it and installs qemu-system-arm)");
        return;
    }
    let dir = tmp_dir("run");
    let (reference, delayed) = (dir.join("ref"), dir.join("delayed"));
    commission(&reference, None);
    commission(&delayed, Some(DELAY));
    for bar in [4.0, 7.0] {
        // The shift the captures show (what the monitor read until now).
        let captured_ms = 1e3 * (captured_front_feed_s(&delayed, bar) - captured_front_feed_s(&reference, bar));

        // The board with the hidden delay, other noise than the records'.
        let (stdout, relay) = monitored(bar, Some(DELAY), 5, 160, &reference);
        // Nothing asked of the board but who it is and its configuration.
        assert!(relay.commands() >= 2, "the relay saw no command");
        assert_eq!(relay.start_captures(), 0, "StartCaptures sent");
        let lines: Vec<(u32, f64, bool)> = stdout
            .lines()
            .filter(|l| l.contains("drift since commissioning"))
            .map(window_and_front_feed)
            .collect();
        assert!(lines.len() >= 10, "{} drift readings\n{stdout}", lines.len());
        // The alarm within three windows, and on from then.
        let first = lines.iter().find(|l| l.2).map(|l| l.0);
        assert!(first.is_some_and(|w| w <= 3), "first alarm at {first:?}\n{stdout}");
        // Within 0.1 ms of the shift the captures show.
        let drifts: Vec<f64> = lines.iter().map(|l| l.1).collect();
        let reported_ms = median(&drifts);
        println!(
            "{bar} bar: front feed drift {reported_ms:+.3} ms from the reports, {captured_ms:+.3} ms from raw captures ({} windows, first alarm at window {})",
            lines.len(),
            first.unwrap()
        );
        assert!(
            (reported_ms - captured_ms).abs() < 0.1,
            "{bar} bar: {reported_ms} ms from the reports, {captured_ms} ms from the captures"
        );
    }
    // The sound hammer with other noise, every blow counted: 3 000 cycles,
    // no alarm.
    let (stdout, relay) = monitored(4.0, None, 6, 3000, &reference);
    assert_eq!(relay.start_captures(), 0);
    let readings: Vec<&str> = stdout
        .lines()
        .filter(|l| l.contains("drift since commissioning"))
        .collect();
    assert!(readings.len() >= 295, "{} readings", readings.len());
    let alarms = readings.iter().filter(|l| l.contains("ALARM")).count();
    let beyond = |name: &str| {
        let n = readings
            .iter()
            .filter(|l| {
                l.split(&format!("{name} "))
                    .nth(1)
                    .is_some_and(|v| v.split(',').next().unwrap().contains("beyond"))
            })
            .count();
        100.0 * n as f64 / readings.len() as f64
    };
    println!(
        "4 bar, sound, 3 000 reported cycles: {} windows, {alarms} alarms; beyond U: front feed {:.1} %, rear feed {:.1} %, exponents {:.1} and {:.1} %",
        readings.len(),
        beyond("front_feed_s"),
        beyond("rear_feed_s"),
        beyond("front_closed_exponent"),
        beyond("rear_closed_exponent")
    );
    assert_eq!(alarms, 0, "alarms on the sound hammer");
    let _ = std::fs::remove_dir_all(&dir);
}

/// `hammer monitor --headless --reference` on the emulated board running
/// the hammer at `bar` (with `effect`, noise `seed`) through a counting
/// relay, until `reports` reports: its output and the relay.
fn monitored(bar: f64, effect: Option<&str>, seed: u64, reports: u32, reference: &Path) -> (String, Relay) {
    let mut hammer = DemoArgs::for_capture(bar);
    hammer.effects = effect.map(String::from).into_iter().collect();
    hammer.seed = seed;
    let full_rate = FullRate::start(&hammer, None).unwrap();
    let (board, rx, tx) = start_board(false, Some(&full_rate.stimulus), false).unwrap();
    let relay = Relay::start(rx, tx).unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_hammer"))
        .args([
            "monitor",
            "--headless",
            "--port",
            &format!("tcp:127.0.0.1:{}", relay.port),
        ])
        .args(["--exit-after-reports", &reports.to_string(), "--drift-cycles", "10"])
        .args(["--point-bar", &bar.to_string(), "--reference"])
        .arg(reference)
        .output()
        .unwrap();
    drop(board);
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(
        out.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    (stdout, relay)
}

/// The sound hammer's cycles as the board reports them (the host's copy of
/// its estimator and reader, the same bytes), the start-up dropped.
fn reported(bar: f64, seconds: f64, seed: u64) -> Vec<hammer_host::drift::Reading> {
    let mut cfg = SimConfig::nominal(bar);
    cfg.effects.apply_spec("coulomb_friction").unwrap();
    cfg.solver.duration_s = seconds;
    cfg.seed = seed;
    let sim = hammer_sim::simulate::simulate(&cfg).unwrap();
    let mut board = hammer_sim::board_reading::pipeline(cfg.estimator_config(Some(bar)).unwrap()).unwrap();
    let mut reports = Vec::new();
    board.push_block(&sim.measured.codes, &mut |r| reports.push(r));
    hammer_host::drift::steady_readings(&reports)
}

/// Every blow counted, the sound hammer raises no alarm: 3 000 cycles with
/// other noise than the record's, in windows of 10 against a record of the
/// cycles a commissioning at 4 bar keeps (about 240 reported). Each
/// characteristic's share of windows beyond their uncertainty is printed;
/// at k = 2 about 5 % are by chance, and none may be far above it.
#[test]
fn the_sound_hammer_raises_no_alarm_over_3000_reported_cycles() {
    use hammer_host::drift::{Baseline, Window, N_CHARACTERISTICS};
    let record = reported(4.0, 12.0, 1);
    assert!(record.len() >= 200, "{} record cycles", record.len());
    let live = reported(4.0, 150.0, 2);
    assert!(live.len() >= 3000, "{} cycles", live.len());
    let mut w = Window::new(Baseline::of(4.0, &record), 10, 3);
    let (mut windows, mut beyond, mut alarms) = (0u32, [0u32; N_CHARACTERISTICS], 0u32);
    let mut names = vec![];
    for r in &live[..3000] {
        let Some(d) = w.push(*r) else { continue };
        windows += 1;
        alarms += d.alarm() as u32;
        for (i, c) in d.characteristics.iter().enumerate() {
            beyond[i] += c.beyond as u32;
        }
        names = d.characteristics.iter().map(|c| c.name.clone()).collect();
    }
    assert_eq!(windows, 300);
    for (name, b) in names.iter().zip(beyond) {
        let share = f64::from(b) / f64::from(windows);
        println!(
            "{name}: {:.1} % of {windows} windows beyond their uncertainty",
            100.0 * share
        );
        assert!(share < 0.12, "{name}: {:.1} %", 100.0 * share);
    }
    assert_eq!(alarms, 0, "alarms on the sound hammer");
}

/// A record made before the board read its chambers (version 1: captures,
/// no reports) still reads: the monitor reads its captures with the host's
/// extractor, says so, carries the offset to the board's reading in every
/// uncertainty, and still finds a valve delay.
#[test]
fn a_record_from_before_the_reports_still_reads() {
    let dir = tmp_dir("v1");
    let reference = dir.join("ref");
    let o = Command::new(env!("CARGO_BIN_EXE_hammer"))
        .args([
            "commission",
            "--demo",
            "--native",
            "--supply-bar",
            "4",
            "--cycles",
            "30",
            "--out",
        ])
        .arg(&reference)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    // As version 1 wrote it: no reports.
    let path = reference.join("commission.json");
    let mut record: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    record["version"] = 1.into();
    for p in record["points"].as_array_mut().unwrap() {
        p.as_object_mut().unwrap().remove("reports");
    }
    std::fs::write(&path, record.to_string()).unwrap();
    std::fs::remove_file(reference.join("4.0bar/reports.csv")).unwrap();
    let run = |effect: Option<&str>| {
        let mut cmd = Command::new(env!("CARGO_BIN_EXE_hammer"));
        cmd.args(["demo", "--native", "--headless", "--supply-bar", "4", "--cycles", "120"])
            .args(["--seed", "4", "--drift-cycles", "10", "--reference"])
            .arg(&reference);
        if let Some(e) = effect {
            cmd.args(["--effect", e]);
        }
        let o = cmd.output().unwrap();
        let stdout = String::from_utf8_lossy(&o.stdout).into_owned();
        assert!(o.status.success(), "{stdout}\n{}", String::from_utf8_lossy(&o.stderr));
        stdout
    };
    let delayed = run(Some(DELAY));
    assert!(delayed.contains("is read from its raw captures"), "{delayed}");
    let lines: Vec<(u32, f64, bool)> = delayed
        .lines()
        .filter(|l| l.contains("drift since commissioning"))
        .map(window_and_front_feed)
        .collect();
    assert!(lines.len() >= 8, "{delayed}");
    assert!(lines.iter().all(|l| (1.0..2.0).contains(&l.1)), "{lines:?}");
    assert!(lines.last().unwrap().2, "{delayed}");
    // The sound hammer against it: no alarm.
    let sound = run(None);
    let alarms = sound
        .lines()
        .filter(|l| l.contains("drift since commissioning") && l.contains("ALARM"))
        .count();
    assert_eq!(alarms, 0, "{sound}");
    let _ = std::fs::remove_dir_all(&dir);
}
