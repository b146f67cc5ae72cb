//! When does the valve feed the front chamber, relative to the impact, in
//! the diagnosis' model and in the second model family (`hammer-variants`),
//! with and without a hidden valve delay? The structural benchmark never
//! names a `valve_delay`; this measures why (docs/diagnosis.md).
//!
//! The marker is the same on both sides: the front chamber's p·V^1.4 (from
//! the true piston position) rising 2 % above its value where the piston
//! passes 30 mm in the stroke — gas entering a closed chamber. Negative
//! times are before the impact.
//!
//! `cargo run --release -p hammer-host --example valve_timing`

use hammer_host::diagnose::engine::extractor_for;
use hammer_host::diagnose::model::{Candidate, ModelRunner};
use hammer_sim::effects::Effects;
use hammer_sim::SimConfig;
use hammer_variants::{generate, Structure, VariantParams};

/// Positions and pressures of one run, with the chamber's geometry.
struct Run<'a> {
    t_s: &'a [f64],
    x_m: &'a [f64],
    v_mps: &'a [f64],
    p_front_pa: &'a [f64],
    front_dead_m3: f64,
    x_impact_m: f64,
}

/// Mean feed onset relative to the impact (ms) over the later two thirds of
/// the run's cycles, and how many cycles had one.
fn feed_onset_ms(r: &Run) -> Option<(f64, usize)> {
    let a2 = std::f64::consts::PI * 0.25 * (0.041f64.powi(2) - 0.028f64.powi(2));
    let y =
        |i: usize| (r.p_front_pa[i] + 101_325.0).ln() + 1.4 * (r.front_dead_m3 + a2 * (r.x_impact_m - r.x_m[i])).ln();
    let n = r.t_s.len();
    let dt = r.t_s[1] - r.t_s[0];
    let after = (8e-3 / dt) as usize;
    let (mut sum, mut count) = (0.0, 0usize);
    let mut i = n / 3;
    while i + 1 < n {
        if !(r.v_mps[i] > 0.5 && r.x_m[i] <= 0.030 && r.x_m[i + 1] > 0.030) {
            i += 1;
            continue;
        }
        let Some(impact) = (i..n).find(|&k| r.v_mps[k] <= 0.0) else {
            break;
        };
        let y0 = y(i);
        if let Some(j) = (i..(impact + after).min(n)).find(|&j| y(j) >= y0 + 0.02) {
            sum += r.t_s[j] - r.t_s[impact];
            count += 1;
        }
        i = impact + 1;
    }
    (count > 0).then(|| (1e3 * sum / count as f64, count))
}

fn effects(spec: &str) -> Effects {
    let mut e = Effects::default();
    if spec != "none" {
        e.apply_spec(spec).expect("catalogue effect");
    }
    e
}

fn main() {
    let delays = [
        "none",
        "valve_delay:tau_s=0.0006",
        "valve_delay:tau_s=0.0012",
        "valve_delay:tau_s=0.0024",
    ];
    let show = |bar: f64, who: &str, spec: &str, onset: Option<(f64, usize)>| match onset {
        Some((ms, n)) => {
            println!("{bar:3} bar  {who:30} {spec:26} front fed {ms:+6.2} ms from the impact ({n} cycles)")
        }
        None => println!("{bar:3} bar  {who:30} {spec:26} no feed onset found"),
    };
    let base = SimConfig::default();
    let extractor = extractor_for(&base);
    for bar in [4.0, 7.0] {
        for (who, damping) in [("model", 1.0), ("model, valve damping ×0.5", 0.5)] {
            let mut cfg = base.clone();
            cfg.valve.damping_n_s_per_m *= damping;
            let runner = ModelRunner::new(cfg.clone(), extractor);
            for spec in delays {
                let Some(t) = runner.truth(bar, &Candidate { effects: effects(spec) }) else {
                    println!("{bar} bar  {who}: the model does not run");
                    continue;
                };
                let run = Run {
                    t_s: &t.t_s,
                    x_m: &t.x_m,
                    v_mps: &t.v_mps,
                    p_front_pa: &t.p_front_pa,
                    front_dead_m3: cfg.hammer.front_dead_volume_m3,
                    x_impact_m: cfg.hammer.impact_position_m,
                };
                show(bar, who, spec, feed_onset_ms(&run));
            }
        }
        let mut structures = vec![("variants: base", Structure::BASE)];
        for s in Structure::singles() {
            structures.push((s.variants()[0], s));
        }
        let p = VariantParams::default();
        for (who, structure) in structures {
            for spec in delays {
                let g = generate(&p, structure, &effects(spec), bar, 0.6, 5);
                let t = &g.trace;
                let run = Run {
                    t_s: &t.t_s,
                    x_m: &t.extra["x_m"],
                    v_mps: &t.extra["v_mps"],
                    p_front_pa: &t.p_front_pa,
                    front_dead_m3: p.front_dead_m3,
                    x_impact_m: p.x_impact_m,
                };
                show(bar, who, spec, feed_onset_ms(&run));
            }
        }
    }
}
