//! One cycle's running sums, and the estimate made from them when it closes.
//!
//! Nothing per sample is stored: the sums the estimate needs are kept as
//! prefix sums at one checkpoint per millisecond, so once the turning point
//! is known at the end of the cycle the samples can be split into backhaul
//! and stroke (with a guard band around the turning point) without a second
//! pass. Memory is bounded by [`MAX_CHECKPOINTS`].
//!
//! The method (docs/estimator.md):
//! - force balance residual `r = m·a − (p1·A1 − p2·A2 + m·g·sinθ)`; in the
//!   backhaul `r = +F_b`, in the stroke `r = −F_s` (the paper's
//!   `F = s·(p1·A1 − p2·A2 − m·a)`), plus `m·o·e(t)` for the accelerometer's
//!   zero shift, `e(t)` decaying from the impact with the sensor's time constant;
//!   `F_b`, `F_s` and `o` are a least-squares fit;
//! - velocity from the pressures, `v(t) = v_b + ∫(P ∓ F)/m dt`, its constant
//!   fixed by the piston returning to the impact position (the displacement
//!   over a cycle closes); the turning point is where `v` crosses zero;
//! - impact velocity is `v` at the impact, i.e. the stroke integral from rest.

use heapless::Vec;

use crate::config::Config;
use crate::math;
use crate::Flags;

/// Checkpoints per cycle: with one per millisecond, cycles up to 128 ms.
pub const MAX_CHECKPOINTS: usize = 128;

