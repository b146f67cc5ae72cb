//! One FMU instance in safe Rust: its values, its state machine
//! (instantiated → initialisation → stepping → terminated, and back by
//! reset) and the run it steps. The C boundary ([`crate::ffi`]) only
//! converts pointers and statuses.
//!
//! The outputs at a communication point are those of the output-grid
//! sample at or just before it (a sample within a millionth of a grid step
//! past it counts as at it: a master's t + h may miss the grid by an ulp).
//! Grid samples, not the dense state at the point, because the sensor
//! chain (filter, noise, quantisation) is defined sample by sample on that
//! grid: the outputs are then `hammer simulate`'s trace values bit for bit
//! when the communication step is a multiple of `solver.output_step_s`.
//! The impact outputs count the impacts located at or before the point.

use std::collections::VecDeque;

use hammer_sim::gas::R_AIR;
use hammer_sim::model;
use hammer_sim::run::{EventRecord, RunError, TruthSample, TruthSink};
use hammer_sim::sensor::{ChainSample, SensorChain};
use hammer_sim::simulate::ENDLESS_S;
use hammer_sim::stepper::Stepper;
use hammer_sim::SimConfig;

use crate::table::{Binding, Kind, Out, Table, Val};
use crate::variants::VariantsConfig;

/// A run under way, of either family.
pub trait Runner {
    /// Advances to the communication point `t_s` (see the module's doc).
    fn advance_to(&mut self, t_s: f64) -> Result<(), String>;
    /// Output `which` at the communication point.
    fn output(&self, which: Out) -> Val;
    /// The communication point reached.
    fn time_s(&self) -> f64;
    /// The output grid's step, s.
    fn dt_s(&self) -> f64;
    /// The run's end, s.
    fn t_end_s(&self) -> f64;
}

/// The model an FMU holds: the built-in simulator or the second family.
#[derive(Debug, Clone, PartialEq)]
pub enum Model {
    Hammer(SimConfig),
    Variants(VariantsConfig),
}

/// Where an instance is in FMI 2.0's co-simulation state machine.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Phase {
    Instantiated,
    Initialising,
    Stepping,
    Terminated,
    /// A call failed in a way that leaves the run unusable (reset recovers).
    Failed,
}

/// The sink the stepper hands its samples and impacts to: the sensor chain
/// follows the samples as in `hammer simulate`, the last one is kept.
struct Probe {
    chain: SensorChain,
    last: Option<(TruthSample, ChainSample)>,
    /// Impacts handed out but not yet past a communication point: time, velocity.
    pending: VecDeque<(f64, f64)>,
}

impl TruthSink for Probe {
    type Error = std::convert::Infallible;
    fn sample(&mut self, s: &TruthSample) -> Result<(), Self::Error> {
        let m = self.chain.measure(s);
        self.last = Some((*s, m));
        Ok(())
    }
    fn impact(&mut self, e: &EventRecord) -> Result<(), Self::Error> {
        self.chain.impact(e.t_s);
        self.pending.push_back((e.t_s, e.y[model::V]));
        Ok(())
    }
}

/// A run under way.
struct Run {
    stepper: Stepper,
    probe: Probe,
    /// The communication point reached.
    time_s: f64,
    dt_s: f64,
    t_end_s: f64,
    impacts: i32,
    last_impact: Option<(f64, f64)>,
    last_period_s: f64,
}

impl Runner for Run {
    fn advance_to(&mut self, t_s: f64) -> Result<(), String> {
        Run::advance_to(self, t_s)
    }
    fn output(&self, which: Out) -> Val {
        Run::output(self, which)
    }
    fn time_s(&self) -> f64 {
        self.time_s
    }
    fn dt_s(&self) -> f64 {
        self.dt_s
    }
    fn t_end_s(&self) -> f64 {
        self.t_end_s
    }
}

impl Run {
    fn new(cfg: &SimConfig) -> Self {
        let probe = Probe {
            chain: SensorChain::new(&cfg.sensors, &cfg.effects, cfg.solver.output_step_s, cfg.seed),
            last: None,
            pending: VecDeque::new(),
        };
        Self {
            stepper: Stepper::new(cfg).with_chamber_masses(),
            probe,
            time_s: 0.0,
            dt_s: cfg.solver.output_step_s,
            t_end_s: cfg.solver.duration_s,
            impacts: 0,
            last_impact: None,
            last_period_s: 0.0,
        }
    }

    fn advance_to(&mut self, t_s: f64) -> Result<(), String> {
        let snap = t_s + 1e-6 * self.dt_s;
        self.stepper.advance_to(snap, &mut self.probe).map_err(|e| match e {
            RunError::Solver(e) => format!("the simulation failed at t = {t_s} s: {e}"),
            RunError::Sink(never) => match never {},
        })?;
        while let Some(&(t, v)) = self.probe.pending.front() {
            if t > snap {
                break;
            }
            self.probe.pending.pop_front();
            self.impacts = self.impacts.saturating_add(1);
            if let Some((t0, _)) = self.last_impact {
                self.last_period_s = t - t0;
            }
            self.last_impact = Some((t, v));
        }
        self.time_s = t_s;
        Ok(())
    }

