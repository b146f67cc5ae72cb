//! The trace format: round trips, outside data, and clear errors on bad files.

use std::path::PathBuf;

use hammer_sim::simulate::simulate;
use hammer_sim::SimConfig;
use hammer_trace::rows::MAX_LINE_BYTES;
use hammer_trace::trace::{
    read_csv, read_sidecar, sidecar_path, write_csv, write_sidecar, Gap, Sidecar, TraceError, SIDECAR_VERSION,
};

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
    // An interval that is no whole number of periods is refused at its own line.
    let e = error_of(
        "jitter.csv",
        "t_s,p_rear_pa,p_front_pa,accel_mps2\n0,1,2,3\n0.1,1,2,3\n0.2,1,2,3\n0.35,1,2,3\n0.45,1,2,3\n",
    );
    assert!(e.contains(":5:") && e.contains("not uniform"), "{e}");
    let e = error_of(
        "backwards.csv",
        "t_s,p_rear_pa,p_front_pa,accel_mps2\n0,1,2,3\n0.1,1,2,3\n0.0,1,2,3\n",
    );
    assert!(e.contains(":4:") && e.contains("time goes backwards"), "{e}");
    let e = error_of(
        "binary.csv",
        "t_s,p_rear_pa,p_front_pa,accel_mps2\n0,1,2,3\n\u{0}\u{0}\u{ff}\n",
    );
    assert!(e.contains(":3:"), "{e}");
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
    // What an outside user writes by hand: the operating point alone (the
    // version is then this tool's).
    std::fs::write(sidecar_path(&path), "{\"supply_pressure_bar\": 4}").unwrap();
    let s = read_sidecar(&path).unwrap().unwrap();
    assert_eq!(
        (s.format.as_str(), s.version, s.supply_pressure_bar),
        ("hammer-trace", SIDECAR_VERSION, Some(4.0))
    );
    // A version-1 sidecar (Box–Muller noise, `SIDECAR_VERSION`'s history) still reads.
    std::fs::write(sidecar_path(&path), "{\"version\": 1, \"supply_pressure_bar\": 4}").unwrap();
    assert_eq!(read_sidecar(&path).unwrap().unwrap().version, 1);
    assert_eq!(s.source, "import");
}

#[test]
fn a_gap_in_the_timestamps_is_a_gap_not_a_rejected_file() {
    let e = |t: &[f64]| {
        let mut text = String::from("t_s,p_rear_pa,p_front_pa,accel_mps2\n");
        for x in t {
            text += &format!("{x},1,2,3\n");
        }
        text
    };
    let path = tmp("gap.csv");
    std::fs::write(&path, e(&[0.0, 0.1, 0.4, 0.5, 0.6])).unwrap();
    let t = read_csv(&path).unwrap();
    assert_eq!(t.len(), 5);
    assert_eq!(t.gaps, vec![Gap { before: 2, missing: 2 }]);
    assert!((t.dt_s - 0.1).abs() < 1e-12, "{}", t.dt_s);
    // A gap right after the first row does not fool the period either.
    std::fs::write(&path, e(&[0.0, 0.2, 0.3, 0.4])).unwrap();
    let t = read_csv(&path).unwrap();
    assert_eq!(t.gaps, vec![Gap { before: 1, missing: 1 }]);
    assert!((t.dt_s - 0.1).abs() < 1e-12, "{}", t.dt_s);
    // Times at the edge of f64 (found by the fuzzer): a span that overflows
    // still gives a finite period; a step that overflows, or a gap longer than
    // the estimator can count, is refused at its line.
    std::fs::write(&path, e(&[-1e308, 0.0, 1e308])).unwrap();
    let t = read_csv(&path).unwrap();
    assert!(t.dt_s.is_finite() && (t.dt_s / 1e308 - 1.0).abs() < 1e-12, "{}", t.dt_s);
    std::fs::write(&path, e(&[-1.5e308, -1.4e308, -1.3e308, 1.5e308])).unwrap();
    assert!(matches!(read_csv(&path), Err(TraceError::NotUniform { line: 5, .. })));
    std::fs::write(&path, e(&[0.0, 1e-5, 2e-5, 1e6])).unwrap();
    assert!(matches!(read_csv(&path), Err(TraceError::NotUniform { line: 5, .. })));
}

#[test]
fn text_in_a_further_column_is_kept_as_nan_not_refused() {
    let path = tmp("text.csv");
    std::fs::write(
        &path,
        "t_s,p_rear_pa,p_front_pa,accel_mps2,operator\n0,1,2,3,anna\n0.1,1,2,3,anna\n0.2,1,2,3,ben\n",
    )
    .unwrap();
    let t = read_csv(&path).unwrap();
    assert_eq!(t.len(), 3);
    assert!(t.extra["operator"].iter().all(|v| v.is_nan()));
}

#[test]
fn a_line_without_end_is_refused_in_bounded_memory() {
    let mut text = String::from("t_s,p_rear_pa,p_front_pa,accel_mps2\n0,1,2,3\n");
    text.extend(std::iter::repeat('7').take(MAX_LINE_BYTES * 4));
    let e = hammer_trace::trace::read_csv_from(text.as_bytes(), "long.csv")
        .unwrap_err()
        .to_string();
    assert!(e.contains("long.csv:3: line longer than"), "{e}");
    // The header too.
    let e = hammer_trace::trace::read_csv_from(&[b'x'; MAX_LINE_BYTES * 2][..], "h.csv")
        .unwrap_err()
        .to_string();
    assert!(e.contains("h.csv:1: line longer than"), "{e}");
}

