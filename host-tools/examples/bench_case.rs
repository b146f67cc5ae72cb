//! One case of `hammer diagnose-bench` with the ranking laid open: every
//! effect's score and explained share, the model-form factors, the
//! recalibration and the remainder. For finding why a case is misnamed.
//!
//! `cargo run --release -p hammer-host --example bench_case -- [--structural] [--reference] [--held-out] [--oracle] [--jitter J] SEED INDEX...`
//!
//! With `--held-out` (and `--reference`), only the held-out check of each
//! case, with the record and without it side by side: the verdict, its
//! sizes, the recalibration and every point's energies, for finding why
//! the two modes' checks differ. With `--oracle`, each single's truth
//! checked as `diagnose-bench --oracle` does.

use hammer_host::diagnose::bench::{draw_case, run_case, BenchOptions};
use hammer_host::diagnose::engine::{diagnose_with, Options, Report};
use hammer_host::diagnose::model::Builtin;
use hammer_sim::SimConfig;
use std::sync::Arc;

fn main() {
    let mut args: Vec<String> = std::env::args().skip(1).collect();
    let structural = args.iter().any(|a| a == "--structural");
    let reference = args.iter().any(|a| a == "--reference");
    let oracle = args.iter().any(|a| a == "--oracle");
    let held_out = args.iter().any(|a| a == "--held-out");
    args.retain(|a| a != "--structural" && a != "--reference" && a != "--oracle" && a != "--held-out");
    let jitter = match args.iter().position(|a| a == "--jitter") {
        Some(i) => {
            let j = args.get(i + 1).and_then(|s| s.parse::<f64>().ok());
            args.drain(i..(i + 2).min(args.len()));
            j
        }
        None => None,
    };
    let seed: u64 = args.first().and_then(|s| s.parse().ok()).unwrap_or(7);
    let mut bench = BenchOptions::of(seed, structural, reference);
    bench.oracle = oracle;
    if let Some(j) = jitter {
        bench.jitter = j;
    }
    let diag = Options {
        figures: false,
        ..Options::default()
    };
    for index in args.iter().skip(1).filter_map(|s| s.parse::<usize>().ok()) {
        if held_out {
            held_out_side_by_side(&bench, index, &diag);
            continue;
        }
        let c = match run_case(&bench, index, &diag) {
            Ok(c) => c,
            Err(e) => {
                println!("case {index}: {e}");
                continue;
            }
        };
        let Some(r) = &c.report else { continue };
        println!(
            "case {index} {:?} hidden {:?} named {:?} ({:.1} s)",
            c.variants, c.hidden, c.named, c.diagnose_s
        );
        println!("  hidden params: {}", c.hidden_params);
        println!("  parameter errors: {:?}", c.param_errors);
        if let Some(t) = c.true_port_delay_s {
            println!(
                "  the front port truly opens {:+.3} ms later than without the delay",
                1e3 * t
            );
        }
        for row in &r.force_balance {
            for q in row.quantities.iter().filter(|q| q.key.ends_with(".friction_n")) {
                println!(
                    "  force balance at {} bar ({}): friction {:.3} N ± {:.3} N (expanded)",
                    row.supply_bar,
                    if row.fit_point { "fitted" } else { "held out" },
                    q.value,
                    q.expanded_u
                );
            }
        }
        if let Some(o) = &c.oracle {
            println!(
                "  oracle: the truth ({}) adds {:.1} and explains {:.1} % of χ² {:.1} without any effect: {}",
                o.effect,
                o.score,
                100.0 * o.explained_fraction,
                o.chi2_without,
                if o.passes { "passes" } else { "fails" }
            );
        }
        if let Some(c) = &c.confirmation {
            println!(
                "  confirm: {} adds {:.1}, explains {:.1} % of χ² {:.1}: {}",
                c.effect,
                c.score,
                100.0 * c.explained_fraction,
                c.chi2_without,
                if c.kept { "kept" } else { "dropped" }
            );
        }
        for p in &c.physical_sizes {
            println!(
                "  {} as {}: the verdict's model {:.4e} against the hammer's {:.4e} ({:.1} % off)",
                p.effect,
                p.quantity,
                p.model,
                p.truth,
                100.0 * p.error
            );
        }
        if let Some(e) = c.port_shift_error {
            println!(
                "  the named delay shifts the model's front port within {:.1} % of that",
                100.0 * e
            );
        }
        for f in &r.detection_floors {
            println!("  floor: {}", f.statement);
        }
        println!(
            "  χ² nominal {:.0} over {} features; {}",
            r.chi2_nominal, r.features_compared, r.verdict.reason
        );
        for e in r.effects.iter().chain(&r.pairs) {
            let fitted: Vec<String> = e
                .fitted
                .iter()
                .map(|p| format!("{}={:.3}±{:.3}", p.key, p.value, p.sd))
                .collect();
            println!(
                "  {:<40} score {:>8.1} explained {:>5.1} % χ² {:>8.1} [{}]",
                e.name,
                e.score,
                100.0 * e.explained_fraction,
                e.chi2,
                fitted.join(" ")
            );
            if let Some(z) = e.model_free_z {
                println!("      model-free z {z:.1}");
            }
            if let Some(why) = &e.contradicted_by {
                println!("      ruled out: {why}");
            }
            for ev in &e.evidence {
                println!("      {ev}");
            }
        }
        for m in r.model_free.iter().chain(&r.chambers) {
            println!(
                "  model-free {:<32} {:>10.4} vs {:>10.4} ± {:.4}  z {:>6.1}",
                m.feature, m.measured, m.nominal, m.se, m.z
            );
        }
        let mf: Vec<String> = r
            .model_form
            .iter()
            .map(|m| format!("{} {:.2}", m.group, m.factor))
            .collect();
        println!("  model form: {}", mf.join(", "));
        for rc in &r.recalibration {
            println!(
                "  recal {:<32} {:.4e} -> {:.4e} ({:+.2} sd)",
                rc.parameter, rc.nominal, rc.value, rc.prior_sds
            );
        }
        for rm in r.remainder.iter().take(4) {
            println!("  remainder {}", rm.statement);
        }
        let s = &r.shrink;
        println!(
            "  energy {:.2} % -> recal {:.2} % / effects in nominal {:.2} % -> {:.2} %; freq {:.2} % -> {:.2} %",
            s.impact_energy_error_before,
            s.impact_energy_error_recalibrated_only,
            s.impact_energy_error_effects_only,
            s.impact_energy_error_after,
            s.frequency_error_before,
            s.frequency_error_after
        );
        for p in &s.points {
            println!(
                "    {} bar{}: energy measured {:.3} J, nominal {:.3}, recalibrated {:.3}, effects in nominal {:.3}, verdict {:.3}",
                p.supply_bar,
                if p.held_out_point { " (held out)" } else { "" },
                p.impact_energy_measured_j,
                p.impact_energy_nominal_j,
                p.impact_energy_recalibrated_j,
                p.impact_energy_effects_only_j,
                p.impact_energy_fitted_j
            );
        }
    }
}

