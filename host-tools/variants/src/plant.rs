//! The variant hammer's state and its time derivative. One function,
//! [`Plant::deriv`], holds every law; the structure picks among them.

use std::f64::consts::PI;

use hammer_sim::effects::Effects;

use crate::flow::{
    annular_gap, circular_segment_fraction, iso6358_at, smooth_ramp_fraction, Temp, CP, GAMMA, P_ATM, R,
};
use crate::structure::{AnvilLaw, ChamberLaw, PortLaw, Structure, SupplyLaw, VariantParams};

pub const X: usize = 0;
pub const V: usize = 1;
pub const M1: usize = 2;
pub const P1: usize = 3;
pub const M2: usize = 4;
pub const P2: usize = 5;
/// Spool position, 0 feeds the front chamber, 1 the rear.
pub const S: usize = 6;
/// The spool's command after the valve-delay lag.
pub const C: usize = 7;
/// Pressure of the node behind a supply restriction, Pa abs.
pub const PR: usize = 8;
/// Pressure at the valve inlet behind a hose, Pa abs.
pub const PIN: usize = 9;
/// Mass flow in the hose, kg/s.
pub const W: usize = 10;
pub const XT: usize = 11;
pub const VT: usize = 12;
/// Work dissipated by friction, J.
pub const WF: usize = 13;
/// Work of the pressure forces and of the contacts on the piston, J.
pub const WP: usize = 14;
pub const WC: usize = 15;
/// Heat the walls gave both chambers' air, J.
pub const QW: usize = 16;
/// Heat that crossed the walls either way (|rear| + |front|), J.
pub const QX: usize = 17;
/// Air through the leak paths, past the piston either way and out past
/// the rod, kg.
pub const ML: usize = 18;
pub const N: usize = 19;

/// Collar stiffness that holds the tool against the feed force.
const COLLAR_N_PER_M: f64 = 1e8;
/// Velocity over which the friction sign is smoothed (tanh).
const FRICTION_SMOOTHING_MPS: f64 = 4e-3;

/// What the derivative also reports, for truth and sensors.
#[derive(Debug, Clone, Copy, Default)]
pub struct Outputs {
    pub accel_mps2: f64,
    pub friction_n: f64,
    pub contact_n: f64,
}

pub struct Plant {
    pub p: VariantParams,
    pub s: Structure,
    pub e: Effects,
    pub supply_abs: f64,
    pub supply_bar: f64,
    a1: f64,
    a2: f64,
    contact_c: f64,
    restriction_c: f64,
    drags: hammer_sim::effects::PistonDrags,
    /// The run's constants [`Plant::deriv`] would otherwise work out at
    /// every evaluation (four per 1 µs step), each the same expression of
    /// the same values, so the same bits: the supply and ambient
    /// temperatures with their flow factor, the hose's and lines'
    /// coefficients, the tool's collar and workpiece damping.
    ts: Temp,
    ta: Temp,
    consts: Consts,
}

#[derive(Debug, Clone, Copy)]
struct Consts {
    /// R·T of the supply air.
    r_ts: f64,
    /// The line volume's R·T/V behind a supply restriction.
    line_gain: f64,
    hose_area: f64,
    /// 0.03·L/D of the hose's loss, A/L of its flow, R·T/V of the inlet volume.
    hose_loss: f64,
    hose_gain: f64,
    inlet_gain: f64,
    c_collar: f64,
    c_workpiece: f64,
}

