//! The time loop: classical RK4 at a fixed step (no event location: the
//! contact and the ports are resolved by the step alone), the valve's
//! discrete decision between steps, the sensor chain at every step, and the
//! per-cycle truth from the states.

use serde::{Deserialize, Serialize};

use crate::plant::{Plant, N, QW, V, WC, WF, WP, X, XT};
use crate::sensors::{FrontEndState, Noise};
use crate::structure::AnvilLaw;

/// Ground truth of one cycle: the backhaul after an impact and the stroke
/// that ends in the next.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct VariantCycle {
    pub t_impact_s: f64,
    pub impact_velocity_mps: f64,
    pub impact_energy_j: f64,
    pub period_s: f64,
    pub frequency_hz: f64,
    pub stroke_m: f64,
    /// Mean friction magnitude over the stroke and over the backhaul (contact excluded).
    pub friction_stroke_n: f64,
    pub friction_backhaul_n: f64,
    pub friction_work_j: f64,
    /// Heat the walls gave both chambers' air over the cycle (negative:
    /// the air lost it); absent in truth files written before it was kept.
    #[serde(default)]
    pub wall_heat_j: f64,
}

/// Samples on the output grid plus the truth.
pub struct Run {
    pub dt_s: f64,
    pub t_s: Vec<f64>,
    pub p_rear_pa: Vec<f64>,
    pub p_front_pa: Vec<f64>,
    pub accel_mps2: Vec<f64>,
    pub x_m: Vec<f64>,
    pub v_mps: Vec<f64>,
    /// The chambers' true pressures (gauge) and the spool's position
    /// (0 feeds the front, 1 the rear; each port opens past 0.5).
    pub p_rear_true_pa: Vec<f64>,
    pub p_front_true_pa: Vec<f64>,
    pub spool: Vec<f64>,
    pub cycles: Vec<VariantCycle>,
    /// Work balance over the run: pressure + contact + friction work − ΔKE.
    pub energy_residual_j: f64,
    pub pressure_work_j: f64,
}

#[derive(Default)]
struct Phase {
    sum: f64,
    n: u64,
}

impl Phase {
    fn mean(&self) -> f64 {
        if self.n == 0 {
            0.0
        } else {
            self.sum / self.n as f64
        }
    }
}

