//! One cycle's running sums, kept sample by sample while the cycle runs.
//!
//! Nothing per sample is stored: the sums the estimate needs are kept as
//! prefix sums at one checkpoint per millisecond, so once the turning point
//! is known at the end of the cycle the samples can be split into backhaul
//! and stroke (with a guard band around the turning point) without a second
//! pass. Memory is bounded by [`MAX_CHECKPOINTS`].
//!
//! Modules: `pass` (the per-sample pass, the hot loop), `rails` (the
//! samples at a pressure's rail, out of the fit: the slow path). What a
//! closed cycle makes of these sums is [`crate::estimate`].

use heapless::Vec;

use crate::config::Config;
use crate::math;
use crate::Flags;

mod pass;
mod rails;
use pass::{Balance, CodeSums, Squares};
pub use rails::Left;
use rails::Railed;

/// Checkpoints per cycle: with one per millisecond, cycles up to 128 ms.
pub const MAX_CHECKPOINTS: usize = 128;

/// Prefix sums over a cycle's samples since the blanking ended. The fit's
/// sums (`n` to `rr`) leave out the samples at which a pressure sat at a
/// rail (see [`Left`]); the pressures' sums take every sample, and the
/// velocity integrals `v`, `w` too, those with the measured acceleration.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Sums {
    /// Samples in the fit (at checkpoint i, (i + 1)·k less those at a rail).
    pub n: f32,
    pub e: f32,
    pub ee: f32,
    pub r: f32,
    pub re: f32,
    pub rr: f32,
    pub p1: f32,
    pub p2: f32,
    /// ∫ P/m dt: velocity gained from the pressure (and gravity) forces.
    pub v: f32,
    /// ∫ v dt of the above.
    pub w: f32,
}

/// Σ force, Σ force², Σ r·force (with n and Σ r): the slope of the force
/// balance's residual on the force, ≈ 0 for a sound accelerometer (−0.5 at
/// half gain, −1 for a dead one, −2 with its sign inverted).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct SlopeSums {
    pub n: f32,
    pub r: f32,
    pub f: f32,
    pub ff: f32,
    pub rf: f32,
}

impl Sums {
    pub(crate) fn minus(&self, o: &Sums) -> Sums {
        Sums {
            n: self.n - o.n,
            e: self.e - o.e,
            ee: self.ee - o.ee,
            r: self.r - o.r,
            re: self.re - o.re,
            rr: self.rr - o.rr,
            p1: self.p1 - o.p1,
            p2: self.p2 - o.p2,
            v: self.v - o.v,
            w: self.w - o.w,
        }
    }
}

/// Constants derived once from the configuration.
#[derive(Debug, Clone, Copy)]
pub struct Derived {
    pub dt: f32,
    pub m: f32,
    pub a1: f32,
    pub a2: f32,
    pub fg: f32,
    pub half_dt_over_m: f32,
    pub half_dt: f32,
    /// Per-sample decay of the zero-shift regressor (0 when the fit is off).
    pub q: f32,
    pub k: u32,
    /// Σ q^j and Σ q^2j over one checkpoint's samples (j = 1..=k).
    pub e_k: f32,
    pub ee_k: f32,
    /// What helps the rear chamber drive a stroke at most, beside it: the
    /// front chamber at vacuum on its area, and gravity along the axis
    /// (`estimate::beyond_the_hammer`).
    pub assist_n: f32,
}

impl Derived {
    pub fn new(c: &Config) -> Self {
        let dt = c.dt_s();
        let m = c.mass_kg();
        let q = if c.accel_zero_shift_tau_s > 0.0 {
            math::exp(-dt / c.accel_zero_shift_tau_s)
        } else {
            0.0
        };
        let k = c.checkpoint_samples();
        let (e_k, ee_k) = pass::geometric(q, k);
        let (a2, fg) = (c.front_area_m2(), c.gravity_n());
        Self {
            dt,
            m,
            a1: c.rear_area_m2(),
            a2,
            fg,
            half_dt_over_m: 0.5 * dt / m,
            half_dt: 0.5 * dt,
            q,
            k,
            e_k,
            ee_k,
            assist_n: crate::chambers::P_ATM_PA * a2 + fg,
        }
    }
}

