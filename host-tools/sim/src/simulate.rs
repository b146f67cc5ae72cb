//! A complete simulated measurement: truth, sensor chain, trace and sidecar.

use std::fmt::Write as _;
use std::ops::ControlFlow;

use serde::{Deserialize, Serialize};

use std::path::Path;

use crate::run::{
    run_model, CycleTruth, EventRecord, MassBalance, RunError, RunSummary, SimRun, TruthSample, TruthSink, TruthTrace,
};
use crate::sensor::{ChainSample, Measured, SensorChain};
use crate::solver::{SolverError, SolverStats};
use crate::SimConfig;
use hammer_estimator::RawSample;
use hammer_trace::trace::{read_sidecar_as, write_sidecar, CsvWriter, Trace, TraceError};

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

/// Why a simulation streamed to a file stopped.
#[derive(Debug, thiserror::Error)]
pub enum SimulateError {
    #[error(transparent)]
    Solver(#[from] SolverError),
    #[error(transparent)]
    Output(#[from] TraceError),
}

/// The truth columns a simulated trace carries beside the measured channels,
/// by their CSV names: the one list both the in-memory trace and the file use.
const TRUTH_COLUMNS: [(&str, fn(&TruthSample) -> f64); 7] = [
    ("x_m", |s| s.x_m),
    ("v_mps", |s| s.v_mps),
    ("valve_m", |s| s.valve_m),
    ("p_rear_true_pa", |s| s.p_rear_pa),
    ("p_front_true_pa", |s| s.p_front_pa),
    ("accel_true_mps2", |s| s.accel_mps2),
    ("friction_true_n", |s| s.friction_n),
];

/// [`TRUTH_COLUMNS`] in the order a trace's columns are written (by name, as
/// [`Trace::extra`] keeps them).
fn truth_columns_in_file_order() -> [(&'static str, fn(&TruthSample) -> f64); 7] {
    let mut c = TRUTH_COLUMNS;
    c.sort_by_key(|c| c.0);
    c
}

/// Where measured samples go: kept in memory or written as trace rows.
trait MeasuredSink {
    type Error;
    fn sample(&mut self, truth: &TruthSample, measured: ChainSample) -> Result<(), Self::Error>;
}

/// The run's samples through the sensor chain into a [`MeasuredSink`].
struct Measuring<O> {
    chain: SensorChain,
    out: O,
}

impl<O: MeasuredSink> TruthSink for Measuring<O> {
    type Error = O::Error;
    fn sample(&mut self, s: &TruthSample) -> Result<(), O::Error> {
        let m = self.chain.measure(s);
        self.out.sample(s, m)
    }
    fn impact(&mut self, e: &EventRecord) -> Result<(), O::Error> {
        self.chain.impact(e.t_s);
        Ok(())
    }
}

struct InMemory {
    truth: TruthTrace,
    measured: Measured,
}

impl MeasuredSink for InMemory {
    type Error = std::convert::Infallible;
    fn sample(&mut self, truth: &TruthSample, measured: ChainSample) -> Result<(), Self::Error> {
        self.truth.push(truth);
        self.measured.push(measured);
        Ok(())
    }
}

struct CsvSink {
    w: CsvWriter,
    columns: [(&'static str, fn(&TruthSample) -> f64); 7],
}

impl MeasuredSink for CsvSink {
    type Error = TraceError;
    fn sample(&mut self, truth: &TruthSample, m: ChainSample) -> Result<(), TraceError> {
        let [rear, front, accel] = m.values;
        self.w.row(
            truth.t_s,
            rear,
            front,
            accel,
            self.columns.iter().map(|(_, f)| f(truth)),
        )
    }
}

/// Runs `config` through the model and the sensor chain into `out`.
fn run_measured<O: MeasuredSink>(
    config: &SimConfig,
    out: O,
) -> Result<(RunSummary, O, [usize; 3]), RunError<O::Error>> {
    let chain = SensorChain::new(
        &config.sensors,
        &config.effects,
        config.solver.output_step_s,
        config.seed,
    );
    let mut sink = Measuring { chain, out };
    let summary = run_model(config, &mut sink)?;
    let clipped = sink.chain.clipped();
    Ok((summary, sink.out, clipped))
}

/// A simulation kept whole in memory (tests, figures, diagnosis).
pub fn simulate(config: &SimConfig) -> Result<Simulation, SolverError> {
    let out = InMemory {
        truth: TruthTrace::with_capacity_for(config),
        measured: Measured::with_capacity(crate::run::output_len(config)),
    };
    let (summary, out, clipped) = run_measured(config, out).map_err(|e| match e {
        RunError::Solver(e) => e,
        RunError::Sink(never) => match never {},
    })?;
    let mut measured = out.measured;
    measured.clipped = clipped;
    Ok(Simulation {
        config: config.clone(),
        run: SimRun {
            truth: out.truth,
            events: summary.events,
            cycles: summary.cycles,
            mass_balance: summary.mass_balance,
            stats: summary.stats,
        },
        measured,
    })
}

/// A streamed run ended by its consumer.
#[derive(Debug)]
pub struct Stopped;

/// The measured codes to a closure, nothing kept per sample.
struct CodeStream<F>(F);

impl<F: FnMut(RawSample) -> ControlFlow<()>> MeasuredSink for CodeStream<F> {
    type Error = Stopped;
    fn sample(&mut self, _: &TruthSample, m: ChainSample) -> Result<(), Stopped> {
        match (self.0)(m.codes) {
            ControlFlow::Continue(()) => Ok(()),
            ControlFlow::Break(()) => Err(Stopped),
        }
    }
}

/// Simulated time of an endless [`stream_codes`] run: 115 days, past any
/// demo or soak, and still a finite output grid.
pub const ENDLESS_S: f64 = 1e7;

/// The ADC codes a board would sample, handed to `sink` as the run makes
/// them: memory does not grow with the run's length beyond the per-cycle
/// records, so a board can be fed for as long as it runs. With `endless`
/// the run goes on past `solver.duration_s` until `sink` breaks; effects
/// that drift with time (wear) keep drifting. `Ok` when `sink` ended it or
/// the duration was reached.
pub fn stream_codes(
    config: &SimConfig,
    endless: bool,
    sink: impl FnMut(RawSample) -> ControlFlow<()>,
) -> Result<(), SolverError> {
    let mut cfg = config.clone();
    if endless {
        cfg.solver.duration_s = ENDLESS_S;
    }
    match run_measured(&cfg, CodeStream(sink)) {
        Ok(_) | Err(RunError::Sink(Stopped)) => Ok(()),
        Err(RunError::Solver(e)) => Err(e),
    }
}

/// With no trace to write the samples are dropped as they are made.
impl<O: MeasuredSink> MeasuredSink for Option<O> {
    type Error = O::Error;
    fn sample(&mut self, truth: &TruthSample, measured: ChainSample) -> Result<(), O::Error> {
        self.as_mut().map_or(Ok(()), |o| o.sample(truth, measured))
    }
}

/// A simulation streamed as it runs into the trace `out` and its sidecar (or
/// nowhere): memory stays bounded however long the run, only the cycles are
/// kept. The files are the ones [`Simulation::trace`] and
/// [`Simulation::sidecar`] would give for the same config.
pub fn simulate_to_file(config: &SimConfig, out: Option<&Path>) -> Result<SimulationInfo, SimulateError> {
    let columns = truth_columns_in_file_order();
    let names = columns.map(|c| c.0);
    let sink = match out {
        Some(path) => Some(CsvSink {
            w: CsvWriter::create(path, &names)?,
            columns,
        }),
        None => None,
    };
    let (summary, sink, clipped) = run_measured(config, sink).map_err(|e| match e {
        RunError::Solver(e) => SimulateError::Solver(e),
        RunError::Sink(e) => SimulateError::Output(e),
    })?;
    let info = SimulationInfo::new(config, summary.cycles, summary.mass_balance, summary.stats, clipped);
    if let (Some(sink), Some(path)) = (sink, out) {
        sink.w.finish()?;
        write_sidecar(path, &info.sidecar())?;
    }
    Ok(info)
}

/// The trace's columns filled as the run makes them, each allocated once
/// for the whole run: what a caller that wants the trace and nothing else
/// per sample keeps (the Python package's `simulate`).
struct TraceColumns {
    trace: Trace,
    truth: [Vec<f64>; 7],
}

impl MeasuredSink for TraceColumns {
    type Error = std::convert::Infallible;
    fn sample(&mut self, truth: &TruthSample, m: ChainSample) -> Result<(), Self::Error> {
        let [rear, front, accel] = m.values;
        self.trace.t_s.push(truth.t_s);
        self.trace.p_rear_pa.push(rear);
        self.trace.p_front_pa.push(front);
        self.trace.accel_mps2.push(accel);
        for (col, (_, f)) in self.truth.iter_mut().zip(TRUTH_COLUMNS) {
            col.push(f(truth));
        }
        Ok(())
    }
}

/// A simulation kept as its trace alone (the columns [`Simulation::trace`]
/// gives, the same values) and what its sidecar records: about a quarter
/// of [`simulate`]'s memory, which also keeps the solver's truth, the sensor
/// chain's codes and then copies them into the trace.
pub fn simulate_trace(config: &SimConfig) -> Result<(Trace, SimulationInfo), SolverError> {
    let n = crate::run::output_len(config);
    let column = || Vec::with_capacity(n);
    let out = TraceColumns {
        trace: Trace {
            dt_s: config.solver.output_step_s,
            t_s: column(),
            p_rear_pa: column(),
            p_front_pa: column(),
            accel_mps2: column(),
            extra: Default::default(),
            gaps: Vec::new(),
        },
        truth: std::array::from_fn(|_| column()),
    };
    let (summary, out, clipped) = run_measured(config, out).map_err(|e| match e {
        RunError::Solver(e) => e,
        RunError::Sink(never) => match never {},
    })?;
    let mut trace = out.trace;
    for ((name, _), col) in TRUTH_COLUMNS.iter().zip(out.truth) {
        trace.extra.insert(name.to_string(), col);
    }
    let info = SimulationInfo::new(config, summary.cycles, summary.mass_balance, summary.stats, clipped);
    Ok((trace, info))
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
        for (name, f) in TRUTH_COLUMNS {
            let col = (0..t.len()).map(|i| f(&t.sample(i))).collect();
            trace.extra.insert(name.to_string(), col);
        }
        trace
    }

    /// The ADC codes the bench board reads of this run, sample by sample.
    pub fn codes(&self) -> &[RawSample] {
        &self.measured.codes
    }

    /// What the sidecar records about this run.
    pub fn info(&self) -> SimulationInfo {
        SimulationInfo::new(
            &self.config,
            self.run.cycles.clone(),
            self.run.mass_balance,
            self.run.stats,
            self.measured.clipped,
        )
    }

    pub fn sidecar(&self) -> Sidecar {
        self.info().sidecar()
    }

    /// Cycles after the start-up transient (the first 0.1 s and the first two impacts).
    pub fn steady_cycles(&self) -> &[CycleTruth] {
        steady(&self.run.cycles)
    }

    /// A human-readable cycle summary.
    pub fn summary(&self) -> String {
        self.info().summary()
    }
}

fn steady(c: &[CycleTruth]) -> &[CycleTruth] {
    let first = c
        .iter()
        .position(|c| c.t_impact_s > 0.1 && c.index >= 2)
        .unwrap_or(c.len());
    &c[first..]
}

impl SimulationInfo {
    fn new(
        config: &SimConfig,
        cycles: Vec<CycleTruth>,
        mass_balance: MassBalance,
        solver: SolverStats,
        clipped_samples: [usize; 3],
    ) -> Self {
        Self {
            active_effects: config.effects.active().iter().map(|s| s.to_string()).collect(),
            config: config.clone(),
            cycles,
            mass_balance,
            solver,
            clipped_samples,
        }
    }

    pub fn sidecar(&self) -> Sidecar {
        let mut s = Sidecar::new(Some(self.config.supply.pressure_bar), "simulator");
        s.simulation = Some(self.clone());
        s
    }

    /// Cycles after the start-up transient (the first 0.1 s and the first two impacts).
    pub fn steady_cycles(&self) -> &[CycleTruth] {
        steady(&self.cycles)
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
        for c in &self.cycles {
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
        let st = &self.solver;
        let _ = writeln!(
            s,
            "solver: {} steps ({} rejected, {} stiff), {} restarts, {} rhs evaluations; clipped samples rear/front/accel: {:?}",
            st.accepted_steps, st.rejected_steps, st.stiff_steps, st.restarts, st.rhs_evaluations, self.clipped_samples
        );
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sensor::measure;
    use hammer_trace::trace::write_csv;

    /// The trace kept alone is the whole simulation's trace, value for
    /// value, with the same cycles and sidecar record.
    #[test]
    fn the_trace_kept_alone_is_the_simulations_trace() {
        let cfg = short_run_with_sensor_effects();
        let sim = simulate(&cfg).unwrap();
        let (trace, info) = simulate_trace(&cfg).unwrap();
        let whole = sim.trace();
        assert_eq!(trace.t_s.len(), whole.t_s.len());
        assert_eq!(trace.dt_s.to_bits(), whole.dt_s.to_bits());
        for (a, b) in [
            (&trace.t_s, &whole.t_s),
            (&trace.p_rear_pa, &whole.p_rear_pa),
            (&trace.p_front_pa, &whole.p_front_pa),
            (&trace.accel_mps2, &whole.accel_mps2),
        ] {
            assert!(a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits()));
        }
        assert_eq!(
            trace.extra.keys().collect::<Vec<_>>(),
            whole.extra.keys().collect::<Vec<_>>()
        );
        for (name, col) in &whole.extra {
            assert!(
                trace.extra[name]
                    .iter()
                    .zip(col)
                    .all(|(x, y)| x.to_bits() == y.to_bits()),
                "{name}"
            );
        }
        assert_eq!(info, sim.info());
    }

    /// The codes a simulation carries are the ADC's own (with the chain on:
    /// the code the channel converted, read back through the board's
    /// calibration without loss) and what a file of its values reads as.
    #[test]
    fn the_codes_are_the_adcs_and_a_file_of_the_values_reads_as_them() {
        for enabled in [true, false] {
            let mut cfg = short_run_with_sensor_effects();
            cfg.sensors.enabled = enabled;
            let sim = simulate(&cfg).unwrap();
            let est = cfg.estimator_config(None).unwrap();
            assert_eq!(sim.codes().len(), sim.run.truth.len());
            assert_eq!(
                sim.codes(),
                crate::estimation::to_codes(&sim.trace(), &est),
                "enabled {enabled}"
            );
            if enabled {
                let ch = &cfg.sensors.rear;
                for (c, v) in sim.codes().iter().zip(&sim.measured.p_rear_pa) {
                    assert_eq!(u32::from(c.rear), ch.code(*v), "{v}");
                }
            }
        }
    }

    fn short_run_with_sensor_effects() -> SimConfig {
        let mut cfg = SimConfig::nominal(5.0);
        cfg.solver.duration_s = 0.2;
        cfg.seed = 11;
        cfg.effects.apply_spec("accel_zero_shift").unwrap();
        cfg.effects.apply_spec("pressure_gain_error:rear=0.03").unwrap();
        cfg.effects.apply_spec("coulomb_friction").unwrap();
        cfg
    }

    /// The streamed files are byte for byte what the in-memory path writes.
    #[test]
    fn streamed_trace_and_sidecar_equal_the_in_memory_ones() {
        let cfg = short_run_with_sensor_effects();
        let dir = std::env::temp_dir().join(format!("hammer-sim-stream-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let (mem, streamed) = (dir.join("mem.csv"), dir.join("streamed.csv"));
        let sim = simulate(&cfg).unwrap();
        write_csv(&mem, &sim.trace()).unwrap();
        write_sidecar(&mem, &sim.sidecar()).unwrap();
        let info = simulate_to_file(&cfg, Some(&streamed)).unwrap();
        assert!(info.cycles.len() >= 3 && info.clipped_samples[2] > 0, "{info:?}");
        assert_eq!(info, sim.info());
        for ext in ["csv", "json"] {
            let a = std::fs::read(mem.with_extension(ext)).unwrap();
            let b = std::fs::read(streamed.with_extension(ext)).unwrap();
            assert!(a.len() > 1000 && a == b, "{ext} differs");
        }
        // Without a file the same run gives the same record.
        assert_eq!(simulate_to_file(&cfg, None).unwrap(), info);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// The sensor chain over a stored trace is the one that followed the run.
    #[test]
    fn measuring_a_stored_truth_repeats_the_streamed_measurement() {
        let cfg = short_run_with_sensor_effects();
        let sim = simulate(&cfg).unwrap();
        let again = measure(
            &cfg.sensors,
            &cfg.effects,
            &sim.run.truth,
            &sim.run.events.impacts,
            cfg.seed,
        );
        assert_eq!(again.accel_mps2, sim.measured.accel_mps2);
        assert_eq!(again.p_rear_pa, sim.measured.p_rear_pa);
        assert_eq!(again.clipped, sim.measured.clipped);
        // And the zero shift is really there: measured minus truth after an impact.
        let imp = sim.run.events.impacts[2].t_s;
        let i = (imp / sim.run.truth.dt_s) as usize + 200;
        assert!((sim.measured.accel_mps2[i] - sim.run.truth.accel_mps2[i]).abs() > 5.0);
    }

    /// A write failure ends the run with the path in the error, not a panic.
    #[test]
    fn an_unwritable_trace_is_an_error() {
        let cfg = short_run_with_sensor_effects();
        let e = simulate_to_file(&cfg, Some(Path::new("/nonexistent-dir/run.csv"))).unwrap_err();
        assert!(
            matches!(e, SimulateError::Output(_)) && e.to_string().contains("/nonexistent-dir/run.csv"),
            "{e}"
        );
    }
}
