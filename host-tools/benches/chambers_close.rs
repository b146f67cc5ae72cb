//! The chamber characteristics' cost at a cycle's close on the Cortex-M4
//! ISA (`cargo xtask bench-chambers`, which builds the firmware and the
//! profiling plugin first): instructions per reading of one 4 bar cycle on
//! the emulated board, under QEMU with `-icount shift=0` (one instruction a
//! nanosecond of guest time; the board's SysTick at 25 MHz counts 40).
//!
//! The board's side is `firmware/emulated/src/bin/chambers_bench.rs`: the
//! codes of 0.5 s of the paper's hammer at 4 bar with its friction lie in
//! the stimulus' ring before QEMU starts, the configuration record in the
//! bench's exchange. The board runs the estimator over the codes and reads
//! each cycle at its close (`chambers::at_close`) three ways: with the
//! closed fits' log cache (12 000 floats), with a room as long as the
//! window (the track's source, then the logarithms of a closed phase up to
//! half the window; a longer one's computed as read), and so with one
//! track (no track term: the values alike, the uncertainties not widened). Each reading is
//! checked here against the host's reading of the same codes and report,
//! bit for bit: the figures are those of the reading the host trusts.
//! With the profiling plugin the split by function follows (the whole run:
//! the estimator's pass over the codes and every reading).

mod common;
use common::plugin;
use std::sync::atomic::AtomicBool;
use std::time::Duration;

use hammer_estimator::chambers::at_close::{characterise_cycle, Work};
use hammer_estimator::chambers::{ChamberGeometry, Characteristics, Feed};
use hammer_host::emulator::{firmware_elf, qemu_available, Emulator, Icount};
use hammer_host::stimulus::Stimulus;
use hammer_sim::simulate::simulate;
use hammer_sim::SimConfig;
use hammer_wire::stimulus::{BENCH_CONFIG, BENCH_MAGIC, BENCH_OUTPUT, BENCH_RECORD_WORDS, RATE_HZ, SYSCLK_HZ};
use hammer_wire::DeviceConfig;

/// Guest instructions per board clock cycle at `-icount shift=0` (1 ns each).
const INSTRUCTIONS_PER_CYCLE: f64 = 1e9 / SYSCLK_HZ as f64;
/// The board's log cache, floats (the bench binary's `LOG_CACHE`).
const LOG_CACHE: usize = 12_000;

fn feed_words(f: &Option<Feed>) -> [f32; 10] {
    f.map_or([f32::NAN; 10], |f| {
        [
            f.onset_s,
            f.onset_uncertainty_s,
            f.x_m,
            f.p_rear_pa,
            f.p_front_pa,
            f.closed_exponent,
            f.closed_exponent_uncertainty,
            f.feed_area_m2,
            f.feed_area_uncertainty_m2,
            f.dead_volume_offset_m3,
        ]
    })
}

/// The 22 values the board writes, from a reading.
fn values(c: &Characteristics) -> Vec<f32> {
    let mut v = feed_words(&c.front).to_vec();
    v.extend(feed_words(&c.rear));
    v.extend(c.charge.map_or([f32::NAN; 2], |q| [q.rear_j, q.front_j]));
    v
}