/// The streamed estimation (what `hammer estimate` runs) gives the very
/// reports of the in-memory path, and reads the chambers into them as a
/// board does; a gap flags its cycle and only its cycle.
#[test]
fn streamed_estimation_matches_the_in_memory_path_and_flags_gaps() {
    use hammer_sim::estimation::{open_for_estimation, stream_estimation};
    let mut cfg = SimConfig::nominal(5.0);
    cfg.solver.duration_s = 0.4;
    cfg.effects.apply_spec("coulomb_friction").unwrap();
    let sim = simulate(&cfg).unwrap();
    let path = tmp("stream.csv");
    write_csv(&path, &sim.trace()).unwrap();
    write_sidecar(&path, &sim.sidecar()).unwrap();
    let whole = open_for_estimation(&path, &SimConfig::default(), None).unwrap();
    let in_memory = whole.run().unwrap();
    let mut streamed = Vec::new();
    let summary = stream_estimation(&path, &SimConfig::default(), None, |r| streamed.push(r)).unwrap();
    assert!(in_memory.len() >= 5, "{} cycles", in_memory.len());
    let unread = hammer_estimator::Flags::CHAMBERS_UNREAD;
    assert!(streamed.iter().filter(|r| !r.flags.contains(unread)).count() + 2 >= streamed.len());
    let bare = |rs: &[hammer_estimator::CycleReport]| -> Vec<hammer_estimator::CycleReport> {
        rs.iter()
            .map(|r| {
                let mut r = *r;
                r.mark_chambers_unread();
                r
            })
            .collect()
    };
    assert_eq!(bare(&streamed), in_memory);
    assert_eq!(summary.samples as usize, whole.trace.len());
    assert_eq!(summary.missing_samples, 0);

    // 50 rows cut out in the middle of the third cycle.
    let mut trace = sim.trace();
    let t_mid = 0.5 * (in_memory[2].t_impact_s() + in_memory[3].t_impact_s());
    let at = (t_mid / trace.dt_s) as usize;
    for col in [
        &mut trace.t_s,
        &mut trace.p_rear_pa,
        &mut trace.p_front_pa,
        &mut trace.accel_mps2,
    ] {
        col.drain(at..at + 50);
    }
    for col in trace.extra.values_mut() {
        col.drain(at..at + 50);
    }
    let cut = tmp("stream-gap.csv");
    write_csv(&cut, &trace).unwrap();
    write_sidecar(&cut, &sim.sidecar()).unwrap();
    let mut gapped = Vec::new();
    let summary = stream_estimation(&cut, &SimConfig::default(), None, |r| gapped.push(r)).unwrap();
    assert_eq!(summary.missing_samples, 50);
    assert_eq!(gapped.len(), in_memory.len());
    let dropped = hammer_estimator::Flags::DROPPED_SAMPLES;
    for (g, r) in gapped.iter().zip(&in_memory) {
        // Timing stays right across the gap.
        assert!(
            (g.t_impact_s() - r.t_impact_s()).abs() < 1e-9,
            "{} vs {}",
            g.t_impact_s(),
            r.t_impact_s()
        );
        assert_eq!(g.flags.contains(dropped), g.seq == 3, "cycle {}: {:?}", g.seq, g.flags);
        if !g.flags.contains(dropped) {
            // Cycles after the gap carry the wear state of one cycle fewer.
            assert!((g.impact_energy_j - r.impact_energy_j).abs() < 1e-6 * r.impact_energy_j);
        }
    }
    let back = open_for_estimation(&cut, &SimConfig::default(), None).unwrap();
    assert_eq!(back.run().unwrap(), bare(&gapped));
}

/// A recorder that stamps time in whole µs at 48 kS/s writes intervals of 20
/// and 21 µs: that is uniform sampling, read at the true rate (here to
/// within 1 S/s), and a real jitter in such a file is still refused.
#[test]
fn time_stamps_rounded_to_the_recorders_resolution_are_uniform() {
    use hammer_trace::rows::{RowReader, Uniform};
    let mut text = String::from("t_s,p_rear_pa,p_front_pa,accel_mps2\n");
    for i in 0..20_000 {
        text.push_str(&format!("{:.6},{},0,0\n", i as f64 / 48_000.0, i % 7));
    }
    let path = tmp("us48k.csv");
    std::fs::write(&path, &text).unwrap();
    let t = read_csv(&path).unwrap();
    assert_eq!(t.len(), 20_000);
    assert!(t.gaps.is_empty());
    assert!((1.0 / t.dt_s - 48_000.0).abs() < 1.0, "{}", 1.0 / t.dt_s);
    // The streaming reader knows the rate up front, from its first rows.
    let u = Uniform::new(RowReader::new(text.as_bytes(), "us48k", false).unwrap()).unwrap();
    assert!((1.0 / u.dt_s() - 48_000.0).abs() < 1.0, "{}", 1.0 / u.dt_s());
    // A step of 3 µs off the grid in the same file is jitter, not rounding.
    let bad = text.replacen("\n0.000104,", "\n0.000107,", 1);
    assert_ne!(bad, text);
    std::fs::write(&path, &bad).unwrap();
    let e = read_csv(&path).unwrap_err().to_string();
    assert!(e.contains("not uniform"), "{e}");
}
