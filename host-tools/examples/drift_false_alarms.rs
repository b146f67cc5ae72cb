//! How often the drift alarm fires on a sound hammer: many commissioning
//! records and a long run of windows, all of the same sound hammer with
//! other noise, read by the monitor's own code (`hammer_host::drift`).
//!
//! Each record is read against every window, so a record whose median came
//! out off by chance shows what it does to every window after it: the
//! record's error is common to all of them, so the windows' "beyond" are
//! not independent, and three in a row come more often than (1/20)³.
//!
//! Cycles are read from long simulated runs (the paper's hammer with its
//! friction, sensor noise on), each run's start-up dropped as a record's
//! is, as the board reports them (`hammer_sim::board_reading`: the
//! estimator and the chambers' reader, the board's bytes): the monitor
//! reads every blow's report, and the record holds the board's reports.
//!
//! `cargo run --release -p hammer-host --example drift_false_alarms -- [WINDOWS] [RECORD_CYCLES] [BAR] [WINDOW_CYCLES]`
//! (defaults: 2000 windows of 10 cycles, records of 30 cycles, 4 bar; 40 records).

use hammer_host::diagnose::features::feature_name;
use hammer_host::drift::{steady_readings, Baseline, Reading, Window, N_CHARACTERISTICS};
use hammer_sim::simulate::simulate;
use hammer_sim::SimConfig;

const RECORDS: usize = 40;
const CONFIRM: usize = 3;
const RUN_S: f64 = 20.0;

fn main() {
    let args: Vec<f64> = std::env::args().skip(1).filter_map(|a| a.parse().ok()).collect();
    let windows = args.first().map_or(2000, |&w| w as usize);
    let record_cycles = args.get(1).map_or(30, |&n| n as usize);
    let bar = args.get(2).copied().unwrap_or(4.0);
    let window = args.get(3).map_or(10, |&k| k as usize);
    let mut cfg = SimConfig::nominal(bar);
    cfg.effects.apply_spec("coulomb_friction").expect("known effect");
    cfg.solver.duration_s = RUN_S;
    let needed = RECORDS * record_cycles + windows * window;

    // Runs of RUN_S each, seeds 1.., two at a time, until enough cycles.
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    let mut readings: Vec<Reading> = Vec::with_capacity(needed);
    let mut seed = 1u64;
    let t0 = std::time::Instant::now();
    while readings.len() < needed {
        let batch: Vec<Vec<Reading>> = std::thread::scope(|s| {
            let jobs: Vec<_> = (0..threads as u64)
                .map(|k| {
                    let mut c = cfg.clone();
                    c.seed = seed + k;
                    s.spawn(move || {
                        let sim = simulate(&c).expect("the sound hammer simulates");
                        let config = c.estimator_config(Some(bar)).expect("nominal config");
                        let mut board = hammer_sim::board_reading::pipeline(config).expect("config");
                        let mut reports = Vec::new();
                        board.push_block(&sim.measured.codes, &mut |r| reports.push(r));
                        // The start-up dropped as a record's is.
                        steady_readings(&reports)
                    })
                })
                .collect();
            jobs.into_iter().map(|j| j.join().expect("no panic")).collect()
        });
        seed += threads as u64;
        for b in batch {
            readings.extend(b);
        }
    }
    println!(
        "{} cycles at {bar} bar from {} runs of {RUN_S} s ({:.0} s)",
        readings.len(),
        seed - 1,
        t0.elapsed().as_secs_f64()
    );
    let (records, rest) = readings.split_at(RECORDS * record_cycles);
    let stream = &rest[..windows * window];

    let mut beyond = [0u64; N_CHARACTERISTICS];
    let mut onsets = [0u64; N_CHARACTERISTICS];
    let mut any_onsets = 0u64;
    let mut records_alarming = 0usize;
    let mut worst = (0u64, 0usize);
    for (r, rec) in records.chunks(record_cycles).enumerate() {
        let mut w = Window::new(Baseline::of(bar, rec), window, CONFIRM);
        let mut was = [false; N_CHARACTERISTICS];
        let mut was_any = false;
        let mut this = 0u64;
        for x in stream {
            let Some(d) = w.push(*x) else { continue };
            for (i, c) in d.characteristics.iter().enumerate() {
                beyond[i] += c.beyond as u64;
                if c.alarm && !was[i] {
                    onsets[i] += 1;
                }
                was[i] = c.alarm;
            }
            if d.alarm() && !was_any {
                any_onsets += 1;
                this += 1;
            }
            was_any = d.alarm();
        }
        records_alarming += (this > 0) as usize;
        if this > worst.0 {
            worst = (this, r);
        }
    }
    let n = (RECORDS * windows) as f64;
    println!(
        "{RECORDS} records of {record_cycles} cycles, each against {windows} windows of {window} cycles, alarm at {CONFIRM} in a row"
    );
    println!("characteristic                  beyond per window   alarm onsets per 10 000 windows");
    for i in 0..N_CHARACTERISTICS {
        println!(
            "{:<30} {:>8.2} %           {:>8.1}",
            feature_name(hammer_host::diagnose::features::ESTIMATOR_CHARACTERISTICS[i]),
            100.0 * beyond[i] as f64 / n,
            1e4 * onsets[i] as f64 / n
        );
    }
    println!(
        "any characteristic: {:.1} alarm onsets per 10 000 windows ({:.2} per 1000 cycles); {records_alarming} of {RECORDS} records alarm at least once; worst record {} onsets",
        1e4 * any_onsets as f64 / n,
        1e3 * any_onsets as f64 / (n * window as f64),
        worst.0
    );
}
