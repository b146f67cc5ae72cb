//! The time loop: classical RK4 at a fixed step (no event location: the
//! contact and the ports are resolved by the step alone), the valve's
//! discrete decision between steps, the sensor chain at every step, and the
//! per-cycle truth from the states.

use serde::{Deserialize, Serialize};

use crate::plant::{Plant, ML, N, QW, QX, V, WC, WF, WP, X, XT};
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
    /// Heat that crossed the walls over the cycle, either way: heat
    /// exchange's size, as the built-in model's truth has it.
    #[serde(default)]
    pub heat_exchanged_j: f64,
    /// Air through the leak paths over the cycle: leakage's size, as the
    /// built-in model's truth has it.
    #[serde(default)]
    pub leaked_kg: f64,
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

/// One output sample: the sensors' readings and the states a bench with
/// a position sensor would have.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sample {
    pub t_s: f64,
    pub p_rear_pa: f64,
    pub p_front_pa: f64,
    pub accel_mps2: f64,
    pub x_m: f64,
    pub v_mps: f64,
    pub p_rear_true_pa: f64,
    pub p_front_true_pa: f64,
    pub spool: f64,
    /// The plant's acceleration, and both chambers' air, mass and
    /// temperature (a co-simulation's outputs).
    pub accel_true_mps2: f64,
    pub m_rear_kg: f64,
    pub m_front_kg: f64,
    pub t_rear_k: f64,
    pub t_front_k: f64,
}

/// The second family advanced from outside: [`Stepper::advance_to`] runs
/// the fixed steps that start at or before a communication point and hands
/// out the samples on the way. The steps are the run's own (1 µs), never
/// cut at a communication point, so a run cut into pieces of any size is
/// the same run, sample for sample, as [`run`]. It owns its plant and
/// front end, so a caller (an FMU instance) keeps one value.
pub struct Stepper {
    plant: Plant,
    fe: FrontEndState,
    h_s: f64,
    every: usize,
    steps: usize,
    /// The next step's index (its start time is `i · h`).
    i: usize,
    y: [f64; N],
    target: f64,
    k: [[f64; N]; 4],
    signs: Noise,
    offset: f64,
    in_contact: bool,
    /// (t, then friction work, wall heat, heat exchanged and air leaked) at
    /// the last impact.
    last_impact: Option<(f64, [f64; 4])>,
    stroke_start_x: Option<f64>,
    stroke: Phase,
    backhaul: Phase,
    in_stroke: bool,
    cycles: Vec<VariantCycle>,
    /// Impacts so far, and the time and velocity of the last.
    impacts: usize,
    last_impact_tv: Option<(f64, f64)>,
    last_period_s: f64,
}

impl Stepper {
    /// `plant` at rest, to run `duration_s` at step `h_s`, sampling every `every` steps.
    pub fn new(plant: Plant, fe: FrontEndState, seed: u64, duration_s: f64, h_s: f64, every: usize) -> Self {
        Self {
            y: plant.initial(),
            plant,
            fe,
            h_s,
            every,
            steps: (duration_s / h_s).round() as usize,
            i: 0,
            target: 1.0,
            k: [[0.0; N]; 4],
            signs: Noise::new(seed ^ 0xA11CE),
            offset: 0.0,
            in_contact: false,
            last_impact: None,
            stroke_start_x: None,
            stroke: Phase::default(),
            backhaul: Phase::default(),
            in_stroke: false,
            cycles: Vec::new(),
            impacts: 0,
            last_impact_tv: None,
            last_period_s: 0.0,
        }
    }

    /// Impacts so far, the time and velocity of the last, and the time
    /// between the last two (0 before the second). Located inside the steps
    /// run, so up to one step past the last advance.
    pub fn impacts(&self) -> (usize, Option<(f64, f64)>, f64) {
        (self.impacts, self.last_impact_tv, self.last_period_s)
    }

    /// The states now (the plant's layout, `crate::plant`).
    pub fn state(&self) -> &[f64; N] {
        &self.y
    }

    /// The cycles closed so far.
    pub fn cycles(&self) -> &[VariantCycle] {
        &self.cycles
    }

    /// Whether the run has reached its duration.
    pub fn done(&self) -> bool {
        self.i > self.steps
    }

    /// Runs every step that starts at or before `t_s` (and within the
    /// run), handing each output sample to `sample`.
    pub fn advance_to(&mut self, t_s: f64, sample: &mut impl FnMut(Sample)) {
        while self.i <= self.steps && self.i as f64 * self.h_s <= t_s {
            self.step(sample);
        }
    }

