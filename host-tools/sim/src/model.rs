//! The lumped-parameter hammer: piston, two chambers, pilot valve, supply.
//!
//! Equations are in `docs/model.md`; this file is their one implementation.

use std::cell::Cell;
use std::f64::consts::PI;

use super::effects::Effects;
use super::gas::{annular_leak_mass_flow, circular_port_area_m2, orifice_mass_flow, GAMMA, P_ATM_PA, R_AIR};
use super::params::{ContactLaw, SimConfig};
use super::solver::OdeSystem;
use hammer_estimator::geometry::STANDARD_GRAVITY_MPS2;

// State layout. The first `N_DYN` states are dynamic and error-controlled;
// the rest are running integrals used for the energy and mass balances.
pub const X: usize = 0; // piston position, m
pub const V: usize = 1; // piston velocity, m/s (forward +)
pub const M1: usize = 2; // rear chamber air mass, kg
pub const P1: usize = 3; // rear chamber pressure, Pa abs
pub const M2: usize = 4; // front chamber air mass, kg
pub const P2: usize = 5; // front chamber pressure, Pa abs
pub const XV: usize = 6; // valve position, m (0 = feeds front, travel = feeds rear)
pub const VV: usize = 7; // valve velocity, m/s
pub const PS: usize = 8; // supply pressure at the valve inlet, Pa abs
pub const PF: usize = 9; // pilot force seen by the valve, N (lagged with valve_delay)
pub const W_PRESSURE: usize = 10; // ∫(p1·A1 − p2·A2)·v dt, J
pub const W_FRICTION: usize = 11; // ∫ −F_friction·v dt (dissipated), J
pub const W_CONTACT: usize = 12; // ∫ F_contact·v dt, J
pub const W_GRAVITY: usize = 13; // ∫ m·g·sinθ·v dt, J
pub const M_IN: usize = 14; // air drawn from the source, kg
pub const M_OUT: usize = 15; // air vented to atmosphere, kg
pub const Q_WALL: usize = 16; // ∫ heat from the walls into both chambers' air dt, J
pub const Q_EXCHANGED: usize = 17; // ∫ (|q_wall,rear| + |q_wall,front|) dt: heat across the walls either way, J
pub const M_LEAKED: usize = 18; // ∫ (|q_piston gap| + |q_rod guide|) dt: air through the leak paths, kg
pub const N: usize = 19;
pub const N_DYN: usize = 10;

/// Forces on the piston at one instant.
#[derive(Debug, Clone, Copy, Default)]
pub struct PistonForces {
    pub pressure_n: f64,
    pub friction_n: f64,
    pub contact_n: f64,
    pub gravity_n: f64,
}

impl PistonForces {
    pub fn total_n(&self) -> f64 {
        self.pressure_n + self.friction_n + self.contact_n + self.gravity_n
    }
}

/// Precomputed constants of one configuration.
pub struct HammerModel {
    pub mass_kg: f64,
    pub a1_m2: f64,
    pub a2_m2: f64,
    pub bore_m: f64,
    pub rod_m: f64,
    pub piston_length_m: f64,
    pub x_impact_m: f64,
    x_rear_out_m: f64,
    x_front_out_m: f64,
    d_out_m: f64,
    out_count: f64,
    cd_out: f64,
    v1_dead_m3: f64,
    v2_dead_m3: f64,
    gravity_n: f64,
    // valve
    valve_mass_kg: f64,
    pub valve_travel_m: f64,
    valve_opening_m: f64,
    valve_cd: f64,
    d_cp_m: f64,
    full_open_area_m2: f64,
    pilot_rear_m2: f64,
    pilot_front_m2: f64,
    valve_damping: f64,
    // contact
    contact_law: ContactLaw,
    k_contact: f64,
    c_contact: f64,
    hc_exponent: f64,
    restitution: f64,
    /// Impact velocity of the contact under way (Hunt–Crossley damping needs it).
    pub contact_v_in: Cell<f64>,
    // supply
    pub p_supply_abs: f64,
    t_supply_k: f64,
    t_amb_k: f64,
    // effects (resolved to numbers; zero means off)
    coulomb_n: f64,
    coulomb_vs: f64,
    coulomb: Option<super::effects::CoulombFriction>,
    viscous: f64,
    leak: Option<(f64, f64, f64)>, // gap, eccentricity, rod guide length
    valve_tau_s: f64,
    h_wall: f64,
    supply_orifice_m2: f64,
    supply_volume_m3: f64,
    drags: super::effects::PistonDrags,
    supply_bar: f64,
}

