//! How many times faster than real time the simulator runs (not a timed test:
//! it prints figures), and where the time goes. `cargo bench -p hammer-host
//! --bench simulate`.
//!
//! The split, without timers inside the hot code: the solver alone
//! (`simulate_truth`: steps, right-hand sides, events, resampling,
//! per-cycle truth), the sensor chain alone (`sensor::measure` over that
//! run's truth), and the solver's counts. A sampling profile by function
//! (`perf`) is in `docs/model.md` ("Speed"), with its command.

use std::hint::black_box;
use std::time::Instant;

use hammer_sim::sensor::measure;
use hammer_sim::simulate::simulate;
use hammer_sim::{simulate_truth, SimConfig};

/// The best of `n` timings of `f`, seconds.
fn best_of<T>(n: usize, mut f: impl FnMut() -> T) -> f64 {
    (0..n)
        .map(|_| {
            let t0 = Instant::now();
            black_box(f());
            t0.elapsed().as_secs_f64()
        })
        .fold(f64::INFINITY, f64::min)
}

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
            let run = simulate_truth(&cfg).unwrap();
            let best_truth = best_of(5, || simulate_truth(&cfg).unwrap());
            let best_full = best_of(5, || simulate(&cfg).unwrap());
            let best_chain = best_of(5, || {
                measure(&cfg.sensors, &cfg.effects, &run.truth, &run.events.impacts, cfg.seed)
            });
            let st = run.stats;
            let sim_s = cfg.solver.duration_s;
            let samples = run.truth.len() as f64;
            println!(
                "{label:>18} @ {bar} bar: {sim_s} s simulated, 10 us output: solver {:.2} ms ({:.0}x real time, \
                 {} steps, {} rejected, {} restarts at events); with sensor model {:.2} ms ({:.0}x real time)",
                best_truth * 1e3,
                sim_s / best_truth,
                st.accepted_steps,
                st.rejected_steps,
                st.restarts,
                best_full * 1e3,
                sim_s / best_full
            );
            // The ceiling of fewer steps: a solver five times as loose
            // with steps up to 1 ms (not the model's settings: its anchors
            // are checked at rtol 1e-6, 0.2 ms) still pays for every output
            // sample (interpolation, the piston's forces for the
            // acceleration, the cycle's truth, the stored fields).
            let mut loose = cfg.clone();
            loose.solver.rtol = 1e-5;
            loose.solver.max_step_s = 1e-3;
            let loose_run = simulate_truth(&loose).unwrap();
            let best_loose = best_of(5, || simulate_truth(&loose).unwrap());
            println!(
                "{:>30} loose solver (rtol 1e-5, steps ≤ 1 ms): {:.2} ms ({:.0}x real time) with {} right-hand sides",
                "",
                best_loose * 1e3,
                sim_s / best_loose,
                loose_run.stats.rhs_evaluations
            );
            println!(
                "{:>30} {} right-hand sides; sensor chain alone {:.2} ms ({:.0} ns a sample-set of 3 channels, \
                 {} sample-sets)",
                "",
                st.rhs_evaluations,
                best_chain * 1e3,
                best_chain / samples * 1e9,
                run.truth.len()
            );
        }
    }
}