    /// Output `which` ([`crate::table::OUTPUTS`]).
    fn output(&self, which: Out) -> Val {
        let Some((s, m)) = &self.probe.last else {
            return Val::Real(0.0);
        };
        let y = self.stepper.last_sample_state();
        let md = self.stepper.model();
        // p·V = m·R·T with the state's absolute pressure.
        let temperature = |p: usize, mass: usize, volume_m3: f64| y[p] * volume_m3 / (y[mass] * R_AIR);
        let x = match which {
            Out::PRearTrue => s.p_rear_pa,
            Out::PFrontTrue => s.p_front_pa,
            Out::AccelTrue => s.accel_mps2,
            Out::PRear => m.values[0],
            Out::PFront => m.values[1],
            Out::Accel => m.values[2],
            Out::X => s.x_m,
            Out::V => s.v_mps,
            Out::Valve => s.valve_m,
            Out::RearMass => y[model::M1],
            Out::FrontMass => y[model::M2],
            Out::RearTemperature => temperature(model::P1, model::M1, md.rear_volume_m3(s.x_m)),
            Out::FrontTemperature => temperature(model::P2, model::M2, md.front_volume_m3(s.x_m)),
            Out::ImpactCount => return Val::Integer(self.impacts),
            Out::LastImpactVelocity => self.last_impact.map_or(0.0, |(_, v)| v),
            Out::LastPeriod => self.last_period_s,
        };
        Val::Real(x)
    }
}

/// One instance: the table, the values set, the phase and the run.
pub struct Instance {
    model: Model,
    table: Table,
    values: Vec<Val>,
    phase: Phase,
    stop_time_s: Option<f64>,
    run: Option<Box<dyn Runner>>,
}

/// A refused call: the message for the logger.
pub type Refusal = String;

impl Instance {
    pub fn new(model: Model) -> Result<Self, Refusal> {
        let table = match &model {
            Model::Hammer(cfg) => Table::new(cfg)?,
            Model::Variants(cfg) => crate::variants::table(cfg)?,
        };
        let values = table.starts();
        Ok(Self {
            model,
            table,
            values,
            phase: Phase::Instantiated,
            stop_time_s: None,
            run: None,
        })
    }

    pub fn phase(&self) -> Phase {
        self.phase
    }

    pub fn fail(&mut self) {
        self.phase = Phase::Failed;
    }

    pub fn setup_experiment(&mut self, start_s: f64, stop_s: Option<f64>) -> Result<(), Refusal> {
        self.expect(&[Phase::Instantiated], "fmi2SetupExperiment")?;
        if start_s != 0.0 {
            return Err(format!(
                "the hammer starts at rest at t = 0; a start time of {start_s} s is not supported"
            ));
        }
        match stop_s {
            Some(t) if !(t > 0.0 && t <= ENDLESS_S) => {
                return Err(format!("stop time {t} s: allowed 0 < t <= {ENDLESS_S}"))
            }
            _ => self.stop_time_s = stop_s,
        }
        Ok(())
    }

    pub fn enter_initialization(&mut self) -> Result<(), Refusal> {
        self.expect(&[Phase::Instantiated], "fmi2EnterInitializationMode")?;
        self.phase = Phase::Initialising;
        Ok(())
    }

    /// A run of the parameters set (validated), to the stop time or
    /// open-ended, at its start.
    fn start_run(&self) -> Result<Box<dyn Runner>, Refusal> {
        let duration_s = self.stop_time_s.unwrap_or(ENDLESS_S);
        let mut run: Box<dyn Runner> = match &self.model {
            Model::Hammer(_) => {
                let mut cfg = self.table.config(&self.values)?;
                cfg.solver.duration_s = duration_s;
                Box::new(Run::new(&cfg))
            }
            Model::Variants(_) => Box::new(crate::variants::start(&self.table, &self.values, duration_s)?),
        };
        run.advance_to(0.0)?;
        Ok(run)
    }

    pub fn exit_initialization(&mut self) -> Result<(), Refusal> {
        self.expect(&[Phase::Initialising], "fmi2ExitInitializationMode")?;
        self.run = Some(self.start_run()?);
        self.phase = Phase::Stepping;
        Ok(())
    }

    pub fn do_step(&mut self, t_s: f64, h_s: f64) -> Result<(), Refusal> {
        self.expect(&[Phase::Stepping], "fmi2DoStep")?;
        let Some(run) = self.run.as_mut() else {
            return Err("no run".into());
        };
        let slack = 1e-6 * run.dt_s();
        if (t_s - run.time_s()).abs() > slack || !(h_s >= 0.0) {
            return Err(format!(
                "doStep from t = {t_s} s by {h_s} s: the FMU is at t = {} s",
                run.time_s()
            ));
        }
        let to = t_s + h_s;
        if to > run.t_end_s() + slack {
            return Err(format!("doStep to t = {to} s: past the stop time {} s", run.t_end_s()));
        }
        let r = run.advance_to(to);
        if r.is_err() {
            self.phase = Phase::Failed;
        }
        r
    }

