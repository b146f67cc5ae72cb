//! The trace format: round trips, outside data, and clear errors on bad files.

use std::path::PathBuf;

use hammer_sim::simulate::simulate;
use hammer_sim::SimConfig;
use hammer_trace::trace::{read_csv, read_sidecar, sidecar_path, write_csv, write_sidecar, Sidecar, TraceError};

fn tmp(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("hammer-trace-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}

#[test]
fn simulated_trace_round_trips_exactly_with_its_sidecar() {
    let mut cfg = SimConfig::nominal(5.0);
    cfg.solver.duration_s = 0.12;
    cfg.effects.apply_spec("coulomb_friction").unwrap();
    let sim = simulate(&cfg).unwrap();
    let path = tmp("round.csv");
    let trace = sim.trace();
    write_csv(&path, &trace).unwrap();
    write_sidecar(&path, &sim.sidecar()).unwrap();
    let back = read_csv(&path).unwrap();
    assert_eq!(back.len(), trace.len());
    assert_eq!(back.p_rear_pa, trace.p_rear_pa);
    assert_eq!(back.p_front_pa, trace.p_front_pa);
    assert_eq!(back.accel_mps2, trace.accel_mps2);
    assert_eq!(back.extra["x_m"], trace.extra["x_m"]);
    assert_eq!(back.extra["v_mps"], trace.extra["v_mps"]);
    assert!((back.dt_s - 10e-6).abs() < 1e-12);
    let side = hammer_sim::simulate::read_simulated_sidecar(&path)
        .unwrap()
        .expect("sidecar");
    assert_eq!(side.supply_pressure_bar, Some(5.0));
    let info = side.simulation.expect("simulation info");
    assert_eq!(info.active_effects, vec!["coulomb_friction"]);
    assert_eq!(info.config, cfg);
    assert_eq!(info.cycles, sim.run.cycles);
    // The truth columns agree with the per-cycle truth: the piston reaches the
    // impact position at the recorded impact time.
    let c = &info.cycles[0];
    let i = (c.t_impact_s / back.dt_s).ceil() as usize;
    assert!(back.extra["x_m"][i] >= cfg.hammer.impact_position_m - 1e-9);
    assert!(back.extra["x_m"][i - 2] < cfg.hammer.impact_position_m);
}

#[test]
fn outside_data_with_reordered_and_extra_columns_is_read() {
    let path = tmp("outside.csv");
    std::fs::write(
        &path,
        "comment_col,accel_mps2,t_s,p_front_pa,p_rear_pa\n1,0.5,0.0,100,200\n2,0.25,0.00002,110,210\n3,0.0,0.00004,120,220\n",
    )
    .unwrap();
    let t = read_csv(&path).unwrap();
    assert_eq!(t.p_rear_pa, vec![200.0, 210.0, 220.0]);
    assert_eq!(t.accel_mps2, vec![0.5, 0.25, 0.0]);
    assert!((t.dt_s - 2e-5).abs() < 1e-15);
    assert_eq!(t.extra["comment_col"], vec![1.0, 2.0, 3.0]);
    assert!(read_sidecar(&path).unwrap().is_none());
}

fn error_of(name: &str, text: &str) -> String {
    let path = tmp(name);
    std::fs::write(&path, text).unwrap();
    read_csv(&path).unwrap_err().to_string()
}

#[test]
fn malformed_files_get_errors_that_say_where_and_what() {
    let e = error_of("empty.csv", "");
    assert!(e.contains("empty file"), "{e}");
    let e = error_of("nocol.csv", "t_s,p_rear_pa,accel_mps2\n0,1,2\n");
    assert!(e.contains("missing column `p_front_pa`"), "{e}");
    let e = error_of("bad.csv", "t_s,p_rear_pa,p_front_pa,accel_mps2\n0,1,2,3\n0.1,1,x2,3\n");
    assert!(e.contains(":3:") && e.contains("p_front_pa") && e.contains("x2"), "{e}");
    let e = error_of("nan.csv", "t_s,p_rear_pa,p_front_pa,accel_mps2\n0,1,2,3\n0.1,NaN,2,3\n");
    assert!(e.contains("p_rear_pa") && e.contains("NaN"), "{e}");
    let e = error_of("short.csv", "t_s,p_rear_pa,p_front_pa,accel_mps2\n0,1,2,3\n0.1,1,2\n");
    assert!(e.contains("expected 4 fields, found 3"), "{e}");
    let e = error_of(
        "gap.csv",
        "t_s,p_rear_pa,p_front_pa,accel_mps2\n0,1,2,3\n0.1,1,2,3\n0.3,1,2,3\n0.4,1,2,3\n",
    );
    assert!(e.contains("not uniform"), "{e}");
    let e = error_of("dup.csv", "t_s,p_rear_pa,p_front_pa,accel_mps2,t_s\n0,1,2,3,0\n");
    assert!(e.contains("duplicate column `t_s`"), "{e}");
    let e = error_of("one.csv", "t_s,p_rear_pa,p_front_pa,accel_mps2\n0,1,2,3\n");
    assert!(e.contains("at least 2 samples"), "{e}");
    let missing = read_csv(&tmp("does-not-exist.csv")).unwrap_err();
    assert!(matches!(missing, TraceError::Io { .. }));
}

#[test]
fn sidecars_of_another_format_or_a_newer_version_are_refused() {
    let path = tmp("side.csv");
    let mut s: Sidecar = Sidecar::new(Some(4.0), "device");
    s.version = 99;
    write_sidecar(&path, &s).unwrap();
    let e = read_sidecar(&path).unwrap_err().to_string();
    assert!(e.contains("version 99"), "{e}");
    std::fs::write(
        sidecar_path(&path),
        "{\"format\":\"other\",\"version\":1,\"supply_pressure_bar\":4,\"source\":\"x\"}",
    )
    .unwrap();
    let e = read_sidecar(&path).unwrap_err().to_string();
    assert!(e.contains("format is `other`"), "{e}");
    std::fs::write(sidecar_path(&path), "{not json").unwrap();
    assert!(read_sidecar(&path).is_err());
}