/// The ADC calibration in the form the hot loop wants.
#[derive(Debug, Clone, Copy)]
pub struct Calibration {
    pub zero: [f32; 3],
    pub scale: [f32; 3],
    pub full: [u16; 3],
    /// Whether a sample at the bottom rail is a fault. A pressure transducer
    /// whose range reaches vacuum cannot be driven there by the air (the
    /// default); one that starts at 0 gauge clips a vented chamber's dip
    /// below atmosphere, which is data lost, not a fault.
    pub bottom_is_fault: [bool; 3],
}

/// Gauge pressure below which no chamber can go (absolute vacuum), with margin.
pub const VACUUM_GAUGE_PA: f32 = -0.9e5;

impl Calibration {
    pub fn new(c: &Config) -> Self {
        Self {
            zero: [c.rear.zero_code, c.front.zero_code, c.accel.zero_code],
            scale: [c.rear.scale, c.front.scale, c.accel.scale],
            full: [c.rear.full_scale_code, c.front.full_scale_code, c.accel.full_scale_code],
            bottom_is_fault: [
                c.rear.value(0) <= VACUUM_GAUGE_PA,
                c.front.value(0) <= VACUUM_GAUGE_PA,
                true,
            ],
        }
    }
}

/// Rail and stuck-code bookkeeping of the three channels.
struct Watch {
    rail: [u32; 3],
    run: [u32; 3],
    last: [u16; 3],
    flags: Flags,
}

impl Watch {
    /// A sample at a rail is a saturated reading, except a pressure at the
    /// bottom rail of a transducer that starts at 0 gauge (`bottom_is_fault`
    /// false): a vented chamber below atmosphere, clipped. That is neither
    /// saturation nor a stuck sensor; those samples leave the fit instead
    /// (see [`Left`]).
    #[inline(always)]
    fn check(&mut self, ch: usize, c: u16, full: u16, stuck_limit: u32, bottom_is_fault: bool) {
        const SAT: [Flags; 3] = [Flags::REAR_SATURATED, Flags::FRONT_SATURATED, Flags::ACCEL_SATURATED];
        const STUCK: [Flags; 3] = [Flags::REAR_STUCK, Flags::FRONT_STUCK, Flags::ACCEL_STUCK];
        // One compare for both rails: code 0 wraps to the top.
        // A clipped dip holds code 0 for a while without the sensor being
        // stuck: there, only a run longer than any dip (4× the limit, 20 ms
        // by default against the ~12 ms dips seen) is.
        let mut limit = stuck_limit;
        if c.wrapping_sub(1) >= full.wrapping_sub(1) {
            self.rail[ch] = self.rail[ch].saturating_add(1);
            if bottom_is_fault || c != 0 {
                self.flags.insert(SAT[ch]);
            } else {
                limit = stuck_limit.saturating_mul(4);
            }
        }
        if c == self.last[ch] {
            self.run[ch] = self.run[ch].saturating_add(1);
            if self.run[ch] == limit || (self.run[ch] > limit && limit == stuck_limit) {
                self.flags.insert(STUCK[ch]);
            }
        } else {
            self.run[ch] = 0;
            self.last[ch] = c;
        }
    }
}

