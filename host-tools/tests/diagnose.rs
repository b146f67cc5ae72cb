//! The diagnosis on measurements it was not told about. The "measurements"
//! come from the benchmark's generator, not from the diagnosis' model: its
//! uncertain nominal parameters are jittered by up to ±3 %, the solver runs at
//! a finer tolerance, the sensors have noise, a random bandwidth and a 12-bit
//! ADC (the inverse crime would make every check here easy).

use hammer_host::diagnose::bench::generator_config;
use hammer_host::diagnose::engine::{diagnose, MeasuredInput, Options, Report};
use hammer_sim::sensor::Rng;
use hammer_sim::simulate::simulate;
use hammer_sim::SimConfig;

fn measure(effects: &[&str], bars: &[f64], fit: &[f64], seed: u64) -> Vec<MeasuredInput> {
    let mut rng = Rng::new(seed);
    let mut gen = generator_config(&SimConfig::default(), 0.03, &mut rng);
    gen.solver.duration_s = 1.0;
    for e in effects {
        gen.effects.apply_spec(e).unwrap();
    }
    bars.iter()
        .map(|&bar| {
            let mut c = gen.clone();
            c.supply.pressure_bar = bar;
            c.seed = rng.next_u64();
            MeasuredInput {
                label: format!("{bar} bar"),
                supply_bar: bar,
                trace: simulate(&c).unwrap().trace(),
                fit: fit.contains(&bar),
            }
        })
        .collect()
}

fn run(inputs: &[MeasuredInput]) -> Report {
    let opts = Options {
        figures: false,
        ..Options::default()
    };
    diagnose(inputs, &SimConfig::default(), &opts, &|_, _, _| {})
        .unwrap()
        .report
}

#[test]
fn paper_friction_is_named_and_the_energy_gap_closes_on_held_out_pressures() {
    let inputs = measure(&["coulomb_friction"], &[4.0, 5.0, 6.0, 7.0], &[4.0, 7.0], 21);
    let r = run(&inputs);
    let s = &r.shrink;
    println!(
        "verdict {:?} ({}); energy error {:.2} % -> {:.2} % (recalibrated only {:.2} %, effects in nominal {:.2} %), frequency {:.2} % -> {:.2} % on {:?}",
        r.verdict.effects,
        r.verdict.reason,
        s.impact_energy_error_before,
        s.impact_energy_error_after,
        s.impact_energy_error_recalibrated_only,
        s.impact_energy_error_effects_only,
        s.frequency_error_before,
        s.frequency_error_after,
        s.held_out_points
    );
    assert_eq!(r.verdict.effects, vec!["coulomb_friction"]);
    // The paper's friction: 10.27 N at 4 bar, 16.7 N at 7 bar.
    let f = |k: &str| r.effects[0].fitted.iter().find(|p| p.key.ends_with(k)).unwrap().value;
    assert!(
        (f("friction_at_low_n") - 10.27).abs() < 0.05 * 10.27,
        "{}",
        f("friction_at_low_n")
    );
    assert!(
        (f("friction_at_high_n") - 16.7).abs() < 0.05 * 16.7,
        "{}",
        f("friction_at_high_n")
    );
    // The friction-blind model misses the impact energy by the paper's order
    // (its earlier models: 9.7–13 %; this simulator's friction costs more).
    assert!(
        (9.0..=25.0).contains(&s.impact_energy_error_before),
        "{}",
        s.impact_energy_error_before
    );
    assert!(s.impact_energy_error_after <= 1.0, "{}", s.impact_energy_error_after);
    assert!(s.frequency_error_after < s.frequency_error_before);
    // The paper's own check: its friction put into the nominal model,
    // nothing refitted, closes most of the friction-blind gap on a hammer
    // of the model's form (what is left is the ±3 % the generator jitters).
    assert!(
        s.impact_energy_error_effects_only < s.impact_energy_error_before / 3.0,
        "{} vs nominal {}",
        s.impact_energy_error_effects_only,
        s.impact_energy_error_before
    );
    // Nine nominal parameters with a real hammer's ±20 % can bend the impact
    // energy too, so the recalibration alone is a control, not a proof: the
    // named model does at least as well, and the nominal parameters it needs
    // stay within their prior (the friction is pinned by the force balance,
    // which no nominal parameter can fake).
    assert!(
        s.impact_energy_error_after <= s.impact_energy_error_recalibrated_only + 0.2,
        "{} vs recalibrated only {}",
        s.impact_energy_error_after,
        s.impact_energy_error_recalibrated_only
    );
    let moved: Vec<_> = r.recalibration.iter().filter(|p| p.beyond_prior).collect();
    assert!(moved.is_empty(), "{moved:?}");
    assert_eq!(r.recalibration.len(), 9);
    assert_eq!(s.held_out_points, vec![5.0, 6.0]);
    // Where: the motion in the stroke, as the paper found.
    let top = &r.where_[0];
    assert!(top.signal == "accel_mps2" || top.signal == "velocity_mps", "{top:?}");
    assert!(top.stage.name().starts_with("stroke"), "{top:?}");
    // The evidence names the signature: an offset that flips with the motion.
    assert!(r.effects[0].evidence.iter().any(|e| e.contains("flips sign")));
}

#[test]
fn a_hammer_without_an_unmodelled_effect_gets_none() {
    for seed in [3, 4] {
        let inputs = measure(&[], &[4.0, 5.5, 7.0], &[4.0, 7.0], seed);
        let r = run(&inputs);
        println!("seed {seed}: {:?}: {}", r.verdict.effects, r.verdict.reason);
        assert_eq!(r.verdict.effects, vec!["none"], "{}", r.verdict.reason);
        assert!(r.effects.iter().all(|e| e.score < Options::default().min_score));
    }
}

#[test]
fn a_pressure_gain_error_is_not_mistaken_for_friction() {
    let inputs = measure(&["pressure_gain_error:rear=0.03,front=-0.02"], &[4.0, 7.0], &[4.0], 8);
    let r = run(&inputs);
    println!("{:?}: {}", r.verdict.effects, r.verdict.reason);
    assert_eq!(r.verdict.effects, vec!["pressure_gain_error"]);
    let g = &r.verdict.params;
    assert!((g["rear"].as_f64().unwrap() - 0.03).abs() < 0.003, "{g}");
    assert!((g["front"].as_f64().unwrap() + 0.02).abs() < 0.002, "{g}");
    assert!(r.effects[0].evidence[0].contains("does not flip"));
}

#[test]
fn one_operating_point_is_judged_on_its_later_cycles() {
    let inputs = measure(&["valve_delay:tau_s=0.0015"], &[5.0], &[], 9);
    let r = run(&inputs);
    println!("{:?}: {}  {:?}", r.verdict.effects, r.verdict.reason, r.verdict.params);
    assert_eq!(r.verdict.effects, vec!["valve_delay"]);
    assert!(r.shrink.held_out_points.is_empty());
    assert!(r.shrink.judged_on.contains("later half"));
    assert!(r.inputs[0].fit_cycles > 0 && r.inputs[0].held_out_cycles > 0);
    assert!(r.shrink.impact_energy_error_after < r.shrink.impact_energy_error_before);
}
