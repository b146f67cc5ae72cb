//! How each hidden effect moves the front chamber's floor (its lowest
//! 0.1 ms mean pressure in a cycle, `features::front_floor_pa`) against the
//! same hammer's record, as `hammer diagnose-bench --reference` reads it:
//! per case and operating point, the change in mbar and in standard errors
//! of the cycles' spread, then per hidden effect how many cases rose or fell
//! at every point. The evidence behind the leak's rule (a floor that fell
//! rules a leak out: `effects/leakage.rs`).
//!
//! `cargo run --release -p hammer-host --example front_floor -- [--structural] SEED CASES`

use hammer_host::diagnose::bench::{draw_case, BenchOptions};
use hammer_host::diagnose::engine::extractor_for;
use hammer_host::diagnose::features::{Signals, FRONT_FLOOR};
use hammer_sim::SimConfig;
use hammer_trace::trace::Trace;
use std::collections::BTreeMap;

/// The settled cycles' front floors (after the benchmark's 0.27 s start-up).
fn floors(t: &Trace, bar: f64) -> Vec<f64> {
    let ex = extractor_for(&SimConfig::default());
    ex.cycles(&Signals::of_trace(t, bar))
        .iter()
        .filter(|c| c.t_impact_s > 0.27)
        .map(|c| c.values[FRONT_FLOOR])
        .filter(|x| x.is_finite())
        .collect()
}

fn mean_se(v: &[f64]) -> (f64, f64) {
    let n = v.len() as f64;
    let m = v.iter().sum::<f64>() / n;
    let var = v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (n - 1.0);
    (m, (var / n).sqrt())
}

fn main() {
    let mut args: Vec<String> = std::env::args().skip(1).collect();
    let structural = args.iter().any(|a| a == "--structural");
    args.retain(|a| a != "--structural");
    let seed: u64 = args.first().and_then(|s| s.parse().ok()).unwrap_or(7);
    let cases: usize = args.get(1).and_then(|s| s.parse().ok()).unwrap_or(120);
    let bench = BenchOptions::of(seed, structural, true);
    println!("front floor's change against the record, mbar (standard errors), per point");
    // Per hidden effect: cases whose floor rose at every point, fell at every point, other.
    let mut tally: BTreeMap<String, [usize; 3]> = BTreeMap::new();
    for index in 0..cases {
        let case = match draw_case(&bench, index) {
            Ok(c) => c,
            Err(e) => {
                println!("case {index}: {e:#}");
                continue;
            }
        };
        let names = case.hidden.names();
        let label = if names.is_empty() {
            "none".to_string()
        } else {
            names.join("+")
        };
        let mut line = format!("{index:>3} {label:<40}");
        let mut signs = Vec::new();
        for (m, r) in case.inputs.iter().zip(&case.references) {
            let (fm, fr) = (floors(&m.trace, m.supply_bar), floors(&r.trace, r.supply_bar));
            if fm.len() < 3 || fr.len() < 3 {
                line += &format!(" | {:>4} bar: -", m.supply_bar);
                continue;
            }
            let ((a, sa), (b, sb)) = (mean_se(&fm), mean_se(&fr));
            let z = (a - b) / (sa * sa + sb * sb).sqrt();
            line += &format!(" | {:>4} bar {:+6.2} ({z:+5.0})", m.supply_bar, (a - b) / 100.0);
            signs.push(z);
        }
        println!("{line}");
        let t = tally.entry(label).or_default();
        if signs.iter().all(|z| *z >= 3.0) {
            t[0] += 1;
        } else if signs.iter().all(|z| *z <= -3.0) {
            t[1] += 1;
        } else {
            t[2] += 1;
        }
    }
    println!("\nhidden effect: cases whose floor rose | fell | neither at every point (3 standard errors)");
    for (name, [up, down, other]) in &tally {
        println!("  {name:<40} {up:>3} | {down:>3} | {other:>3}");
    }
}
