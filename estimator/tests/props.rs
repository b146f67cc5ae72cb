//! Arbitrary input never panics the estimator, every buffer stays bounded,
//! and whatever it reports is either flagged or finite.

use hammer_estimator::cycle::MAX_CHECKPOINTS;
use hammer_estimator::{Config, ConfigError, Estimator, RawSample};
use proptest::prelude::*;

/// A stretch of signal: base codes, a noise amplitude, a length; an impact
/// (accelerometer at its bottom rail) may open it; a gap may follow it.
#[derive(Debug, Clone)]
struct Segment {
    base: [u16; 3],
    noise: u16,
    len: u16,
    impact: bool,
    gap: u16,
}

fn segment() -> impl Strategy<Value = Segment> {
    (
        any::<[u16; 3]>(),
        0u16..200,
        1u16..6000,
        any::<bool>(),
        prop_oneof![Just(0u16), 0u16..500],
    )
        .prop_map(|(base, noise, len, impact, gap)| Segment {
            base: base.map(|b| b % 4096),
            noise,
            len,
            impact,
            gap,
        })
}

fn config() -> impl Strategy<Value = Config> {
    (
        10_000.0f32..200_000.0,
        100.0f32..5000.0,
        0.0f32..2e-3,
        0.0f32..0.05,
        0.0f32..30.0,
    )
        .prop_map(|(fs, thr, blank, tau, incl)| {
            let mut c = Config::default();
            c.sample_rate_hz = fs;
            c.impact_threshold_mps2 = thr;
            c.blank_after_s = blank;
            c.accel_zero_shift_tau_s = tau;
            c.inclination_deg = incl;
            c.max_period_s = 0.1;
            c
        })
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 200, ..ProptestConfig::default() })]

    #[test]
    fn arbitrary_streams_never_panic_and_reports_are_flagged_or_finite(
        cfg in config(),
        segments in prop::collection::vec(segment(), 1..40),
        seed in any::<u32>(),
    ) {
        let mut est = Estimator::new(cfg).unwrap();
        let calibration = est.config().calibration_hash();
        let mut x = seed | 1;
        let mut lcg = move || { x ^= x << 13; x ^= x >> 17; x ^= x << 5; x };
        let mut last_seq = None;
        for s in &segments {
            for i in 0..s.len {
                let jitter = |b: u16, r: u32| {
                    let n = if s.noise == 0 { 0 } else { (r % (2 * s.noise as u32 + 1)) as i32 - s.noise as i32 };
                    (b as i32 + n).clamp(0, 4095) as u16
                };
                let accel = if s.impact && i < 5 { 0 } else { jitter(s.base[2], lcg()) };
                let sample = RawSample { rear: jitter(s.base[0], lcg()), front: jitter(s.base[1], lcg()), accel };
                if let Some(r) = est.push(sample) {
                    prop_assert_eq!(r.calibration_hash, calibration, "every report names its calibration");
                    if r.is_valid() {
                        for v in [r.friction_n, r.friction_uncertainty_n, r.impact_energy_j, r.impact_energy_uncertainty_j, r.frequency_hz, r.stroke_m] {
                            prop_assert!(v.is_finite(), "valid report with a non-finite field: {:?}", r);
                        }
                        prop_assert!(r.friction_uncertainty_n >= 0.0 && r.impact_energy_uncertainty_j >= 0.0);
                    }
                    if let Some(prev) = last_seq {
                        prop_assert_eq!(r.seq, prev + 1, "sequence numbers are continuous");
                    }
                    last_seq = Some(r.seq);
                }
            }
            if s.gap > 0 {
                est.push_gap(s.gap as u32);
            }
        }
        let c = est.counters();
        prop_assert!(c.invalid_cycles <= c.cycles);
    }

    #[test]
    fn out_of_range_configs_are_rejected_not_accepted(fs in -1e7f32..1e7, tau in -1.0f32..20.0) {
        let mut c = Config::default();
        c.sample_rate_hz = fs;
        c.accel_zero_shift_tau_s = tau;
        let in_range = (1_000.0..=1_000_000.0).contains(&fs) && (0.0..=10.0).contains(&tau);
        // One checkpoint per millisecond (at least one per sample) and at most
        // MAX_CHECKPOINTS of them: below ~1.07 kHz the default 0.12 s period
        // does not fit and must be refused too.
        let per_checkpoint = (fs * 1e-3).round().max(1.0);
        let fits = c.max_period_s <= MAX_CHECKPOINTS as f32 * per_checkpoint / fs;
        let result = Estimator::new(c);
        prop_assert_eq!(result.is_ok(), in_range && fits, "{:?}", result.err());
        if in_range && !fits {
            let memory = matches!(result, Err(ConfigError::PeriodTooLongForMemory { .. }));
            prop_assert!(memory, "refused for the period's memory");
        }
    }
}

#[test]
fn the_estimator_state_fits_its_memory_budget() {
    // The firmware keeps one estimator in static RAM; the aim is ≤ 8 KiB.
    let size = core::mem::size_of::<Estimator>();
    println!("estimator state: {size} bytes");
    assert!(size <= 8 * 1024, "{size} bytes");
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 100, ..ProptestConfig::default() })]

    /// The block path and the one-sample path are the same estimator.
    #[test]
    fn push_block_equals_push_sample_by_sample(
        cfg in config(),
        segments in prop::collection::vec(segment(), 1..30),
        split in 1usize..700,
    ) {
        let mut samples = vec![];
        let mut x = 12345u32;
        for s in &segments {
            for i in 0..s.len {
                x ^= x << 13; x ^= x >> 17; x ^= x << 5;
                let n = if s.noise == 0 { 0 } else { (x % (2 * s.noise as u32 + 1)) as i32 - s.noise as i32 };
                let j = |b: u16| (b as i32 + n).clamp(0, 4095) as u16;
                let accel = if s.impact && i < 5 { 0 } else { j(s.base[2]) };
                samples.push(RawSample { rear: j(s.base[0]), front: j(s.base[1]), accel });
            }
        }
        let mut one = Estimator::new(cfg).unwrap();
        let a: Vec<_> = samples.iter().filter_map(|s| one.push(*s)).collect();
        let mut blocks = Estimator::new(cfg).unwrap();
        let mut b = vec![];
        for chunk in samples.chunks(split) {
            blocks.push_block(chunk, |r| b.push(r));
        }
        prop_assert_eq!(a.len(), b.len());
        for (x, y) in a.iter().zip(&b) {
            // Bit for bit (NaN-safe): the debug forms are equal.
            prop_assert_eq!(format!("{x:?}"), format!("{y:?}"));
        }
        prop_assert_eq!(one.counters(), blocks.counters());
    }
}

#[test]
fn a_period_that_does_not_fit_the_checkpoints_is_refused() {
    // The case proptest found: 1323 Hz gives one checkpoint per sample, so
    // 128 checkpoints hold 0.097 s, less than the default 0.12 s period.
    let mut c = Config::default();
    c.sample_rate_hz = 1323.1045;
    c.accel_zero_shift_tau_s = 0.0;
    assert!(matches!(
        Estimator::new(c.clone()),
        Err(ConfigError::PeriodTooLongForMemory { .. })
    ));
    c.max_period_s = 0.09;
    assert!(Estimator::new(c).is_ok());
}
