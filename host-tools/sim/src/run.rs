//! Drives the integrator through the hammer's events and resamples the
//! solution onto the uniform output grid.

use serde::{Deserialize, Serialize};

use super::gas::P_ATM_PA;
use super::model::{self, HammerModel, N};
use super::params::SimConfig;
use super::solver::{SolverError, SolverStats};
pub use super::stepper::Stepper;

/// The noiseless solution on the output grid (SI, gauge pressures).
#[derive(Debug, Clone, Default)]
pub struct TruthTrace {
    pub dt_s: f64,
    pub t_s: Vec<f64>,
    pub x_m: Vec<f64>,
    pub v_mps: Vec<f64>,
    pub accel_mps2: Vec<f64>,
    pub p_rear_pa: Vec<f64>,
    pub p_front_pa: Vec<f64>,
    pub valve_m: Vec<f64>,
    pub friction_n: Vec<f64>,
    pub contact_n: Vec<f64>,
    pub supply_pa: Vec<f64>,
}

impl TruthTrace {
    pub fn len(&self) -> usize {
        self.t_s.len()
    }

    pub fn is_empty(&self) -> bool {
        self.t_s.is_empty()
    }

    /// An empty trace with room for the whole run of `cfg`.
    pub fn with_capacity_for(cfg: &SimConfig) -> Self {
        let n_out = output_len(cfg);
        let mut out = TruthTrace {
            dt_s: cfg.solver.output_step_s,
            ..Default::default()
        };
        for v in [
            &mut out.t_s,
            &mut out.x_m,
            &mut out.v_mps,
            &mut out.accel_mps2,
            &mut out.p_rear_pa,
            &mut out.p_front_pa,
            &mut out.valve_m,
            &mut out.friction_n,
            &mut out.contact_n,
            &mut out.supply_pa,
        ] {
            v.reserve_exact(n_out);
        }
        out
    }

    /// Row `i` (panics past the end, as indexing does).
    pub fn sample(&self, i: usize) -> TruthSample {
        TruthSample {
            index: i,
            t_s: self.t_s[i],
            x_m: self.x_m[i],
            v_mps: self.v_mps[i],
            accel_mps2: self.accel_mps2[i],
            p_rear_pa: self.p_rear_pa[i],
            p_front_pa: self.p_front_pa[i],
            valve_m: self.valve_m[i],
            friction_n: self.friction_n[i],
            contact_n: self.contact_n[i],
            supply_pa: self.supply_pa[i],
        }
    }

    pub fn push(&mut self, s: &TruthSample) {
        self.t_s.push(s.t_s);
        self.x_m.push(s.x_m);
        self.v_mps.push(s.v_mps);
        self.accel_mps2.push(s.accel_mps2);
        self.p_rear_pa.push(s.p_rear_pa);
        self.p_front_pa.push(s.p_front_pa);
        self.valve_m.push(s.valve_m);
        self.friction_n.push(s.friction_n);
        self.contact_n.push(s.contact_n);
        self.supply_pa.push(s.supply_pa);
    }
}

/// One point of the output grid: a row of [`TruthTrace`].
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct TruthSample {
    /// Position on the output grid (0 at t = 0).
    pub index: usize,
    pub t_s: f64,
    pub x_m: f64,
    pub v_mps: f64,
    pub accel_mps2: f64,
    pub p_rear_pa: f64,
    pub p_front_pa: f64,
    pub valve_m: f64,
    pub friction_n: f64,
    pub contact_n: f64,
    pub supply_pa: f64,
}

/// Where the run puts its output grid as it is produced, so a long run can
/// stream to disk in bounded memory while tests keep whole vectors: both go
/// through [`run_model`].
pub trait TruthSink {
    type Error;
    fn sample(&mut self, s: &TruthSample) -> Result<(), Self::Error>;
    /// An impact, reported after every sample up to its time.
    fn impact(&mut self, _impact: &EventRecord) -> Result<(), Self::Error> {
        Ok(())
    }
}

impl TruthSink for TruthTrace {
    type Error = std::convert::Infallible;
    fn sample(&mut self, s: &TruthSample) -> Result<(), Self::Error> {
        self.push(s);
        Ok(())
    }
}

