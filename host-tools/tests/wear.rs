//! The wear indicator on long simulated runs: the drift alarm fires on a
//! friction step and stays quiet for 10 000 cycles of constant friction; the
//! wear state survives a reset.

use hammer_estimator::{CycleReport, Estimator, Flags, RawSample, WearState};
use hammer_sim::sensor::measure;
use hammer_sim::simulate::simulate;
use hammer_sim::{simulate_truth, SimConfig};

fn config_for(sim_cfg: &SimConfig) -> hammer_estimator::Config {
    sim_cfg.estimator_config(Some(sim_cfg.supply.pressure_bar)).unwrap()
}

#[test]
fn a_five_percent_friction_step_fires_the_alarm_within_50_cycles() {
    let step_at = 3.5;
    let mut cfg = SimConfig::nominal(5.0);
    cfg.solver.duration_s = 6.5;
    cfg.effects
        .apply_spec(&format!("coulomb_friction:step_at_s={step_at},step_factor=1.05"))
        .unwrap();
    let sim = simulate(&cfg).unwrap();
    let est_cfg = config_for(&cfg);
    let mut est = Estimator::new(est_cfg).unwrap();
    let mut reports = Vec::new();
    est.push_block(sim.codes(), |r| reports.push(r));
    let before: Vec<&CycleReport> = reports.iter().filter(|r| r.t_impact_s() < step_at).collect();
    assert!(
        before.iter().filter(|r| r.is_valid()).count() > 60,
        "baseline needs 50 cycles before the step"
    );
    assert!(
        before.iter().all(|r| !r.flags.contains(Flags::DRIFT_ALARM)),
        "alarm before the step"
    );
    let after: Vec<&CycleReport> = reports.iter().filter(|r| r.t_impact_s() >= step_at).collect();
    let first = after
        .iter()
        .position(|r| r.flags.contains(Flags::DRIFT_ALARM))
        .expect("alarm after the step");
    println!("+5 % friction step: alarm after {} cycles", first + 1);
    assert!(first < 50, "alarm after {} cycles", first + 1);
    // And it stays on while the friction stays up.
    assert!(after[first..]
        .iter()
        .filter(|r| r.is_valid())
        .all(|r| r.flags.contains(Flags::DRIFT_ALARM)));
}

/// One steady stretch of the hammer, impact to impact, measured again and
/// again with fresh sensor noise: a long run at constant friction.
fn constant_friction_stream(cycles_wanted: usize, mut sink: impl FnMut(&[RawSample])) -> usize {
    let mut cfg = SimConfig::nominal(5.0);
    cfg.solver.duration_s = 1.3;
    cfg.effects.apply_spec("coulomb_friction").unwrap();
    let run = simulate_truth(&cfg).unwrap();
    let dt = run.truth.dt_s;
    let impacts: Vec<usize> = run
        .events
        .impacts
        .iter()
        .filter(|e| e.t_s > 0.15)
        .map(|e| (e.t_s / dt).ceil() as usize)
        .collect();
    let (i0, i1) = (impacts[0], *impacts.last().unwrap());
    let per_window = impacts.len() - 1;
    let _est_cfg = config_for(&cfg);
    let mut cycles = 0;
    let mut seed = 1;
    while cycles < cycles_wanted {
        let m = measure(&cfg.sensors, &cfg.effects, &run.truth, &run.events.impacts, seed);
        sink(&m.codes[i0..i1]);
        cycles += per_window;
        seed += 1;
    }
    cycles
}

#[test]
fn ten_thousand_cycles_of_constant_friction_raise_no_alarm() {
    let mut cfg = SimConfig::nominal(5.0);
    cfg.solver.duration_s = 1.3;
    let mut est = Estimator::new(config_for(&cfg)).unwrap();
    let mut reports = 0usize;
    let mut valid = 0usize;
    let mut alarms = 0usize;
    let mut max_score = 0.0f32;
    constant_friction_stream(10_050, |block| {
        est.push_block(block, |r| {
            reports += 1;
            if r.is_valid() {
                valid += 1;
            }
            if r.flags.contains(Flags::DRIFT_ALARM) {
                alarms += 1;
            }
            max_score = max_score.max(r.drift_score);
        })
    });
    println!("{reports} cycles ({valid} valid), highest drift score {max_score:.2}, alarms {alarms}");
    assert!(valid >= 10_000, "{valid} valid cycles");
    assert_eq!(alarms, 0);
    assert_eq!(est.counters().stalls, 0);
}

#[test]
fn wear_state_survives_a_reset() {
    let mut cfg = SimConfig::nominal(5.0);
    cfg.solver.duration_s = 1.3;
    let est_cfg = config_for(&cfg);
    let mut samples = Vec::new();
    constant_friction_stream(150, |b| samples.extend_from_slice(b));
    let half = samples.len() / 2 + 1234; // mid-cycle

    let mut whole = Estimator::new(est_cfg).unwrap();
    let mut last_whole = None;
    whole.push_block(&samples, |r| last_whole = Some(r));

    let mut first = Estimator::new(est_cfg).unwrap();
    first.push_block(&samples[..half], |_| {});
    let saved = first.wear_state().to_bytes();
    let mut second = Estimator::new(est_cfg).unwrap();
    second.restore_wear(WearState::from_bytes(&saved).unwrap());
    let mut last = None;
    second.push_block(&samples[half..], |r| last = Some(r));
    let (a, b) = (last_whole.unwrap(), last.unwrap());
    // The reset loses the cycle under way at the cut (and the one after it
    // needs an impact to start): at most two cycles' friction work.
    let per_cycle = a.friction_work_j;
    assert!(
        b.wear_index_j < a.wear_index_j - 0.5 * per_cycle && b.wear_index_j > a.wear_index_j - 2.5 * per_cycle,
        "{} vs {}",
        b.wear_index_j,
        a.wear_index_j
    );
    // The baseline came with the state: no relearning, the drift score is live.
    assert_eq!(second.wear_state().n_baselines, 1);
    assert!(second.wear_state().baselines[0].n >= 50);
}
