//! Dormand–Prince 5(4) with dense output, stiffness detection and restarts.
//!
//! The hammer is a hybrid system: port edges, valve end stops and the impact
//! make the right-hand side non-smooth. The driver (see `model::run`) finds
//! those events on the dense output and restarts the integrator exactly there,
//! so no step ever straddles a kink. The laminar orifice branch keeps the gas
//! dynamics mildly stiff at most; Hairer's stiffness test counts the steps in
//! which the step size was stability-limited rather than accuracy-limited, and
//! the count is reported with every run so a parameter set that makes the
//! explicit method struggle is visible instead of silently slow.

/// A system y' = f(t, y) of `N` states.
pub trait OdeSystem<const N: usize> {
    fn rhs(&self, t: f64, y: &[f64; N], dy: &mut [f64; N]);
}

// Butcher tableau of Dormand & Prince (1980).
const C2: f64 = 1.0 / 5.0;
const C3: f64 = 3.0 / 10.0;
const C4: f64 = 4.0 / 5.0;
const C5: f64 = 8.0 / 9.0;
const A21: f64 = 1.0 / 5.0;
const A31: f64 = 3.0 / 40.0;
const A32: f64 = 9.0 / 40.0;
const A41: f64 = 44.0 / 45.0;
const A42: f64 = -56.0 / 15.0;
const A43: f64 = 32.0 / 9.0;
const A51: f64 = 19372.0 / 6561.0;
const A52: f64 = -25360.0 / 2187.0;
const A53: f64 = 64448.0 / 6561.0;
const A54: f64 = -212.0 / 729.0;
const A61: f64 = 9017.0 / 3168.0;
const A62: f64 = -355.0 / 33.0;
const A63: f64 = 46732.0 / 5247.0;
const A64: f64 = 49.0 / 176.0;
const A65: f64 = -5103.0 / 18656.0;
const A71: f64 = 35.0 / 384.0;
const A73: f64 = 500.0 / 1113.0;
const A74: f64 = 125.0 / 192.0;
const A75: f64 = -2187.0 / 6784.0;
const A76: f64 = 11.0 / 84.0;
const E1: f64 = 71.0 / 57600.0;
const E3: f64 = -71.0 / 16695.0;
const E4: f64 = 71.0 / 1920.0;
const E5: f64 = -17253.0 / 339200.0;
const E6: f64 = 22.0 / 525.0;
const E7: f64 = -1.0 / 40.0;
// Dense output of order 4 (Hairer, Nørsett & Wanner, contd5).
const D1: f64 = -12715105075.0 / 11282082432.0;
const D3: f64 = 87487479700.0 / 32700410799.0;
const D4: f64 = -10690763975.0 / 1880347072.0;
const D5: f64 = 701980252875.0 / 199316789632.0;
const D6: f64 = -1453857185.0 / 822651844.0;
const D7: f64 = 69997945.0 / 29380423.0;

/// The interpolant of one accepted step, valid on `[t0, t0 + h]`.
#[derive(Clone)]
pub struct Dense<const N: usize> {
    pub t0: f64,
    pub h: f64,
    r: [[f64; N]; 5],
}

impl<const N: usize> Dense<N> {
    /// An interpolant that holds `y` (for a zero-length step).
    pub fn constant(t0: f64, y: &[f64; N]) -> Self {
        let mut r = [[0.0; N]; 5];
        r[0] = *y;
        Self { t0, h: 1.0, r }
    }

    pub fn t1(&self) -> f64 {
        self.t0 + self.h
    }

    /// Component `i` at time `t`.
    #[inline]
    pub fn at(&self, t: f64, i: usize) -> f64 {
        let s = (t - self.t0) / self.h;
        let s1 = 1.0 - s;
        let r = &self.r;
        r[0][i] + s * (r[1][i] + s1 * (r[2][i] + s * (r[3][i] + s1 * r[4][i])))
    }

