//! The chamber characteristics against their truth (the same calculation on
//! the true pressures and position) on both model families, at 4 and 7 bar:
//! what `docs/estimator.md` ("Chamber characteristics") states.

use hammer_host::chambers::{
    compare, effects_of as effects, mean_front_port_opening_s, mean_onset_s, run, Family, Tally,
};

/// The effects the characteristics are checked with (the pressure gain
/// error left out: a calibration error, which the stated uncertainty leaves
/// out by design).
const CHECKED_EFFECTS: [&str; 8] = [
    "none",
    "coulomb_friction:f0_n=1.7,k_n_per_bar=2.14",
    "viscous_friction",
    "leakage",
    "valve_delay:tau_s=0.0015",
    "heat_transfer",
    "supply_restriction",
    "accel_zero_shift",
];

/// Every cycle of a sound hammer gives both feeds, and each characteristic
/// lies near its truth: onsets within 0.1 ms RMS, closed-phase exponents
/// within 0.01, feed areas within 10 % (measured: at most 0.03 ms, 0.003
/// and 4.4 %).
#[test]
fn a_sound_hammer_gives_both_feeds_near_their_truth_on_both_families() {
    for family in [Family::Model, Family::Variant] {
        for bar in [4.0, 7.0] {
            let t = Tally::of(&run(family, bar, &effects("none"), 1.0, 3));
            let what = format!("{} at {bar} bar: {}", family.name(), t.line());
            assert!(t.cycles >= 15, "{what}");
            assert_eq!(t.missing, 0, "{what}");
            assert!(t.front_onset.rms() < 0.1e-3 && t.rear_onset.rms() < 0.1e-3, "{what}");
            assert!(t.front_exponent.rms() < 0.01 && t.rear_exponent.rms() < 0.01, "{what}");
            assert!(t.front_area.rms() < 0.10 && t.rear_area.rms() < 0.10, "{what}");
            assert!(t.rear_onset.max_u < 0.3e-3 && t.front_onset.max_u < 0.3e-3, "{what}");
            assert!(t.front_exponent.max_u < 0.1 && t.rear_exponent.max_u < 0.1, "{what}");
        }
    }
}

/// The evidence the structural diagnosis lacked, measured from the signals:
/// the second family's valve feeds the front chamber before the impact, the
/// model's after it (docs/diagnosis.md, why no valve delay was named).
#[test]
fn the_second_familys_front_feed_starts_before_the_impact_and_the_models_after() {
    for bar in [4.0, 7.0] {
        let model = mean_onset_s(&run(Family::Model, bar, &effects("none"), 1.0, 3).measured, true).unwrap();
        let variant = mean_onset_s(&run(Family::Variant, bar, &effects("none"), 1.0, 3).measured, true).unwrap();
        assert!(
            model > 0.0 && variant < -0.5e-3,
            "{bar} bar: model {model:e} s, variant {variant:e} s"
        );
    }
}

/// A hidden valve delay of 1.5 ms moves the measured front feed by the
/// spool's true shift within 0.25 ms on both families (measured over 1 s
/// runs: model +0.085 / −0.004 ms at 4 / 7 bar, second family −0.071 /
/// +0.237 ms; docs/estimator.md).
#[test]
fn a_hidden_valve_delay_moves_the_measured_switching_with_the_spool() {
    for bar in [4.0, 7.0] {
        for family in [Family::Model, Family::Variant] {
            let none = run(family, bar, &effects("none"), 1.0, 5);
            let delayed = run(family, bar, &effects("valve_delay:tau_s=0.0015"), 1.0, 5);
            let measured = mean_onset_s(&delayed.measured, true).unwrap() - mean_onset_s(&none.measured, true).unwrap();
            let port = mean_front_port_opening_s(&delayed).unwrap() - mean_front_port_opening_s(&none).unwrap();
            let what = format!(
                "{} at {bar} bar: measured {measured:e} s, port {port:e} s",
                family.name()
            );
            assert!(port > 0.5e-3 && measured > 0.5e-3, "{what}");
            assert!((measured - port).abs() < 0.25e-3, "{what}");
        }
    }
}

/// The stated expanded uncertainties (k = 2, random and track terms, no
/// calibration terms) against the truth, over both families at 4 and 7 bar
/// with no effect and each effect but the pressure gain error (a
/// calibration error, which the stated uncertainty leaves out by design).
/// Measured over 1 s runs (docs/estimator.md), with the pressures read
/// back by their transducers' delay: onsets 98 % / 98 %, exponents 99 % /
/// 99 %, areas 98 % / 99 %, the onsets' mean differences −0.004 and
/// −0.012 ms (without it the front onset covered 89 %, the areas 97 % /
/// 100 %). Here 0.5 s runs: each within the 90–99.5 % (the upper
/// bound: a U that covers every cycle is too wide), every onset's mean
/// difference within 0.03 ms (it was −0.056 ms on the rear feed while the
/// band was chosen by the noisy samples).
#[test]
fn the_stated_uncertainties_cover_the_truth_in_most_cycles() {
    let mut total = Tally::default();
    for family in [Family::Model, Family::Variant] {
        for bar in [4.0, 7.0] {
            for spec in CHECKED_EFFECTS {
                total.add(&compare(family, bar, &effects(spec), 0.5, 7).0);
            }
        }
    }
    let line = total.line();
    for a in total.all() {
        assert!(a.cycles >= 200 && (0.90..=0.995).contains(&a.coverage()), "{line}");
    }
    assert!(
        total.front_onset.mean().abs() < 0.03e-3 && total.rear_onset.mean().abs() < 0.03e-3,
        "{line}"
    );
}

/// A feed is stated for the cycle it belongs to. On a hammer whose leak
/// feeds the front chamber all through its closed phase (a 32 µm gap past
/// the piston, a position-latched valve and ramped ports, as the
/// structural benchmark's case 98 of seed 7), the slow rise's tangent used
/// to meet zero tens to hundreds of milliseconds before the impact, in
/// cycles long gone (measured: −40 to −564 ms, where the cycle lasts about
/// 45 ms), and the diagnosis averaged them. A front feed read now starts
/// after the previous impact, or is not read at all.
#[test]
fn a_feed_read_lies_within_its_own_cycle() {
    use hammer_host::diagnose::engine::extractor_for;
    use hammer_host::diagnose::features::{Signals, FRONT_FEED};
    use hammer_sim::effects::Effects;
    use hammer_variants::{generate, Structure, VariantParams};
    let singles = Structure::singles();
    let structure = Structure::BASE.with(&singles[0]).with(&singles[1]);
    let mut leak = Effects::default();
    leak.apply_spec("leakage:gap_m=3.2e-5").unwrap();
    let ex = extractor_for(&hammer_sim::SimConfig::default());
    let mut read = 0;
    for bar in [5.5, 7.0] {
        let g = generate(&VariantParams::default(), structure, &leak, bar, 1.0, 3);
        let cycles = ex.cycles(&Signals::of_trace(&g.trace, bar));
        for w in cycles.windows(2) {
            let onset = w[1].values[FRONT_FEED];
            let period = w[1].t_impact_s - w[0].t_impact_s;
            assert!(
                onset.is_nan() || (onset > -period && onset < 0.01),
                "{bar} bar: a front feed {:.1} ms from its impact, the cycle lasting {:.1} ms",
                1e3 * onset,
                1e3 * period
            );
            read += usize::from(onset.is_finite());
        }
    }
    println!("{read} front feeds read");
}
