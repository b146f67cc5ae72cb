//! The monitor's received bytes per second with the drift since
//! commissioning on, and without it (issue 47): the emulated board (QEMU,
//! kept to host time, so that the monitor's pauses are the hammer's) at
//! 4 bar, `hammer monitor --headless` reading it through a counting relay
//! (`hammer_link::relay`) until it has `REPORTS` reports.
//!
//! `HAMMER` is the monitor's binary: this tree's, or an earlier one's, to
//! measure the drift read from raw captures (`StartCapture`, one cycle
//! every half second) against the drift read from the reports.
//!
//! `cargo run --release -p hammer-host --example drift_link_bytes -- HAMMER REFERENCE_DIR [REPORTS]`

use std::process::Command;
use std::time::Instant;

use hammer_host::demo::{start_board, DemoArgs, FullRate};
use hammer_host::relay::Relay;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [hammer, reference, ..] = args.as_slice() else {
        eprintln!("usage: drift_link_bytes HAMMER REFERENCE_DIR [REPORTS]");
        std::process::exit(2);
    };
    let reports: u32 = args.get(2).and_then(|n| n.parse().ok()).unwrap_or(400);
    for drift in [false, true] {
        let hammer_args = DemoArgs::for_capture(4.0);
        let full_rate = FullRate::start(&hammer_args, None).expect("the simulator streams");
        let (board, rx, tx) = start_board(false, Some(&full_rate.stimulus), true).expect("the emulated board");
        let relay = Relay::start(rx, tx).expect("a local port");
        let mut cmd = Command::new(hammer);
        cmd.args([
            "monitor",
            "--headless",
            "--port",
            &format!("tcp:127.0.0.1:{}", relay.port),
        ])
        .args(["--exit-after-reports", &reports.to_string()]);
        if drift {
            cmd.args(["--point-bar", "4", "--reference", reference]);
        }
        let t0 = Instant::now();
        let out = cmd.output().expect("the monitor runs");
        let seconds = t0.elapsed().as_secs_f64();
        drop(board);
        let stdout = String::from_utf8_lossy(&out.stdout);
        let readings = stdout
            .lines()
            .filter(|l| l.contains("drift since commissioning"))
            .count();
        println!(
            "{} drift: {} reports in {seconds:.1} s, {} bytes received ({:.1} kB/s), {} commands sent, {} StartCapture, {readings} drift readings{}",
            if drift { "with   " } else { "without" },
            reports,
            relay.to_host_bytes(),
            relay.to_host_bytes() as f64 / seconds / 1e3,
            relay.commands(),
            relay.start_captures(),
            if out.status.success() { "" } else { " (the monitor failed)" }
        );
    }
}
