//! Bad input gets a flagged cycle, never a silent wrong number: disconnected,
//! stuck and saturated sensors, dropped samples, a hammer that stops.

use hammer_estimator::{CycleReport, Estimator, Flags, RawSample};
use hammer_sim::simulate::simulate;
use hammer_sim::SimConfig;

fn stream(sensors_tweak: impl Fn(&mut SimConfig)) -> (Vec<RawSample>, hammer_estimator::Config) {
    let mut cfg = SimConfig::nominal(5.0);
    cfg.solver.duration_s = 1.0;
    cfg.effects.apply_spec("coulomb_friction").unwrap();
    sensors_tweak(&mut cfg);
    let sim = simulate(&cfg).unwrap();
    let est = cfg.estimator_config(Some(5.0)).unwrap();
    (sim.measured.codes, est)
}

fn run(samples: &[RawSample], cfg: hammer_estimator::Config) -> Vec<CycleReport> {
    let mut e = Estimator::new(cfg).unwrap();
    let mut out = vec![];
    e.push_block(samples, |r| out.push(r));
    out
}

/// Cycles whose kept samples (after the 1 ms blanking) overlap [t0, t1] by at
/// least 6 ms: longer than the 5 ms a channel must hold one code to be stuck.
fn overlapping(reports: &[CycleReport], t0: f64, t1: f64) -> Vec<&CycleReport> {
    reports
        .iter()
        .filter(|r| {
            let start = r.t_impact_s() - r.period_s as f64 + 0.001;
            r.t_impact_s().min(t1) - start.max(t0) >= 0.006
        })
        .collect()
}

#[test]
fn a_disconnected_or_stuck_channel_flags_the_cycles_it_touches_and_only_those() {
    let (clean, cfg) = stream(|_| {});
    let baseline = run(&clean, cfg);
    assert!(baseline.iter().filter(|r| r.t_impact_s() > 0.15).all(|r| r.is_valid()));

    let mut open = clean.clone();
    for s in &mut open[40_000..60_000] {
        s.rear = 0; // open circuit: the amplifier sits at its bottom rail
    }
    let reports = run(&open, cfg);
    for r in overlapping(&reports, 0.4, 0.6) {
        assert!(
            r.flags.intersects(Flags::DISCONNECTED | Flags::REAR_STUCK),
            "{:?}",
            r.flags.names().collect::<Vec<_>>()
        );
        assert!(!r.is_valid());
    }
    let after: Vec<_> = reports
        .iter()
        .filter(|r| r.t_impact_s() - r.period_s as f64 > 0.62)
        .collect();
    assert!(
        !after.is_empty() && after.iter().all(|r| r.is_valid()),
        "the estimator recovers"
    );

    let mut stuck = clean.clone();
    for s in &mut stuck[40_000..50_000] {
        s.front = 1234;
    }
    let reports = run(&stuck, cfg);
    let hit = overlapping(&reports, 0.4, 0.5);
    assert!(!hit.is_empty());
    for r in hit {
        assert!(r.flags.contains(Flags::FRONT_STUCK) && !r.is_valid());
    }
}

#[test]
fn saturated_channels_are_flagged() {
    // A 0–3 bar pressure range clips the 5 bar hammer's peaks.
    let (s, cfg) = stream(|c| {
        c.sensors.rear.range_max = 3e5;
        c.sensors.front.range_max = 3e5;
    });
    let reports = run(&s, cfg);
    assert!(reports
        .iter()
        .filter(|r| r.t_impact_s() > 0.15)
        .all(|r| r.flags.contains(Flags::REAR_SATURATED) && !r.is_valid()));
    // A ±300 m/s² accelerometer clips in flight, not only at impacts.
    let (s, cfg) = stream(|c| {
        c.sensors.accel.range_min = -300.0;
        c.sensors.accel.range_max = 300.0;
    });
    let reports = run(&s, cfg);
    assert!(!reports.is_empty());
    assert!(reports
        .iter()
        .filter(|r| r.t_impact_s() > 0.15)
        .all(|r| r.flags.contains(Flags::ACCEL_SATURATED) && !r.is_valid()));
}