/// The running state of the cycle under way.
#[derive(Debug, Clone)]
pub struct CycleAcc {
    pub cp: Vec<Sums, MAX_CHECKPOINTS>,
    pub cur: Sums,
    /// Samples kept so far, in the fit or not.
    pub samples: f32,
    /// The zero-shift regressor before the first kept sample (the j-th
    /// sample's is `e_first·q^(j+1)`).
    pub e_first: f32,
    /// Totals over the samples that left the fit, and the interval's.
    pub left: Left,
    railed: Railed,
    /// Σ r·e, Σ r², Σ force², Σ r·force of the samples that left the fit,
    /// since the cycle began (the running sums they come off).
    left_sq: [f32; 4],
    since_cp: u32,
    /// Σ j·p1 and Σ j·p2 (j = sample index): with Σp1, Σp2 they give the
    /// pressure integrals the gain sensitivities need.
    pub jp1: f32,
    pub jp2: f32,
    /// The float sums that need every sample, up to the newest one.
    sq: Squares,
    /// The regressor e and the pressure force at the last sample before the
    /// samples in `pend` (where `settle` continues the integrals from).
    e_before: f32,
    force_before: f32,
    pub last_force: f32,
    pub first_force: f32,
    pub peak_p1: f32,
    pub peak_p2: f32,
    pub flags: Flags,
    pub rail: [u32; 3],
    run: [u32; 3],
    last_code: [u16; 3],
    /// Running slope sums, and their values at the last checkpoints (a ring).
    pub slope: SlopeSums,
    slope_cp: [SlopeSums; SLOPE_WINDOW_CP],
    slope_cp_len: usize,
    /// Pressure extremes (rear high, rear low, front high, front low) of the
    /// last few 8 ms spans: whether the hammer runs *now*.
    spans: [[f32; 4]; SPANS],
    span_count: usize,
    span_now: [f32; 4],
    /// Kept samples at which an accelerometer fault was first seen.
    pub accel_fault_at: Option<u32>,
    /// The codes' exact sums since the last checkpoint (see [`Self::settle`]).
    pend: CodeSums,
}

/// Checkpoints per span of the recent-activity record, and spans kept.
const SPAN_CP: usize = 8;
const SPANS: usize = 4;
const EMPTY_SPAN: [f32; 4] = [f32::NEG_INFINITY, f32::INFINITY, f32::NEG_INFINITY, f32::INFINITY];

/// Samples the accelerometer's force-balance slope is judged on: the last
/// few milliseconds (checkpoints), so a fault that begins mid-cycle shows.
const SLOPE_WINDOW_CP: usize = 8;
const SLOPE_MIN_SAMPLES: f32 = 500.0;
/// Spread of the pressure force (standard deviation, N) needed to judge it:
/// a running hammer swings by hundreds of newtons.
const SLOPE_MIN_FORCE_SD_N: f32 = 50.0;
/// |slope| above which the accelerometer disagrees with the pressures; a
/// sound one stays within a few percent (its gain error, friction's share).
const SLOPE_LIMIT: f32 = 0.3;

impl CycleAcc {
    /// The slope of r on the force over the last milliseconds, if they hold
    /// enough samples and enough swing of the force to judge it.
    pub fn force_slope(&self) -> Option<f32> {
        let c = self.slope;
        // The oldest checkpoint in the ring, once it is full: the window's start.
        let w = if self.slope_cp_len >= SLOPE_WINDOW_CP {
            let o = self.slope_cp[self.slope_cp_len % SLOPE_WINDOW_CP];
            SlopeSums {
                n: c.n - o.n,
                r: c.r - o.r,
                f: c.f - o.f,
                ff: c.ff - o.ff,
                rf: c.rf - o.rf,
            }
        } else {
            c
        };
        let n = w.n;
        if n < SLOPE_MIN_SAMPLES {
            return None;
        }
        let var = w.ff - w.f * w.f / n;
        if !(var > n * SLOPE_MIN_FORCE_SD_N * SLOPE_MIN_FORCE_SD_N) {
            return None;
        }
        Some((w.rf - w.r * w.f / n) / var)
    }

    /// Samples still to be pushed before the next checkpoint (where the
    /// accelerometer is judged): runs end there, so that the block path and
    /// the sample path see a fault at the same sample.
    #[inline(always)]
    pub fn to_checkpoint(&self, d: &Derived) -> u32 {
        d.k - self.since_cp
    }

