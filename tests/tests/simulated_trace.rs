//! Across crates: a trace written by `hammer simulate`, read back from disk,
//! carries what the estimator needs: with ideal sensors the paper's force
//! balance F = s·(p1·A1 − p2·A2 − m·a), using the estimator's geometry,
//! recovers the friction the simulator applied.

use clap::Parser;
use hammer_estimator::Geometry;
use hammer_host::cli::{run, Cli};
use hammer_sim::simulate::read_simulated_sidecar;
use hammer_trace::trace::read_csv;

#[test]
fn paper_force_balance_on_a_simulated_trace_recovers_the_applied_friction() {
    let dir = std::env::temp_dir().join(format!("hammer-e2e-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("run.csv");
    let mut cli = vec![
        "simulate",
        "--supply-bar",
        "6",
        "--duration",
        "0.4",
        "--ideal-sensors",
        "--out",
    ];
    let path_str = path.to_str().unwrap().to_string();
    cli.push(&path_str);
    cli.extend(["--effect", "coulomb_friction"]);
    run(Cli::parse_from(std::iter::once("hammer").chain(cli))).unwrap();

    let trace = read_csv(&path).unwrap();
    let side = read_simulated_sidecar(&path).unwrap().unwrap();
    let truth = side.simulation.unwrap();
    let g = Geometry::PAPER;
    let (a1, a2, m) = (g.rear_area_m2(), g.front_area_m2(), g.piston_mass_kg);
    let v = &trace.extra["v_mps"];
    let expected = 10.27 + (16.7 - 10.27) / 3.0 * 2.0; // the paper's friction line at 6 bar
    for c in truth.cycles.iter().skip(2) {
        // Stroke phase: from the turning point to the impact, 0.5 ms margins.
        let i0 = ((c.t_stroke_start_s + 5e-4) / trace.dt_s) as usize;
        let i1 = ((c.t_impact_s - 5e-4) / trace.dt_s) as usize;
        let f: f64 = (i0..i1)
            .map(|i| v[i].signum() * (trace.p_rear_pa[i] * a1 - trace.p_front_pa[i] * a2 - m * trace.accel_mps2[i]))
            .sum::<f64>()
            / (i1 - i0) as f64;
        assert!(
            (f - expected).abs() < 0.01 * expected,
            "cycle {}: {f:.3} N vs {expected:.3} N",
            c.index
        );
        assert!((c.friction_stroke_n - expected).abs() < 0.01 * expected);
    }
}
