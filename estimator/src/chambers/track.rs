//! The piston's position over a cycle, from the force balance alone.
//!
//! No position sensor is assumed. The velocity is the integral of the
//! pressure force (less the cycle's friction per phase) over the mass; its
//! unknown start, the rebound the impact leaves, is fixed by the cycle's
//! closure: the piston meets the tool at both impacts, so the displacement
//! over the cycle is zero. The samples after a cycle's closing impact are
//! the next cycle's: its own track, closed at its own impacts.

/// The piston's mass and areas (from [`crate::Config`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Piston {
    pub mass_kg: f32,
    pub rear_area_m2: f32,
    pub front_area_m2: f32,
    /// Gravity's component along the stroke.
    pub gravity_n: f32,
}

impl Piston {
    pub fn of(c: &crate::Config) -> Self {
        Self {
            mass_kg: c.mass_kg(),
            rear_area_m2: c.rear_area_m2(),
            front_area_m2: c.front_area_m2(),
            gravity_n: c.gravity_n(),
        }
    }
}

/// One cycle's friction per phase (NaN reads as none).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PhaseFriction {
    pub backhaul_n: f32,
    pub stroke_n: f32,
}

/// Fills `x[open..=close]` with the track between two impacts from the
/// piston's acceleration `accel(i, turn)` (`turn`: the turning point's
/// index, which splits friction's sign): `x[open] = x[close] = impact_m`,
/// the start velocity set by the closure. Other samples are left as they are.
#[inline(always)]
///
/// Each of the three passes asks for `open`, then every later sample in
/// order, so a source may carry state from one sample to the next and
/// start over when asked for `open` again (`at_close`'s reading without a
/// room for the source).
pub fn closed(
    dt_s: f32,
    impact_m: f32,
    open: usize,
    close: usize,
    x: &mut [f32],
    mut accel: impl FnMut(usize, usize) -> f32,
) {
    if !(open < close && close < x.len() && dt_s > 0.0) {
        return;
    }
    // Twice: the turning point that splits the friction's sign depends on
    // the start velocity, which depends on the friction.
    let mut turn = close;
    let mut v0 = 0.0f32;
    for _ in 0..2 {
        let split = turn;
        // u: velocity gained from rest, kept in `x` (overwritten below) so
        // that the turn is found without evaluating `accel` again; its
        // integral over the cycle.
        let (mut u, mut du_prev, mut area) = (0.0f32, accel(open, split), 0.0f32);
        x[open] = 0.0;
        for i in open + 1..=close {
            let du = accel(i, split);
            let u_next = u + 0.5 * dt_s * (du_prev + du);
            area += 0.5 * dt_s * (u + u_next);
            u = u_next;
            x[i] = u;
            du_prev = du;
        }
        v0 = -area / ((close - open) as f32 * dt_s);
        // The turn: where the velocity first goes from backwards to forwards.
        turn = (open + 1..=close).find(|&i| v0 + x[i] > 0.0).unwrap_or(close);
    }
    let (mut v, mut du_prev) = (v0, accel(open, turn));
    x[open] = impact_m;
    for i in open + 1..=close {
        let du = accel(i, turn);
        let v_next = v + 0.5 * dt_s * (du_prev + du);
        x[i] = x[i - 1] + 0.5 * dt_s * (v + v_next);
        v = v_next;
        du_prev = du;
    }
    // The closure puts x[close] at the impact to rounding; set it exactly.
    x[close] = impact_m;
}

/// The pressure force on the piston at sample `i` (and gravity's share),
/// N: the force balance's sum before friction and the mass, which a
/// reading may keep a sample at a time ([`WithFriction`]).
#[inline]
pub fn pressure_force<P: super::Series + ?Sized>(p_rear_pa: &P, p_front_pa: &P, piston: &Piston, i: usize) -> f32 {
    piston.rear_area_m2 * p_rear_pa.at(i) - piston.front_area_m2 * p_front_pa.at(i) + piston.gravity_n
}

/// The force balance's acceleration from a kept [`pressure_force`]:
/// friction per phase (NaN read as none: backhaul before the turn, stroke
/// after), over the mass. A struct, not a closure, so that a reading's
/// track passes inline it.
#[derive(Debug, Clone, Copy)]
pub struct WithFriction {
    backhaul_n: f32,
    stroke_n: f32,
    mass_kg: f32,
}

impl WithFriction {
    pub fn new(piston: &Piston, friction: PhaseFriction) -> Self {
        let f = |v: f32| if v.is_finite() { v } else { 0.0 };
        Self {
            backhaul_n: f(friction.backhaul_n),
            stroke_n: f(friction.stroke_n),
            mass_kg: piston.mass_kg,
        }
    }

    #[inline(always)]
    pub fn acceleration(&self, force_n: f32, i: usize, turn: usize) -> f32 {
        (force_n + if i < turn { self.backhaul_n } else { -self.stroke_n }) / self.mass_kg
    }
}