/// Prefix sums over a cycle's samples since the blanking ended.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Sums {
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
    fn minus(&self, o: &Sums) -> Sums {
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
        Self {
            dt,
            m,
            a1: c.rear_area_m2(),
            a2: c.front_area_m2(),
            fg: c.gravity_n(),
            half_dt_over_m: 0.5 * dt / m,
            half_dt: 0.5 * dt,
            q,
            k: c.checkpoint_samples(),
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
/// How far below atmosphere a vented chamber's dip can reach: twice the
/// deepest the simulator shows (−9 kPa at 4 bar, docs/estimator.md).
pub const CLIPPED_DIP_BOUND_PA: f32 = 0.2e5;

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
    /// saturation nor a stuck sensor; its share of the cycle goes into the
    /// uncertainty instead (see [`estimate`]).
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
    since_cp: u32,
    prev_force: f32,
    /// Σ j·p1 and Σ j·p2 (j = sample index): with Σp1, Σp2 they give the
    /// pressure integrals the gain sensitivities need, at two flops a channel.
    pub jp1: f32,
    pub jp2: f32,
    e: f32,
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
            since_cp: 0,
            prev_force: 0.0,
            jp1: 0.0,
            jp2: 0.0,
            e: 0.0,
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
        }
    }

    /// Restarts for a cycle whose blanking ended `samples_since_impact` samples after the impact.
    pub fn start(&mut self, d: &Derived, samples_since_impact: u32) {
        *self = Self::new();
        // e(t) = exp(−(t − t_impact)/τ); the first push multiplies by q once.
        self.e = if d.q > 0.0 {
            math::pow(d.q, samples_since_impact as f32 - 1.0)
        } else {
            0.0
        };
    }

    /// Adds a run of consecutive samples. The hot loop of the estimator: the
    /// running sums live in locals (registers) for the whole run and go back
    /// to memory at checkpoints and at the end.
    #[inline]
    pub fn push_run(&mut self, d: &Derived, cal: &Calibration, samples: &[crate::RawSample], stuck_limit: u32) {
        let mut s = self.cur;
        let mut e = self.e;
        let mut prev_force = self.prev_force;
        let (mut jp1, mut jp2) = (self.jp1, self.jp2);
        let (mut peak_p1, mut peak_p2) = (self.peak_p1, self.peak_p2);
        let mut sl = self.slope;
        let mut since_cp = self.since_cp;
        let mut w = Watch {
            rail: self.rail,
            run: self.run,
            last: self.last_code,
            flags: self.flags,
        };
        for smp in samples {
            let p1 = (smp.rear as f32 - cal.zero[0]) * cal.scale[0];
            let p2 = (smp.front as f32 - cal.zero[1]) * cal.scale[1];
            let a = (smp.accel as f32 - cal.zero[2]) * cal.scale[2];
            let force = d.a1 * p1 - d.a2 * p2 + d.fg;
            let r = d.m * a - force;
            e *= d.q;
            if s.n > 0.0 {
                let v_new = s.v + (force + prev_force) * d.half_dt_over_m;
                s.w += (s.v + v_new) * d.half_dt;
                s.v = v_new;
            } else {
                self.first_force = force;
            }
            jp1 += s.n * p1;
            jp2 += s.n * p2;
            s.n += 1.0;
            s.e += e;
            s.ee += e * e;
            s.r += r;
            s.re += r * e;
            s.rr += r * r;
            s.p1 += p1;
            s.p2 += p2;
            sl.f += force;
            sl.ff += force * force;
            sl.rf += r * force;
            prev_force = force;
            peak_p1 = if p1 > peak_p1 { p1 } else { peak_p1 };
            peak_p2 = if p2 > peak_p2 { p2 } else { peak_p2 };
            w.check(0, smp.rear, cal.full[0], stuck_limit, cal.bottom_is_fault[0]);
            w.check(1, smp.front, cal.full[1], stuck_limit, cal.bottom_is_fault[1]);
            w.check(2, smp.accel, cal.full[2], stuck_limit, cal.bottom_is_fault[2]);
            since_cp += 1;
            if since_cp == d.k {
                since_cp = 0;
                if self.cp.push(s).is_err() {
                    w.flags.insert(Flags::OVERFLOW);
                }
                // Once a millisecond: is the accelerometer still believable?
                sl.n = s.n;
                sl.r = s.r;
                self.slope = sl;
                if self.accel_fault_at.is_none() {
                    if self.force_slope().is_some_and(|b| math::abs(b) > SLOPE_LIMIT) {
                        w.flags.insert(Flags::ACCEL_FAULT);
                    }
                    if w.flags.intersects(Flags::ACCEL_FAULT | Flags::ACCEL_STUCK) {
                        self.accel_fault_at = Some(s.n as u32);
                    }
                }
                self.slope_cp[self.slope_cp_len % SLOPE_WINDOW_CP] = sl;
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
        }
        self.cur = s;
        self.e = e;
        self.prev_force = prev_force;
        self.last_force = prev_force;
        self.jp1 = jp1;
        self.jp2 = jp2;
        self.peak_p1 = peak_p1;
        self.peak_p2 = peak_p2;
        sl.n = s.n;
        sl.r = s.r;
        self.slope = sl;
        self.since_cp = since_cp;
        self.rail = w.rail;
        self.run = w.run;
        self.last_code = w.last;
        self.flags = w.flags;
    }

    /// Time of checkpoint `i` from the first kept sample.
    fn cp_time(d: &Derived, i: usize) -> f32 {
        (((i as u32 + 1) * d.k - 1) as f32) * d.dt
    }
}

impl Default for CycleAcc {
    fn default() -> Self {
        Self::new()
    }
}

/// The numbers of one closed cycle before the wear bookkeeping.
#[derive(Debug, Clone, Copy, Default)]
pub struct Estimate {
    pub friction_n: f32,
    pub friction_stroke_n: f32,
    pub friction_backhaul_n: f32,
    pub u_friction_n: f32,
    pub u_friction_stroke_n: f32,
    pub u_friction_backhaul_n: f32,
    pub v_impact_mps: f32,
    pub v_impact_frictionless_mps: f32,
    pub u_v_impact_mps: f32,
    pub u_v_frictionless_mps: f32,
    pub stroke_m: f32,
    pub backhaul_m: f32,
    pub zero_shift_mps2: f32,
    pub friction_work_j: f32,
    pub friction_work_stroke_j: f32,
    pub flags: Flags,
}

/// Geometry of the cycle in time, relative to the first kept sample.
#[derive(Debug, Clone, Copy)]
struct Timing {
    /// Impact onset to first kept sample.
    d: f32,
    /// Duration of the contact (the shock seen by the accelerometer).
    contact: f32,
    /// First to last kept sample.
    t_end: f32,
    /// Last kept sample to the next impact's onset.
    gap: f32,
}

/// Kinematic totals that the closure uses; perturbed for sensitivities.
#[derive(Debug, Clone, Copy)]
struct Totals {
    v: f32,
    w: f32,
    first_accel: f32,
    last_accel: f32,
}