impl HammerModel {
    pub fn new(cfg: &SimConfig) -> Self {
        let h = &cfg.hammer;
        let g = h.geometry();
        let e: &Effects = &cfg.effects;
        let k = cfg.contact.stiffness_n_per_m;
        let ln_e = cfg.contact.restitution.ln();
        let zeta = -ln_e / (PI * PI + ln_e * ln_e).sqrt();
        let (supply_orifice_m2, supply_volume_m3) = match &e.supply_restriction {
            Some(s) => (PI * 0.25 * s.orifice_diameter_m.powi(2), s.line_volume_m3),
            None => (0.0, 0.0),
        };
        Self {
            mass_kg: h.piston_mass_kg,
            a1_m2: g.rear_area_m2(),
            a2_m2: g.front_area_m2(),
            bore_m: h.bore_diameter_m,
            rod_m: h.rod_diameter_m,
            piston_length_m: h.piston_length_m,
            x_impact_m: h.impact_position_m,
            x_rear_out_m: h.rear_outlet_opens_m,
            x_front_out_m: h.front_outlet_opens_m,
            d_out_m: h.outlet_diameter_m,
            out_count: h.outlet_count as f64,
            cd_out: h.outlet_cd,
            v1_dead_m3: h.rear_dead_volume_m3,
            v2_dead_m3: h.front_dead_volume_m3,
            gravity_n: h.piston_mass_kg * STANDARD_GRAVITY_MPS2 * h.inclination_deg.to_radians().sin(),
            valve_mass_kg: cfg.valve.mass_kg,
            valve_travel_m: cfg.valve.travel_m,
            valve_opening_m: cfg.valve.opening_m,
            valve_cd: cfg.valve.cd,
            d_cp_m: cfg.valve.control_port_diameter_m,
            full_open_area_m2: cfg.valve.full_open_area_m2,
            pilot_rear_m2: cfg.valve.pilot_area_rear_m2,
            pilot_front_m2: cfg.valve.pilot_area_front_m2,
            valve_damping: cfg.valve.damping_n_s_per_m,
            contact_law: cfg.contact.law,
            k_contact: k,
            c_contact: 2.0 * zeta * (k * h.piston_mass_kg).sqrt(),
            hc_exponent: cfg.contact.hunt_crossley_exponent,
            restitution: cfg.contact.restitution,
            contact_v_in: Cell::new(1.0),
            p_supply_abs: P_ATM_PA + cfg.supply.pressure_bar * 1e5,
            t_supply_k: cfg.supply.temperature_k,
            t_amb_k: cfg.supply.ambient_temperature_k,
            coulomb_n: e
                .coulomb_friction
                .as_ref()
                .map_or(0.0, |f| f.force_n(cfg.supply.pressure_bar)),
            coulomb_vs: e.coulomb_friction.as_ref().map_or(1e-3, |f| f.smoothing_mps),
            coulomb: e.coulomb_friction.clone(),
            viscous: e.viscous_friction.as_ref().map_or(0.0, |f| f.c_n_s_per_m),
            leak: e
                .leakage
                .as_ref()
                .map(|l| (l.gap_m, l.eccentricity, l.rod_guide_length_m)),
            valve_tau_s: e.valve_delay.as_ref().map_or(0.0, |d| d.tau_s),
            h_wall: e.heat_transfer.as_ref().map_or(0.0, |h| h.h_w_per_m2_k),
            supply_orifice_m2,
            supply_volume_m3,
            drags: e.piston_drags(),
            supply_bar: cfg.supply.pressure_bar,
        }
    }

    pub fn rear_volume_m3(&self, x: f64) -> f64 {
        (self.v1_dead_m3 + self.a1_m2 * x).max(0.05 * self.v1_dead_m3)
    }

    pub fn front_volume_m3(&self, x: f64) -> f64 {
        (self.v2_dead_m3 + self.a2_m2 * (self.x_impact_m - x)).max(0.05 * self.v2_dead_m3)
    }

    /// Initial state: piston at rest at `x0`, chambers at atmosphere, valve feeding the rear.
    pub fn initial_state(&self, x0: f64) -> [f64; N] {
        let mut y = [0.0; N];
        y[X] = x0;
        y[P1] = P_ATM_PA;
        y[P2] = P_ATM_PA;
        y[M1] = P_ATM_PA * self.rear_volume_m3(x0) / (R_AIR * self.t_amb_k);
        y[M2] = P_ATM_PA * self.front_volume_m3(x0) / (R_AIR * self.t_amb_k);
        y[XV] = self.valve_travel_m;
        y[PS] = self.p_supply_abs;
        y[PF] = 0.0;
        y
    }

    /// Air mass stored in the supply line (zero without `supply_restriction`).
    pub fn line_mass_kg(&self, y: &[f64; N]) -> f64 {
        y[PS] * self.supply_volume_m3 / (R_AIR * self.t_supply_k)
    }