    fn step(&mut self, sample: &mut impl FnMut(Sample)) {
        let (plant, h_s, i) = (&self.plant, self.h_s, self.i);
        self.i += 1;
        let t = i as f64 * h_s;
        let o = plant.deriv(t, &self.y, self.target, &mut self.k[0]);
        let p_rear = self.y[crate::plant::P1] - crate::flow::P_ATM;
        let p_front = self.y[crate::plant::P2] - crate::flow::P_ATM;
        self.fe.step(h_s, p_rear, p_front, o.accel_mps2);
        if let Some(z) = &plant.e.accel_zero_shift {
            self.offset *= (-h_s / z.tau_s).exp();
        }
        if i % self.every == 0 {
            let gains = plant
                .e
                .pressure_gain_error
                .as_ref()
                .map_or((0.0, 0.0), |g| (g.rear, g.front));
            let (r, f, a) = self.fe.sample(gains, self.offset);
            let (t_rear_k, t_front_k) = plant.temperatures_k(&self.y);
            sample(Sample {
                t_s: t,
                p_rear_pa: r,
                p_front_pa: f,
                accel_mps2: a,
                x_m: self.y[X],
                v_mps: self.y[V],
                p_rear_true_pa: p_rear,
                p_front_true_pa: p_front,
                spool: self.y[crate::plant::S],
                accel_true_mps2: o.accel_mps2,
                m_rear_kg: self.y[crate::plant::M1],
                m_front_kg: self.y[crate::plant::M2],
                t_rear_k,
                t_front_k,
            });
        }
        if i == self.steps {
            return;
        }
        // Phase accounting on the state at the start of the step.
        let touching = o.contact_n < 0.0 && self.y[X] > 0.0;
        if !touching {
            if self.in_stroke {
                self.stroke.sum += o.friction_n.abs();
                self.stroke.n += 1;
            } else if self.last_impact.is_some() {
                self.backhaul.sum += o.friction_n.abs();
                self.backhaul.n += 1;
            }
        }
        // RK4.
        let y0 = self.y;
        let mut tmp = [0.0; N];
        for (stage, c) in [(1usize, 0.5), (2, 0.5), (3, 1.0)] {
            for j in 0..N {
                tmp[j] = y0[j] + c * h_s * self.k[stage - 1][j];
            }
            let (_, after) = self.k.split_at_mut(stage);
            plant.deriv(t + c * h_s, &tmp, self.target, &mut after[0]);
        }
        let k = &self.k;
        for j in 0..N {
            self.y[j] = y0[j] + h_s / 6.0 * (k[0][j] + 2.0 * k[1][j] + 2.0 * k[2][j] + k[3][j]);
        }
        self.target = plant.next_target(&self.y, self.target);
        self.events(t, &y0);
    }

    /// Events of the step from `y0` at `t`, resolved to the step by linear interpolation.
    fn events(&mut self, t: f64, y0: &[f64; N]) {
        let (plant, h_s, y) = (&self.plant, self.h_s, self.y);
        let anvil = |y: &[f64; N]| match plant.s.anvil {
            AnvilLaw::Fixed => plant.p.x_impact_m,
            AnvilLaw::MovingTool => y[XT],
        };
        let (d0, d1) = (y0[X] - anvil(y0), y[X] - anvil(&y));
        if !self.in_contact && d0 <= 0.0 && d1 > 0.0 {
            self.in_contact = true;
            let f = -d0 / (d1 - d0);
            let t_imp = t + f * h_s;
            let v_imp = y0[V] + f * (y[V] - y0[V]);
            self.impacts += 1;
            if let Some((t0, _)) = self.last_impact_tv {
                self.last_period_s = t_imp - t0;
            }
            self.last_impact_tv = Some((t_imp, v_imp));
            if let (Some((t_last, last)), Some(x_turn)) = (self.last_impact, self.stroke_start_x) {
                let period = t_imp - t_last;
                self.cycles.push(VariantCycle {
                    t_impact_s: t_imp,
                    impact_velocity_mps: v_imp,
                    impact_energy_j: 0.5 * plant.p.piston_mass_kg * v_imp * v_imp,
                    period_s: period,
                    frequency_hz: 1.0 / period,
                    stroke_m: anvil(y0) - x_turn,
                    friction_stroke_n: self.stroke.mean(),
                    friction_backhaul_n: self.backhaul.mean(),
                    friction_work_j: y[WF] - last[0],
                    wall_heat_j: y[QW] - last[1],
                    heat_exchanged_j: y[QX] - last[2],
                    leaked_kg: y[ML] - last[3],
                });
            }
            self.last_impact = Some((t_imp, [y[WF], y[QW], y[QX], y[ML]]));
            self.stroke_start_x = None;
            self.in_stroke = false;
            self.stroke = Phase::default();
            self.backhaul = Phase::default();
            if let Some(z) = &plant.e.accel_zero_shift {
                self.offset += if self.signs.next_u64() & 1 == 0 {
                    z.amplitude_mps2
                } else {
                    -z.amplitude_mps2
                };
            }
        } else if self.in_contact && d1 <= 0.0 {
            self.in_contact = false;
        }
        if !self.in_contact && !self.in_stroke && self.last_impact.is_some() && y0[V] <= 0.0 && y[V] > 0.0 {
            self.in_stroke = true;
            self.stroke_start_x = Some(y[X]);
        }
    }

