//! The estimator (model-free) on variant traces: friction and energy against the truth.
use hammer_sim::effects::Effects;
use hammer_sim::estimation::open_for_estimation;
use hammer_sim::SimConfig;
use hammer_variants::{generate, Structure, VariantParams};

fn main() {
    let p = VariantParams::default();
    let mut e = Effects::default();
    e.apply_spec(hammer_sim::effects::EFFECT_NAMES[0]).unwrap();
    let dir = std::env::temp_dir().join("variants-est");
    std::fs::create_dir_all(&dir).unwrap();
    let structures: Vec<Structure> = std::iter::once(Structure::BASE).chain(Structure::singles()).collect();
    for s in structures {
        for bar in [4.0, 7.0] {
            let g = generate(&p, s, &e, bar, 0.6, 2);
            let path = dir.join("v.csv");
            g.write(&path).unwrap();
            let input = open_for_estimation(&path, &SimConfig::default(), None).unwrap();
            let reports = input.run().unwrap();
            let valid: Vec<_> = reports.iter().filter(|r| r.is_valid()).skip(1).collect();
            let n = valid.len().max(1) as f32;
            let f = valid.iter().map(|r| r.friction_n).sum::<f32>() / n;
            let uf = valid.iter().map(|r| r.friction_uncertainty_n).sum::<f32>() / n;
            let en = valid.iter().map(|r| r.impact_energy_j).sum::<f32>() / n;
            let ue = valid.iter().map(|r| r.impact_energy_uncertainty_j).sum::<f32>() / n;
            let flags: std::collections::BTreeSet<&str> = reports.iter().flat_map(|r| r.flags.names()).collect();
            let tf = g
                .truth
                .steady(1, |c| 0.5 * (c.friction_stroke_n + c.friction_backhaul_n))
                .unwrap();
            let te = g.truth.steady(1, |c| c.impact_energy_j).unwrap();
            println!(
                "{:<28} {bar:.0} bar: {}/{} valid, F {:.2}±{:.2} (true {:.2}, {:+.1}%), E {:.3}±{:.3} (true {:.3}, {:+.1}%) {:?}",
                g.truth.variants.join("+"),
                valid.len(),
                reports.len(),
                f, uf, tf, 100.0 * (f as f64 - tf) / tf,
                en, ue, te, 100.0 * (en as f64 - te) / te,
                flags
            );
        }
    }
}
