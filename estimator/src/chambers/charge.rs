//! The air each chamber draws per cycle, from its pressure and volume over
//! its feed, as R·T_s·m (J; over p_atm, free air at the supply's temperature).
//!
//! A chamber's feed runs from its onset to the valve's switch to the other
//! chamber (that chamber's onset). While the chamber is closed to its outlet
//! the energy equation of `fill` counts what came in,
//! γ·R·T_s·Δm = Δ(p·V) + (γ − 1)·∫p dV: the air's heating by the fill is in
//! it, no temperature is measured. Once the piston uncovers the chamber's
//! outlet while the feed is still open, air blows through to atmosphere;
//! that part is the orifice law with the feed's own area (`fill`) and the
//! measured pressure, R·T_s·ṁ = A·p_s·Ψ(p/p_s)·√(R·T_s). Heat exchange with
//! the walls, leakage and an area that changes through the feed make it an
//! estimate (`docs/bench-sheet.md` says so where it is shown).
//!
//! The front chamber's feed runs across the impact into the next backhaul;
//! that part is read in the cycle's own backhaul (the feed that began in the
//! cycle before): in a steady run the two are the same.

use super::fill::{psi, sqrt_rt_supply, GAMMA};
use super::{each, interpolate, ChamberGeometry, Characteristics, Series, Window, P_ATM_PA};

/// The air each chamber drew in one cycle, as R·T_s·m, J.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Charge {
    pub rear_j: f32,
    pub front_j: f32,
}

impl Charge {
    /// Both chambers' air as free air (at atmosphere and the supply's
    /// temperature), m³.
    pub fn free_air_m3(&self) -> f32 {
        (self.rear_j + self.front_j) / P_ATM_PA
    }
}

/// One chamber's pressure (gauge) and volume law over the window.
struct Chamber<'a, P: Series + ?Sized> {
    p: &'a P,
    x: &'a [f32],
    volume: &'a dyn Fn(f32) -> f32,
}

impl<P: Series + ?Sized> Chamber<'_, P> {
    fn pv(&self, k: f32) -> f32 {
        (interpolate(self.p, 0, k) + P_ATM_PA) * (self.volume)(interpolate(self.x, 0, k))
    }

    /// ∫ p_abs dV over the samples from `a` to `b`.
    fn p_dv(&self, a: f32, b: f32) -> f32 {
        let (a, b) = (
            a.max(0.0) as usize,
            (b.max(0.0) as usize).min(self.p.len().saturating_sub(1)),
        );
        // Each sample's pressure and volume read once, carried to the next
        // step (a board reads the pressure from its codes).
        if a >= b {
            return 0.0;
        }
        let (mut p0, mut v0) = (f32::NAN, (self.volume)(self.x[a]));
        let mut sum = 0.0f32;
        each(self.p, a, b + 1, |i, p1| {
            if i > a {
                let v1 = (self.volume)(self.x[i]);
                let pm = 0.5 * (p0 + p1) + P_ATM_PA;
                sum += pm * (v1 - v0);
                v0 = v1;
            }
            p0 = p1;
        });
        sum
    }

    /// What blows through the feed of area `area_m2` from `a` to `b`.
    fn through(&self, a: f32, b: f32, area_m2: f32, supply_abs_pa: f32, dt: f32) -> f32 {
        let (a, b) = (a.max(0.0) as usize, (b.max(0.0) as usize).min(self.p.len()));
        let mut flow = 0.0f32;
        each(self.p, a, b, |_, p| flow += psi((p + P_ATM_PA) / supply_abs_pa) * dt);
        if b > a {
            area_m2 * supply_abs_pa * sqrt_rt_supply() * flow
        } else {
            0.0
        }
    }
}

/// The charge of the cycle in `w` whose feeds `c` found.
pub(super) fn charge<P: Series + ?Sized>(
    w: &Window<P>,
    geo: &ChamberGeometry,
    c: &Characteristics,
    supply_abs_pa: f32,
) -> Option<Charge> {
    let (rear, front) = (c.rear?, c.front?);
    let n = w.p_rear_pa.len().min(w.p_front_pa.len()).min(w.x_m.len());
    let dt = w.dt_s;
    let (open, close) = (w.open as f32, w.close as f32);
    let on_rear = open + rear.onset_s / dt;
    let on_front = close + front.onset_s / dt;
    if !(on_rear >= 0.0 && on_rear < on_front && on_front < n as f32 && supply_abs_pa > P_ATM_PA) {
        return None;
    }
    // The first sample from `from` at which the piston has uncovered an outlet.
    let uncovered = |from: f32, to: f32, open: &dyn Fn(f32) -> bool| {
        (from as usize..(to as usize).min(n))
            .find(|&i| open(w.x_m[i]))
            .map_or(to, |i| i as f32)
    };
    let vol = geo.volumes();
    let rear_volume = |x: f32| vol.rear_m3(x);
    let front_volume = |x: f32| vol.front_m3(x);
    let rc = Chamber {
        p: w.p_rear_pa,
        x: w.x_m,
        volume: &rear_volume,
    };
    let fc = Chamber {
        p: w.p_front_pa,
        x: w.x_m,
        volume: &front_volume,
    };
    let filled = |dpv: f32, p_dv: f32| (dpv + (GAMMA - 1.0) * p_dv) / GAMMA;
    // Rear: onset to the switch, its outlet uncovered in the stroke on the way.
    let rear_edge = geo.rear_outlet_m as f32;
    let rear_closed = uncovered(on_rear + 1.0, on_front, &|x| x >= rear_edge);
    let rear_j = filled(rc.pv(rear_closed) - rc.pv(on_rear), rc.p_dv(on_rear, rear_closed))
        + rc.through(rear_closed, on_front, rear.feed_area_m2, supply_abs_pa, dt);
    // Front: onset to the impact, then (the cycle's own backhaul standing
    // for the next one's) from the impact to the switch to the rear.
    let (before_impact, after) = if on_front < close {
        (fc.p_dv(on_front, close), open)
    } else {
        (0.0, open + (on_front - close))
    };
    let front_edge = geo.front_outlet_m as f32;
    let front_closed = uncovered(after, on_rear, &|x| x < front_edge);
    let front_j = filled(
        fc.pv(front_closed) - fc.pv(on_front),
        before_impact + fc.p_dv(after, front_closed),
    ) + fc.through(front_closed, on_rear, front.feed_area_m2, supply_abs_pa, dt);
    (rear_j.is_finite() && front_j.is_finite()).then_some(Charge { rear_j, front_j })
}