/// Samples on the output grid of `cfg`, both ends included. The margin is in
/// samples and must outlast the quotient's rounding at 6e7 samples (600 s at
/// 10 µs, where an ulp is 7e-9): 1e-9 lost the last sample there.
pub fn output_len(cfg: &SimConfig) -> usize {
    (cfg.solver.duration_s / cfg.solver.output_step_s + 1e-6).floor() as usize + 1
}

/// Why a run stopped: the integrator failed, or the sink did.
#[derive(Debug, thiserror::Error)]
pub enum RunError<E> {
    #[error(transparent)]
    Solver(#[from] SolverError),
    #[error(transparent)]
    Sink(E),
}

/// What happened at an event, with the full state at that instant.
#[derive(Debug, Clone, Copy)]
pub struct EventRecord {
    pub t_s: f64,
    pub y: [f64; N],
}

#[derive(Debug, Clone, Default)]
pub struct Events {
    /// Contact onsets (the impacts).
    pub impacts: Vec<EventRecord>,
    /// Contact ends (piston leaves the shank).
    pub contact_ends: Vec<EventRecord>,
    /// Velocity crossing zero upwards: backhaul turns into stroke.
    pub stroke_starts: Vec<EventRecord>,
}

/// Ground truth of one impact cycle: the stroke that ends in impact `index`
/// and the backhaul that preceded it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CycleTruth {
    pub index: usize,
    pub t_impact_s: f64,
    pub impact_velocity_mps: f64,
    pub impact_energy_j: f64,
    pub period_s: f64,
    pub frequency_hz: f64,
    /// From the backhaul's turning point to the impact position.
    pub stroke_m: f64,
    pub t_stroke_start_s: f64,
    pub t_backhaul_start_s: f64,
    /// Mean friction magnitude over the stroke and the backhaul (contact excluded).
    pub friction_stroke_n: f64,
    pub friction_backhaul_n: f64,
    pub friction_cycle_n: f64,
    /// Energy dissipated by friction over the whole cycle and over the stroke alone.
    pub friction_work_j: f64,
    pub friction_work_stroke_j: f64,
    pub pressure_work_j: f64,
    /// Net work of the contact forces over the cycle (negative: energy to the shank).
    pub contact_work_j: f64,
    /// Pressure − friction + contact + gravity work − ΔKE over the cycle.
    pub energy_residual_j: f64,
    pub peak_rear_pa: f64,
    pub peak_front_pa: f64,
    /// Air drawn from the source over the cycle (absent in sidecars written
    /// before it was recorded).
    #[serde(default)]
    pub air_drawn_kg: f64,
    /// Heat the walls gave both chambers' air over the cycle (negative:
    /// the air lost it; absent in sidecars written before it was
    /// recorded). A truth of the chambers' heat flow, not a size of heat
    /// exchange: the net heat is what the air gains where expansion cooled
    /// it less what it loses where compression warmed it, and does not
    /// grow steadily with h (examples/heat_equivalent.rs).
    #[serde(default)]
    pub wall_heat_j: f64,
    /// Heat that crossed the chambers' walls over the cycle, either way:
    /// heat exchange's size as a heat quantity. Unlike the net
    /// `wall_heat_j` it grows with the walls' film coefficient, and it is
    /// defined for any law of the walls, so a named heat exchange is
    /// scored against the hammer's own (absent in older sidecars).
    #[serde(default)]
    pub heat_exchanged_j: f64,
    /// Air that went through the leak paths over the cycle (past the
    /// piston either way, and out past the rod): leakage's size as a mass,
    /// whatever the gap's law (absent in older sidecars).
    #[serde(default)]
    pub leaked_kg: f64,
}

/// Air mass bookkeeping over the run.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct MassBalance {
    pub drawn_kg: f64,
    pub vented_kg: f64,
    pub stored_change_kg: f64,
    /// drawn − vented − stored change.
    pub residual_kg: f64,
}

pub struct SimRun {
    pub truth: TruthTrace,
    pub events: Events,
    pub cycles: Vec<CycleTruth>,
    pub mass_balance: MassBalance,
    pub stats: SolverStats,
}