    /// The components `which` at time `t` into `out` (the others left as
    /// they are): [`Dense::at`]'s arithmetic, with the step fraction
    /// computed once for all of them.
    #[inline]
    pub fn at_into(&self, t: f64, which: &[usize], out: &mut [f64; N]) {
        let s = (t - self.t0) / self.h;
        let s1 = 1.0 - s;
        let r = &self.r;
        for &i in which {
            out[i] = r[0][i] + s * (r[1][i] + s1 * (r[2][i] + s * (r[3][i] + s1 * r[4][i])));
        }
    }

    pub fn all(&self, t: f64, out: &mut [f64; N]) {
        for (i, o) in out.iter_mut().enumerate() {
            *o = self.at(t, i);
        }
    }
}

#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SolverStats {
    pub accepted_steps: u64,
    pub rejected_steps: u64,
    pub rhs_evaluations: u64,
    pub restarts: u64,
    /// Accepted steps in which |h·λ| exceeded 3.25 (Hairer's test).
    pub stiff_steps: u64,
}

/// The smallest step the integrator takes, s. Absolute, not relative to t:
/// an event found a picosecond into a step needs a picosecond step at t = 400 s
/// as much as at t = 0.4 s, and a floor growing with t made long runs fail
/// with an underflow that short runs never see. It stays above half an ulp of
/// t for t < 1024 s, so every allowed step advances time (durations are at
/// most 600 s; see `SolverParams`).
pub const MIN_STEP_S: f64 = 1e-13;

/// Whether a step of `h_s` from `t_s` is one the integrator can take: at
/// least [`MIN_STEP_S`] and large enough to move t at all.
pub fn step_is_representable(t_s: f64, h_s: f64) -> bool {
    h_s >= MIN_STEP_S && t_s + h_s > t_s
}

#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SolverError {
    #[error("step size underflow at t = {t_s} s (h = {h_s} s)")]
    StepUnderflow { t_s: f64, h_s: f64 },
    #[error("non-finite state at t = {t_s} s")]
    NonFinite { t_s: f64 },
}

pub struct Checkpoint<const N: usize> {
    t: f64,
    y: [f64; N],
    k1: [f64; N],
    h: f64,
    fac_old: f64,
}

pub struct Dopri5<const N: usize> {
    pub t: f64,
    pub y: [f64; N],
    k1: [f64; N],
    pub h: f64,
    pub rtol: f64,
    pub atol: [f64; N],
    /// Only the first `n_err` states take part in error control (the rest are
    /// integrals kept for bookkeeping).
    pub n_err: usize,
    pub h_max: f64,
    fac_old: f64,
    pub stats: SolverStats,
}

impl<const N: usize> Dopri5<N> {
    pub fn new<S: OdeSystem<N>>(
        sys: &S,
        t0: f64,
        y0: [f64; N],
        rtol: f64,
        atol: [f64; N],
        n_err: usize,
        h_max: f64,
    ) -> Self {
        let mut s = Self {
            t: t0,
            y: y0,
            k1: [0.0; N],
            h: 0.0,
            rtol,
            atol,
            n_err: n_err.min(N),
            h_max,
            fac_old: 1e-4,
            stats: SolverStats::default(),
        };
        s.restart(sys, t0, y0);
        s
    }

    /// The integrator's state, to return to with [`Dopri5::rewind`].
    pub fn checkpoint(&self) -> Checkpoint<N> {
        Checkpoint {
            t: self.t,
            y: self.y,
            k1: self.k1,
            h: self.h,
            fac_old: self.fac_old,
        }
    }

    /// Undoes the steps taken since `c` (statistics are kept).
    pub fn rewind(&mut self, c: &Checkpoint<N>) {
        self.t = c.t;
        self.y = c.y;
        self.k1 = c.k1;
        self.h = c.h;
        self.fac_old = c.fac_old;
    }

    /// Continue from a new point (after an event or a state reset).
    pub fn restart<S: OdeSystem<N>>(&mut self, sys: &S, t: f64, y: [f64; N]) {
        self.t = t;
        self.y = y;
        sys.rhs(t, &self.y, &mut self.k1);
        self.stats.rhs_evaluations += 1;
        self.stats.restarts += 1;
        // Small first step: events usually sit on discontinuities of f.
        let first = 1e-7_f64.max(self.rtol.powf(0.2) * 1e-5);
        self.h = if self.h > 0.0 {
            self.h.min(self.h_max).max(first)
        } else {
            first
        };
        self.fac_old = 1e-4;
    }

