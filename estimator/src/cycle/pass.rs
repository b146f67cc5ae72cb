//! The per-sample pass over a piece of a cycle: the estimator's hot loop.
//!
//! What is linear in the codes (Σ p1, Σ p2, Σ r, Σ force, the velocity and
//! position integrals, Σ j·p) is summed exactly over the raw codes in
//! integers ([`CodeSums`]) and turned into floats once per checkpoint (see
//! `CycleAcc::settle`): integers add exactly, so how the samples were split
//! into pieces or blocks cannot show in the result, and the float work per
//! sample shrinks to what is not linear in the codes: the decaying
//! zero-shift regressor e and the sums r·e, r², force², r·force.

use super::{Calibration, Derived};
use crate::RawSample;

/// The longest piece [`pass`] takes: its running sums stay in u32 for
/// 16-bit codes (65535 · 256 · 257 / 2 < 2^32).
pub(super) const MAX_PIECE: usize = 256;

/// Exact integer sums over the codes since the last checkpoint. With at
/// most one checkpoint's samples (≤ 1000) of ≤ 16-bit codes nothing can
/// overflow: Σ c < 2^26, Σ (n − j)·c_j < 2^36.
#[derive(Debug, Clone, Copy)]
pub(super) struct CodeSums {
    pub n: u32,
    /// Σ c per channel.
    pub s: [u32; 3],
    /// Σ over the samples of the pressures' running Σ c, i.e. Σ (n − j)·c_j
    /// (j from 0): with `s` it gives Σ j·c and the trapezoid integrals.
    pub q: [u64; 2],
    /// The codes' extremes: the pressures' peaks (the calibration is
    /// monotonic, so the peak code reads the peak value exactly). `min` is
    /// taken only when needed (a negative scale, a rail touched); it stays
    /// `u16::MAX` otherwise.
    pub min: [u16; 3],
    pub max: [u16; 3],
}

impl Default for CodeSums {
    fn default() -> Self {
        CodeSums {
            n: 0,
            s: [0; 3],
            q: [0; 2],
            min: [u16::MAX; 3],
            max: [0; 3],
        }
    }
}

impl CodeSums {
    /// Appends the sums of the samples that follow.
    #[inline(always)]
    pub fn merge(&mut self, o: &CodeSums) {
        for ch in 0..2 {
            // The running sums of `o` start from this one's total.
            self.q[ch] = self.q[ch]
                .wrapping_add(o.q[ch])
                .wrapping_add(u64::from(o.n) * u64::from(self.s[ch]));
        }
        for ch in 0..3 {
            self.s[ch] = self.s[ch].wrapping_add(o.s[ch]);
            self.min[ch] = self.min[ch].min(o.min[ch]);
            self.max[ch] = self.max[ch].max(o.max[ch]);
        }
        self.n = self.n.wrapping_add(o.n);
    }
}

/// The float sums that need every sample, kept in registers for a piece.
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct Squares {
    /// The zero-shift regressor at the last sample.
    pub e: f32,
    pub re: f32,
    pub rr: f32,
    pub ff: f32,
    pub rf: f32,
    /// The last sample's pressure force.
    pub force: f32,
}

/// The pressure force and the force-balance residual of one sample, with
/// the calibration folded into three coefficients per quantity.
#[derive(Debug, Clone, Copy)]
pub(super) struct Balance {
    k1: f32,
    k2: f32,
    f0: f32,
    m3: f32,
    r0: f32,
}

impl Balance {
    #[inline(always)]
    pub fn new(d: &Derived, cal: &Calibration) -> Self {
        let k1 = d.a1 * cal.scale[0];
        let k2 = -d.a2 * cal.scale[1];
        let m3 = d.m * cal.scale[2];
        Self {
            k1,
            k2,
            f0: d.fg - k1 * cal.zero[0] - k2 * cal.zero[1],
            m3,
            r0: -m3 * cal.zero[2],
        }
    }

    #[inline(always)]
    pub fn force(&self, c1: u16, c2: u16) -> f32 {
        self.f0 + c1 as f32 * self.k1 + c2 as f32 * self.k2
    }

    #[inline(always)]
    pub fn residual(&self, c3: u16, force: f32) -> f32 {
        self.r0 + c3 as f32 * self.m3 - force
    }
}

/// The running sums of [`pass`], kept in registers over its two slices.
struct Acc {
    sq: Squares,
    s: [u32; 3],
    run: [u32; 2],
    top: [u32; 3],
}