fn friction_integrals(m: f32, fs: f32, fb: f32, tr: f32, t: f32) -> (f32, f32) {
    // f(t) = F_b/m·min(t, tr) − F_s/m·max(0, t − tr); returns (f(T), ∫_0^T f).
    let tr = tr.clamp(0.0, t);
    let f_t = (fb * tr - fs * (t - tr)) / m;
    let int = (fb * (0.5 * tr * tr + tr * (t - tr)) - fs * 0.5 * (t - tr) * (t - tr)) / m;
    (f_t, int)
}

/// Backhaul start velocity from the closure, and the impact velocity.
fn kinematics(m: f32, tm: &Timing, tot: &Totals, fs: f32, fb: f32, tr: f32) -> (f32, f32) {
    let (f_t, f_int) = friction_integrals(m, fs, fb, tr, tm.t_end);
    let v_end_rel = tot.v + f_t;
    let a_last = tot.last_accel - fs / m;
    let a_first = tot.first_accel + fb / m;
    // ∫ v over the cycle = 0. After the contact, through the blanking, the
    // piston moves with v_b − a_b·(t_b − t); then the kept samples; then the
    // tail before the next impact with v(T) + a·t.
    let l = (tm.d - tm.contact).max(0.0);
    let vb = -(-0.5 * a_first * l * l + tot.w + f_int + v_end_rel * tm.gap + 0.5 * a_last * tm.gap * tm.gap)
        / (l + tm.t_end + tm.gap);
    let v_imp = vb + v_end_rel + a_last * tm.gap;
    (vb, v_imp)
}

struct Split {
    back: Sums,
    stroke: Sums,
}

fn split(acc: &CycleAcc, d: &Derived, tr: f32, guard: f32) -> Option<Split> {
    let cps = &acc.cp;
    // Last checkpoint before tr − guard, first after tr + guard.
    let mut lo = None;
    let mut hi = None;
    for i in 0..cps.len() {
        let t = CycleAcc::cp_time(d, i);
        if t <= tr - guard {
            lo = Some(i);
        }
        if hi.is_none() && t >= tr + guard {
            hi = Some(i);
        }
    }
    let back = cps[lo?];
    let stroke = match hi {
        Some(h) => acc.cur.minus(&cps[h]),
        None => return None,
    };
    if back.n < 10.0 || stroke.n < 10.0 {
        return None;
    }
    Some(Split { back, stroke })
}

/// Least-squares friction fit on a split: returns (F_b, F_s, o·m, var F_b, var F_s, cov, σ²).
fn fit(sp: &Split, zero_shift: bool, kappa: f32) -> (f32, f32, f32, f32, f32, f32, f32) {
    let b = &sp.back;
    let s = &sp.stroke;
    let (nb, ns) = (b.n, s.n);
    let (mb, ms) = (b.r / nb, s.r / ns);
    let (eb, es) = (b.e / nb, s.e / ns);
    // Within-phase scatter of e and its covariance with r.
    let dee = (b.ee - b.e * eb) + (s.ee - s.e * es);
    let dre = (b.re - b.r * eb) + (s.re - s.r * es);
    let use_e = zero_shift && dee > 1e-3;
    let o = if use_e { dre / dee } else { 0.0 };
    let fb = mb - eb * o;
    let fs = -(ms - es * o);
    let rss = (b.rr - b.r * mb) + (s.rr - s.r * ms) - if use_e { o * dre } else { 0.0 };
    let p = if use_e { 3.0 } else { 2.0 };
    let sigma2 = (rss.max(0.0) / (nb + ns - p).max(1.0)) * kappa * kappa;
    let var_o = if use_e { sigma2 / dee } else { 0.0 };
    let var_fb = sigma2 / nb + eb * eb * var_o;
    let var_fs = sigma2 / ns + es * es * var_o;
    let cov = -eb * es * var_o;
    (fb, fs, o, var_fb, var_fs, cov, sigma2)
}