/// Case `index` diagnosed with its records and without them, and each
/// mode's held-out check printed.
fn held_out_side_by_side(bench: &BenchOptions, index: usize, diag: &Options) {
    let case = match draw_case(bench, index) {
        Ok(c) => c,
        Err(e) => {
            println!("case {index}: {e}");
            return;
        }
    };
    let base = SimConfig::default();
    println!("case {index} hidden {:?}", case.hidden);
    for (mode, refs) in [("record", case.references.as_slice()), ("alone", &[])] {
        let plant = Arc::new(Builtin::new(base.clone()));
        match diagnose_with(&case.inputs, refs, &base, plant, diag, &|_, _, _| {}) {
            Ok(out) => print_check(mode, &out.report),
            Err(e) => println!("  {mode}: {e}"),
        }
    }
}

/// One mode's verdict, its sizes, its recalibration and its check.
fn print_check(mode: &str, r: &Report) {
    let s = &r.shrink;
    println!(
        "  {mode}: named {:?}, energy error after {:.2} % (recalibrated only {:.2} %)",
        r.verdict.effects, s.impact_energy_error_after, s.impact_energy_error_recalibrated_only
    );
    for e in r.effects.iter().chain(&r.pairs) {
        if r.verdict.effects.iter().any(|v| *v == e.name) || r.verdict.effects.join("+") == e.name {
            let fitted: Vec<String> = e.fitted.iter().map(|p| format!("{}={:.4}", p.key, p.value)).collect();
            println!("    sizes {}: {}", e.name, fitted.join(" "));
        }
    }
    let moves: Vec<String> = r
        .recalibration
        .iter()
        .map(|rc| format!("{} {:+.2}", rc.parameter, rc.prior_sds))
        .collect();
    println!("    recal (prior sds): {}", moves.join(", "));
    for p in &s.points {
        println!(
            "    {} bar{}: measured {:.4} J, nominal {:.4}, recalibrated {:.4}, verdict {:.4} ({:+.2} %)",
            p.supply_bar,
            if p.held_out_point { " (held out)" } else { "" },
            p.impact_energy_measured_j,
            p.impact_energy_nominal_j,
            p.impact_energy_recalibrated_j,
            p.impact_energy_fitted_j,
            100.0 * (p.impact_energy_fitted_j / p.impact_energy_measured_j - 1.0)
        );
    }
}