    /// The work balance at the end: (pressure work, pressure + contact +
    /// friction work − ΔKE), and the cycles.
    pub fn finish(self) -> (f64, f64, Vec<VariantCycle>) {
        let y = self.y;
        let ke = 0.5 * self.plant.p.piston_mass_kg * y[V] * y[V];
        // The piston starts at rest.
        (y[WP], y[WP] + y[WC] - y[WF] - ke, self.cycles)
    }
}

/// Runs `plant` for `duration_s` at step `h_s`, sampling every `every` steps.
pub fn run(plant: Plant, fe: FrontEndState, seed: u64, duration_s: f64, h_s: f64, every: usize) -> Run {
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
    let mut stepper = Stepper::new(plant, fe, seed, duration_s, h_s, every);
    stepper.advance_to(f64::INFINITY, &mut |s| out.push(s));
    let (pressure_work_j, energy_residual_j, cycles) = stepper.finish();
    out.pressure_work_j = pressure_work_j;
    out.energy_residual_j = energy_residual_j;
    out.cycles = cycles;
    out
}

impl Run {
    fn push(&mut self, s: Sample) {
        self.t_s.push(s.t_s);
        self.p_rear_pa.push(s.p_rear_pa);
        self.p_front_pa.push(s.p_front_pa);
        self.accel_mps2.push(s.accel_mps2);
        self.x_m.push(s.x_m);
        self.v_mps.push(s.v_mps);
        self.p_rear_true_pa.push(s.p_rear_true_pa);
        self.p_front_true_pa.push(s.p_front_true_pa);
        self.spool.push(s.spool);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::structure::{Structure, VariantParams};
    use hammer_sim::effects::Effects;

    /// Cut into pieces of any size, on every structure, the run is the
    /// whole run sample for sample and cycle for cycle.
    #[test]
    fn the_run_does_not_depend_on_how_it_is_cut() {
        let mut effects = Effects::default();
        effects.apply_spec("coulomb_friction").unwrap();
        effects.apply_spec("accel_zero_shift").unwrap();
        let mut structures = vec![Structure::BASE];
        structures.extend(Structure::singles());
        for (k, s) in structures.into_iter().enumerate() {
            let plant = || Plant::new(VariantParams::default(), s, effects.clone(), 5.0);
            let (h_s, every, duration_s) = (1e-6, 10, 0.2);
            let whole = run(plant(), FrontEndState::new(s.front_end, 3), 3, duration_s, h_s, every);
            for piece_s in [7e-6, 1e-5, 2.5e-3] {
                let fe = FrontEndState::new(s.front_end, 3);
                let mut stepper = Stepper::new(plant(), fe, 3, duration_s, h_s, every);
                let mut samples = Vec::new();
                let mut t = 0.0;
                while !stepper.done() {
                    t += piece_s;
                    stepper.advance_to(t, &mut |x| samples.push(x));
                }
                let (_, _, cycles) = stepper.finish();
                assert_eq!(samples.len(), whole.t_s.len(), "structure {k}, pieces of {piece_s} s");
                for (i, x) in samples.iter().enumerate() {
                    assert_eq!(x.t_s.to_bits(), whole.t_s[i].to_bits());
                    assert_eq!(x.p_rear_pa.to_bits(), whole.p_rear_pa[i].to_bits());
                    assert_eq!(x.accel_mps2.to_bits(), whole.accel_mps2[i].to_bits());
                    assert_eq!(x.x_m.to_bits(), whole.x_m[i].to_bits());
                }
                assert_eq!(cycles, whole.cycles, "structure {k}, pieces of {piece_s} s");
            }
            assert!(!whole.cycles.is_empty(), "structure {k} runs");
        }
    }
}
