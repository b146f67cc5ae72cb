//! The trace CSV reader on arbitrary text, and the estimator on whatever it
//! accepts. Invariants: no panic; an accepted trace is consistent (columns
//! of one length, a positive period, finite required values, gaps in order);
//! the streaming reader agrees with the in-memory one; a cycle reported
//! valid carries finite numbers.

use hammer_trace::rows::{Item, RowReader, Uniform};
use hammer_trace::trace::{read_csv_from, Trace, TraceError};

use super::{bit, Target};

pub const TARGET: Target = Target {
    name: "trace_csv",
    run,
    dict: &[
        b",",
        b"\n",
        b"\r\n",
        b"t_s",
        b"p_rear_pa",
        b"p_front_pa",
        b"accel_mps2",
        b"NaN",
        b"inf",
        b"-1e308",
        b"1e-5",
        b"0.00001",
        b"-2000",
        b"\xef\xbb\xbf",
    ],
    seeds,
};

fn run(data: &[u8]) -> u64 {
    let streamed = stream_count(data);
    match read_csv_from(data, "fuzz.csv") {
        Ok(t) => {
            check(&t);
            let expected = (t.len(), t.gaps.iter().map(|g| g.missing).sum::<u64>());
            assert_eq!(streamed.ok(), Some(expected), "the streaming reader agrees");
            bit(1 + t.gaps.len().min(3) as u32) | estimate(&t)
        }
        Err(e) => {
            assert!(
                streamed.is_err(),
                "the streaming reader refuses what the in-memory one refuses"
            );
            bit(10 + error_code(&e))
        }
    }
}

fn check(t: &Trace) {
    let n = t.len();
    assert!(n >= 2);
    for col in [&t.p_rear_pa, &t.p_front_pa, &t.accel_mps2] {
        assert_eq!(col.len(), n);
        assert!(col.iter().all(|v| v.is_finite()));
    }
    assert!(t.extra.values().all(|c| c.len() == n));
    assert!(t.dt_s > 0.0 && t.dt_s.is_finite(), "dt {}", t.dt_s);
    assert!(t.t_s.windows(2).all(|w| w[1] > w[0]), "time runs forward");
    let mut last = 0;
    for g in &t.gaps {
        assert!(
            g.missing >= 1 && g.before >= last.max(1) && g.before < n,
            "{:?}",
            t.gaps
        );
        last = g.before + 1;
    }
}

fn stream_count(data: &[u8]) -> Result<(usize, u64), TraceError> {
    let mut u = Uniform::new(RowReader::new(data, "fuzz.csv", false)?)?;
    let (mut n, mut missing) = (0, 0);
    while let Some(item) = u.next_item()? {
        match item {
            Item::Sample(_) => n += 1,
            Item::Gap { missing: m } => missing += m,
        }
    }
    Ok((n, missing))
}

/// The estimator on an accepted trace, at the default sensors.
fn estimate(t: &Trace) -> u64 {
    use hammer_sim::estimation::{estimator_config, run_with_gaps, to_codes};
    let sim = hammer_sim::SimConfig::default();
    let Ok(cfg) = estimator_config(&sim.hammer, &sim.sensors, &sim.estimator, 1.0 / t.dt_s, Some(4.0)) else {
        return bit(20);
    };
    let reports = run_with_gaps(&to_codes(t, &cfg), &t.gaps, cfg).expect("a valid configuration runs");
    for r in reports.iter().filter(|r| r.is_valid()) {
        for v in [
            r.impact_energy_j,
            r.friction_n,
            r.period_s,
            r.impact_energy_uncertainty_j,
        ] {
            assert!(v.is_finite(), "a valid cycle has finite numbers: {r:?}");
        }
    }
    bit(21 + reports.len().min(3) as u32)
}

fn error_code(e: &TraceError) -> u32 {
    match e {
        TraceError::Io { .. } => 0,
        TraceError::Empty { .. } => 1,
        TraceError::MissingColumn { .. } => 2,
        TraceError::DuplicateColumn { .. } => 3,
        TraceError::FieldCount { .. } => 4,
        TraceError::BadNumber { .. } => 5,
        TraceError::NotUniform { .. } => 6,
        TraceError::LineTooLong { .. } => 7,
        TraceError::NotUtf8 { .. } => 8,
        TraceError::TooShort { .. } => 9,
        TraceError::Sidecar { .. } => 10,
        TraceError::Import { .. } => 11,
        TraceError::TimeBackwards { .. } => 12,
    }
}

/// Rows of a simulated trace written by the project's own writer: the start
/// of a run (before the first impact), one around an impact, and outside
/// data with reordered and text columns.
fn seeds() -> Vec<Vec<u8>> {
    let mut cfg = hammer_sim::SimConfig::nominal(5.0);
    cfg.solver.duration_s = 0.06;
    let sim = hammer_sim::simulate::simulate(&cfg).expect("simulates");
    let mut t = sim.trace();
    t.extra.retain(|k, _| k == "x_m");
    let dir = std::env::temp_dir().join(format!("hammer-fuzz-seeds-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let path = dir.join("seed.csv");
    hammer_trace::trace::write_csv(&path, &t).expect("writes");
    let text = std::fs::read(&path).expect("reads");
    let _ = std::fs::remove_dir_all(&dir);
    let lines: Vec<&[u8]> = text.split_inclusive(|&b| b == b'\n').collect();
    let take = |from: usize, n: usize| -> Vec<u8> {
        let mut v = lines[0].to_vec();
        for l in lines.iter().skip(from.max(1)).take(n) {
            v.extend_from_slice(l);
        }
        v
    };
    let impact = sim
        .run
        .cycles
        .first()
        .map_or(lines.len() / 2, |c| (c.t_impact_s / t.dt_s) as usize);
    vec![
        take(1, 150),
        take(impact.saturating_sub(60), 150),
        b"operator,accel_mps2,t_s,p_front_pa,p_rear_pa\nanna,0.5,0.0,100,200\nanna,0.25,0.00001,110,210\nben,-3000,0.00003,120,220\n".to_vec(),
    ]
}