impl Acc {
    /// The loop is written out channel by channel, with every running sum
    /// a local: the board builds the estimator for size (`opt-level = "z"`),
    /// which neither unrolls the per-channel loops nor keeps arrays in
    /// registers, and this form is as fast there as at `-O3`.
    #[inline(always)]
    fn feed(&mut self, q: f32, b: &Balance, piece: &[RawSample]) {
        let Squares {
            mut e,
            mut re,
            mut rr,
            mut ff,
            mut rf,
            mut force,
        } = self.sq;
        let [mut s0, mut s1, mut s2] = self.s;
        let [mut run0, mut run1] = self.run;
        let [mut top0, mut top1, mut top2] = self.top;
        // Not unrolled: two samples a turn run out of registers (measured worse).
        for smp in piece {
            let (c0, c1, c2) = (smp.rear, smp.front, smp.accel);
            s0 = s0.wrapping_add(u32::from(c0));
            s1 = s1.wrapping_add(u32::from(c1));
            s2 = s2.wrapping_add(u32::from(c2));
            // Code 0 wraps to the top: one maximum finds both rails.
            top0 = top0.max(u32::from(c0).wrapping_sub(1));
            top1 = top1.max(u32::from(c1).wrapping_sub(1));
            top2 = top2.max(u32::from(c2).wrapping_sub(1));
            run0 = run0.wrapping_add(s0);
            run1 = run1.wrapping_add(s1);
            force = b.force(c0, c1);
            let r = b.residual(c2, force);
            e *= q;
            re += r * e;
            rr += r * r;
            ff += force * force;
            rf += r * force;
        }
        self.sq = Squares {
            e,
            re,
            rr,
            ff,
            rf,
            force,
        };
        self.s = [s0, s1, s2];
        self.run = [run0, run1];
        self.top = [top0, top1, top2];
    }
}

/// One pass over a piece (at most [`MAX_PIECE`] samples, given as two
/// slices that follow each other: the delay line's and the new samples'):
/// its exact code sums, and the squares carried on in `sq`. Each sample is
/// loaded once; the rails are found from one maximum per channel (code 0
/// wraps to the top), and only a piece that touched one (or a pressure with
/// a negative scale, whose peak is its lowest code) pays for exact extremes.
#[inline(always)]
pub(super) fn pass(
    d: &Derived,
    cal: &Calibration,
    b: &Balance,
    piece: [&[RawSample]; 2],
    sq: &mut Squares,
) -> CodeSums {
    let mut acc = Acc {
        sq: *sq,
        s: [0; 3],
        run: [0; 2],
        top: [0; 3],
    };
    acc.feed(d.q, b, piece[0]);
    acc.feed(d.q, b, piece[1]);
    *sq = acc.sq;
    let top = acc.top;
    let n = piece[0].len() + piece[1].len();
    let mut c = CodeSums {
        n: n as u32,
        s: acc.s,
        q: [u64::from(acc.run[0]), u64::from(acc.run[1])],
        ..Default::default()
    };
    let rail = (0..3).any(|ch| top[ch] >= u32::from(cal.full[ch]).saturating_sub(1));
    if rail || cal.scale[0] < 0.0 || cal.scale[1] < 0.0 {
        let mut min = [u16::MAX as u32; 3];
        let mut max = [0u32; 3];
        for smp in piece[0].iter().chain(piece[1]) {
            let x = [smp.rear as u32, smp.front as u32, smp.accel as u32];
            for ch in 0..3 {
                min[ch] = min[ch].min(x[ch]);
                max[ch] = max[ch].max(x[ch]);
            }
        }
        c.min = min.map(|v| v as u16);
        c.max = max.map(|v| v as u16);
    } else if n > 0 {
        // No code was 0, so the largest code less one is `top`.
        c.max = top.map(|t| (t + 1) as u16);
    }
    c
}

/// Σ q^j and Σ q^2j for j = 1..=n: the zero-shift regressor's sums over
/// `n` samples from e = 1 (the same arithmetic wherever it runs).
pub(super) fn geometric(q: f32, n: u32) -> (f32, f32) {
    let (mut e, mut s, mut ss) = (1.0f32, 0.0f32, 0.0f32);
    for _ in 0..n {
        e *= q;
        s += e;
        ss += e * e;
    }
    (s, ss)
}

/// u64 to f32, the same value as `x as f32` (both round to nearest), by
/// the one-instruction u32 conversion when it fits (it always does at
/// 100 kS/s with 12-bit codes).
#[inline(always)]
pub(super) fn to_f32(x: u64) -> f32 {
    match u32::try_from(x) {
        Ok(v) => v as f32,
        Err(_) => x as f32,
    }
}
