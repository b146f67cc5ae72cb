//! The offset between the two readings of a cycle's chamber characteristics
//! (issue 47): as the monitor reads them today, from the board's one-cycle
//! raw captures (`hammer_host::drift`: the diagnosis' extractor, its own
//! impacts and friction, the pressures as sampled), and as the board reads
//! them at a cycle's close into its report (`hammer_app::chambers`: half
//! rate, the estimator's impacts and friction, the pressures read back by
//! their group delay). A commissioning record read from captures and windows read
//! from reports differ by this offset, not by any drift.
//!
//! The board's own monitor code (`hammer_app::Monitor`) makes the captures
//! from the simulated hammer's codes, one cycle at a time as the monitor
//! asks for them; every cycle of the same run is also read as the board
//! reports it (`hammer_sim::board_reading`, the board's bytes).
//! Printed per characteristic: each reading's median over the run, the
//! offset (report − capture) and its standard uncertainty from the two
//! medians' spreads.
//!
//! Then the same hammer with a hidden valve delay of 1.5 ms
//! (`valve_delay:tau_s=0.0015`): the front feed's shift from the sound
//! hammer as each reading sees it (the drift either would show).
//!
//! `cargo run --release -p hammer-host --example report_vs_capture -- [SECONDS] [BAR...]`
//! (defaults: 20 s at 4 and 7 bar).

use hammer_app::Monitor;
use hammer_host::diagnose::engine::extractor_for;
use hammer_host::diagnose::features::{feature_name, ESTIMATOR_CHARACTERISTICS};
use hammer_host::drift::{median, readings_of, robust_sd, N_CHARACTERISTICS};
use hammer_sim::simulate::simulate;
use hammer_sim::SimConfig;
use hammer_wire::{DeviceMsg, HostMsg, BLOCK_SAMPLES};

fn main() {
    let args: Vec<f64> = std::env::args().skip(1).filter_map(|a| a.parse().ok()).collect();
    let seconds = args.first().copied().unwrap_or(20.0);
    let bars: Vec<f64> = if args.len() > 1 {
        args[1..].to_vec()
    } else {
        vec![4.0, 7.0]
    };
    for bar in bars {
        let sound = offsets(bar, seconds, None);
        let delayed = offsets(bar, seconds, Some("valve_delay:tau_s=0.0015"));
        println!(
            "  valve delay 1.5 ms at {bar} bar: front feed moved {:+.3} ms read from captures, {:+.3} ms read at the close (difference {:+.3} ms)\n",
            1e3 * (delayed[0] - sound[0]),
            1e3 * (delayed[1] - sound[1]),
            1e3 * ((delayed[1] - sound[1]) - (delayed[0] - sound[0]))
        );
    }
}

/// Prints both readings' medians and their offset; returns the front
/// feed's median as (capture, report).
fn offsets(bar: f64, seconds: f64, effect: Option<&str>) -> [f64; 2] {
    let mut cfg = SimConfig::nominal(bar);
    cfg.effects.apply_spec("coulomb_friction").expect("known effect");
    if let Some(e) = effect {
        cfg.effects.apply_spec(e).expect("known effect");
    }
    cfg.solver.duration_s = seconds;
    let config = cfg.estimator_config(Some(bar)).expect("nominal config");
    let sim = simulate(&cfg).expect("the sound hammer simulates");
    let codes = sim.measured.codes.clone();
    let extractor = extractor_for(&cfg);

    // The board's monitor: one capture at a time.
    let mut monitor = Monitor::new(config, "offset").expect("config");
    let mut captured: Vec<Vec<[u16; 3]>> = Vec::new();
    let mut chunks: Vec<[u16; 3]> = Vec::new();
    let mut ignore = |_: DeviceMsg| {};
    monitor.on_command(HostMsg::StartCapture { cycles: 1 }, 0, &mut ignore);
    for block in codes.chunks(BLOCK_SAMPLES) {
        monitor.on_samples(block, &mut |_| {});
        let mut done = false;
        while let Some(m) = monitor.next_capture_chunk() {
            if let DeviceMsg::Capture(c) = m {
                chunks.extend_from_slice(&c.samples);
                done |= c.offset as usize + c.samples.len() == c.total as usize;
            }
        }
        // The next capture once this one has streamed (the board is idle again).
        if done {
            captured.push(std::mem::take(&mut chunks));
            monitor.on_command(HostMsg::StartCapture { cycles: 1 }, 0, &mut ignore);
        }
    }
    let by_capture: Vec<[f64; N_CHARACTERISTICS]> = captured
        .iter()
        .flat_map(|c| {
            let (trace, _) = hammer_host::capture::to_trace(c, &config, None);
            readings_of(&extractor, &trace, bar)
        })
        .collect();

    // Every cycle as the board reports it: the estimator, then its reader
    // (half rate, at the close), on the same codes.
    let mut board = hammer_sim::board_reading::pipeline(config).expect("config");
    let mut read = Vec::new();
    board.push_block(&codes, &mut |r| read.push(r));
    board.finish(&mut |r| read.push(r));
    // The run's start-up dropped as a record's is.
    let by_report = hammer_host::drift::steady_readings(&read);

    println!(
        "{bar} bar{}, {seconds} s: {} cycles read from {} captures, {} at their close",
        effect.map_or(String::new(), |e| format!(" with {e}")),
        by_capture.len(),
        captured.len(),
        by_report.len()
    );
    println!(
        "  {:<16} {:>13} {:>13} {:>13} {:>11}",
        "characteristic", "capture", "report", "offset", "u(offset)"
    );
    let mut front = [f64::NAN; 2];
    for k in 0..N_CHARACTERISTICS {
        let col = |rs: &[[f64; N_CHARACTERISTICS]]| -> Vec<f64> {
            rs.iter().map(|r| r[k]).filter(|v| v.is_finite()).collect()
        };
        let (cap, rep) = (col(&by_capture), col(&by_report));
        let (mc, mr) = (median(&cap), median(&rep));
        if k == 0 {
            front = [mc, mr];
        }
        // A median's standard error: 1.2533·σ/√n.
        let se = |v: &[f64]| 1.2533 * robust_sd(v) / (v.len() as f64).sqrt();
        let u = (se(&cap).powi(2) + se(&rep).powi(2)).sqrt();
        let name = feature_name(ESTIMATOR_CHARACTERISTICS[k]);
        println!(
            "  {name:<16} {mc:>13.6e} {mr:>13.6e} {:>13.6e} {u:>11.2e}   ({} / {} cycles)",
            mr - mc,
            cap.len(),
            rep.len()
        );
    }
    front
}
