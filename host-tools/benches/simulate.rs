//! How many times faster than real time the simulator runs (not a timed test:
//! it prints figures). `cargo bench -p hammer-host --bench simulate`.

use std::time::Instant;

use hammer_sim::simulate::simulate;
use hammer_sim::{simulate_truth, SimConfig};

fn main() {
    for (label, effects) in [
        ("nominal", vec![]),
        ("coulomb_friction", vec!["coulomb_friction"]),
        (
            "all model effects",
            vec![
                "coulomb_friction",
                "viscous_friction",
                "leakage",
                "valve_delay",
                "heat_transfer",
                "supply_restriction",
            ],
        ),
    ] {
        for bar in [4.0, 7.0] {
            let mut cfg = SimConfig::nominal(bar);
            for e in &effects {
                cfg.effects.apply_spec(e).unwrap();
            }
            // Warm-up, then the best of 5.
            let _ = simulate_truth(&cfg).unwrap();
            let mut best_truth = f64::INFINITY;
            let mut best_full = f64::INFINITY;
            let mut steps = 0;
            for _ in 0..5 {
                let t0 = Instant::now();
                let run = simulate_truth(&cfg).unwrap();
                best_truth = best_truth.min(t0.elapsed().as_secs_f64());
                steps = run.stats.accepted_steps;
                let t0 = Instant::now();
                let _ = simulate(&cfg).unwrap();
                best_full = best_full.min(t0.elapsed().as_secs_f64());
            }
            let sim_s = cfg.solver.duration_s;
            println!(
                "{label:>18} @ {bar} bar: {sim_s} s simulated, 10 us output: solver {:.2} ms ({:.0}x real time, {steps} steps); with sensor model {:.2} ms ({:.0}x real time)",
                best_truth * 1e3,
                sim_s / best_truth,
                best_full * 1e3,
                sim_s / best_full
            );
        }
    }
}
