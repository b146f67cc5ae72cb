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
        let mut scan = RailScan::default();
        x.iter().for_each(|&v| scan.push(v));
        let rails = scan.rails().into_iter().flatten().collect();
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
/// is the channel's extreme over the file, occurs in at least
/// [`RAIL_MIN_RUNS`] runs of [`RAIL_MIN_RUN`] samples, and equal neighbours
/// are rare elsewhere (the channel is neither quantised nor flat, so a
/// repeated value means something). A vented chamber that rests at exactly
/// 0 gauge in noise-free data is not a rail as long as it dips below
/// atmosphere somewhere else in the file (as a running hammer's does): 0 is
/// then not the channel's extreme. [`RailScan`] applies the rule.
pub fn clipped_at(x: &[f64], v: f64) -> Option<Rail> {
    let mut scan = RailScan::default();
    x.iter().for_each(|&y| scan.push(y));
    let [lo, hi] = scan.rails();
    [lo, hi].into_iter().flatten().find(|r| r.value == v)
}

/// [`clipped_at`]'s rule over a channel read once, sample by sample: what
/// `hammer estimate` needs of a file it streams without holding it. A new
/// extreme has not been seen before, so its counts start from nothing.
#[derive(Debug, Clone, Default)]
pub struct RailScan {
    n: usize,
    prev: Option<f64>,
    pairs: usize,
    equal: usize,
    lo: Option<Side>,
    hi: Option<Side>,
}

/// The counts at one extreme.
#[derive(Debug, Clone, Copy)]
struct Side {
    value: f64,
    samples: usize,
    runs: usize,
    run: usize,
    /// Neighbour pairs with either sample at the value, and with both.
    touching: usize,
    equal: usize,
}

impl Side {
    fn new(value: f64) -> Self {
        Side {
            value,
            samples: 0,
            runs: 0,
            run: 0,
            touching: 0,
            equal: 0,
        }
    }

    fn push(&mut self, prev: Option<f64>, x: f64) {
        let v = self.value;
        if x == v {
            self.samples += 1;
            self.run = if prev == Some(v) { self.run + 1 } else { 1 };
            if self.run == RAIL_MIN_RUN {
                self.runs += 1;
            }
        }
        if let Some(p) = prev {
            if p == v || x == v {
                self.touching += 1;
                if p == x {
                    self.equal += 1;
                }
            }
        }
    }
}

impl RailScan {
    pub fn push(&mut self, x: f64) {
        self.n += 1;
        if let Some(p) = self.prev {
            self.pairs += 1;
            if p == x {
                self.equal += 1;
            }
        }
        if self.lo.is_none_or(|s| x < s.value) {
            self.lo = Some(Side::new(x));
        }
        if self.hi.is_none_or(|s| x > s.value) {
            self.hi = Some(Side::new(x));
        }
        for side in [&mut self.lo, &mut self.hi].into_iter().flatten() {
            side.push(self.prev, x);
        }
        self.prev = Some(x);
    }

    /// The bottom and the top rail, where the rule finds one.
    pub fn rails(&self) -> [Option<Rail>; 2] {
        let rail = |s: &Option<Side>| {
            let s = s.as_ref()?;
            let pairs_elsewhere = self.pairs - s.touching;
            let equal_elsewhere = self.equal - s.equal;
            let quantised = equal_elsewhere as f64 > RAIL_MAX_EQUAL_ELSEWHERE * pairs_elsewhere as f64;
            (self.n >= 8 && s.runs >= RAIL_MIN_RUNS && pairs_elsewhere > 0 && !quantised).then_some(Rail {
                value: s.value,
                samples: s.samples,
                runs: s.runs,
            })
        };
        let (lo, hi) = (rail(&self.lo), rail(&self.hi));
        // A channel flat at one value has one extreme, not two rails.
        let lo_value = lo.as_ref().map(|l| l.value);
        [lo, hi.filter(|h| lo_value != Some(h.value))]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A sine clipped at −0.5 is a rail; a chamber resting at exactly 0
    /// between dips below it (a vented chamber, noise-free) is not; a
    /// quantised channel's repeated extreme is not either.
    #[test]
    fn clipped_values_are_rails_and_settled_values_are_not() {
        let n = 5000;
        let clipped: Vec<f64> = (0..n)
            .map(|i| ((i as f64 * 0.01).sin() + 0.001 * (i as f64 * 1.7).sin()).max(-0.5))
            .collect();
        let r = clipped_at(&clipped, -0.5).expect("a clipped sine has a rail");
        assert!(r.runs >= 5 && r.samples > n / 10, "{r:?}");
        // Cycles of a rise, a dip below 0, then a rest at exactly 0.
        let settled: Vec<f64> = (0..n)
            .map(|i| {
                let k = i % 500;
                if k < 100 {
                    k as f64 / 100.0
                } else if k < 200 {
                    -0.05 * ((k - 100) as f64 * std::f64::consts::PI / 100.0).sin()
                } else {
                    0.0
                }
            })
            .collect();
        assert_eq!(clipped_at(&settled, 0.0), None);
        // The same clipped at 0 by a recorder: then 0 is a rail.
        let at_zero: Vec<f64> = settled.iter().map(|v| v.max(0.0)).collect();
        assert!(clipped_at(&at_zero, 0.0).is_some());
        let quantised: Vec<f64> = clipped.iter().map(|v| (v * 20.0).round() / 20.0).collect();
        assert_eq!(clipped_at(&quantised, -0.5), None);
    }
}