    /// Takes one accepted step no further than `t_end`; returns its interpolant.
    pub fn step<S: OdeSystem<N>>(&mut self, sys: &S, t_end: f64) -> Result<Dense<N>, SolverError> {
        let mut k2 = [0.0; N];
        let mut k3 = [0.0; N];
        let mut k4 = [0.0; N];
        let mut k5 = [0.0; N];
        let mut k6 = [0.0; N];
        let mut k7 = [0.0; N];
        let mut ys = [0.0; N];
        let mut ysti = [0.0; N];
        let mut y1 = [0.0; N];
        let k1 = self.k1;
        let y = self.y;
        loop {
            let mut h = self.h.min(self.h_max);
            let last = self.t + h >= t_end;
            if last {
                h = t_end - self.t;
            }
            if !step_is_representable(self.t, h) {
                return Err(SolverError::StepUnderflow { t_s: self.t, h_s: h });
            }
            let t = self.t;
            for i in 0..N {
                ys[i] = y[i] + h * A21 * k1[i];
            }
            sys.rhs(t + C2 * h, &ys, &mut k2);
            for i in 0..N {
                ys[i] = y[i] + h * (A31 * k1[i] + A32 * k2[i]);
            }
            sys.rhs(t + C3 * h, &ys, &mut k3);
            for i in 0..N {
                ys[i] = y[i] + h * (A41 * k1[i] + A42 * k2[i] + A43 * k3[i]);
            }
            sys.rhs(t + C4 * h, &ys, &mut k4);
            for i in 0..N {
                ys[i] = y[i] + h * (A51 * k1[i] + A52 * k2[i] + A53 * k3[i] + A54 * k4[i]);
            }
            sys.rhs(t + C5 * h, &ys, &mut k5);
            for i in 0..N {
                ysti[i] = y[i] + h * (A61 * k1[i] + A62 * k2[i] + A63 * k3[i] + A64 * k4[i] + A65 * k5[i]);
            }
            sys.rhs(t + h, &ysti, &mut k6);
            for i in 0..N {
                y1[i] = y[i] + h * (A71 * k1[i] + A73 * k3[i] + A74 * k4[i] + A75 * k5[i] + A76 * k6[i]);
            }
            sys.rhs(t + h, &y1, &mut k7);
            self.stats.rhs_evaluations += 6;

            let mut err = 0.0;
            for i in 0..self.n_err {
                let e = h * (E1 * k1[i] + E3 * k3[i] + E4 * k4[i] + E5 * k5[i] + E6 * k6[i] + E7 * k7[i]);
                let sk = self.atol[i] + self.rtol * y[i].abs().max(y1[i].abs());
                err += (e / sk) * (e / sk);
            }
            let err = (err / self.n_err.max(1) as f64).sqrt();
            if !err.is_finite() {
                // A non-finite trial state: shrink hard and retry.
                self.stats.rejected_steps += 1;
                self.h = h * 0.1;
                continue;
            }
            // PI step-size control (Hairer's DOPRI5 defaults).
            let beta = 0.04;
            let fac11 = err.powf(0.2 - beta * 0.75);
            let mut fac = fac11 / self.fac_old.powf(beta);
            fac = (fac / 0.9).clamp(1.0 / 10.0, 5.0);
            let h_new = h / fac;
            if err <= 1.0 {
                self.fac_old = err.max(1e-4);
                self.stats.accepted_steps += 1;
                // Stiffness test on the last two stages.
                let (mut num, mut den) = (0.0, 0.0);
                for i in 0..self.n_err {
                    let a = (k7[i] - k6[i]) / (self.atol[i] + self.rtol * y1[i].abs());
                    let b = (y1[i] - ysti[i]) / (self.atol[i] + self.rtol * y1[i].abs());
                    num += a * a;
                    den += b * b;
                }
                if den > 0.0 && h * h * num > 3.25 * 3.25 * den {
                    self.stats.stiff_steps += 1;
                }
                let mut r = [[0.0; N]; 5];
                for i in 0..N {
                    let ydiff = y1[i] - y[i];
                    let bspl = h * k1[i] - ydiff;
                    r[0][i] = y[i];
                    r[1][i] = ydiff;
                    r[2][i] = bspl;
                    r[3][i] = ydiff - h * k7[i] - bspl;
                    r[4][i] = h * (D1 * k1[i] + D3 * k3[i] + D4 * k4[i] + D5 * k5[i] + D6 * k6[i] + D7 * k7[i]);
                }
                if y1.iter().any(|v| !v.is_finite()) {
                    return Err(SolverError::NonFinite { t_s: t + h });
                }
                self.t = if last { t_end } else { t + h };
                self.y = y1;
                self.k1 = k7;
                self.h = if last { self.h } else { h_new.min(self.h_max) };
                return Ok(Dense { t0: t, h, r });
            }
            self.stats.rejected_steps += 1;
            self.h = h / (fac11 / 0.9).min(10.0);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    struct Oscillator;
    impl OdeSystem<2> for Oscillator {
        fn rhs(&self, _t: f64, y: &[f64; 2], dy: &mut [f64; 2]) {
            dy[0] = y[1];
            dy[1] = -y[0];
        }
    }

    #[test]
    fn harmonic_oscillator_and_its_dense_output_are_accurate() {
        let sys = Oscillator;
        let mut s = Dopri5::new(&sys, 0.0, [1.0, 0.0], 1e-9, [1e-12; 2], 2, 1.0);
        let mut worst_dense: f64 = 0.0;
        while s.t < 10.0 {
            let d = s.step(&sys, 10.0).unwrap();
            for k in 1..10 {
                let t = d.t0 + d.h * k as f64 / 10.0;
                worst_dense = worst_dense.max((d.at(t, 0) - t.cos()).abs());
            }
        }
        assert!((s.y[0] - 10f64.cos()).abs() < 1e-7, "{}", s.y[0]);
        assert!(worst_dense < 1e-6, "dense output error {worst_dense}");
        assert!(s.stats.accepted_steps < 2000);
    }

    /// Late in a long run the solver must take the same tiny steps it takes
    /// early on (a floor relative to t refused a 2 ps step at t = 500 s).
    #[test]
    fn tiny_steps_late_in_a_long_run_do_not_underflow() {
        let sys = Oscillator;
        for t0 in [0.5, 500.0, 599.0] {
            let mut s = Dopri5::new(&sys, t0, [t0.cos(), -t0.sin()], 1e-9, [1e-12; 2], 2, 1e-3);
            let d = s.step(&sys, t0 + 2e-12).unwrap_or_else(|e| panic!("t0 = {t0}: {e}"));
            assert_eq!(s.t, t0 + 2e-12);
            assert!(d.h > 0.0);
            while s.t < t0 + 1.0 {
                s.step(&sys, t0 + 1.0).unwrap();
            }
            assert!((s.y[0] - (t0 + 1.0).cos()).abs() < 1e-6, "t0 = {t0}: {}", s.y[0]);
        }
        assert!(step_is_representable(599.0, 1e-12) && step_is_representable(0.0, 1e-12));
        // Below the floor, or too small to move t: refused, not looped on.
        assert!(!step_is_representable(0.0, 1e-14));
        assert!(!step_is_representable(1e6, 1e-12));
    }

    #[test]
    fn tighter_tolerance_converges() {
        let sys = Oscillator;
        let mut errs = vec![];
        for rtol in [1e-4, 1e-6, 1e-8] {
            let mut s = Dopri5::new(&sys, 0.0, [1.0, 0.0], rtol, [rtol * 1e-3; 2], 2, 1.0);
            while s.t < 20.0 {
                s.step(&sys, 20.0).unwrap();
            }
            errs.push((s.y[0] - 20f64.cos()).abs());
        }
        assert!(errs[1] < errs[0] && errs[2] < errs[1], "{errs:?}");
    }
}