/// Closes the cycle: finds the turning point, fits the friction, integrates
/// the stroke and propagates the uncertainties.
#[allow(clippy::too_many_arguments)]
pub fn estimate(
    acc: &CycleAcc,
    c: &Config,
    d: &Derived,
    blank_samples: u32,
    contact_samples: u32,
    tail_samples: u32,
    friction_guess: f32,
) -> Estimate {
    let mut out = Estimate {
        flags: acc.flags,
        ..Default::default()
    };
    let n = acc.cur.n;
    if n < 2.0 || acc.cp.len() < 4 {
        out.flags.insert(Flags::NO_REVERSAL);
        return out;
    }
    let m = d.m;
    let tm = Timing {
        d: (blank_samples as f32 + 0.5) * d.dt,
        contact: contact_samples as f32 * d.dt,
        t_end: (n - 1.0) * d.dt,
        gap: (tail_samples as f32 + 0.5) * d.dt,
    };
    let tot = Totals {
        v: acc.cur.v,
        w: acc.cur.w,
        first_accel: acc.first_force / m,
        last_accel: acc.last_force / m,
    };
    let guard = 1.0e-3;
    let zero_shift = d.q > 0.0;
    let kappa = c.residual_correlation_factor;

    // Fixed-point iteration: friction → turning point → friction.
    let (mut fs, mut fb) = (friction_guess, friction_guess);
    let mut tr = 0.5 * tm.t_end;
    let mut result = None;
    for _ in 0..4 {
        let (vb, _) = kinematics(m, &tm, &tot, fs, fb, tr);
        let Some(t_new) = turning_point(acc, d, &tm, vb, fs, fb, tr) else {
            out.flags.insert(Flags::NO_REVERSAL);
            return out;
        };
        tr = t_new;
        let Some(sp) = split(acc, d, tr, guard) else {
            out.flags.insert(Flags::NO_REVERSAL);
            return out;
        };
        let f = fit(&sp, zero_shift, kappa);
        fb = f.0;
        fs = f.1;
        result = Some((sp, f));
    }
    let Some((sp, (_, _, o, var_fb, var_fs, cov, sigma2))) = result else {
        out.flags.insert(Flags::NO_REVERSAL);
        return out;
    };
    let (nb, ns) = (sp.back.n, sp.stroke.n);
    let (wb, ws) = (nb / (nb + ns), ns / (nb + ns));
    let friction = wb * fb + ws * fs;

    // Systematic sensitivities of (F_b, F_s) to each calibration error.
    let mean = |x: f32, k: f32| x / k;
    let (p1b, p1s) = (mean(sp.back.p1, nb), mean(sp.stroke.p1, ns));
    let (p2b, p2s) = (mean(sp.back.p2, nb), mean(sp.stroke.p2, ns));
    let force_b = d.a1 * p1b - d.a2 * p2b + d.fg;
    let force_s = d.a1 * p1s - d.a2 * p2s + d.fg;
    let ab = (mean(sp.back.r, nb) + force_b) / m;
    let as_ = (mean(sp.stroke.r, ns) + force_s) / m;
    // (source standard uncertainty, ∂F_b, ∂F_s, ∂V_T, ∂W_T)
    let t_end = tm.t_end;
    // ∫A·p/m dt ≈ (A/m)·dt·Σp and ∫∫ ≈ (A/m)·dt²·(J·Σp − Σ j·p), J the last index.
    let last = n - 1.0;
    let (v1, w1) = (
        d.a1 / m * d.dt * acc.cur.p1,
        d.a1 / m * d.dt * d.dt * (last * acc.cur.p1 - acc.jp1),
    );
    let (v2, w2) = (
        d.a2 / m * d.dt * acc.cur.p2,
        d.a2 / m * d.dt * d.dt * (last * acc.cur.p2 - acc.jp2),
    );
    // A transducer that starts at 0 gauge clips a vented chamber's dip below
    // atmosphere: those samples read high by up to the dip's depth. Carried
    // as an offset uncertainty over the cycle, in proportion to the samples
    // at the bottom rail (none with the default vacuum-reaching ranges).
    let clip_u = |cal: &crate::config::ChannelCal, rail: u32| {
        if rail == 0 || cal.value(0) <= VACUUM_GAUGE_PA {
            0.0
        } else {
            CLIPPED_DIP_BOUND_PA * (rail as f32 / n) / math::sqrt(3.0)
        }
    };
    let (clip_rear, clip_front) = (clip_u(&c.rear, acc.rail[0]), clip_u(&c.front, acc.rail[1]));
    let sources: [(f32, f32, f32, f32, f32); 8] = [
        (c.rear_spec.gain_rel, -d.a1 * p1b, d.a1 * p1s, v1, w1),
        (c.front_spec.gain_rel, d.a2 * p2b, -d.a2 * p2s, -v2, -w2),
        (c.accel_spec.gain_rel, m * ab, -m * as_, 0.0, 0.0),
        (
            c.rear_spec.offset,
            -d.a1,
            d.a1,
            d.a1 * t_end / m,
            d.a1 * 0.5 * t_end * t_end / m,
        ),
        (
            c.front_spec.offset,
            d.a2,
            -d.a2,
            -d.a2 * t_end / m,
            -d.a2 * 0.5 * t_end * t_end / m,
        ),
        (c.accel_spec.offset, m, -m, 0.0, 0.0),
        (clip_rear, -d.a1, d.a1, d.a1 * t_end / m, d.a1 * 0.5 * t_end * t_end / m),
        (
            clip_front,
            d.a2,
            -d.a2,
            -d.a2 * t_end / m,
            -d.a2 * 0.5 * t_end * t_end / m,
        ),
    ];

    // The impact velocity and its sensitivities (by linearity, one closure each).
    let (vb, v_imp) = kinematics(m, &tm, &tot, fs, fb, tr);
    let stroke_time = (tm.t_end + tm.gap - tr).max(0.0);
    let v_free = v_imp + fs * stroke_time / m;
    let vimp_of = |dv: f32, dw: f32, dfs: f32, dfb: f32| {
        let t2 = Totals {
            v: tot.v + dv,
            w: tot.w + dw,
            ..tot
        };
        let (_, vi) = kinematics(m, &tm, &t2, fs + dfs, fb + dfb, tr);
        (vi, vi + (fs + dfs) * stroke_time / m)
    };
    let (mut sys_f, mut sys_fb, mut sys_fs, mut sys_v, mut sys_v0) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for (u, dfb, dfs, dv, dw) in sources {
        let df = wb * dfb + ws * dfs;
        sys_f += (u * df) * (u * df);
        sys_fb += (u * dfb) * (u * dfb);
        sys_fs += (u * dfs) * (u * dfs);
        let (vi, v0) = vimp_of(u * dv, u * dw, u * dfs, u * dfb);
        sys_v += (vi - v_imp) * (vi - v_imp);
        sys_v0 += (v0 - v_free) * (v0 - v_free);
    }
    // Random part: the fit's covariance, propagated to the impact velocity.
    let var_f = wb * wb * var_fb + ws * ws * var_fs + 2.0 * wb * ws * cov;
    let (dv_dfs, dv0_dfs) = {
        let (vi, v0) = vimp_of(0.0, 0.0, 1.0, 0.0);
        (vi - v_imp, v0 - v_free)
    };
    let (dv_dfb, dv0_dfb) = {
        let (vi, v0) = vimp_of(0.0, 0.0, 0.0, 1.0);
        (vi - v_imp, v0 - v_free)
    };
    // Noise integrated into V and W (a random walk: n·(1 + 1/3) steps of
    // σ·dt/m, with the residual σ as a conservative bound of the force noise),
    // and the impact instant known to ±½ sample.
    let step = d.dt / m;
    let a_last = tot.last_accel - fs / m;
    let var_walk = sigma2 * step * step * n * (4.0 / 3.0) + (a_last * d.dt) * (a_last * d.dt) / 12.0;
    let var_v = dv_dfs * dv_dfs * var_fs + dv_dfb * dv_dfb * var_fb + 2.0 * dv_dfs * dv_dfb * cov + var_walk;
    let var_v0 = dv0_dfs * dv0_dfs * var_fs + dv0_dfb * dv0_dfb * var_fb + 2.0 * dv0_dfs * dv0_dfb * cov + var_walk;

    let k = c.coverage_factor;
    out.friction_n = friction;
    out.friction_backhaul_n = fb;
    out.friction_stroke_n = fs;
    out.u_friction_n = k * math::sqrt(var_f.max(0.0) + sys_f);
    out.u_friction_backhaul_n = k * math::sqrt(var_fb.max(0.0) + sys_fb);
    out.u_friction_stroke_n = k * math::sqrt(var_fs.max(0.0) + sys_fs);
    out.v_impact_mps = v_imp;
    out.v_impact_frictionless_mps = v_free;
    out.u_v_impact_mps = k * math::sqrt(var_v.max(0.0) + sys_v);
    out.u_v_frictionless_mps = k * math::sqrt(var_v0.max(0.0) + sys_v0);
    out.zero_shift_mps2 = o / m;

    // Distances: stroke from the turning point to the impact, backhaul from the impact to the turning point.
    let w_tr = interp_w(acc, d, tr);
    let (_, f_int_tr) = friction_integrals(m, fs, fb, tr, tr);
    let (_, f_int_t) = friction_integrals(m, fs, fb, tr, tm.t_end);
    let l = (tm.d - tm.contact).max(0.0);
    let x_back = -(vb * tr + w_tr + f_int_tr) - (vb * l - 0.5 * (tot.first_accel + fb / m) * l * l); // positive
    let (f_t, _) = friction_integrals(m, fs, fb, tr, tm.t_end);
    let x_stroke = (tot.w - w_tr) + vb * (tm.t_end - tr) + (f_int_t - f_int_tr) + (vb + tot.v + f_t) * tm.gap;
    out.stroke_m = x_stroke;
    out.backhaul_m = x_back;
    out.friction_work_stroke_j = fs * x_stroke;
    out.friction_work_j = fs * x_stroke + fb * x_back;

    // Plausibility and warnings.
    let peak_force = d.a1 * acc.peak_p1.max(0.0) + d.a2 * acc.peak_p2.max(0.0);
    let u_f = out.u_friction_n;
    if !(x_stroke > 0.002 && x_stroke < 1.0)
        || !(v_imp > 0.0)
        || friction < -u_f - 1.0
        || friction > 0.5 * peak_force + 1.0
        || !math::is_finite(friction)
    {
        out.flags.insert(Flags::IMPLAUSIBLE);
    }
    let u_o = k * math::sqrt(var_fb.max(0.0)) / m; // scale of the fit's resolution
    if zero_shift && math::abs(out.zero_shift_mps2) > (3.0 * u_o).max(1.0) {
        out.flags.insert(Flags::ACCEL_ZERO_SHIFT);
    }
    let u_diff = math::sqrt(
        out.u_friction_backhaul_n * out.u_friction_backhaul_n + out.u_friction_stroke_n * out.u_friction_stroke_n,
    );
    if math::abs(fb - fs) > u_diff {
        out.flags.insert(Flags::PHASE_MISMATCH);
    }
    out
}

