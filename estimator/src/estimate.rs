//! The estimate made from a closed cycle's running sums ([`crate::cycle`]).
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
//! - impact velocity is `v` at the impact, i.e. the stroke integral from rest;
//! - samples at which a pressure sat at a rail are out of the fit, and the
//!   velocity takes their measured acceleration (`left`).

mod left;

use crate::config::Config;
use crate::cycle::{CycleAcc, Derived, Sums};
use crate::math;
use crate::Flags;
use left::{count, upto, Upto};

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
    /// The samples that left the fit, over the cycle, and the fitted zero
    /// shift (m·o) their measured acceleration held.
    left: Upto,
    mo: f32,
}

fn friction_integrals(m: f32, fs: f32, fb: f32, tr: f32, t: f32) -> (f32, f32) {
    // f(t) = F_b/m·min(t, tr) − F_s/m·max(0, t − tr); returns (f(T), ∫_0^T f).
    let tr = math::clamp(tr, 0.0, t);
    let f_t = (fb * tr - fs * (t - tr)) / m;
    let int = (fb * (0.5 * tr * tr + tr * (t - tr)) - fs * 0.5 * (t - tr) * (t - tr)) / m;
    (f_t, int)
}

/// Backhaul start velocity from the closure, and the impact velocity.
fn kinematics(m: f32, tm: &Timing, tot: &Totals, fs: f32, fb: f32, tr: f32) -> (f32, f32) {
    let (f_t, f_int) = friction_integrals(m, fs, fb, tr, tm.t_end);
    let v_end_rel = tot.v + tot.left.dv(m, tot.mo, fs, fb) + f_t;
    let w = tot.w + tot.left.dw(m, tot.mo, fs, fb);
    let a_last = tot.last_accel - fs / m;
    let a_first = tot.first_accel + fb / m;
    // ∫ v over the cycle = 0. After the contact, through the blanking, the
    // piston moves with v_b − a_b·(t_b − t); then the kept samples; then the
    // tail before the next impact with v(T) + a·t.
    let l = (tm.d - tm.contact).max(0.0);
    let vb = -(-0.5 * a_first * l * l + w + f_int + v_end_rel * tm.gap + 0.5 * a_last * tm.gap * tm.gap)
        / (l + tm.t_end + tm.gap);
    let v_imp = vb + v_end_rel + a_last * tm.gap;
    (vb, v_imp)
}

struct Split {
    back: Sums,
    stroke: Sums,
    /// Samples in each phase, in the fit or not (what the pressures' sums hold).
    all: (f32, f32),
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
    let (lo, hi) = (lo?, hi?);
    let back = cps[lo];
    let stroke = acc.cur.minus(&cps[hi]);
    if back.n < 10.0 || stroke.n < 10.0 {
        return None;
    }
    let k = d.k as f32;
    let all = ((lo + 1) as f32 * k, acc.samples - (hi + 1) as f32 * k);
    Some(Split { back, stroke, all })
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
    let n = acc.samples;
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
    let mut tot = Totals {
        v: acc.cur.v,
        w: acc.cur.w,
        first_accel: acc.first_force / m,
        last_accel: acc.last_force / m,
        left: Upto::default(),
        mo: 0.0,
    };
    let guard = 1.0e-3;
    let zero_shift = d.q > 0.0;
    let kappa = c.residual_correlation_factor;