/// What a run keeps beside the samples it hands to its sink: small, growing
/// with the number of cycles only.
pub struct RunSummary {
    pub events: Events,
    pub cycles: Vec<CycleTruth>,
    pub mass_balance: MassBalance,
    pub stats: SolverStats,
}

/// Runs the model of `cfg` and extracts its per-cycle truth.
pub fn simulate_truth(cfg: &SimConfig) -> Result<SimRun, SolverError> {
    let mut truth = TruthTrace::with_capacity_for(cfg);
    let summary = run_model(cfg, &mut truth).map_err(|e| match e {
        RunError::Solver(e) => e,
        RunError::Sink(never) => match never {},
    })?;
    Ok(SimRun {
        truth,
        events: summary.events,
        cycles: summary.cycles,
        mass_balance: summary.mass_balance,
        stats: summary.stats,
    })
}

/// Runs the model of `cfg`, handing each output sample and impact to `sink`
/// as it is produced; the per-cycle truth is extracted on the fly. One
/// [`Stepper`] advanced to the end in one go: a run advanced in pieces
/// gives the same samples.
pub fn run_model<S: TruthSink>(cfg: &SimConfig, sink: &mut S) -> Result<RunSummary, RunError<S::Error>> {
    let mut stepper = Stepper::new(cfg);
    stepper.advance_to(f64::INFINITY, sink)?;
    stepper.finish(sink)
}

pub(crate) fn truth_sample(model: &HammerModel, index: usize, t: f64, y: &[f64; N]) -> TruthSample {
    let f = model.piston_forces(t, y);
    TruthSample {
        index,
        t_s: t,
        x_m: y[model::X],
        v_mps: y[model::V],
        accel_mps2: f.total_n() / model.mass_kg,
        p_rear_pa: y[model::P1] - P_ATM_PA,
        p_front_pa: y[model::P2] - P_ATM_PA,
        valve_m: y[model::XV],
        friction_n: f.friction_n,
        contact_n: f.contact_n,
        supply_pa: y[model::PS] - P_ATM_PA,
    }
}

fn kinetic_j(m: f64, y: &[f64; N]) -> f64 {
    0.5 * m * y[model::V] * y[model::V]
}

/// A running sum of friction over samples (a mean needs no stored samples).
#[derive(Debug, Clone, Copy, Default)]
struct FrictionSum {
    sum_n: f64,
    samples: usize,
}

impl FrictionSum {
    fn mean_n(&self) -> f64 {
        if self.samples == 0 {
            0.0
        } else {
            self.sum_n / self.samples as f64
        }
    }
}

/// Extracts the per-cycle truth while the run goes, from the events and the
/// samples between them, so no trace has to be kept. A cycle is the stroke
/// that ends in an impact and the backhaul before it: from the first contact
/// end after the previous impact, through the last stroke start, to the impact.
/// Every sample counts towards the interval it was produced in (a sample at an
/// event's time belongs to the interval before it).
pub(crate) struct CycleTracker {
    mass_kg: f64,
    x_impact_m: f64,
    impacts_seen: usize,
    prev_impact: Option<EventRecord>,
    contact_end: Option<EventRecord>,
    /// Friction (sign: opposing the backhaul) since `contact_end`.
    backhaul: FrictionSum,
    /// The last stroke start and the backhaul sum up to it.
    stroke_start: Option<(EventRecord, FrictionSum)>,
    /// Friction (sign: opposing the stroke) since `stroke_start`.
    stroke: FrictionSum,
    peak_rear_pa: f64,
    peak_front_pa: f64,
    pub(crate) cycles: Vec<CycleTruth>,
}

impl CycleTracker {
    pub(crate) fn new(model: &HammerModel) -> Self {
        Self {
            mass_kg: model.mass_kg,
            x_impact_m: model.x_impact_m,
            impacts_seen: 0,
            prev_impact: None,
            contact_end: None,
            backhaul: FrictionSum::default(),
            stroke_start: None,
            stroke: FrictionSum::default(),
            peak_rear_pa: f64::NEG_INFINITY,
            peak_front_pa: f64::NEG_INFINITY,
            cycles: Vec::new(),
        }
    }