#[test]
fn dropped_samples_flag_their_cycle_keep_the_timing_and_the_sequence() {
    let (clean, cfg) = stream(|_| {});
    let baseline = run(&clean, cfg);
    let mut e = Estimator::new(cfg).unwrap();
    let mut out = vec![];
    e.push_block(&clean[..45_000], |r| out.push(r));
    e.push_gap(300); // an ADC overrun lost 3 ms
    e.push_block(&clean[45_300..], |r| out.push(r));
    assert_eq!(e.counters().dropped_samples, 300);
    assert_eq!(out.len(), baseline.len());
    for (a, b) in out.iter().zip(&baseline) {
        assert_eq!(a.seq, b.seq);
        assert!(
            (a.t_impact_s() - b.t_impact_s()).abs() < 1e-9,
            "timing survives the gap"
        );
        let touched = a.t_impact_s() > 0.45 && a.t_impact_s() - (a.period_s as f64) < 0.453;
        assert_eq!(
            a.flags.contains(Flags::DROPPED_SAMPLES),
            touched,
            "cycle at {}",
            a.t_impact_s()
        );
        if touched {
            assert!(!a.is_valid());
        }
    }
}

#[test]
fn a_hammer_that_stops_is_counted_as_a_stall_not_reported_as_a_cycle() {
    let (clean, cfg) = stream(|_| {});
    // Cut out 0.4–0.7 s and hold the last sample with the sensors' noise
    // (±2 LSB): the piston stands still, the sensors live.
    let mut s = clean[..40_000].to_vec();
    let held = clean[40_000];
    let mut x = 7u32;
    let mut lsb = move |c: u16| {
        x ^= x << 13;
        x ^= x >> 17;
        x ^= x << 5;
        (c as i32 + (x % 5) as i32 - 2).clamp(0, 4095) as u16
    };
    s.extend((0..30_000).map(|_| RawSample {
        rear: lsb(held.rear),
        front: lsb(held.front),
        accel: lsb(held.accel),
    }));
    s.extend_from_slice(&clean[70_000..]);
    let mut e = Estimator::new(cfg).unwrap();
    let mut out = vec![];
    e.push_block(&s, |r| out.push(r));
    assert_eq!(e.counters().stalls, 1);
    assert!(out.iter().all(|r| !(r.t_impact_s() > 0.4 && r.t_impact_s() < 0.7)));
    // Sequence numbers stay continuous over the stall: reports were not lost, cycles were not closed.
    for w in out.windows(2) {
        assert_eq!(w[1].seq, w[0].seq + 1);
    }
}

/// A cycle longer or stronger than the hammer can make is `implausible`,
/// never valid (issue 48, item 3): the same sound codes read on a wrong time
/// base (a map's 50 kS/s, a WAV header's 48 kHz, for 100 kS/s data) give
/// strokes over three times the piston's 52 mm travel and every cycle is
/// flagged; read right, at 4 and 7 bar, every cycle is valid and its stroke
/// within the travel.
#[test]
fn a_stroke_beyond_the_travel_is_implausible_and_a_sound_one_is_valid() {
    for bar in [4.0, 7.0] {
        let mut cfg = SimConfig::nominal(bar);
        cfg.solver.duration_s = 0.6;
        cfg.effects.apply_spec("coulomb_friction").unwrap();
        let sim = simulate(&cfg).unwrap();
        let est = cfg.estimator_config(Some(bar)).unwrap();
        let travel = est.geometry.travel_m;
        let cycles: Vec<_> = run(&sim.measured.codes, est)
            .into_iter()
            .filter(|r| r.is_cycle())
            .collect();
        assert!(cycles.len() >= 8, "{bar} bar");
        assert!(
            cycles.iter().all(|r| r.is_valid() && r.stroke_m < travel),
            "{bar} bar: {:?}",
            cycles
                .iter()
                .map(|r| (r.stroke_m, r.flags.names().collect::<Vec<_>>()))
                .collect::<Vec<_>>()
        );
        for wrong_hz in [50e3, 48e3] {
            let mut wrong = est;
            wrong.sample_rate_hz = wrong_hz;
            let cycles: Vec<_> = run(&sim.measured.codes, wrong)
                .into_iter()
                .filter(|r| r.is_cycle())
                .collect();
            assert!(!cycles.is_empty(), "{bar} bar at {wrong_hz} Hz");
            for r in &cycles {
                assert!(
                    r.flags.contains(Flags::IMPLAUSIBLE) && !r.is_valid(),
                    "{bar} bar at {wrong_hz} Hz: stroke {} m, {} J",
                    r.stroke_m,
                    r.impact_energy_j
                );
            }
        }
    }
}