    /// Pressure swing over the last 24–32 ms (the larger of the two
    /// chambers'): a hammer that runs swings by bars within a cycle, one that
    /// has stopped by its sensors' noise.
    pub fn recent_pressure_swing_pa(&self) -> f32 {
        let mut e = self.span_now;
        for sp in &self.spans[..self.span_count.min(SPANS)] {
            e = [e[0].max(sp[0]), e[1].min(sp[1]), e[2].max(sp[2]), e[3].min(sp[3])];
        }
        let swing = |hi: f32, lo: f32| if hi >= lo { hi - lo } else { 0.0 };
        swing(e[0], e[1]).max(swing(e[2], e[3]))
    }

    pub fn new() -> Self {
        Self {
            cp: Vec::new(),
            cur: Sums::default(),
            samples: 0.0,
            e_first: 0.0,
            left: Left::default(),
            railed: Railed::default(),
            left_sq: [0.0; 4],
            since_cp: 0,
            jp1: 0.0,
            jp2: 0.0,
            sq: Squares::default(),
            e_before: 0.0,
            force_before: 0.0,
            last_force: 0.0,
            first_force: 0.0,
            peak_p1: f32::NEG_INFINITY,
            peak_p2: f32::NEG_INFINITY,
            flags: Flags::default(),
            rail: [0; 3],
            run: [0; 3],
            last_code: [u16::MAX; 3],
            slope: SlopeSums::default(),
            slope_cp: [SlopeSums::default(); SLOPE_WINDOW_CP],
            slope_cp_len: 0,
            spans: [EMPTY_SPAN; SPANS],
            span_count: 0,
            span_now: EMPTY_SPAN,
            accel_fault_at: None,
            pend: CodeSums::default(),
        }
    }

    /// [`Self::new`] in place: a fresh accumulator is ~5.5 KB (its
    /// checkpoints), and `*self = Self::new()` put one on the stack at every
    /// impact, the deepest frame of the sampling task on a size build. A
    /// test holds it to `new`.
    fn clear(&mut self) {
        self.cp.clear();
        self.cur = Sums::default();
        self.samples = 0.0;
        self.e_first = 0.0;
        self.left = Left::default();
        self.railed = Railed::default();
        self.left_sq = [0.0; 4];
        self.since_cp = 0;
        self.jp1 = 0.0;
        self.jp2 = 0.0;
        self.sq = Squares::default();
        self.e_before = 0.0;
        self.force_before = 0.0;
        self.last_force = 0.0;
        self.first_force = 0.0;
        self.peak_p1 = f32::NEG_INFINITY;
        self.peak_p2 = f32::NEG_INFINITY;
        self.flags = Flags::default();
        self.rail = [0; 3];
        self.run = [0; 3];
        self.last_code = [u16::MAX; 3];
        self.slope = SlopeSums::default();
        self.slope_cp = [SlopeSums::default(); SLOPE_WINDOW_CP];
        self.slope_cp_len = 0;
        self.spans = [EMPTY_SPAN; SPANS];
        self.span_count = 0;
        self.span_now = EMPTY_SPAN;
        self.accel_fault_at = None;
        self.pend = CodeSums::default();
    }

    /// Restarts for a cycle whose blanking ended `samples_since_impact` samples after the impact.
    pub fn start(&mut self, d: &Derived, samples_since_impact: u32) {
        self.clear();
        // e(t) = exp(−(t − t_impact)/τ); the first push multiplies by q once.
        self.e_before = if d.q > 0.0 {
            match samples_since_impact {
                0 => 1.0 / d.q,
                n => math::powi(d.q, n - 1),
            }
        } else {
            0.0
        };
        self.sq.e = self.e_before;
        self.e_first = self.e_before;
    }