impl Plant {
    pub fn new(p: VariantParams, s: Structure, e: Effects, supply_bar: f64) -> Self {
        let a1 = PI * 0.25 * p.bore_m * p.bore_m;
        let a2 = a1 - PI * 0.25 * p.rod_m * p.rod_m;
        let mass = match s.anvil {
            AnvilLaw::Fixed => p.piston_mass_kg,
            AnvilLaw::MovingTool => p.piston_mass_kg * p.tool_mass_kg / (p.piston_mass_kg + p.tool_mass_kg),
        };
        let contact_c = 2.0 * p.contact_damping_ratio * (p.contact_stiffness_n_per_m * mass).sqrt();
        // A sharp-edged orifice: Cd 0.62, and C from the effective area (ISO 6358 ↔ nozzle at b = 0.5).
        let restriction_c = e
            .supply_restriction
            .as_ref()
            .map_or(0.0, |r| 1.99e-3 * 0.62 * PI * 0.25 * r.orifice_diameter_m.powi(2));
        let ts = p.supply_temperature_k;
        let hose_area = PI * 0.25 * p.hose_diameter_m.powi(2);
        let kw = p.workpiece_stiffness_n_per_m;
        let consts = Consts {
            r_ts: R * ts,
            line_gain: e.supply_restriction.as_ref().map_or(0.0, |r| R * ts / r.line_volume_m3),
            hose_area,
            hose_loss: 0.03 * p.hose_length_m / p.hose_diameter_m,
            hose_gain: hose_area / p.hose_length_m,
            inlet_gain: R * ts / p.inlet_volume_m3,
            c_collar: 2.0 * 0.7 * (COLLAR_N_PER_M * p.tool_mass_kg).sqrt(),
            c_workpiece: 2.0 * 0.5 * (kw * p.tool_mass_kg).sqrt(),
        };
        Self {
            supply_abs: P_ATM + supply_bar * 1e5,
            supply_bar,
            a1,
            a2,
            contact_c,
            restriction_c,
            drags: e.piston_drags(),
            ts: Temp::fixed(ts),
            ta: Temp::fixed(p.ambient_temperature_k),
            consts,
            p,
            s,
            e,
        }
    }

    pub fn a1(&self) -> f64 {
        self.a1
    }

    pub fn a2(&self) -> f64 {
        self.a2
    }

    fn vol1(&self, x: f64) -> f64 {
        (self.p.rear_dead_m3 + self.a1 * x).max(0.1 * self.p.rear_dead_m3)
    }

    fn vol2(&self, x: f64) -> f64 {
        (self.p.front_dead_m3 + self.a2 * (self.p.x_impact_m - x)).max(0.1 * self.p.front_dead_m3)
    }

    /// Both chambers' air temperatures in state `y`, K (p·V = m·R·T).
    pub fn temperatures_k(&self, y: &[f64; N]) -> (f64, f64) {
        (
            y[P1] * self.vol1(y[X]) / (y[M1] * R),
            y[P2] * self.vol2(y[X]) / (y[M2] * R),
        )
    }

    fn line_volume(&self) -> Option<f64> {
        self.e.supply_restriction.as_ref().map(|r| r.line_volume_m3)
    }

    /// At rest at the start position, chambers at atmosphere, lines charged.
    pub fn initial(&self) -> [f64; N] {
        let mut y = [0.0; N];
        let p = &self.p;
        let t = p.ambient_temperature_k;
        y[X] = p.x_start_m;
        y[P1] = P_ATM;
        y[P2] = P_ATM;
        y[M1] = P_ATM * self.vol1(p.x_start_m) / (R * t);
        y[M2] = P_ATM * self.vol2(p.x_start_m) / (R * t);
        y[S] = 1.0;
        y[C] = 1.0;
        y[PR] = self.supply_abs;
        y[PIN] = self.supply_abs;
        y[XT] = p.x_impact_m - p.feed_force_n / COLLAR_N_PER_M;
        y
    }

    /// Friction on the piston (negative opposes forward motion).
    pub fn friction_n(&self, t: f64, v: f64) -> f64 {
        let mut f = 0.0;
        if let Some(c) = &self.e.coulomb_friction {
            let mut mag = c.f0_n + c.k_n_per_bar * self.supply_bar;
            mag *= 1.0 + c.growth_per_s * t;
            if c.step_at_s > 0.0 && t >= c.step_at_s {
                mag *= c.step_factor;
            }
            f -= mag * (v / FRICTION_SMOOTHING_MPS).tanh();
        }
        if let Some(vf) = &self.e.viscous_friction {
            f -= vf.c_n_s_per_m * v;
        }
        if !self.drags.is_empty() {
            f += self.drags.force_n(t, v, self.supply_bar);
        }
        f
    }

    /// Pressure at the valve inlet.
    fn inlet(&self, y: &[f64; N]) -> f64 {
        match (self.s.supply, self.line_volume().is_some()) {
            (SupplyLaw::Hose, _) => y[PIN],
            (SupplyLaw::Stiff, true) => y[PR],
            (SupplyLaw::Stiff, false) => self.supply_abs,
        }
    }

