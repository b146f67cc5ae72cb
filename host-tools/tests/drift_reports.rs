//! The drift since commissioning read from the board's reports alone
//! (issue 47): the emulated board (QEMU, sampling its simulated hammer at
//! the full rate through its ADC model) is commissioned sound at 4 and
//! 7 bar, then runs with a hidden 1.5 ms valve delay under `hammer monitor
//! --reference`. Between the monitor and the board sits a relay that
//! decodes every command the monitor sends, so the test counts the
//! `StartCapture`s: none.
//!
//! The drift the reports show is compared with the shift the monitor read
//! until now, from raw captures: the diagnosis' extractor on the captures
//! of the same board commissioned sound and commissioned delayed.

use std::io::{Read, Write};
use std::net::{TcpListener, TcpStream};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::atomic::{AtomicBool, AtomicU32, Ordering};
use std::sync::Arc;
use std::time::Duration;

use hammer_host::demo::{emulated_board_available, start_board, DemoArgs, FullRate};
use hammer_host::diagnose::engine::extractor_for;
use hammer_host::diagnose::record::Folder;
use hammer_host::drift::{median, readings_of};
use hammer_sim::SimConfig;
use hammer_wire::{Decoder, HostMsg};

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
    let feeds: Vec<f64> = point
        .traces
        .iter()
        .flat_map(|t| {
            let (trace, _, _) = hammer_trace::import::read_trace(t, None).unwrap();
            readings_of(&extractor, &trace, bar)
        })
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

/// Relays bytes between the monitor (accepted on `listener`) and the
/// board, counting the commands the monitor sends: (all, StartCapture).
fn relay(
    listener: TcpListener,
    mut board_rx: Box<dyn Read + Send>,
    mut board_tx: Box<dyn Write + Send>,
    stop: Arc<AtomicBool>,
) -> (Arc<AtomicU32>, Arc<AtomicU32>) {
    let (commands, captures) = (Arc::new(AtomicU32::new(0)), Arc::new(AtomicU32::new(0)));
    let (c, k) = (commands.clone(), captures.clone());
    std::thread::spawn(move || {
        let (monitor, _) = listener.accept().unwrap();
        monitor.set_read_timeout(Some(Duration::from_millis(20))).unwrap();
        let mut to_monitor = monitor.try_clone().unwrap();
        let stop2 = stop.clone();
        std::thread::spawn(move || {
            let mut buf = [0u8; 4096];
            while !stop2.load(Ordering::Relaxed) {
                match board_rx.read(&mut buf) {
                    Ok(0) => break,
                    Ok(n) => {
                        if to_monitor.write_all(&buf[..n]).is_err() {
                            break;
                        }
                    }
                    Err(_) => {}
                }
            }
        });
        let mut from_monitor: TcpStream = monitor;
        let mut dec: Decoder<512> = Decoder::new();
        let mut buf = [0u8; 512];
        while !stop.load(Ordering::Relaxed) {
            match from_monitor.read(&mut buf) {
                Ok(0) => break,
                Ok(n) => {
                    for &b in &buf[..n] {
                        if let Some(Ok(m)) = dec.push::<HostMsg>(b) {
                            c.fetch_add(1, Ordering::Relaxed);
                            if matches!(m, HostMsg::StartCapture { .. }) {
                                k.fetch_add(1, Ordering::Relaxed);
                            }
                        }
                    }
                    if board_tx.write_all(&buf[..n]).is_err() {
                        break;
                    }
                }
                Err(_) => {}
            }
        }
    });
    (commands, captures)
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
        let mut hammer = DemoArgs::for_capture(bar);
        hammer.effects = vec![DELAY.into()];
        hammer.seed = 5;
        let full_rate = FullRate::start(&hammer, None).unwrap();
        let (board, rx, tx) = start_board(false, Some(&full_rate.stimulus), false).unwrap();
        let listener = TcpListener::bind("127.0.0.1:0").unwrap();
        let port = listener.local_addr().unwrap().port();
        let stop = Arc::new(AtomicBool::new(false));
        let (commands, captures) = relay(listener, rx, tx, stop.clone());
        let out = Command::new(env!("CARGO_BIN_EXE_hammer"))
            .args(["monitor", "--headless", "--port", &format!("tcp:127.0.0.1:{port}")])
            .args(["--exit-after-reports", "160", "--drift-cycles", "10"])
            .args(["--point-bar", &bar.to_string(), "--reference"])
            .arg(&reference)
            .output()
            .unwrap();
        stop.store(true, Ordering::Relaxed);
        drop(board);
        let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
        assert!(
            out.status.success(),
            "{stdout}\n{}",
            String::from_utf8_lossy(&out.stderr)
        );

        // Nothing asked of the board but who it is and its configuration.
        assert!(commands.load(Ordering::Relaxed) >= 2, "the relay saw no command");
        assert_eq!(captures.load(Ordering::Relaxed), 0, "StartCaptures sent");
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
    let _ = std::fs::remove_dir_all(&dir);
}
