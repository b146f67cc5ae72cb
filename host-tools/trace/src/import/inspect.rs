//! What a trace holds, as `hammer import` reports it: sample rate, length,
//! gaps, each channel's range, values a recorder clipped (rails), and
//! whether the pressures look absolute where gauge is expected.

use serde::Serialize;

use crate::trace::Trace;

/// Runs at one value, of at least [`RAIL_MIN_RUN`] samples, that make it a rail.
pub const RAIL_MIN_RUNS: usize = 3;
pub const RAIL_MIN_RUN: usize = 3;
/// Equal neighbours away from the rail, as a fraction of the pairs, above
/// which a channel is quantised (or flat) and a repeated extreme says nothing.
pub const RAIL_MAX_EQUAL_ELSEWHERE: f64 = 0.01;
/// A vented chamber's lowest pressure sits near atmosphere gauge 0; when both
/// chambers' lowest read above this, the pressures are absolute.
pub const ABSOLUTE_MIN_GAUGE_PA: f64 = 50e3;

/// One channel's extent and rails.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ChannelStats {
    pub name: String,
    pub min: f64,
    pub max: f64,
    /// Values a recorder clipped: (value, samples at it).
    pub rails: Vec<Rail>,
}

#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Rail {
    pub value: f64,
    pub samples: usize,
    pub runs: usize,
}

#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Stats {
    pub samples: usize,
    pub sample_rate_hz: f64,
    pub duration_s: f64,
    pub gaps: usize,
    pub missing_samples: u64,
    pub channels: Vec<ChannelStats>,
    /// Both vented chambers' lowest pressure read well above 0 gauge.
    pub looks_absolute: bool,
}

/// The statistics of a trace read whole.
pub fn stats(t: &Trace) -> Stats {
    let channels = [
        ("p_rear_pa", &t.p_rear_pa),
        ("p_front_pa", &t.p_front_pa),
        ("accel_mps2", &t.accel_mps2),
    ]
    .into_iter()
    .map(|(name, x)| {
        let (min, max) = x
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| (a.min(v), b.max(v)));
        let rails = [min, max].into_iter().filter_map(|v| clipped_at(x, v)).collect();
        ChannelStats {
            name: name.into(),
            min,
            max,
            rails,
        }
    })
    .collect::<Vec<_>>();
    let missing: u64 = t.gaps.iter().map(|g| g.missing).sum();
    Stats {
        samples: t.len(),
        sample_rate_hz: 1.0 / t.dt_s,
        duration_s: (t.len() as u64 + missing) as f64 * t.dt_s,
        gaps: t.gaps.len(),
        missing_samples: missing,
        looks_absolute: channels[0].min > ABSOLUTE_MIN_GAUGE_PA && channels[1].min > ABSOLUTE_MIN_GAUGE_PA,
        channels,
    }
}

/// Whether `v` (an extreme of `x`) is a value a recorder clipped to: it
/// occurs in at least [`RAIL_MIN_RUNS`] runs of [`RAIL_MIN_RUN`] samples,
/// equal neighbours are rare elsewhere (the channel is neither quantised nor
/// flat), and the signal arrives at and leaves it steeply (at least half the
/// channel's median step): a clipped signal runs into the rail, while a
/// chamber that settles at a value (a vented chamber at exactly 0 gauge in
/// noise-free data) creeps into it with ever smaller steps.
pub fn clipped_at(x: &[f64], v: f64) -> Option<Rail> {
    if x.len() < 8 {
        return None;
    }
    let (mut runs, mut samples, mut equal_elsewhere, mut pairs_elsewhere) = (0usize, 0usize, 0usize, 0usize);
    let mut edge_steps = Vec::new();
    let mut i = 0;
    while i < x.len() {
        if x[i] == v {
            let start = i;
            while i < x.len() && x[i] == v {
                i += 1;
            }
            let len = i - start;
            samples += len;
            if len >= RAIL_MIN_RUN {
                runs += 1;
                // The steps next to the run (the one into it is cut by the clip).
                if start > 1 {
                    edge_steps.push((x[start - 1] - x[start - 2]).abs());
                }
                if i + 1 < x.len() {
                    edge_steps.push((x[i + 1] - x[i]).abs());
                }
            }
        } else {
            if i + 1 < x.len() && x[i + 1] != v {
                pairs_elsewhere += 1;
                if x[i + 1] == x[i] {
                    equal_elsewhere += 1;
                }
            }
            i += 1;
        }
    }
    if runs < RAIL_MIN_RUNS || pairs_elsewhere == 0 {
        return None;
    }
    if equal_elsewhere as f64 > RAIL_MAX_EQUAL_ELSEWHERE * pairs_elsewhere as f64 {
        return None;
    }
    let mut steps: Vec<f64> = x.windows(2).map(|w| (w[1] - w[0]).abs()).filter(|d| *d > 0.0).collect();
    if steps.is_empty() || edge_steps.is_empty() {
        return None;
    }
    steps.sort_by(f64::total_cmp);
    let median = steps[steps.len() / 2];
    edge_steps.sort_by(f64::total_cmp);
    let edge = edge_steps[edge_steps.len() / 2];
    (edge >= 0.5 * median).then_some(Rail {
        value: v,
        samples,
        runs,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A sine clipped at −0.5 is a rail; the same shape settling
    /// exponentially onto exactly 0 (a vented chamber, noise-free) is not;
    /// a quantised channel's repeated extreme is not either.
    #[test]
    fn clipped_values_are_rails_and_settled_values_are_not() {
        let n = 5000;
        let clipped: Vec<f64> = (0..n)
            .map(|i| ((i as f64 * 0.01).sin() + 0.001 * (i as f64 * 1.7).sin()).max(-0.5))
            .collect();
        let r = clipped_at(&clipped, -0.5).expect("a clipped sine has a rail");
        assert!(r.runs >= 5 && r.samples > n / 10, "{r:?}");
        // Cycles of a rise then an exponential settle onto exactly 0.
        let settled: Vec<f64> = (0..n)
            .map(|i| {
                let k = i % 500;
                if k < 100 {
                    k as f64 / 100.0
                } else {
                    let v = (-(k as f64 - 100.0) / 20.0).exp();
                    if v < 1e-6 {
                        0.0
                    } else {
                        v
                    }
                }
            })
            .collect();
        assert_eq!(clipped_at(&settled, 0.0), None);
        let quantised: Vec<f64> = clipped.iter().map(|v| (v * 20.0).round() / 20.0).collect();
        assert_eq!(clipped_at(&quantised, -0.5), None);
    }
}