    pub fn deriv(&self, t: f64, y: &[f64; N], target: f64, dy: &mut [f64; N]) -> Outputs {
        *dy = [0.0; N];
        let p = &self.p;
        let (x, v) = (y[X], y[V]);
        let (ts, ta) = (p.supply_temperature_k, p.ambient_temperature_k);
        let p1 = y[P1].max(100.0);
        let p2 = y[P2].max(100.0);
        let (v1, v2) = (self.vol1(x), self.vol2(x));
        let t1 = p1 * v1 / (y[M1].max(1e-12) * R);
        let t2 = p2 * v2 / (y[M2].max(1e-12) * R);
        let p_in = self.inlet(y);

        // Valve: zero-lapped, each supply path opens over half the spool travel.
        let s = y[S].clamp(0.0, 1.0);
        let open_rear = (2.0 * s - 1.0).clamp(0.0, 1.0);
        let open_front = (1.0 - 2.0 * s).clamp(0.0, 1.0);
        let q3 = iso6358_at(
            p.valve_conductance * open_rear,
            p.valve_critical_ratio,
            p_in,
            self.ts,
            p1,
            Temp::at(t1),
        );
        let q4 = iso6358_at(
            p.valve_conductance * open_front,
            p.valve_critical_ratio,
            p_in,
            self.ts,
            p2,
            Temp::at(t2),
        );

        // Outlets uncovered by the piston.
        let frac = |u: f64| match self.s.ports {
            PortLaw::CircularSegment => circular_segment_fraction(p.port_diameter_m, u),
            PortLaw::SmoothRamp => smooth_ramp_fraction(p.port_ramp_m, u),
        };
        let qo1 = iso6358_at(
            p.port_conductance * frac(x - p.rear_port_m),
            p.port_critical_ratio,
            p1,
            Temp::at(t1),
            P_ATM,
            self.ta,
        );
        let qo2 = iso6358_at(
            p.port_conductance * frac(p.front_port_m - x),
            p.port_critical_ratio,
            p2,
            Temp::at(t2),
            P_ATM,
            self.ta,
        );

        let (mut q12, mut q2a) = (0.0, 0.0);
        if let Some(l) = &self.e.leakage {
            q12 = annular_gap(p.bore_m, l.gap_m, p.piston_length_m, l.eccentricity, p1, t1, p2, t2);
            q2a = annular_gap(
                p.rod_m,
                l.gap_m,
                l.rod_guide_length_m,
                l.eccentricity,
                p2,
                t2,
                P_ATM,
                ta,
            );
        }

        // Mass and enthalpy into each chamber (upstream temperatures).
        let up = |q: f64, t_from: f64, t_to: f64| if q >= 0.0 { t_from } else { t_to };
        let dm1 = q3 - qo1 - q12;
        let dm2 = q4 - qo2 + q12 - q2a;
        let dh1 = CP * (q3 * up(q3, ts, t1) - qo1 * t1 - q12 * up(q12, t1, t2));
        let dh2 = CP * (q4 * up(q4, ts, t2) - qo2 * t2 + q12 * up(q12, t1, t2) - q2a * t2);
        let (mut qw1, mut qw2) = (0.0, 0.0);
        if let Some(h) = &self.e.heat_transfer {
            let wall = |vol: f64, a: f64, perimeter: f64| 2.0 * a + perimeter * vol / a;
            qw1 = h.h_w_per_m2_k * wall(v1, self.a1, PI * p.bore_m) * (ta - t1);
            qw2 = h.h_w_per_m2_k * wall(v2, self.a2, PI * (p.bore_m + p.rod_m)) * (ta - t2);
        }
        dy[QW] = qw1 + qw2;
        dy[QX] = qw1.abs() + qw2.abs();
        dy[ML] = q12.abs() + q2a.abs();
        let (dv1, dv2) = (self.a1 * v, -self.a2 * v);
        dy[M1] = dm1;
        dy[M2] = dm2;
        match self.s.chambers {
            ChamberLaw::Adiabatic => {
                dy[P1] = (GAMMA - 1.0) / v1 * (dh1 + qw1) - GAMMA * p1 / v1 * dv1;
                dy[P2] = (GAMMA - 1.0) / v2 * (dh2 + qw2) - GAMMA * p2 / v2 * dv2;
            }
            ChamberLaw::Polytropic => {
                let n = p.polytropic_n;
                dy[P1] = n * p1 * (dm1 / y[M1].max(1e-12) - dv1 / v1) + (GAMMA - 1.0) / v1 * qw1;
                dy[P2] = n * p2 * (dm2 / y[M2].max(1e-12) - dv2 / v2) + (GAMMA - 1.0) / v2 * qw2;
            }
        }

        // Supply: source → [restriction → node] → [hose → inlet volume] → valve.
        let drawn = q3 + q4;
        let source = self.supply_abs;
        let restricted = self.line_volume();
        let node = if restricted.is_some() { y[PR] } else { source };
        let c = &self.consts;
        if restricted.is_some() {
            let q_in = iso6358_at(self.restriction_c, 0.5, source, self.ts, y[PR], self.ts);
            let q_out = if self.s.supply == SupplyLaw::Hose { y[W] } else { drawn };
            dy[PR] = c.line_gain * (q_in - q_out);
        }
        if self.s.supply == SupplyLaw::Hose {
            let area = c.hose_area;
            let rho = 0.5 * (node + y[PIN]) / c.r_ts;
            let w = y[W];
            let loss = c.hose_loss * w * w.abs() / (2.0 * rho * area * area);
            dy[W] = c.hose_gain * (node - y[PIN] - loss);
            dy[PIN] = c.inlet_gain * (w - drawn);
        }

        // Spool: the command (lagged by a valve delay) moves it first-order.
        let cmd = if let Some(d) = &self.e.valve_delay {
            dy[C] = (target - y[C]) / d.tau_s;
            y[C]
        } else {
            target
        };
        dy[S] = (cmd - y[S]) / p.spool_tau_s;

        // Piston, tool, contacts.
        let k = p.contact_stiffness_n_per_m;
        let friction = self.friction_n(t, v);
        let mut contact = 0.0;
        match self.s.anvil {
            AnvilLaw::Fixed => {
                let d = x - p.x_impact_m;
                if d > 0.0 {
                    contact = -(k * d + self.contact_c * v).max(0.0);
                }
            }
            AnvilLaw::MovingTool => {
                let d = x - y[XT];
                let push = if d > 0.0 {
                    (k * d + self.contact_c * (v - y[VT])).max(0.0)
                } else {
                    0.0
                };
                contact = -push;
                let xt = y[XT];
                let mut f_tool = push - p.feed_force_n;
                if xt < p.x_impact_m {
                    f_tool += (COLLAR_N_PER_M * (p.x_impact_m - xt) - c.c_collar * y[VT]).max(0.0);
                } else {
                    let kw = p.workpiece_stiffness_n_per_m;
                    f_tool -= kw * (xt - p.x_impact_m) + c.c_workpiece * y[VT];
                }
                dy[XT] = y[VT];
                dy[VT] = f_tool / p.tool_mass_kg;
            }
        }
        if x < 0.0 {
            contact += (k * -x - self.contact_c * v).max(0.0);
        }
        let pressure = (p1 - P_ATM) * self.a1 - (p2 - P_ATM) * self.a2;
        let accel = (pressure + friction + contact) / p.piston_mass_kg;
        dy[X] = v;
        dy[V] = accel;
        dy[WF] = -friction * v;
        dy[WP] = pressure * v;
        dy[WC] = contact * v;
        Outputs {
            accel_mps2: accel,
            friction_n: friction,
            contact_n: contact,
        }
    }

    /// The valve's discrete decision: which way the spool is sent.
    pub fn next_target(&self, y: &[f64; N], target: f64) -> f64 {
        use crate::structure::ValveLaw;
        let p = &self.p;
        match self.s.valve {
            ValveLaw::PilotThreshold => {
                let f = p.pilot_rear_m2 * (y[P1] - P_ATM) - p.pilot_front_m2 * (y[P2] - P_ATM);
                if f > p.pilot_hysteresis_n {
                    1.0
                } else if f < -p.pilot_hysteresis_n {
                    0.0
                } else {
                    target
                }
            }
            ValveLaw::PositionLatched => {
                if y[X] >= p.latch_forward_m {
                    0.0
                } else if y[X] <= p.latch_back_m {
                    1.0
                } else {
                    target
                }
            }
        }
    }
}