/// The force balance's acceleration: the pressure force less the cycle's
/// friction per phase (backhaul before the turn, stroke after), over the mass.
pub fn force_balance<'a, P: super::Series + ?Sized>(
    p_rear_pa: &'a P,
    p_front_pa: &'a P,
    piston: &'a Piston,
    friction: PhaseFriction,
) -> impl Fn(usize, usize) -> f32 + 'a {
    let acc = WithFriction::new(piston, friction);
    move |i, turn| acc.acceleration(pressure_force(p_rear_pa, p_front_pa, piston, i), i, turn)
}

/// The track of [`force_balance`] (what the estimator's velocity integral assumes).
#[allow(clippy::too_many_arguments)]
pub fn position(
    p_rear_pa: &[f32],
    p_front_pa: &[f32],
    dt_s: f32,
    piston: &Piston,
    friction: PhaseFriction,
    impact_m: f32,
    open: usize,
    close: usize,
    x: &mut [f32],
) {
    let n = p_rear_pa.len().min(p_front_pa.len());
    if close < n && piston.mass_kg > 0.0 {
        closed(
            dt_s,
            impact_m,
            open,
            close,
            x,
            force_balance(p_rear_pa, p_front_pa, piston, friction),
        );
    }
}

/// The accelerometer's acceleration less the zero shift the estimator
/// fitted (`zero_shift_mps2`, decaying from the impact at `open` with
/// `tau_s`), written sample after sample from `from`: `out[k]` is sample
/// `from + k`'s. The decay is carried from one sample to the next (one
/// multiplication a sample; a power of the distance from the impact cost a
/// tenth of a board's reading). It sees friction of any form, which the
/// force balance's two constants only approximate; where the accelerometer
/// still rings from the shock the caller puts the force balance's instead.
pub fn accelerometer<A: super::Series + ?Sized>(
    accel_mps2: &A,
    zero_shift_mps2: f32,
    tau_s: f32,
    dt_s: f32,
    open: usize,
    from: usize,
    out: &mut [f32],
) {
    let mut decay = Decay::new(zero_shift_mps2, tau_s, dt_s);
    decay.start(open, from);
    accel_mps2.read_into(from, out);
    for v in out.iter_mut() {
        *v -= decay.step();
    }
}

/// The fitted zero shift as it decays from its impact, sample after
/// sample: one multiplication a sample, the same chain of roundings
/// wherever it is carried ([`accelerometer`], or a reading that computes
/// the source as it goes).
#[derive(Debug, Clone, Copy)]
pub struct Decay {
    q: f32,
    zs: f32,
    shift: f32,
}

impl Decay {
    pub fn new(zero_shift_mps2: f32, tau_s: f32, dt_s: f32) -> Self {
        let finite = zero_shift_mps2.is_finite();
        Self {
            q: if tau_s > 0.0 && finite {
                crate::math::exp(-dt_s / tau_s)
            } else {
                0.0
            },
            zs: if finite { zero_shift_mps2 } else { 0.0 },
            shift: 0.0,
        }
    }

    /// Starts at sample `from` of a cycle opened at `open`.
    #[inline]
    pub fn start(&mut self, open: usize, from: usize) {
        self.shift = self.zs * crate::math::powi(self.q, from.saturating_sub(open) as u32);
    }

    /// The shift at the current sample; moves on to the next.
    #[inline(always)]
    pub fn step(&mut self) -> f32 {
        let s = self.shift;
        self.shift *= self.q;
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A force of +1000 N then −1000 N on 1 kg, 10 ms each: the closure
    /// needs a start of −5 m/s (∫v = 0.02·v0 + 0.1 = 0), so the piston turns
    /// at 5 ms, 12.5 mm behind the impact, and is back there at 20 ms.
    #[test]
    fn a_symmetric_cycle_closes_and_turns_where_the_closure_says() {
        let piston = Piston {
            mass_kg: 1.0,
            rear_area_m2: 1e-3,
            front_area_m2: 1e-3,
            gravity_n: 0.0,
        };
        let dt = 1e-5f32;
        let p1: heapless::Vec<f32, 2101> = (0..2101).map(|i| if i < 1000 { 1e6 } else { -1e6 }).collect();
        let p2 = [0.0f32; 2101];
        let mut x = [0.0f32; 2101];
        let f = PhaseFriction {
            backhaul_n: 0.0,
            stroke_n: 0.0,
        };
        position(&p1, &p2, dt, &piston, f, 0.05, 0, 2000, &mut x);
        assert_eq!(x[2000], 0.05);
        let (i_min, x_min) = x[..2001]
            .iter()
            .enumerate()
            .fold((0, f32::MAX), |m, (i, &v)| if v < m.1 { (i, v) } else { m });
        assert!((i_min as i32 - 500).abs() <= 1, "turn at sample {i_min}");
        assert!((x_min - 0.0375).abs() < 1e-4, "turn at {x_min} m");
        assert_eq!(x[2100], 0.0, "beyond the closing impact nothing is written");
    }
}
