//! A complete simulated measurement: truth, sensor chain, trace and sidecar.

use std::fmt::Write as _;

use serde::{Deserialize, Serialize};

use crate::run::{simulate_truth, CycleTruth, MassBalance, SimRun};
use crate::sensor::{measure, Measured};
use crate::solver::{SolverError, SolverStats};
use crate::SimConfig;
use hammer_trace::trace::{read_sidecar_as, Trace, TraceError};

/// Everything the simulator knows about a trace it wrote: the sidecar's
/// `simulation` object.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SimulationInfo {
    pub active_effects: Vec<String>,
    pub config: SimConfig,
    pub cycles: Vec<CycleTruth>,
    pub mass_balance: MassBalance,
    pub solver: SolverStats,
    /// Samples at either end of the ADC range: rear, front, accel.
    pub clipped_samples: [usize; 3],
}

/// A sidecar read by a tool that knows the simulator.
pub type Sidecar = hammer_trace::trace::Sidecar<SimulationInfo>;

/// Reads the sidecar beside a trace, typing the simulator's record; a
/// malformed record is an error, as any malformed sidecar field is.
pub fn read_simulated_sidecar(trace: &std::path::Path) -> Result<Option<Sidecar>, TraceError> {
    read_sidecar_as(trace)
}

pub struct Simulation {
    pub config: SimConfig,
    pub run: SimRun,
    pub measured: Measured,
}

pub fn simulate(config: &SimConfig) -> Result<Simulation, SolverError> {
    let run = simulate_truth(config)?;
    let measured = measure(
        &config.sensors,
        &config.effects,
        &run.truth,
        &run.events.impacts,
        config.seed,
    );
    Ok(Simulation {
        config: config.clone(),
        run,
        measured,
    })
}

impl Simulation {
    /// The measured channels plus truth columns, in the project's trace format.
    pub fn trace(&self) -> Trace {
        let t = &self.run.truth;
        let mut trace = Trace {
            dt_s: t.dt_s,
            t_s: t.t_s.clone(),
            p_rear_pa: self.measured.p_rear_pa.clone(),
            p_front_pa: self.measured.p_front_pa.clone(),
            accel_mps2: self.measured.accel_mps2.clone(),
            extra: Default::default(),
            gaps: Vec::new(),
        };
        for (name, col) in [
            ("x_m", &t.x_m),
            ("v_mps", &t.v_mps),
            ("valve_m", &t.valve_m),
            ("p_rear_true_pa", &t.p_rear_pa),
            ("p_front_true_pa", &t.p_front_pa),
            ("accel_true_mps2", &t.accel_mps2),
            ("friction_true_n", &t.friction_n),
        ] {
            trace.extra.insert(name.to_string(), col.clone());
        }
        trace
    }

    pub fn sidecar(&self) -> Sidecar {
        let mut s = Sidecar::new(Some(self.config.supply.pressure_bar), "simulator");
        s.simulation = Some(SimulationInfo {
            active_effects: self.config.effects.active().iter().map(|s| s.to_string()).collect(),
            config: self.config.clone(),
            cycles: self.run.cycles.clone(),
            mass_balance: self.run.mass_balance,
            solver: self.run.stats,
            clipped_samples: self.measured.clipped,
        });
        s
    }

    /// Cycles after the start-up transient (the first 0.1 s and the first two impacts).
    pub fn steady_cycles(&self) -> &[CycleTruth] {
        let c = &self.run.cycles;
        let first = c
            .iter()
            .position(|c| c.t_impact_s > 0.1 && c.index >= 2)
            .unwrap_or(c.len());
        &c[first..]
    }

    /// A human-readable cycle summary.
    pub fn summary(&self) -> String {
        let mut s = String::new();
        let cfg = &self.config;
        let _ = writeln!(
            s,
            "hammer simulation: supply {:.2} bar, {:.3} s, effects: {}",
            cfg.supply.pressure_bar,
            cfg.solver.duration_s,
            if cfg.effects.active().is_empty() {
                "none (nominal)".to_string()
            } else {
                cfg.effects.active().join(", ")
            }
        );
        let _ = writeln!(
            s,
            "{:>3} {:>9} {:>8} {:>8} {:>7} {:>7} {:>8} {:>8} {:>8} {:>8} {:>8}",
            "#", "t_imp_s", "v_mps", "E_j", "f_hz", "stroke", "Ffr_s_n", "Ffr_b_n", "Wfr_j", "p1max", "p2max"
        );
        for c in &self.run.cycles {
            let _ = writeln!(
                s,
                "{:>3} {:>9.5} {:>8.4} {:>8.4} {:>7.3} {:>5.2}mm {:>8.3} {:>8.3} {:>8.4} {:>6.3}b {:>6.3}b",
                c.index,
                c.t_impact_s,
                c.impact_velocity_mps,
                c.impact_energy_j,
                c.frequency_hz,
                c.stroke_m * 1e3,
                c.friction_stroke_n,
                c.friction_backhaul_n,
                c.friction_work_j,
                c.peak_rear_pa / 1e5,
                c.peak_front_pa / 1e5
            );
        }
        let steady = self.steady_cycles();
        if !steady.is_empty() {
            let n = steady.len() as f64;
            let mean = |f: fn(&CycleTruth) -> f64| steady.iter().map(f).sum::<f64>() / n;
            let _ = writeln!(
                s,
                "steady mean over {} cycles: v_imp {:.4} m/s, E {:.4} J, f {:.3} Hz, stroke {:.2} mm, friction work {:.1} % of E",
                steady.len(),
                mean(|c| c.impact_velocity_mps),
                mean(|c| c.impact_energy_j),
                mean(|c| c.frequency_hz),
                mean(|c| c.stroke_m) * 1e3,
                100.0 * mean(|c| c.friction_work_stroke_j) / mean(|c| c.impact_energy_j)
            );
        }
        let st = &self.run.stats;
        let _ = writeln!(
            s,
            "solver: {} steps ({} rejected, {} stiff), {} restarts, {} rhs evaluations; clipped samples rear/front/accel: {:?}",
            st.accepted_steps, st.rejected_steps, st.stiff_steps, st.restarts, st.rhs_evaluations, self.measured.clipped
        );
        s
    }
}
