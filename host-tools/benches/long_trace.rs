//! Memory and throughput of `hammer estimate` on a long trace: an hour at
//! 100 kS/s is 360 M rows (about 14 GB of CSV), so the trace is never
//! written to disk. A simulated stretch of whole cycles (impact to impact,
//! so the loop has no seam) is repeated with time running on, piped into
//! `hammer estimate /dev/stdin`, and the process's peak resident memory
//! (VmHWM) is read while it runs.
//!
//! `cargo bench -p hammer-host --bench long_trace -- [--minutes N]` (60 by
//! default); prints rows, rows/s, cycles reported and valid, peak RSS.

use std::io::{BufRead, BufReader, BufWriter, Write};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use hammer_sim::simulate::simulate;
use hammer_sim::SimConfig;

/// The bound for an hour of trace.
const RSS_LIMIT_MB: f64 = 100.0;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let minutes: f64 = args
        .iter()
        .position(|a| a == "--minutes")
        .and_then(|i| args.get(i + 1))
        .map_or(60.0, |m| m.parse().expect("--minutes takes a number"));

    // Ten whole cycles at 4 bar with the paper's friction, after the start-up.
    let mut cfg = SimConfig::nominal(4.0);
    cfg.solver.duration_s = 0.8;
    cfg.effects.apply_spec("coulomb_friction").expect("known effect");
    let sim = simulate(&cfg).expect("simulates");
    let trace = sim.trace();
    let cycles = &sim.run.cycles;
    assert!(cycles.len() >= 13, "{} cycles in 0.8 s", cycles.len());
    let index = |t_s: f64| (t_s / trace.dt_s).round() as usize;
    let (from, to) = (index(cycles[2].t_impact_s), index(cycles[12].t_impact_s));
    // Everything but the time column, formatted once.
    let rows: Vec<String> = (from..to)
        .map(|i| {
            format!(
                "{},{},{}\n",
                trace.p_rear_pa[i], trace.p_front_pa[i], trace.accel_mps2[i]
            )
        })
        .collect();
    let total_rows = (minutes * 60.0 / trace.dt_s).round() as u64;
    let expected_cycles = total_rows as f64 / rows.len() as f64 * 10.0;

    let mut child = Command::new(env!("CARGO_BIN_EXE_hammer"))
        .args(["estimate", "/dev/stdin", "--supply-bar", "4", "--format", "jsonl"])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .spawn()
        .expect("runs hammer");
    let pid = child.id();
    let mut stdin = BufWriter::with_capacity(1 << 20, child.stdin.take().expect("stdin"));
    let stdout = child.stdout.take().expect("stdout");
    let reader = std::thread::spawn(move || {
        let (mut n, mut valid) = (0u64, 0u64);
        for line in BufReader::new(stdout).lines() {
            let line = line.expect("reads reports");
            n += 1;
            valid += u64::from(line.contains("\"valid\":true"));
        }
        (n, valid)
    });
    let peak = std::sync::Arc::new(std::sync::atomic::AtomicU64::new(0));
    let watcher = {
        let peak = peak.clone();
        std::thread::spawn(move || {
            while let Ok(status) = std::fs::read_to_string(format!("/proc/{pid}/status")) {
                if let Some(kb) = status
                    .lines()
                    .find_map(|l| l.strip_prefix("VmHWM:"))
                    .and_then(|v| v.trim().trim_end_matches("kB").trim().parse::<u64>().ok())
                {
                    peak.fetch_max(kb, std::sync::atomic::Ordering::Relaxed);
                }
                std::thread::sleep(Duration::from_millis(50));
            }
        })
    };

    let start = Instant::now();
    writeln!(stdin, "t_s,p_rear_pa,p_front_pa,accel_mps2").expect("writes");
    let mut next_report = Instant::now();
    for i in 0..total_rows {
        let t_s = i as f64 * trace.dt_s;
        write!(stdin, "{t_s:.5},").expect("writes");
        stdin
            .write_all(rows[(i % rows.len() as u64) as usize].as_bytes())
            .expect("writes");
        if i % (1 << 22) == 0 && Instant::now() >= next_report {
            eprint!(
                "\r{:5.1} % of {minutes} min of trace",
                100.0 * i as f64 / total_rows as f64
            );
            next_report = Instant::now() + Duration::from_secs(5);
        }
    }
    drop(stdin);
    // Read the high-water mark once more before the process is reaped.
    let status = child.wait().expect("waits");
    let wall = start.elapsed().as_secs_f64();
    let (reports, valid) = reader.join().expect("reader");
    let _ = watcher.join();
    let peak_mb = peak.load(std::sync::atomic::Ordering::Relaxed) as f64 / 1024.0;
    eprintln!();
    println!(
        "trace:        {minutes} min at {:.0} S/s, {total_rows} rows",
        1.0 / trace.dt_s
    );
    println!(
        "wall time:    {wall:.1} s ({:.2} M rows/s)",
        total_rows as f64 / wall / 1e6
    );
    println!("cycles:       {reports} reported ({expected_cycles:.0} expected), {valid} valid");
    println!("peak RSS:     {peak_mb:.1} MB (limit {RSS_LIMIT_MB} MB)");
    let ok = status.success() && peak_mb < RSS_LIMIT_MB && (reports as f64 - expected_cycles).abs() <= 2.0;
    println!("long_trace:   {}", if ok { "ok" } else { "FAILED" });
    if !ok {
        std::process::exit(1);
    }
}
