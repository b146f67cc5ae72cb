//! What a trace holds, as `hammer import` reports it: sample rate, length,
//! gaps, each channel's range, values a recorder clipped (rails), and
//! whether the pressures look absolute where gauge is expected.

use serde::Serialize;

use crate::trace::Trace;

/// Runs at one value, of at least [`RAIL_MIN_RUN`] samples, that make it a rail.
pub const RAIL_MIN_RUNS: usize = 3;
pub const RAIL_MIN_RUN: usize = 3;
/// Equal neighbours away from the rail, as a fraction of the pairs, above
/// which a channel is quantised (or flat): a repeated extreme then says
/// nothing by itself, and the rail must pile up samples ([`RAIL_PILE_UP`]).
pub const RAIL_MAX_EQUAL_ELSEWHERE: f64 = 0.01;
/// On a quantised channel, how many times the samples of the level next to
/// it a clipped extreme holds at least. A recorder's clip puts on its bound
/// every sample the signal spent beyond it, so the bound holds many times
/// its neighbour level (12 to 185 times for a vented chamber's dip clipped
/// at 0 gauge by a 0–10 bar recorder of 10 to 16 bits under 500 Pa of
/// noise); a signal's own extreme is a thin tail under noise (fewer than
/// its neighbour), and noise-free about as many (1.4 times at a smooth
/// minimum, 3 at the flattest quartic one).
pub const RAIL_PILE_UP: f64 = 4.0;
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
/// [`RAIL_MIN_RUNS`] runs of [`RAIL_MIN_RUN`] samples, and either equal
/// neighbours are rare elsewhere (the channel is neither quantised nor
/// flat, so a repeated value means something) or, on a quantised channel,
/// the extreme piles up [`RAIL_PILE_UP`] times the samples of the value
/// next to it (the mass beyond the bound, put on it). A vented chamber that rests at exactly
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
    /// +1 at the bottom, −1 at the top: the inside is `value + inward·d`.
    inward: f64,
    /// The value next to the extreme inside it, and its samples.
    next: Option<(f64, usize)>,
}

impl Side {
    /// A new extreme `value`; the one it replaces (if any) is now next to it.
    fn new(value: f64, inward: f64, was: Option<Side>) -> Self {
        Side {
            value,
            samples: 0,
            runs: 0,
            run: 0,
            touching: 0,
            equal: 0,
            inward,
            next: was.map(|s| (s.value, s.samples)),
        }
    }

    fn push(&mut self, prev: Option<f64>, x: f64) {
        let v = self.value;
        // Inside the extreme and nearer it than the value next to it so far
        // (false for NaN: a sample that is no number is no level).
        let inside = (x - v) * self.inward > 0.0;
        match self.next {
            Some((n, ref mut k)) if x == n => *k += 1,
            Some((n, _)) if inside && (n - x) * self.inward > 0.0 => self.next = Some((x, 1)),
            None if inside => self.next = Some((x, 1)),
            _ => {}
        }
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
            self.lo = Some(Side::new(x, 1.0, self.lo));
        }
        if self.hi.is_none_or(|s| x > s.value) {
            self.hi = Some(Side::new(x, -1.0, self.hi));
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
            let piled_up = s.next.is_some_and(|(_, k)| s.samples as f64 > RAIL_PILE_UP * k as f64);
            (self.n >= 8 && s.runs >= RAIL_MIN_RUNS && pairs_elsewhere > 0 && (!quantised || piled_up)).then_some(
                Rail {
                    value: s.value,
                    samples: s.samples,
                    runs: s.runs,
                },
            )
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
        // Quantised, a sine's own extreme holds about as many samples as
        // the level beside it, and is not a rail; clipped, the bound piles
        // up the samples beyond it, and is.
        let quantise = |x: &[f64]| x.iter().map(|v| (v * 20.0).round() / 20.0).collect::<Vec<_>>();
        let sine: Vec<f64> = (0..n).map(|i| (i as f64 * 0.01).sin()).collect();
        let q = quantise(&sine);
        let lowest = q.iter().copied().fold(f64::INFINITY, f64::min);
        assert_eq!(clipped_at(&q, lowest), None);
        assert_eq!(clipped_at(&q, 1.0), None);
        let r = clipped_at(&quantise(&clipped), -0.5).expect("a quantised clipped sine has a rail");
        assert!(r.samples > n / 10, "{r:?}");
    }

    /// A 0–10 bar recorder's 12-bit steps (244 Pa) under 500 Pa of noise:
    /// neighbours are often equal everywhere, and a dip clipped at 0 gauge
    /// is still a rail; the same chamber recorded with a range that holds
    /// its dip has none (its lowest values are the noise's thin tail).
    #[test]
    fn a_clipped_floor_under_quantisation_and_noise_is_a_rail() {
        let step = 1e6 / 4095.0;
        let mut rng = 12345u64;
        let mut noise = || {
            // Sum of 12 uniforms: near-normal, σ = 1.
            (0..12)
                .map(|_| {
                    rng = rng.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                    (rng >> 11) as f64 / (1u64 << 53) as f64
                })
                .sum::<f64>()
                - 6.0
        };
        // Cycles of a rise to 4 bar, a fall through 0 into a 0.3 bar dip,
        // and a rest at 0 gauge.
        let truth: Vec<f64> = (0..20_000)
            .map(|i| {
                let k = (i % 2000) as f64 / 2000.0;
                if k < 0.5 {
                    4e5 * (std::f64::consts::PI * k / 0.5).sin()
                } else if k < 0.65 {
                    -0.3e5 * (std::f64::consts::PI * (k - 0.5) / 0.15).sin()
                } else {
                    0.0
                }
            })
            .collect();
        let noisy: Vec<f64> = truth.iter().map(|p| p + 500.0 * noise()).collect();
        let recorded = |lo: f64| -> Vec<f64> {
            noisy
                .iter()
                .map(|p| ((p.max(lo) - lo) / step).round() * step + lo)
                .collect()
        };
        let clipped = recorded(0.0);
        let r = clipped_at(&clipped, 0.0).expect("the clipped floor is a rail");
        assert!(r.samples > clipped.len() / 10, "{r:?}");
        let whole = recorded(-1e5);
        let lowest = whole.iter().copied().fold(f64::INFINITY, f64::min);
        assert_eq!(clipped_at(&whole, lowest), None);
    }
}