    /// Adds a run of consecutive samples. The hot loop of the estimator, in
    /// pieces that end at checkpoints: one pass over the piece (exact
    /// integer sums of its codes, and the few float sums that need each
    /// sample; see `pass`), the sensor watches (see `Self::watch`), then
    /// at a checkpoint the float conversion of the integer sums and the
    /// checkpoint's work.
    ///
    /// The run is given as two slices that follow each other (the delay
    /// line's samples, then the new ones): one call, one set-up.
    #[inline(always)]
    pub fn push_run(&mut self, d: &Derived, cal: &Calibration, run: [&[crate::RawSample]; 2], stuck_limit: u32) {
        let Some(first) = run[0].first().or(run[1].first()) else {
            return;
        };
        let b = Balance::new(d, cal);
        if self.pend.n == 0 && self.samples <= 0.0 {
            // The cycle's first sample: the integrals start at rest there.
            self.first_force = b.force(first.rear, first.front);
        }
        let [mut head, mut body] = run;
        while !(head.is_empty() && body.is_empty()) {
            let room = ((d.k - self.since_cp) as usize).min(pass::MAX_PIECE);
            let (h, h_rest) = head.split_at(head.len().min(room));
            let (t, t_rest) = body.split_at(body.len().min(room - h.len()));
            (head, body) = (h_rest, t_rest);
            let piece = [h, t];
            let e_before = self.sq.e;
            let c = pass::pass(d, cal, &b, piece, &mut self.sq);
            if (0..2).any(|ch| c.min[ch] == 0 || c.max[ch] >= cal.full[ch]) {
                self.leave_fit(d, cal, &b, piece, e_before);
            }
            self.watch(cal, &c, piece, stuck_limit);
            self.pend.merge(&c);
            self.since_cp += c.n;
            if self.since_cp == d.k {
                self.since_cp = 0;
                self.settle(d, cal);
                if let Some(last) = t.last().or(h.last()) {
                    let p1 = (last.rear as f32 - cal.zero[0]) * cal.scale[0];
                    let p2 = (last.front as f32 - cal.zero[1]) * cal.scale[1];
                    self.checkpoint(p1, p2);
                }
            }
        }
    }

    /// Rails and stuck codes over `piece` (two slices that follow each
    /// other). When no channel's run of equal codes can reach the stuck
    /// limit within the piece and no sample is at a rail (from the pass's
    /// extremes), nothing is flagged and only the run lengths at its end are
    /// needed (a scan back from its end); otherwise sample by sample.
    #[inline(always)]
    fn watch(&mut self, cal: &Calibration, c: &CodeSums, piece: [&[crate::RawSample]; 2], stuck_limit: u32) {
        let [head, body] = piece;
        let Some(last) = body.last().or(head.last()) else {
            return;
        };
        let len = head.len() + body.len();
        let longest = self.run[0].max(self.run[1]).max(self.run[2]);
        let fast = (longest as u64 + len as u64) < stuck_limit as u64
            && (0..3).all(|ch| c.min[ch] != 0 && c.max[ch] < cal.full[ch]);
        if fast {
            let codes = |s: &crate::RawSample| [s.rear, s.front, s.accel];
            let newest = codes(last);
            for (ch, &c) in newest.iter().enumerate() {
                // Samples before the last that hold its code, back to the first that does not.
                let tail = |part: &[crate::RawSample]| part.iter().rev().take_while(|s| codes(s)[ch] == c).count();
                let in_body = tail(body);
                let same = if in_body == body.len() {
                    in_body + tail(head)
                } else {
                    in_body
                } - 1;
                self.run[ch] = if same == len - 1 && self.last_code[ch] == c {
                    self.run[ch] + len as u32
                } else {
                    same as u32
                };
                self.last_code[ch] = c;
            }
            return;
        }
        let mut w = Watch {
            rail: self.rail,
            run: self.run,
            last: self.last_code,
            flags: self.flags,
        };
        for smp in head.iter().chain(body) {
            w.check(0, smp.rear, cal.full[0], stuck_limit, cal.bottom_is_fault[0]);
            w.check(1, smp.front, cal.full[1], stuck_limit, cal.bottom_is_fault[1]);
            w.check(2, smp.accel, cal.full[2], stuck_limit, cal.bottom_is_fault[2]);
        }
        self.rail = w.rail;
        self.run = w.run;
        self.last_code = w.last;
        self.flags = w.flags;
    }