fn main() {
    if !qemu_available() {
        eprintln!("qemu-system-arm not installed: apt-get install -y qemu-system-arm");
        std::process::exit(1);
    }
    let bar = 4.0;
    let mut cfg = SimConfig::nominal(bar);
    cfg.solver.duration_s = 0.5;
    cfg.effects.apply_spec("coulomb_friction").unwrap();
    let est = cfg.estimator_config(Some(bar)).unwrap();
    // The configuration as the board reads it back from its record.
    let record = hammer_app::persisted::config_record(&DeviceConfig::from(&est)).expect("record");
    let config = hammer_app::persisted::config_from_record(&record, Some(RATE_HZ as f32)).expect("record reads");
    let codes = simulate(&cfg).unwrap().measured.codes;

    let stimulus = Stimulus::create().expect("stimulus file");
    assert!(stimulus.push(&codes, &AtomicBool::new(false)));
    stimulus.finish();
    let mut input = BENCH_MAGIC.to_le_bytes().to_vec();
    input.resize(BENCH_CONFIG, 0);
    input.extend_from_slice(&record);
    stimulus.write_bench(&input).expect("bench input");

    let plugin = plugin();
    let profile = std::env::temp_dir().join(format!("hammer-chambers-profile-{}.txt", std::process::id()));
    let extra = match &plugin {
        Some(p) => vec![
            "-plugin".to_string(),
            format!("{},out={}", p.display(), profile.display()),
        ],
        None => vec![],
    };
    let elf = firmware_elf().with_file_name("hammer-chambers-bench");
    let mut emu = Emulator::start_with_args(&elf, Some(Icount::COUNT), Some(&stimulus), &extra)
        .expect("the chambers bench (cargo xtask firmware)");
    // QEMU starts the board once its UART has a client.
    let _link = emu.connect(Duration::from_secs(20)).expect("connect");
    let status = emu.wait_exit(Duration::from_secs(600)).expect("qemu");
    assert!(
        status.is_some_and(|s| s.success()),
        "the chambers bench did not end well ({status:?})"
    );

    let out = stimulus.read_bench();
    let word = |k: usize| u32::from_le_bytes(out[BENCH_OUTPUT + 4 * k..BENCH_OUTPUT + 4 * k + 4].try_into().unwrap());
    let read = word(0) as usize;
    assert!(read >= 3, "the board read {read} cycles");

    let reports = hammer_sim::estimation::run(&codes, config).expect("estimator");
    let geo = ChamberGeometry::of(&config);
    let (mut x_room, mut logs_room) = (vec![0.0f32; 10_000], vec![0.0f32; LOG_CACHE]);
    println!(
        "chamber characteristics at a cycle's close on the Cortex-M4 ISA (QEMU -icount shift=0), \
         {bar} bar with coulomb friction, M instructions per reading:"
    );
    println!(
        "  {:>5} {:>7} {:>7} {:>12} {:>12} {:>12} {:>12}",
        "cycle", "sets", "window", "room 12000", "room=window", "one track", "one, no room"
    );
    let mut figures: Vec<[f64; 4]> = Vec::new();
    for k in 0..read {
        let w = |j: usize| word(1 + k * BENCH_RECORD_WORDS + j);
        let (seq, open, close, present) = (w(0), w(1) as usize, w(2) as usize, w(3));
        let t = [w(4), w(5), w(6), w(7)].map(|c| f64::from(c) * INSTRUCTIONS_PER_CYCLE / 1e6);
        assert_eq!(
            present & 0x100,
            0,
            "cycle {seq}: the reading in the window's room differs"
        );
        assert_eq!(present & 0x200, 0, "cycle {seq}: the reading without a room differs");
        let report = reports
            .iter()
            .find(|r| r.seq == seq)
            .expect("the board's cycle among the host's reports");
        let mut work = Work {
            x_m: &mut x_room,
            room: &mut logs_room,
        };
        let host = characterise_cycle(&config, &geo, &codes[open..], close - open, report, true, &mut work);
        assert_eq!(present & 1 == 1, host.is_some(), "cycle {seq}: read by one side only");
        let board: Vec<f32> = (0..22).map(|j| f32::from_bits(w(8 + j))).collect();
        let host = values(&host.unwrap_or_default());
        for (j, (b, h)) in board.iter().zip(&host).enumerate() {
            assert!(
                b.to_bits() == h.to_bits() || (b.is_nan() && h.is_nan()),
                "cycle {seq}, value {j}: board {b}, host {h}"
            );
        }
        let window = hammer_estimator::chambers::at_close::window_samples(close - open, config.dt_s());
        println!(
            "  {seq:>5} {:>7} {window:>7} {:>12.2} {:>12.2} {:>12.2} {:>12.2}",
            close - open,
            t[0],
            t[1],
            t[2],
            t[3]
        );
        figures.push(t);
    }
    let median = |j: usize| {
        let mut v: Vec<f64> = figures.iter().map(|f| f[j]).collect();
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    println!(
        "  median of {read}: two tracks {:.2} M with a room of {LOG_CACHE} floats, {:.2} M with a room as long \
         as the window; one track {:.2} M (room = window), {:.2} M without a room; every two-track reading \
         the host's, bit for bit, and every one-track reading the same with and without a room",
        median(0),
        median(1),
        median(2),
        median(3)
    );
    if plugin.is_some() {
        split(&profile);
    }
    let _ = std::fs::remove_file(&profile);
}

/// The plugin's counts by function over the whole run.
fn split(profile: &std::path::Path) {
    let Ok(text) = std::fs::read_to_string(profile) else {
        println!("per-function split: no profile from the plugin");
        return;
    };
    let mut by_function: std::collections::HashMap<String, u64> = Default::default();
    for line in text.lines() {
        let Some((n, symbol)) = line.split_once('\t') else {
            continue;
        };
        let Ok(n) = n.parse::<u64>() else { continue };
        *by_function
            .entry(format!("{:#}", rustc_demangle::demangle(symbol)))
            .or_default() += n;
    }
    let total: u64 = by_function.values().sum();
    let mut rows: Vec<(String, u64)> = by_function.into_iter().collect();
    rows.sort_by(|a, b| b.1.cmp(&a.1).then_with(|| a.0.cmp(&b.0)));
    println!("per-function split of the whole run (QEMU plugin; the estimator's pass and every reading): {total} instructions");
    for (name, n) in rows.iter().take(20) {
        println!(
            "  {:6.1} M  {:5.1} %  {name}",
            *n as f64 / 1e6,
            *n as f64 * 100.0 / total as f64
        );
    }
}