    pub(crate) fn sample(&mut self, s: &TruthSample) {
        if self.prev_impact.is_none() {
            return;
        }
        self.peak_rear_pa = self.peak_rear_pa.max(s.p_rear_pa);
        self.peak_front_pa = self.peak_front_pa.max(s.p_front_pa);
        if self.contact_end.is_some() {
            self.backhaul.sum_n += s.friction_n;
            self.backhaul.samples += 1;
        }
        if self.stroke_start.is_some() {
            self.stroke.sum_n -= s.friction_n;
            self.stroke.samples += 1;
        }
    }

    pub(crate) fn contact_end(&mut self, e: &EventRecord) {
        if self.prev_impact.is_some() && self.contact_end.is_none() {
            self.contact_end = Some(*e);
            self.backhaul = FrictionSum::default();
        }
    }

    pub(crate) fn stroke_start(&mut self, e: &EventRecord) {
        if self.contact_end.is_some() {
            self.stroke_start = Some((*e, self.backhaul));
            self.stroke = FrictionSum::default();
        }
    }

    pub(crate) fn impact(&mut self, imp: &EventRecord) {
        let k = self.impacts_seen;
        self.impacts_seen += 1;
        if let (Some(prev), Some(ce), Some((ss, backhaul))) = (self.prev_impact, self.contact_end, self.stroke_start) {
            let m = self.mass_kg;
            let (fs, fb) = (self.stroke.mean_n(), backhaul.mean_n());
            let (ns, nb) = (self.stroke.samples as f64, backhaul.samples as f64);
            let fc = if ns + nb > 0.0 {
                (fs * ns + fb * nb) / (ns + nb)
            } else {
                0.0
            };
            let d = |c: usize| imp.y[c] - prev.y[c];
            let residual = d(model::W_PRESSURE) - d(model::W_FRICTION) + d(model::W_CONTACT) + d(model::W_GRAVITY)
                - (kinetic_j(m, &imp.y) - kinetic_j(m, &prev.y));
            let v_imp = imp.y[model::V];
            let period = imp.t_s - prev.t_s;
            self.cycles.push(CycleTruth {
                index: k,
                t_impact_s: imp.t_s,
                impact_velocity_mps: v_imp,
                impact_energy_j: 0.5 * m * v_imp * v_imp,
                period_s: period,
                frequency_hz: 1.0 / period,
                stroke_m: self.x_impact_m - ss.y[model::X],
                t_stroke_start_s: ss.t_s,
                t_backhaul_start_s: ce.t_s,
                friction_stroke_n: fs,
                friction_backhaul_n: fb,
                friction_cycle_n: fc,
                friction_work_j: d(model::W_FRICTION),
                friction_work_stroke_j: imp.y[model::W_FRICTION] - ss.y[model::W_FRICTION],
                pressure_work_j: d(model::W_PRESSURE),
                contact_work_j: d(model::W_CONTACT),
                energy_residual_j: residual,
                peak_rear_pa: self.peak_rear_pa,
                peak_front_pa: self.peak_front_pa,
                air_drawn_kg: d(model::M_IN),
                wall_heat_j: d(model::Q_WALL),
                heat_exchanged_j: d(model::Q_EXCHANGED),
                leaked_kg: d(model::M_LEAKED),
            });
        }
        self.prev_impact = Some(*imp);
        self.contact_end = None;
        self.stroke_start = None;
        self.peak_rear_pa = f64::NEG_INFINITY;
        self.peak_front_pa = f64::NEG_INFINITY;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_output_grid_ends_at_the_duration_for_long_runs_too() {
        let mut cfg = SimConfig::default();
        for (duration_s, dt_s, n) in [
            (0.3, 10e-6, 30_001),
            (0.5, 10e-6, 50_001),
            (600.0, 10e-6, 60_000_001),
            (600.0, 1e-6, 600_000_001),
            (0.0105, 1e-3, 11),
        ] {
            cfg.solver.duration_s = duration_s;
            cfg.solver.output_step_s = dt_s;
            assert_eq!(output_len(&cfg), n, "{duration_s} s at {dt_s} s");
        }
    }
}
