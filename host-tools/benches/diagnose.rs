//! Time to diagnose four operating points against the whole catalogue (the
//! aim: at most 10 s on the 2-core CI machine). Not a timed test: it prints
//! figures. `cargo bench -p hammer-host --bench diagnose`

use hammer_host::diagnose::bench::generator_config;
use hammer_host::diagnose::engine::{diagnose, MeasuredInput, Options};
use hammer_sim::sensor::Rng;
use hammer_sim::simulate::simulate;
use hammer_sim::SimConfig;

fn main() {
    let bars = [4.0, 5.0, 6.0, 7.0];
    let mut rng = Rng::new(5);
    let mut gen = generator_config(&SimConfig::default(), 0.03, &mut rng);
    gen.solver.duration_s = 1.0;
    gen.effects.apply_spec("coulomb_friction").unwrap();
    let traces: Vec<_> = bars
        .iter()
        .map(|&bar| {
            let mut c = gen.clone();
            c.supply.pressure_bar = bar;
            simulate(&c).unwrap().trace()
        })
        .collect();
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    for (label, fit) in [
        ("all four fitted", &bars[..]),
        ("4 and 7 bar fitted, 5 and 6 held out", &[4.0, 7.0][..]),
    ] {
        let inputs: Vec<MeasuredInput> = bars
            .iter()
            .zip(&traces)
            .map(|(&bar, t)| MeasuredInput {
                label: format!("{bar}"),
                supply_bar: bar,
                trace: t.clone(),
                fit: fit.contains(&bar),
            })
            .collect();
        let mut best = f64::INFINITY;
        let mut sims = 0;
        for _ in 0..3 {
            let t0 = std::time::Instant::now();
            let out = diagnose(&inputs, &SimConfig::default(), &Options::default(), &|_, _, _| {}).unwrap();
            best = best.min(t0.elapsed().as_secs_f64());
            sims = out.report.simulations;
        }
        println!(
            "diagnose: 4 operating points × 8 effects (+ pairs, held-out check, figures), {label}: {best:.2} s on {threads} threads, {sims} simulations (aim ≤ 10 s)"
        );
    }
}
