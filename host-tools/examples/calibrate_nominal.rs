//! How the parameters the paper does not give were chosen: a random search,
//! then a local refinement, of the nominal model at 4 bar against the paper's
//! anchors (impact velocity 2.83 m/s, stroke 42 mm, peak pressures 3.28 bar
//! rear and 2.49 bar front). Prints the best candidates; `docs/model.md`
//! records the values adopted as defaults.
//! `cargo run --release -p hammer-host --example calibrate_nominal`

use hammer_sim::sensor::Rng;
use hammer_sim::{simulate_truth, SimConfig};

/// Rear dead volume cm³, front dead volume cm³, outlets, pilot area ratio front/rear,
/// valve full-open area mm², valve damping N·s/m, contact restitution.
type Candidate = [f64; 7];
const LO: Candidate = [6.0, 10.0, 1.0, 0.5, 1.0, 2.0, 0.1];
const HI: Candidate = [25.0, 35.0, 1.99, 1.6, 6.0, 20.0, 0.4];

fn steady_energy(cfg: &SimConfig) -> Option<f64> {
    let run = simulate_truth(cfg).ok()?;
    let e: Vec<f64> = run
        .cycles
        .iter()
        .filter(|c| c.t_impact_s > 0.15)
        .map(|c| c.impact_energy_j)
        .collect();
    (e.len() >= 3).then(|| e.iter().sum::<f64>() / e.len() as f64)
}

/// Relative impact-energy drop caused by the paper's friction at `bar`.
fn friction_drop(base: &SimConfig, bar: f64) -> Option<f64> {
    let mut cfg = base.clone();
    cfg.supply.pressure_bar = bar;
    let e0 = steady_energy(&cfg)?;
    cfg.effects.apply_spec("coulomb_friction").ok()?;
    Some(1.0 - steady_energy(&cfg)? / e0)
}

fn evaluate(c: &Candidate) -> Option<(f64, [f64; 5])> {
    let mut cfg = SimConfig::nominal(4.0);
    cfg.solver.duration_s = 0.4;
    cfg.hammer.rear_dead_volume_m3 = c[0] * 1e-6;
    cfg.hammer.front_dead_volume_m3 = c[1] * 1e-6;
    cfg.hammer.outlet_count = c[2].floor() as u32;
    cfg.valve.pilot_area_front_m2 = cfg.valve.pilot_area_rear_m2 * c[3];
    cfg.valve.full_open_area_m2 = c[4] * 1e-6;
    cfg.valve.damping_n_s_per_m = c[5];
    cfg.contact.restitution = c[6];
    let run = simulate_truth(&cfg).ok()?;
    let steady: Vec<_> = run.cycles.iter().filter(|c| c.t_impact_s > 0.15).collect();
    if steady.len() < 3 {
        return None;
    }
    let n = steady.len() as f64;
    let m = |f: &dyn Fn(&hammer_sim::CycleTruth) -> f64| steady.iter().map(|c| f(c)).sum::<f64>() / n;
    let v = m(&|c| c.impact_velocity_mps);
    let s = m(&|c| c.stroke_m) * 1e3;
    let p1 = m(&|c| c.peak_rear_pa) / 1e5;
    let p2 = m(&|c| c.peak_front_pa) / 1e5;
    let f = m(&|c| c.frequency_hz);
    // Cycle-to-cycle spread: a limit cycle, not a chaotic one.
    let spread = steady
        .iter()
        .map(|c| (c.impact_velocity_mps - v).abs())
        .fold(0.0, f64::max)
        / v;
    // Scales are a third of the tolerances the anchor tests allow.
    let err = ((v / 2.83 - 1.0) / 0.033).powi(2)
        + ((s / 42.0 - 1.0) / 0.033).powi(2)
        + ((p1 / 3.282 - 1.0) / 0.05).powi(2)
        + ((p2 / 2.489 - 1.0) / 0.05).powi(2)
        + (spread / 0.005).powi(2)
        + if std::env::var("CALIBRATE_FRICTION").is_ok() {
            // The paper: friction lowers impact energy by 13 % at 4 bar and 17 % at 7 bar.
            let d4 = friction_drop(&cfg, 4.0)?;
            let d7 = friction_drop(&cfg, 7.0)?;
            ((d4 - 0.13) / 0.013).powi(2) + ((d7 - 0.17) / 0.013).powi(2)
        } else {
            0.0
        }
        // The piston must turn on its air cushion, well clear of the rear cover.
        + if s > 47.0 { 1e3 } else { 0.0 };
    Some((err, [v, s, p1, p2, f]))
}

fn main() {
    let args: Vec<f64> = std::env::args().skip(1).filter_map(|a| a.parse().ok()).collect();
    if args.len() == 7 {
        let c: Candidate = [args[0], args[1], args[2], args[3], args[4], args[5], args[6]];
        match evaluate(&c) {
            Some((e, o)) => println!(
                "{e:6.2} | v_imp {:5.3} stroke {:6.2} p1max {:5.3} p2max {:5.3} f {:5.2}",
                o[0], o[1], o[2], o[3], o[4]
            ),
            None => println!("no steady cycles"),
        }
        return;
    }
    let mut rng = Rng::new(42);
    let mut best: Vec<(f64, Candidate, [f64; 5])> = Vec::new();
    for _ in 0..800 {
        let mut c = [0.0; 7];
        for i in 0..7 {
            c[i] = LO[i] + (HI[i] - LO[i]) * rng.uniform();
        }
        if let Some((e, o)) = evaluate(&c) {
            best.push((e, c, o));
        }
    }
    best.sort_by(|a, b| a.0.total_cmp(&b.0));
    best.truncate(5);
    // Local refinement of the best few by shrinking random perturbations.
    for entry in best.iter_mut() {
        let mut scale = 0.2;
        for _ in 0..300 {
            let mut c = entry.1;
            for i in 0..7 {
                c[i] = (c[i] + scale * (HI[i] - LO[i]) * (rng.uniform() - 0.5)).clamp(LO[i], HI[i]);
            }
            if let Some((e, o)) = evaluate(&c) {
                if e < entry.0 {
                    *entry = (e, c, o);
                }
            }
            scale *= 0.99;
        }
    }
    best.sort_by(|a, b| a.0.total_cmp(&b.0));
    println!(
        "score | V1d_cm3 V2d_cm3 outlets pilot_ratio area_mm2 damping restitution | v_imp stroke_mm p1max p2max f_hz"
    );
    for (e, c, o) in &best {
        println!(
            "{e:6.2} | {:6.2} {:6.2} {:3} {:6.3} {:6.2} {:6.3} {:5.3} | {:5.3} {:6.2} {:5.3} {:5.3} {:5.2}",
            c[0],
            c[1],
            c[2].floor(),
            c[3],
            c[4],
            c[5],
            c[6],
            o[0],
            o[1],
            o[2],
            o[3],
            o[4]
        );
    }
}
