//! Estimator throughput on the host (sample-sets per second on one core) and
//! the size of its state. Not a timed test: it prints figures.
//! `cargo bench -p hammer-host --bench estimator`

use std::time::Instant;

use hammer_estimator::{Estimator, RawSample};
use hammer_sim::simulate::simulate;
use hammer_sim::SimConfig;

fn main() {
    let mut cfg = SimConfig::nominal(5.0);
    cfg.solver.duration_s = 2.0;
    cfg.effects.apply_spec("coulomb_friction").unwrap();
    let sim = simulate(&cfg).unwrap();
    let est_cfg = cfg.estimator_config(Some(5.0)).unwrap();
    let codes: Vec<RawSample> = sim.measured.codes;
    // 20 passes over 2 s of hammer: 4 M sample-sets per timed run.
    let reps = 20;
    let mut best = f64::INFINITY;
    let mut cycles = 0;
    for _ in 0..5 {
        let mut est = Estimator::new(est_cfg).unwrap();
        let t0 = Instant::now();
        for _ in 0..reps {
            est.push_block(std::hint::black_box(&codes), |r| {
                std::hint::black_box(r);
            });
        }
        best = best.min(t0.elapsed().as_secs_f64());
        cycles = est.counters().cycles;
    }
    let n = (codes.len() * reps) as f64;
    println!(
        "estimator: {:.1} M sample-sets/s on one core ({:.2} ns each; {} cycles closed per run, closing included)",
        n / best / 1e6,
        best / n * 1e9,
        cycles
    );
    println!(
        "estimator state: {} bytes (aim ≤ 8192)",
        std::mem::size_of::<Estimator>()
    );
}