    /// Turns the exact integer sums since the last checkpoint into the
    /// float sums (at checkpoints, and before a cycle's numbers are read):
    /// Σ p = k·(Σc − n·z) per channel, the force and residual sums from
    /// those, and the trapezoid integrals in closed form,
    ///   v_end = v0 + h·(2F + f_before − f_last),
    ///   Σv   = n·v0 + h·(n·f_before + Σ(2n−1−2j)·f_j),
    ///   w   += dt/2·(2Σv − v_end + v0)
    /// (h = dt/2m, F = Σ f_j, j from 0), where Σ(2n−1−2j)·c_j = 2q − s is
    /// exact in integers. The cycle's first sample starts at rest: there
    /// f_before = −f_0, so that v_0 = 0. Also adds the pressures' peaks
    /// (kept as code extremes: the calibration is monotonic, so the peak code
    /// reads the peak value exactly).
    pub fn settle(&mut self, d: &Derived, cal: &Calibration) {
        let c = core::mem::take(&mut self.pend);
        if c.n == 0 {
            return;
        }
        let mut peak = [0.0f32; 2];
        for (ch, p) in peak.iter_mut().enumerate() {
            let (z, k) = (cal.zero[ch], cal.scale[ch]);
            let code = if k < 0.0 { c.min[ch] } else { c.max[ch] };
            *p = (code as f32 - z) * k;
        }
        self.peak_p1 = if peak[0] > self.peak_p1 { peak[0] } else { self.peak_p1 };
        self.peak_p2 = if peak[1] > self.peak_p2 { peak[1] } else { self.peak_p2 };

        let n = c.n as f32;
        let n0 = self.samples;
        let x = core::mem::take(&mut self.railed);
        // Σ p, Σ (2n−1−2j)·p and Σ j·p of the interval, per channel.
        let nn = c.n;
        let sum = |ch: usize| (c.s[ch] as f32 - cal.zero[ch] * n) * cal.scale[ch];
        let weighted = |ch: usize| {
            let w = (2 * c.q[ch]).wrapping_sub(u64::from(c.s[ch]));
            (pass::to_f32(w) - cal.zero[ch] * nn.wrapping_mul(nn) as f32) * cal.scale[ch]
        };
        let indexed = |ch: usize| {
            let t = (u64::from(nn) * u64::from(c.s[ch])).wrapping_sub(c.q[ch]);
            (pass::to_f32(t) - cal.zero[ch] * (nn.wrapping_mul(nn - 1) / 2) as f32) * cal.scale[ch]
        };
        let (p1, p2, a) = (sum(0), sum(1), sum(2));
        let f = d.a1 * p1 - d.a2 * p2 + d.fg * n;
        let fw = d.a1 * weighted(0) - d.a2 * weighted(1) + d.fg * nn.wrapping_mul(nn) as f32;
        let f_before = if n0 <= 0.0 {
            -self.first_force
        } else {
            self.force_before
        };
        let f_last = self.sq.force;
        let v0 = self.cur.v;
        let v_end = v0 + d.half_dt_over_m * (2.0 * f + f_before - f_last);
        let sum_v = n * v0 + d.half_dt_over_m * (n * f_before + fw);
        self.cur.w += d.half_dt * (2.0 * sum_v - v_end + v0);
        // Over the samples that left the fit the piston's acceleration is
        // the measured one: (m·a − P)/m = r/m more than the pressures say,
        // from each such sample j on (Σ r_j·(n − 1 − j) for the displacement).
        let h = d.dt / d.m;
        self.cur.v = v_end + h * x.r;
        self.cur.w += d.dt * h * ((nn - 1) as f32 * x.r - x.jr);
        self.force_before = f_last;
        self.last_force = f_last;

        self.jp1 += n0 * p1 + indexed(0);
        self.jp2 += n0 * p2 + indexed(1);
        let (ge, gee) = if c.n == d.k {
            (d.e_k, d.ee_k)
        } else {
            pass::geometric(d.q, c.n)
        };
        let e0 = self.e_before;
        self.e_before = self.sq.e;
        let r = d.m * a - f;
        let sq = &mut self.left_sq;
        for (t, v) in sq.iter_mut().zip([x.re, x.rr, x.ff, x.rf]) {
            *t += v;
        }
        let l = &mut self.left;
        let xn = x.n as f32;
        l.n += xn;
        l.r += x.r;
        l.f += x.f;
        l.e += x.e;
        l.j += n0 * xn + x.j;
        l.je += n0 * x.e + x.je;
        self.samples += n;
        let s = &mut self.cur;
        s.n += n - xn;
        s.e += e0 * ge - x.e;
        s.ee += e0 * e0 * gee - x.ee;
        s.r += r - x.r;
        s.re = self.sq.re - sq[0];
        s.rr = self.sq.rr - sq[1];
        s.p1 += p1;
        s.p2 += p2;
        // The accelerometer's watch leaves them out too: their force is wrong.
        self.slope = SlopeSums {
            n: s.n,
            r: s.r,
            f: self.slope.f + f - x.f,
            ff: self.sq.ff - sq[2],
            rf: self.sq.rf - sq[3],
        };
    }