    pub fn friction_n(&self, t: f64, v: f64) -> f64 {
        let mut f = 0.0;
        if let Some(c) = &self.coulomb {
            let fc = self.coulomb_n * c.factor_at(t);
            f -= fc * v / (v * v + self.coulomb_vs * self.coulomb_vs).sqrt();
        }
        f -= self.viscous * v;
        if !self.drags.is_empty() {
            f += self.drags.force_n(t, v, self.supply_bar);
        }
        f
    }

    fn contact_n(&self, x: f64, v: f64) -> f64 {
        let mut f = 0.0;
        let d = x - self.x_impact_m;
        if d > 0.0 {
            f -= match self.contact_law {
                ContactLaw::SpringDamper => (self.k_contact * d + self.c_contact * v).max(0.0),
                ContactLaw::HuntCrossley => {
                    let lam = 1.5 * (1.0 - self.restitution) / self.contact_v_in.get().abs().max(0.1);
                    (self.k_contact * d.powf(self.hc_exponent) * (1.0 + lam * v)).max(0.0)
                }
            };
        }
        // The rear cover: same spring-damper, only reached if the air cushion fails.
        if x < 0.0 {
            f += (self.k_contact * (-x) - self.c_contact * v).max(0.0);
        }
        f
    }

    pub fn piston_forces(&self, t: f64, y: &[f64; N]) -> PistonForces {
        PistonForces {
            pressure_n: (y[P1] - P_ATM_PA) * self.a1_m2 - (y[P2] - P_ATM_PA) * self.a2_m2,
            friction_n: self.friction_n(t, y[V]),
            contact_n: self.contact_n(y[X], y[V]),
            gravity_n: self.gravity_n,
        }
    }

    /// Effective area of a control port opened by `lift_m`: the poppet and the
    /// port bore as two orifices in series.
    fn control_area_m2(&self, lift_m: f64) -> f64 {
        let curtain = self.full_open_area_m2 * lift_m / self.valve_opening_m;
        if curtain <= 0.0 {
            return 0.0;
        }
        let bore = PI * 0.25 * self.d_cp_m * self.d_cp_m;
        curtain * bore / (curtain * curtain + bore * bore).sqrt()
    }

    fn pilot_force_n(&self, p1: f64, p2: f64) -> f64 {
        self.pilot_rear_m2 * (p1 - P_ATM_PA) - self.pilot_front_m2 * (p2 - P_ATM_PA)
    }

    /// Piston positions and valve positions at which f(t, y) has a kink, and
    /// the impact: the driver restarts the integrator on each.
    pub fn kink_positions(&self) -> [f64; 5] {
        [
            self.x_rear_out_m,
            self.x_rear_out_m + self.d_out_m,
            self.x_front_out_m,
            self.x_front_out_m - self.d_out_m,
            self.x_impact_m,
        ]
    }

    pub fn valve_kinks(&self) -> [f64; 2] {
        [self.valve_travel_m - self.valve_opening_m, self.valve_opening_m]
    }
}

/// Mass and enthalpy bookkeeping of one chamber during an evaluation.
#[derive(Default, Clone, Copy)]
struct Chamber {
    dm: f64,
    dh: f64, // Σ ṁ·T of the flows, signed (in +)
}

/// Moves `q` kg/s from `a` to `b` with the upstream temperature.
#[inline]
fn transfer(q: f64, t_a: f64, t_b: f64, a: &mut Chamber, b: &mut Chamber) {
    let t_up = if q >= 0.0 { t_a } else { t_b };
    a.dm -= q;
    a.dh -= q * t_up;
    b.dm += q;
    b.dh += q * t_up;
}