    pub fn time_s(&self) -> f64 {
        self.run.as_ref().map_or(0.0, |r| r.time_s())
    }

    pub fn terminate(&mut self) -> Result<(), Refusal> {
        self.expect(&[Phase::Stepping, Phase::Failed], "fmi2Terminate")?;
        self.phase = Phase::Terminated;
        Ok(())
    }

    /// Back to the state right after instantiation: start values, no run.
    pub fn reset(&mut self) {
        self.values = self.table.starts();
        self.stop_time_s = None;
        self.run = None;
        self.phase = Phase::Instantiated;
    }

    fn expect(&self, phases: &[Phase], call: &str) -> Result<(), Refusal> {
        if phases.contains(&self.phase) {
            Ok(())
        } else {
            Err(format!("{call} is not allowed in the {:?} state", self.phase))
        }
    }

    /// The value reference of the variable named `name`.
    pub fn vr(&self, name: &str) -> Option<u32> {
        self.table.vars.iter().position(|v| v.name == name).map(|i| i as u32)
    }

    fn variable(&self, vr: u32, kind: Kind) -> Result<usize, Refusal> {
        let i = vr as usize;
        match self.table.vars.get(i) {
            Some(v) if v.kind == kind => Ok(i),
            Some(v) => Err(format!("value reference {vr} ({}) is not a {kind:?}", v.name)),
            None => Err(format!("unknown value reference {vr}")),
        }
    }

    /// The value of `vr`; an output before the run is the initial state's.
    pub fn get(&self, vr: u32, kind: Kind) -> Result<Val, Refusal> {
        let i = self.variable(vr, kind)?;
        let which = |k: usize| Out::ALL.get(k).copied().ok_or_else(|| format!("no output {k}"));
        match (&self.table.vars[i].binding, &self.run) {
            (Binding::Output(k), Some(run)) => Ok(run.output(which(*k)?)),
            (Binding::Output(k), None) if self.phase == Phase::Initialising => Ok(self.start_run()?.output(which(*k)?)),
            (Binding::Output(_), None) => Ok(self.table.vars[i].start),
            _ => Ok(self.values[i]),
        }
    }

    /// Sets a parameter: before the end of initialisation only.
    pub fn set(&mut self, vr: u32, val: Val) -> Result<(), Refusal> {
        let kind = match val {
            Val::Real(_) => Kind::Real,
            Val::Integer(_) => Kind::Integer,
            Val::Boolean(_) => Kind::Boolean,
        };
        let i = self.variable(vr, kind)?;
        let v = &self.table.vars[i];
        if v.is_output() {
            return Err(format!("{} is an output and cannot be set", v.name));
        }
        if !matches!(self.phase, Phase::Instantiated | Phase::Initialising) {
            return Err(format!(
                "{} is a fixed parameter: set it before fmi2ExitInitializationMode",
                v.name
            ));
        }
        self.values[i] = val;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use hammer_sim::simulate;

    fn vr(inst: &Instance, name: &str) -> u32 {
        inst.table.vars.iter().position(|v| v.name == name).unwrap() as u32
    }

    fn run(inst: &mut Instance, stop: f64, h: f64) -> Vec<[u64; 4]> {
        inst.setup_experiment(0.0, Some(stop)).unwrap();
        inst.enter_initialization().unwrap();
        inst.exit_initialization().unwrap();
        let names = ["p_rear_pa", "accel_mps2", "x_m", "last_impact_velocity_mps"];
        let mut out = Vec::new();
        let mut n = 0;
        loop {
            let row = names.map(|k| match inst.get(vr(inst, k), Kind::Real).unwrap() {
                Val::Real(x) => x.to_bits(),
                _ => unreachable!(),
            });
            out.push(row);
            let t = n as f64 * h;
            if t >= stop - 1e-12 {
                break;
            }
            n += 1;
            inst.do_step(t, n as f64 * h - t).unwrap();
        }
        out
    }

    /// Stepped at the output grid, the instance gives `simulate`'s trace
    /// (sensor chain included) sample for sample; a reset reruns it bit
    /// for bit.
    #[test]
    fn the_outputs_are_the_simulators_trace_and_reset_repeats_them() {
        let mut base = SimConfig::nominal(5.0);
        base.seed = 3;
        base.effects.apply_spec("accel_zero_shift").unwrap();
        let mut inst = Instance::new(Model::Hammer(base.clone())).unwrap();
        let a = run(&mut inst, 0.05, base.solver.output_step_s);
        let mut cfg = base.clone();
        cfg.solver.duration_s = 0.05;
        let sim = simulate(&cfg).unwrap();
        assert_eq!(a.len(), sim.run.truth.len());
        for (i, row) in a.iter().enumerate() {
            assert_eq!(row[0], sim.measured.p_rear_pa[i].to_bits(), "sample {i}");
            assert_eq!(row[1], sim.measured.accel_mps2[i].to_bits(), "sample {i}");
            assert_eq!(row[2], sim.run.truth.x_m[i].to_bits(), "sample {i}");
        }
        inst.reset();
        assert_eq!(run(&mut inst, 0.05, base.solver.output_step_s), a);
    }
}