    /// Once a millisecond: the checkpoint's prefix sums, the accelerometer's
    /// judgement, the recent pressure extremes (`p1`, `p2`: the newest sample's).
    fn checkpoint(&mut self, p1: f32, p2: f32) {
        if self.cp.push(self.cur).is_err() {
            self.flags.insert(Flags::OVERFLOW);
        }
        // Once a millisecond: is the accelerometer still believable?
        if self.accel_fault_at.is_none() {
            if self.force_slope().is_some_and(|b| math::abs(b) > SLOPE_LIMIT) {
                self.flags.insert(Flags::ACCEL_FAULT);
            }
            if self.flags.intersects(Flags::ACCEL_FAULT | Flags::ACCEL_STUCK) {
                self.accel_fault_at = Some(self.samples as u32);
            }
        }
        self.slope_cp[self.slope_cp_len % SLOPE_WINDOW_CP] = self.slope;
        self.slope_cp_len += 1;
        // Pressure extremes per span, sampled once a millisecond:
        // enough for swings of bars over tens of milliseconds.
        let sp = &mut self.span_now;
        *sp = [sp[0].max(p1), sp[1].min(p1), sp[2].max(p2), sp[3].min(p2)];
        if self.slope_cp_len % SPAN_CP == 0 {
            self.spans[self.span_count % SPANS] = self.span_now;
            self.span_count += 1;
            self.span_now = EMPTY_SPAN;
        }
    }

    /// Time of checkpoint `i` from the first kept sample.
    pub(crate) fn cp_time(d: &Derived, i: usize) -> f32 {
        (((i as u32 + 1) * d.k - 1) as f32) * d.dt
    }
}

impl Default for CycleAcc {
    fn default() -> Self {
        Self::new()
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use std::format;

    use super::*;
    use crate::{Config, RawSample};

    #[test]
    fn a_restart_in_place_is_a_fresh_accumulator() {
        let cfg = Config::default();
        let (d, cal) = (Derived::new(&cfg), Calibration::new(&cfg));
        let mut used = CycleAcc::new();
        used.start(&d, 3);
        // Every kind of state: sums, checkpoints, rails, runs, spans, a fault.
        let run: heapless::Vec<RawSample, 2048> = (0..2048u32)
            .map(|i| RawSample {
                rear: if i % 700 == 5 { 0 } else { (1000 + i % 97) as u16 },
                front: (900 + i % 53) as u16,
                accel: if i > 1500 { 2048 } else { (2000 + i % 61) as u16 },
            })
            .collect();
        used.push_run(&d, &cal, [&run[..1000], &run[1000..]], 200);
        used.settle(&d, &cal);
        assert!(!used.cp.is_empty() && used.rail[0] > 0);
        used.start(&d, 7);
        let mut fresh = CycleAcc::new();
        fresh.start(&d, 7);
        assert_eq!(format!("{used:?}"), format!("{fresh:?}"));
    }
}
