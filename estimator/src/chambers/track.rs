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

/// Fills `x[open..=close]` with the track between two impacts:
/// `x[open] = x[close] = impact_m`. Other samples are left as they are.
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
    let len = p_rear_pa.len().min(p_front_pa.len()).min(x.len());
    if !(open < close && close < len && dt_s > 0.0 && piston.mass_kg > 0.0) {
        return;
    }
    let accel = |i: usize| {
        (piston.rear_area_m2 * p_rear_pa[i] - piston.front_area_m2 * p_front_pa[i] + piston.gravity_n) / piston.mass_kg
    };
    let f_bh = if friction.backhaul_n.is_finite() {
        friction.backhaul_n
    } else {
        0.0
    };
    let f_st = if friction.stroke_n.is_finite() {
        friction.stroke_n
    } else {
        0.0
    };
    // Twice: the turning point that splits the friction's sign depends on
    // the start velocity, which depends on the friction.
    let fric_at = |i: usize, turn: usize| if i < turn { f_bh } else { -f_st } / piston.mass_kg;
    let mut turn = close;
    let mut v0 = 0.0f32;
    for _ in 0..2 {
        let split = turn;
        let fric = |i: usize| fric_at(i, split);
        // u: velocity gained from rest; its integral over the cycle.
        let (mut u, mut du_prev, mut area) = (0.0f32, accel(open) + fric(open), 0.0f32);
        for i in open + 1..=close {
            let du = accel(i) + fric(i);
            let u_next = u + 0.5 * dt_s * (du_prev + du);
            area += 0.5 * dt_s * (u + u_next);
            u = u_next;
            du_prev = du;
        }
        v0 = -area / ((close - open) as f32 * dt_s);
        // The turn: where the velocity first goes from backwards to forwards.
        let (mut u, mut du_prev) = (0.0f32, accel(open) + fric(open));
        turn = close;
        for i in open + 1..=close {
            let du = accel(i) + fric(i);
            u += 0.5 * dt_s * (du_prev + du);
            du_prev = du;
            if v0 + u > 0.0 {
                turn = i;
                break;
            }
        }
    }
    let fric = |i: usize| fric_at(i, turn);
    let (mut v, mut du_prev) = (v0, accel(open) + fric(open));
    x[open] = impact_m;
    for i in open + 1..=close {
        let du = accel(i) + fric(i);
        let v_next = v + 0.5 * dt_s * (du_prev + du);
        x[i] = x[i - 1] + 0.5 * dt_s * (v + v_next);
        v = v_next;
        du_prev = du;
    }
    // The closure puts x[close] at the impact to rounding; set it exactly.
    x[close] = impact_m;
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
