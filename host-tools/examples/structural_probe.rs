//! The diagnosis on hammers of the second model family (`hammer-variants`):
//! the paper's scenario (friction hidden, 4 / 5.5 / 7 bar, fitted at 4 and
//! 7) and a no-effect control, on the base variant and on structural
//! variants. Prints what a user would read: the verdict, the fitted
//! friction, and the held-out energy error three ways.
//!
//! `cargo run --release -p hammer-host --example structural_probe [-- STRUCTURE...]`

use hammer_host::diagnose::engine::{diagnose, MeasuredInput, Options};
use hammer_sim::effects::Effects;
use hammer_sim::SimConfig;
use hammer_variants::{generate, Structure, VariantParams};

fn main() {
    let pick: Vec<String> = std::env::args().skip(1).collect();
    let mut structures = vec![("base", Structure::BASE)];
    for s in Structure::singles() {
        structures.push((s.variants()[0], s));
    }
    structures.retain(|(n, _)| pick.is_empty() || pick.iter().any(|p| p == n));
    for (name, structure) in structures {
        for hidden in ["coulomb_friction", "none"] {
            let mut effects = Effects::default();
            if hidden != "none" {
                effects.apply_spec(hidden).expect("catalogue effect");
            }
            let t0 = std::time::Instant::now();
            let inputs: Vec<MeasuredInput> = [4.0, 5.5, 7.0]
                .iter()
                .enumerate()
                .map(|(k, &bar)| MeasuredInput {
                    label: format!("{bar} bar"),
                    supply_bar: bar,
                    trace: generate(&VariantParams::default(), structure, &effects, bar, 1.0, 11 + k as u64).trace,
                    fit: bar != 5.5,
                })
                .collect();
            let gen_s = t0.elapsed().as_secs_f64();
            let opts = Options {
                figures: false,
                nominal_uncertainty: std::env::var("PRIOR").map_or(0.2, |v| v.parse().unwrap()),
                ..Options::default()
            };
            let t0 = std::time::Instant::now();
            let r = diagnose(&inputs, &SimConfig::default(), &opts, &|_, _, _| {})
                .expect("diagnoses")
                .report;
            let s = &r.shrink;
            let best = &r.effects[0];
            let fitted: Vec<String> = best
                .fitted
                .iter()
                .map(|p| format!("{}={:.2}", p.key, p.value))
                .collect();
            println!(
                "{name:<26} hidden {hidden:<17} verdict {:<22} best {} ({:.0} %, score {:.0}) [{}]",
                r.verdict.effects.join("+"),
                best.name,
                100.0 * best.explained_fraction,
                best.score,
                fitted.join(" ")
            );
            println!(
                "{:<26} energy err {:.2} % -> {:.2} % (recal only {:.2} %), freq {:.2} % -> {:.2} %  [gen {gen_s:.1} s, diag {:.1} s]",
                "",
                s.impact_energy_error_before,
                s.impact_energy_error_after,
                s.impact_energy_error_recalibrated_only,
                s.frequency_error_before,
                s.frequency_error_after,
                t0.elapsed().as_secs_f64()
            );
            println!("{:<26} reason: {}", "", r.verdict.reason);
        }
    }
}