    // Fixed-point iteration: friction → turning point → friction.
    let (mut fs, mut fb) = (friction_guess, friction_guess);
    let mut tr = 0.5 * tm.t_end;
    let mut result = None;
    for _ in 0..4 {
        tot.left = upto(acc, d, tr, tm.t_end);
        let (vb, _) = kinematics(m, &tm, &tot, fs, fb, tr);
        let Some(t_new) = turning_point(acc, d, &tm, vb, (fs, fb, tr), tot.left.t_b) else {
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
        tot.mo = f.2;
        result = Some((sp, f));
    }
    tot.left = upto(acc, d, tr, tm.t_end);
    let Some((sp, (_, _, o, var_fb, var_fs, cov, sigma2))) = result else {
        out.flags.insert(Flags::NO_REVERSAL);
        return out;
    };
    let (nb, ns) = (sp.back.n, sp.stroke.n);
    let (nb_all, ns_all) = sp.all;
    if 2.0 * nb < nb_all || 2.0 * ns < ns_all {
        // Most of a phase at a rail: the transducer's range does not fit
        // this hammer (docs/estimator.md, "Below atmosphere").
        for (ch, flag) in [Flags::REAR_SATURATED, Flags::FRONT_SATURATED].into_iter().enumerate() {
            if acc.rail[ch] > 0 {
                out.flags.insert(flag);
            }
        }
    }
    let (wb, ws) = (nb / (nb + ns), ns / (nb + ns));
    let friction = wb * fb + ws * fs;

    // Systematic sensitivities of (F_b, F_s) to each calibration error.
    let mean = |x: f32, k: f32| x / k;
    let (p1b, p1s) = (mean(sp.back.p1, nb_all), mean(sp.stroke.p1, ns_all));
    let (p2b, p2s) = (mean(sp.back.p2, nb_all), mean(sp.stroke.p2, ns_all));
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
    // Over the samples at a rail the velocity is the measured acceleration's:
    // the accelerometer's gain and offset reach it there. Its gain by the
    // velocity gained over them, at their mean lag before the cycle's end.
    let lt = &acc.left;
    let (t_left, w_left) = tot.left.time_s();
    let v_left = (lt.r + lt.f) * d.dt / m;
    let w_gain = if lt.n > 0.0 { v_left * w_left / t_left } else { 0.0 };
    let sources: [(f32, f32, f32, f32, f32); 6] = [
        (c.rear_spec.gain_rel, -d.a1 * p1b, d.a1 * p1s, v1, w1),
        (c.front_spec.gain_rel, d.a2 * p2b, -d.a2 * p2s, -v2, -w2),
        (c.accel_spec.gain_rel, m * ab, -m * as_, v_left, w_gain),
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
        (c.accel_spec.offset, m, -m, t_left, w_left),
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
    // The friction their measured acceleration held, off the displacement
    // to the turning point (its zero shift's few µm are left in).
    let l = &tot.left;
    let w_tr = interp_w(acc, d, tr) - fb * (l.t_b * tr - l.at_b * d.dt) / m;
    let tot = Totals {
        v: tot.v + tot.left.dv(m, o, fs, fb),
        w: tot.w + tot.left.dw(m, o, fs, fb),
        ..tot
    };
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
    if !(x_stroke > 0.002)
        || beyond_the_hammer(c, d, acc.peak_p1, x_stroke, v_imp)
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

/// How far past the hammer's own bounds a cycle may read before it is not
/// this hammer's, as a fraction of them: the stroke is a double integral
/// of the measured forces, and the bound on the energy a sum of the
/// pressures' extremes, each off by a few per cent at most through the
/// sensors' gains and offsets (0.8 % and 1 kPa standard on the paper's);
/// a wrong time base (a sample rate read wrong, 50 kS/s for 100 kS/s)
/// scales the stroke by the square of its error, far beyond this. (An
/// eighth: a constant the board's FPU loads without a literal.)
pub const PLAUSIBLE_MARGIN: f32 = 0.125;

/// Whether a cycle's stroke or impact energy is more than this hammer can
/// give: a stroke longer than the piston's travel, or an energy above the
/// most the air can do over the travel, each with [`PLAUSIBLE_MARGIN`].
/// That most is the rear chamber at the cycle's peak pressure (what the
/// supply gave it: no higher in the stroke, from the supply's own pressure
/// or an air cushion's) on the bore, plus [`Derived::assist_n`] (the front
/// chamber at vacuum, gravity). Such a cycle is read on a wrong time base
/// or a wrong hammer, never valid; a travel that is no number flags every
/// cycle. (Few instructions: the reference board's flash is at its aim.)
#[inline(always)]
fn beyond_the_hammer(c: &Config, d: &Derived, peak_p1: f32, x_stroke: f32, v_imp: f32) -> bool {
    let reach = c.geometry.travel_m * (1.0 + PLAUSIBLE_MARGIN);
    !(x_stroke <= reach && 0.5 * d.m * v_imp * v_imp <= (peak_p1 * d.a1 + d.assist_n) * reach)
}

/// The last upward zero crossing of v(t) = v_b + V(t) + f(t), searched on
/// the checkpoints; less, over the samples that left the fit (`t_b` of
/// them before `tr_f`), the friction their acceleration held (their zero
/// shift's share is left in: it moves the crossing by microseconds).
fn turning_point(
    acc: &CycleAcc,
    d: &Derived,
    tm: &Timing,
    vb: f32,
    (fs, fb, tr_f): (f32, f32, f32),
    t_b: f32,
) -> Option<f32> {
    let v_at = |t: f32, v_rel: f32, i: usize| {
        let (f, _) = friction_integrals(d.m, fs, fb, tr_f, t);
        let left = if acc.left.n > 0.0 { count(acc, d, i) * d.dt } else { 0.0 };
        let held = if t < tr_f {
            fb * left
        } else {
            fb * t_b - fs * (left - t_b)
        };
        vb + v_rel + f - held / d.m
    };
    let mut prev_t = 0.0;
    let mut prev_v = vb;
    let mut found = None;
    let cps = &acc.cp;
    for i in 0..=cps.len() {
        let (t, v) = if i < cps.len() {
            let t = CycleAcc::cp_time(d, i);
            (t, v_at(t, cps[i].v, i))
        } else {
            (tm.t_end, v_at(tm.t_end, acc.cur.v, i))
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

#[cfg(test)]
mod tests {
    use super::*;

    /// The paper's hammer at a 4 bar peak can give at most ~35 J over its
    /// 52 mm (rear chamber at the peak on the bore, front at vacuum,
    /// margin): its 3.8 J cycles over 43 mm pass; a stroke beyond the
    /// travel, an energy beyond that bound, or a travel that is no number
    /// does not.
    #[test]
    fn strokes_and_energies_beyond_the_hammer_are_caught() {
        let mut c = Config::default();
        let d = Derived::new(&c);
        let v_for = |j: f32| libm::sqrtf(2.0 * j / d.m);
        assert!(!beyond_the_hammer(&c, &d, 4e5, 0.043, v_for(3.8)));
        assert!(!beyond_the_hammer(&c, &d, 4e5, 0.058, v_for(3.8)));
        assert!(beyond_the_hammer(&c, &d, 4e5, 0.060, v_for(3.8)));
        assert!(!beyond_the_hammer(&c, &d, 4e5, 0.043, v_for(33.0)));
        assert!(beyond_the_hammer(&c, &d, 4e5, 0.043, v_for(36.0)));
        // A higher peak can give more.
        assert!(!beyond_the_hammer(&c, &d, 6e5, 0.043, v_for(36.0)));
        assert!(beyond_the_hammer(&c, &d, 4e5, f32::NAN, v_for(3.8)));
        // A longer hammer makes longer strokes.
        c.geometry.travel_m = 0.1;
        assert!(!beyond_the_hammer(&c, &d, 4e5, 0.065, v_for(3.8)));
        c.geometry.travel_m = f32::NAN;
        assert!(beyond_the_hammer(&c, &d, 4e5, 0.043, v_for(3.8)));
    }
}