impl OdeSystem<N> for HammerModel {
    fn rhs(&self, t: f64, y: &[f64; N], dy: &mut [f64; N]) {
        let x = y[X];
        let v = y[V];
        let p1 = y[P1].max(1.0);
        let p2 = y[P2].max(1.0);
        let vol1 = self.rear_volume_m3(x);
        let vol2 = self.front_volume_m3(x);
        let t1 = p1 * vol1 / (y[M1].max(1e-12) * R_AIR);
        let t2 = p2 * vol2 / (y[M2].max(1e-12) * R_AIR);
        let restricted = self.supply_volume_m3 > 0.0;
        let ps = if restricted { y[PS] } else { self.p_supply_abs };
        let ts = self.t_supply_k;
        let ta = self.t_amb_k;

        let mut rear = Chamber::default();
        let mut front = Chamber::default();
        let mut line = Chamber::default();
        let mut atm = Chamber::default();

        // Valve control ports: poppet curtain in series with the port bore.
        let xv = y[XV];
        let open3 = (xv - (self.valve_travel_m - self.valve_opening_m)).clamp(0.0, self.valve_opening_m);
        let open4 = (self.valve_opening_m - xv).clamp(0.0, self.valve_opening_m);
        let a3 = self.control_area_m2(open3);
        let a4 = self.control_area_m2(open4);
        let q3 = orifice_mass_flow(self.valve_cd, a3, ps, ts, p1, t1);
        let q4 = orifice_mass_flow(self.valve_cd, a4, ps, ts, p2, t2);
        transfer(q3, ts, t1, &mut line, &mut rear);
        transfer(q4, ts, t2, &mut line, &mut front);

        // Piston-controlled outlets.
        let ao1 = self.out_count * circular_port_area_m2(self.d_out_m, x - self.x_rear_out_m);
        let ao2 = self.out_count * circular_port_area_m2(self.d_out_m, self.x_front_out_m - x);
        let qo1 = orifice_mass_flow(self.cd_out, ao1, p1, t1, P_ATM_PA, ta);
        let qo2 = orifice_mass_flow(self.cd_out, ao2, p2, t2, P_ATM_PA, ta);
        transfer(qo1, t1, ta, &mut rear, &mut atm);
        transfer(qo2, t2, ta, &mut front, &mut atm);

        let mut leaked = 0.0;
        if let Some((gap, ecc, guide)) = self.leak {
            let q12 = annular_leak_mass_flow(self.bore_m, gap, self.piston_length_m, ecc, p1, t1, p2, t2);
            let q2a = annular_leak_mass_flow(self.rod_m, gap, guide, ecc, p2, t2, P_ATM_PA, ta);
            transfer(q12, t1, t2, &mut rear, &mut front);
            transfer(q2a, t2, ta, &mut front, &mut atm);
            leaked = q12.abs() + q2a.abs();
        }

        let mut q1 = 0.0;
        let mut q2 = 0.0;
        if self.h_wall > 0.0 {
            let aw1 = 2.0 * self.a1_m2 + PI * self.bore_m * (vol1 / self.a1_m2);
            let aw2 = 2.0 * self.a2_m2 + PI * (self.bore_m + self.rod_m) * (vol2 / self.a2_m2);
            q1 = self.h_wall * aw1 * (ta - t1);
            q2 = self.h_wall * aw2 * (ta - t2);
        }

        // Source → line: through the restriction, or the line is the source.
        let q_src = if restricted {
            let a = self.supply_orifice_m2;
            orifice_mass_flow(0.62, a, self.p_supply_abs, ts, ps, ts)
        } else {
            -line.dm
        };

        // Chamber energy equations (open system, perfect gas).
        let dv1 = self.a1_m2 * v;
        let dv2 = -self.a2_m2 * v;
        dy[M1] = rear.dm;
        dy[P1] = GAMMA * R_AIR / vol1 * rear.dh - GAMMA * p1 / vol1 * dv1 + (GAMMA - 1.0) / vol1 * q1;
        dy[M2] = front.dm;
        dy[P2] = GAMMA * R_AIR / vol2 * front.dh - GAMMA * p2 / vol2 * dv2 + (GAMMA - 1.0) / vol2 * q2;
        // Supply line: isothermal hose.
        dy[PS] = if restricted {
            R_AIR * ts / self.supply_volume_m3 * (q_src + line.dm)
        } else {
            0.0
        };

        // Piston.
        let f = self.piston_forces(t, y);
        dy[X] = v;
        dy[V] = f.total_n() / self.mass_kg;

        // Valve: pilot force (optionally lagged), damping, inelastic end stops.
        let pilot_now = self.pilot_force_n(p1, p2);
        let pilot = if self.valve_tau_s > 0.0 {
            dy[PF] = (pilot_now - y[PF]) / self.valve_tau_s;
            y[PF]
        } else {
            dy[PF] = 0.0;
            pilot_now
        };
        let vv = y[VV];
        let fv = pilot - self.valve_damping * vv;
        let at_right = xv >= self.valve_travel_m && vv >= 0.0 && fv >= 0.0;
        let at_left = xv <= 0.0 && vv <= 0.0 && fv <= 0.0;
        if at_right || at_left {
            dy[XV] = 0.0;
            dy[VV] = 0.0;
        } else {
            dy[XV] = vv;
            dy[VV] = fv / self.valve_mass_kg;
        }

        dy[W_PRESSURE] = f.pressure_n * v;
        dy[W_FRICTION] = -f.friction_n * v;
        dy[W_CONTACT] = f.contact_n * v;
        dy[W_GRAVITY] = f.gravity_n * v;
        dy[M_IN] = q_src;
        dy[M_OUT] = atm.dm;
        dy[Q_WALL] = q1 + q2;
        dy[Q_EXCHANGED] = q1.abs() + q2.abs();
        dy[M_LEAKED] = leaked;
    }
}