/// The last upward zero crossing of v(t) = v_b + V(t) + f(t), searched on the checkpoints.
fn turning_point(acc: &CycleAcc, d: &Derived, tm: &Timing, vb: f32, fs: f32, fb: f32, tr_f: f32) -> Option<f32> {
    let v_at = |t: f32, v_rel: f32| {
        let (f, _) = friction_integrals(d.m, fs, fb, tr_f, t);
        vb + v_rel + f
    };
    let mut prev_t = 0.0;
    let mut prev_v = vb;
    let mut found = None;
    let cps = &acc.cp;
    for i in 0..=cps.len() {
        let (t, v) = if i < cps.len() {
            let t = CycleAcc::cp_time(d, i);
            (t, v_at(t, cps[i].v))
        } else {
            (tm.t_end, v_at(tm.t_end, acc.cur.v))
        };
        if prev_v < 0.0 && v >= 0.0 {
            let frac = -prev_v / (v - prev_v);
            found = Some(prev_t + frac * (t - prev_t));
        }
        prev_t = t;
        prev_v = v;
    }
    found
}

/// W(t) between checkpoints, linearly.
fn interp_w(acc: &CycleAcc, d: &Derived, t: f32) -> f32 {
    let mut prev_t = 0.0;
    let mut prev_w = 0.0;
    for (i, cp) in acc.cp.iter().enumerate() {
        let ti = CycleAcc::cp_time(d, i);
        if ti >= t {
            let frac = if ti > prev_t { (t - prev_t) / (ti - prev_t) } else { 0.0 };
            return prev_w + frac * (cp.w - prev_w);
        }
        prev_t = ti;
        prev_w = cp.w;
    }
    acc.cur.w
}