/// Runs `plant` for `duration_s` at step `h_s`, sampling every `every` steps.
pub fn run(plant: &Plant, fe: &mut FrontEndState, seed: u64, duration_s: f64, h_s: f64, every: usize) -> Run {
    let steps = (duration_s / h_s).round() as usize;
    let mut out = Run {
        dt_s: h_s * every as f64,
        t_s: Vec::with_capacity(steps / every + 1),
        p_rear_pa: Vec::new(),
        p_front_pa: Vec::new(),
        accel_mps2: Vec::new(),
        x_m: Vec::new(),
        v_mps: Vec::new(),
        p_rear_true_pa: Vec::new(),
        p_front_true_pa: Vec::new(),
        spool: Vec::new(),
        cycles: Vec::new(),
        energy_residual_j: 0.0,
        pressure_work_j: 0.0,
    };
    let mut y = plant.initial();
    let mut target = 1.0;
    let mut k = [[0.0; N]; 4];
    let mut tmp = [0.0; N];
    let zero_shift = plant.e.accel_zero_shift.clone();
    let gains = plant
        .e
        .pressure_gain_error
        .as_ref()
        .map_or((0.0, 0.0), |g| (g.rear, g.front));
    let mut signs = Noise::new(seed ^ 0xA11CE);
    let mut offset = 0.0;
    let anvil = |y: &[f64; N]| match plant.s.anvil {
        AnvilLaw::Fixed => plant.p.x_impact_m,
        AnvilLaw::MovingTool => y[XT],
    };
    // Cycle bookkeeping.
    let mut in_contact = false;
    let mut last_impact: Option<(f64, f64, f64)> = None; // (t, friction work and wall heat then)
    let mut stroke_start_x: Option<f64> = None;
    let (mut stroke, mut backhaul) = (Phase::default(), Phase::default());
    let mut in_stroke = false;
    for i in 0..=steps {
        let t = i as f64 * h_s;
        let o = plant.deriv(t, &y, target, &mut k[0]);
        let p_rear = y[crate::plant::P1] - crate::flow::P_ATM;
        let p_front = y[crate::plant::P2] - crate::flow::P_ATM;
        fe.step(h_s, p_rear, p_front, o.accel_mps2);
        if let Some(z) = &zero_shift {
            offset *= (-h_s / z.tau_s).exp();
        }
        if i % every == 0 {
            let (r, f, a) = fe.sample(gains, offset);
            out.t_s.push(t);
            out.p_rear_pa.push(r);
            out.p_front_pa.push(f);
            out.accel_mps2.push(a);
            out.x_m.push(y[X]);
            out.v_mps.push(y[V]);
            out.p_rear_true_pa.push(p_rear);
            out.p_front_true_pa.push(p_front);
            out.spool.push(y[crate::plant::S]);
        }
        if i == steps {
            break;
        }
        // Phase accounting on the state at the start of the step.
        let touching = o.contact_n < 0.0 && y[X] > 0.0;
        if !touching {
            if in_stroke {
                stroke.sum += o.friction_n.abs();
                stroke.n += 1;
            } else if last_impact.is_some() {
                backhaul.sum += o.friction_n.abs();
                backhaul.n += 1;
            }
        }
        // RK4.
        let y0 = y;
        for (stage, c) in [(1usize, 0.5), (2, 0.5), (3, 1.0)] {
            for j in 0..N {
                tmp[j] = y0[j] + c * h_s * k[stage - 1][j];
            }
            let (_, after) = k.split_at_mut(stage);
            plant.deriv(t + c * h_s, &tmp, target, &mut after[0]);
        }
        for j in 0..N {
            y[j] = y0[j] + h_s / 6.0 * (k[0][j] + 2.0 * k[1][j] + 2.0 * k[2][j] + k[3][j]);
        }
        target = plant.next_target(&y, target);

        // Events, resolved to the step by linear interpolation.
        let (d0, d1) = (y0[X] - anvil(&y0), y[X] - anvil(&y));
        if !in_contact && d0 <= 0.0 && d1 > 0.0 {
            in_contact = true;
            let f = -d0 / (d1 - d0);
            let t_imp = t + f * h_s;
            let v_imp = y0[V] + f * (y[V] - y0[V]);
            if let (Some((t_last, w_last, q_last)), Some(x_turn)) = (last_impact, stroke_start_x) {
                let period = t_imp - t_last;
                out.cycles.push(VariantCycle {
                    t_impact_s: t_imp,
                    impact_velocity_mps: v_imp,
                    impact_energy_j: 0.5 * plant.p.piston_mass_kg * v_imp * v_imp,
                    period_s: period,
                    frequency_hz: 1.0 / period,
                    stroke_m: anvil(&y0) - x_turn,
                    friction_stroke_n: stroke.mean(),
                    friction_backhaul_n: backhaul.mean(),
                    friction_work_j: y[WF] - w_last,
                    wall_heat_j: y[QW] - q_last,
                });
            }
            last_impact = Some((t_imp, y[WF], y[QW]));
            stroke_start_x = None;
            in_stroke = false;
            stroke = Phase::default();
            backhaul = Phase::default();
            if let Some(z) = &zero_shift {
                offset += if signs.next_u64() & 1 == 0 {
                    z.amplitude_mps2
                } else {
                    -z.amplitude_mps2
                };
            }
        } else if in_contact && d1 <= 0.0 {
            in_contact = false;
        }
        if !in_contact && !in_stroke && last_impact.is_some() && y0[V] <= 0.0 && y[V] > 0.0 {
            in_stroke = true;
            stroke_start_x = Some(y[X]);
        }
    }
    let ke = 0.5 * plant.p.piston_mass_kg * y[V] * y[V];
    // The piston starts at rest.
    out.pressure_work_j = y[WP];
    out.energy_residual_j = y[WP] + y[WC] - y[WF] - ke;
    out
}
