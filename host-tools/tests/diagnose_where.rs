//! Where the gap lies: the paper found its friction-blind model matched the
//! chamber pressures but missed the piston acceleration. The breakdown must
//! find the same when the "measurement" carries the paper's friction, and
//! find nothing beyond noise when it carries none.

use hammer_host::diagnose::gap::{breakdown, measured_cycles, template, GapCell};
use hammer_sim::estimation::run;
use hammer_sim::simulate::simulate;
use hammer_sim::{simulate_truth, SimConfig};

fn gaps(effect: Option<&str>, bar: f64) -> Vec<GapCell> {
    let mut meas_cfg = SimConfig::nominal(bar);
    meas_cfg.solver.duration_s = 1.0;
    meas_cfg.seed = 11;
    if let Some(e) = effect {
        meas_cfg.effects.apply_spec(e).unwrap();
    }
    let meas = simulate(&meas_cfg).unwrap();
    let trace = meas.trace();
    let est = meas_cfg.estimator_config(Some(bar)).unwrap();
    let impacts: Vec<f64> = run(meas.codes(), est)
        .unwrap()
        .iter()
        .filter(|r| r.t_impact_s() > 0.2)
        .map(|r| r.t_impact_s())
        .collect();
    let mut model = SimConfig::nominal(bar);
    model.solver.duration_s = 0.6;
    let sim = simulate_truth(&model).unwrap();
    let (tpl, stages) = template(&sim.into(), &model.hammer).unwrap();
    breakdown(&tpl, &stages, &measured_cycles(&trace, &impacts))
}

fn worst(cells: &[GapCell], signal: &str) -> f64 {
    cells
        .iter()
        .filter(|c| c.signal == signal)
        .map(|c| c.relative_rms)
        .fold(0.0, f64::max)
}

#[test]
fn friction_shows_in_the_motion_more_than_in_the_pressures() {
    let cells = gaps(Some("coulomb_friction"), 4.0);
    for c in cells.iter().take(8) {
        println!(
            "{:>13} {:>17} bias {:>10.3} rms {:>10.3} rel {:.3} shift {:+.2} ms",
            c.signal,
            c.stage.name(),
            c.bias,
            c.rms,
            c.relative_rms,
            c.timing_shift_s * 1e3
        );
    }
    let motion = worst(&cells, "accel_mps2").max(worst(&cells, "velocity_mps"));
    let pressure = worst(&cells, "p_rear_pa").max(worst(&cells, "p_front_pa"));
    assert!(
        motion > pressure,
        "motion gap {motion:.3} vs pressure gap {pressure:.3}"
    );
    assert!(
        cells[0].signal == "accel_mps2" || cells[0].signal == "velocity_mps",
        "{:?}",
        cells[0]
    );
}

#[test]
fn without_an_unmodelled_effect_the_gap_is_noise() {
    let cells = gaps(None, 5.0);
    for c in cells.iter().take(4) {
        println!("{:>13} {:>17} rel {:.4}", c.signal, c.stage.name(), c.relative_rms);
    }
    assert!(cells.iter().all(|c| c.relative_rms < 0.05), "{:?}", cells[0]);
    let with_friction = gaps(Some("coulomb_friction"), 5.0);
    assert!(with_friction[0].relative_rms > 5.0 * cells[0].relative_rms);
}
