//! The samples that left the friction fit (a pressure at a rail, see
//! [`crate::cycle::Left`]) in the velocity integral.
//!
//! Over those samples the integral took the measured acceleration, which
//! already holds the friction and the accelerometer's zero shift. The
//! model's `∫(P ± F)/m` adds the fitted friction at every sample and the
//! zero shift at none, so over them the friction comes off and the zero
//! shift with it. The zero shift's part and the totals are exact (sums kept
//! per sample); which phase a sample belongs to is known per checkpoint
//! interval (its samples less those in the fit), each taken at its middle.

use crate::cycle::{CycleAcc, Derived};

/// Over the samples that left the fit, for the velocity and displacement
/// at the cycle's last kept sample: their time (s) before and after the
/// turning point, the same weighted by the lag to the end, and Σ e·dt,
/// Σ e·dt·lag.
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct Upto {
    pub t_b: f32,
    pub t_s: f32,
    /// Σ t_j over those before the turning point, s.
    pub at_b: f32,
    w_b: f32,
    w_s: f32,
    e: f32,
    ew: f32,
}

impl Upto {
    /// What the velocity at the end loses (as the model's integral sees
    /// it) with the zero shift `mo` (as m·o, N) and the phases' friction.
    pub fn dv(&self, m: f32, mo: f32, fs: f32, fb: f32) -> f32 {
        -(mo * self.e + fb * self.t_b - fs * self.t_s) / m
    }

    /// The same for the displacement at the end.
    pub fn dw(&self, m: f32, mo: f32, fs: f32, fb: f32) -> f32 {
        -(mo * self.ew + fb * self.w_b - fs * self.w_s) / m
    }

    /// Time at the rails in all, and Σ lag·dt: what the accelerometer's
    /// offset reaches.
    pub fn time_s(&self) -> (f32, f32) {
        (self.t_b + self.t_s, self.w_b + self.w_s)
    }
}

/// Samples out of the fit up to checkpoint `i` (all of them past the last).
pub(super) fn count(acc: &CycleAcc, d: &Derived, i: usize) -> f32 {
    match acc.cp.get(i) {
        Some(cp) => ((i as u32 + 1) * d.k) as f32 - cp.n,
        None => acc.samples - acc.cur.n,
    }
}

/// [`Upto`] for the turning point `tr`, the cycle ending at `t_end`.
pub(super) fn upto(acc: &CycleAcc, d: &Derived, tr: f32, t_end: f32) -> Upto {
    let l = &acc.left;
    if !(l.n > 0.0) {
        return Upto::default();
    }
    let dt = d.dt;
    // Before the turning point: the intervals whose middle is before it.
    let (mut n_b, mut at_b, mut before) = (0.0, 0.0, 0.0);
    for i in 0..=acc.cp.len() {
        let now = count(acc, d, i);
        let mid = ((i as u32 * d.k) as f32 + 0.5 * (d.k - 1) as f32) * dt;
        if mid < tr {
            n_b += now - before;
            at_b += (now - before) * mid;
        }
        before = now;
    }
    let n_s = l.n - n_b;
    let at_s = l.j * dt - at_b;
    Upto {
        t_b: n_b * dt,
        t_s: n_s * dt,
        at_b,
        w_b: (n_b * t_end - at_b) * dt,
        w_s: (n_s * t_end - at_s) * dt,
        e: l.e * dt,
        ew: (l.e * t_end - l.je * dt) * dt,
    }
}
