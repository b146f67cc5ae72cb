//! When does the valve feed the front chamber, relative to the impact, in
//! the diagnosis' model and in the second model family (`hammer-variants`),
//! with and without a hidden valve delay? The structural benchmark never
//! names a `valve_delay`; this measures why (docs/diagnosis.md). The marker
//! is [`hammer_host::diagnose::valve_timing`], read the same way on both.
//!
//! With `--form`, also the model-form factors and detection floors of a
//! no-effect base hammer of the second family whose spool is slowed from
//! 0.25 ms to 1 and 2 ms: how much of the form error is the valve's timing.
//!
//! `cargo run --release -p hammer-host --example valve_timing [-- --form]`

use hammer_host::diagnose::engine::{diagnose, MeasuredInput, Options};
use hammer_host::diagnose::valve_timing::{front_feed_onset_ms, FrontChamberRun};
use hammer_sim::effects::Effects;
use hammer_sim::SimConfig;
use hammer_variants::{generate, Structure, VariantParams};

fn effects(spec: &str) -> Effects {
    let mut e = Effects::default();
    if spec != "none" {
        e.apply_spec(spec).expect("catalogue effect");
    }
    e
}

fn show(bar: f64, who: &str, spec: &str, onset: Option<(f64, usize)>) {
    match onset {
        Some((ms, n)) => {
            println!("{bar:3} bar  {who:30} {spec:26} front fed {ms:+6.2} ms from the impact ({n} cycles)")
        }
        None => println!("{bar:3} bar  {who:30} {spec:26} no feed onset found"),
    }
}

fn timing() {
    let delays = [
        "none",
        "valve_delay:tau_s=0.0006",
        "valve_delay:tau_s=0.0012",
        "valve_delay:tau_s=0.0024",
    ];
    let base = SimConfig::default();
    for bar in [4.0, 7.0] {
        for (who, damping) in [("model", 1.0), ("model, valve damping ×0.5", 0.5)] {
            let mut cfg = base.clone();
            cfg.valve.damping_n_s_per_m *= damping;
            for spec in delays {
                let mut run = cfg.clone();
                run.supply.pressure_bar = bar;
                run.solver.duration_s = 0.45;
                run.effects = effects(spec);
                let onset = hammer_sim::simulate_truth(&run)
                    .ok()
                    .and_then(|r| front_feed_onset_ms(&FrontChamberRun::of_model(&r.truth, &cfg)));
                show(bar, who, spec, onset);
            }
        }
        let mut structures = vec![("second family: base", Structure::BASE)];
        for s in Structure::singles() {
            structures.push((s.variants()[0], s));
        }
        let p = VariantParams::default();
        for (who, structure) in structures {
            for spec in delays {
                let g = generate(&p, structure, &effects(spec), bar, 0.6, 5);
                let onset = FrontChamberRun::of_variant(&g.trace, &p).and_then(|r| front_feed_onset_ms(&r));
                show(bar, who, spec, onset);
            }
        }
    }
}

fn form() {
    for spool_tau_s in [0.25e-3, 1e-3, 2e-3] {
        let p = VariantParams {
            spool_tau_s,
            ..VariantParams::default()
        };
        let inputs: Vec<MeasuredInput> = [4.0, 5.5, 7.0]
            .iter()
            .enumerate()
            .map(|(k, &bar)| MeasuredInput {
                label: format!("{bar} bar"),
                supply_bar: bar,
                trace: generate(&p, Structure::BASE, &Effects::default(), bar, 1.0, 11 + k as u64).trace,
                fit: bar != 5.5,
            })
            .collect();
        let opts = Options {
            figures: false,
            ..Options::default()
        };
        let r = match diagnose(&inputs, &SimConfig::default(), &opts, &|_, _, _| {}) {
            Ok(o) => o.report,
            Err(e) => {
                println!("spool {:.2} ms: {e}", 1e3 * spool_tau_s);
                continue;
            }
        };
        let factors: Vec<String> = r
            .model_form
            .iter()
            .map(|m| format!("{} {:.1}", m.group, m.factor))
            .collect();
        let floors: Vec<String> = r
            .detection_floors
            .iter()
            .filter(|d| !d.model_free)
            .map(|d| format!("{} {}", d.effect, d.value.map_or("-".into(), |v| format!("{v:.3e}"))))
            .collect();
        println!(
            "spool {:.2} ms, no effect: verdict {}; model-form factors {}; floors {}",
            1e3 * spool_tau_s,
            r.verdict.effects.join("+"),
            factors.join(", "),
            floors.join(", ")
        );
    }
}

fn main() {
    timing();
    if std::env::args().any(|a| a == "--form") {
        form();
    }
}
