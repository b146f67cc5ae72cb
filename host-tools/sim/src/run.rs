//! Drives the integrator through the hammer's events and resamples the
//! solution onto the uniform output grid.

use serde::{Deserialize, Serialize};

use super::gas::P_ATM_PA;
use super::model::{self, HammerModel, N, N_DYN};
use super::params::SimConfig;
use super::solver::{Dense, Dopri5, SolverError, SolverStats, MIN_STEP_S};

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

#[derive(Debug, Clone, Copy, PartialEq)]
enum EventKind {
    Kink,
    ContactOnset,
    ContactEnd,
    ValveLeftStop,
    ValveRightStop,
    StrokeStart,
    VelocityZeroDown,
}

struct EventFn {
    kind_up: Option<EventKind>,
    kind_down: Option<EventKind>,
    component: usize,
    level: f64,
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
/// as it is produced; the per-cycle truth is extracted on the fly.
pub fn run_model<S: TruthSink>(cfg: &SimConfig, sink: &mut S) -> Result<RunSummary, RunError<S::Error>> {
    let model = HammerModel::new(cfg);
    let y0 = model.initial_state(cfg.hammer.initial_position_m);
    let rtol = cfg.solver.rtol;
    let mut atol = [0.0; N];
    let scale = [0.05, 3.0, 1e-4, 5e5, 1e-4, 5e5, 2e-3, 2.0, 5e5, 30.0];
    for i in 0..N_DYN {
        atol[i] = rtol * scale[i];
    }
    let mut solver = Dopri5::new(&model, 0.0, y0, rtol, atol, N_DYN, cfg.solver.max_step_s);

    let mut fns = Vec::new();
    for level in model.kink_positions() {
        let is_contact = (level - model.x_impact_m).abs() < 1e-15;
        fns.push(EventFn {
            kind_up: Some(if is_contact {
                EventKind::ContactOnset
            } else {
                EventKind::Kink
            }),
            kind_down: Some(if is_contact {
                EventKind::ContactEnd
            } else {
                EventKind::Kink
            }),
            component: model::X,
            level,
        });
    }
    fns.push(EventFn {
        kind_up: Some(EventKind::Kink),
        kind_down: Some(EventKind::Kink),
        component: model::X,
        level: 0.0,
    });
    for level in model.valve_kinks() {
        fns.push(EventFn {
            kind_up: Some(EventKind::Kink),
            kind_down: Some(EventKind::Kink),
            component: model::XV,
            level,
        });
    }
    fns.push(EventFn {
        kind_up: None,
        kind_down: Some(EventKind::ValveLeftStop),
        component: model::XV,
        level: 0.0,
    });
    fns.push(EventFn {
        kind_up: Some(EventKind::ValveRightStop),
        kind_down: None,
        component: model::XV,
        level: model.valve_travel_m,
    });
    fns.push(EventFn {
        kind_up: Some(EventKind::StrokeStart),
        kind_down: Some(EventKind::VelocityZeroDown),
        component: model::V,
        level: 0.0,
    });

    let t_end = cfg.solver.duration_s;
    let dt = cfg.solver.output_step_s;
    let n_out = output_len(cfg);
    let mut cycles = CycleTracker::new(&model);
    let emit = |cycles: &mut CycleTracker, sink: &mut S, index: usize, t: f64, y: &[f64; N]| {
        let s = truth_sample(&model, index, t, y);
        cycles.sample(&s);
        sink.sample(&s).map_err(RunError::Sink)
    };
    let mut next_out = 0usize;
    emit(&mut cycles, sink, next_out, 0.0, &y0)?;
    next_out += 1;

    let mut events = Events::default();
    // The redone step may stop a rounding error short of the crossing; the same
    // crossing must then not count twice.
    let mut last_event: Option<(usize, f64)> = None;
    while solver.t < t_end {
        let checkpoint = solver.checkpoint();
        let t0 = solver.t;
        let ya = solver.y;
        let mut dense = solver.step(&model, t_end)?;
        let mut earliest = first_event(&fns, &dense, &ya, &solver.y, last_event);
        if let Some((te, _, _)) = earliest {
            // The step's later stages saw the far side of a discontinuity, so
            // its interpolant is polluted there: redo it to end at the event.
            if te - t0 >= MIN_STEP_S {
                solver.rewind(&checkpoint);
                dense = solver.step(&model, te)?;
                if solver.t < te {
                    earliest = None; // error control cut the step short; look again next step
                }
            } else {
                dense = Dense::constant(t0, &ya);
            }
        }
        let t_stop = solver.t;
        while next_out < n_out {
            let t = next_out as f64 * dt;
            if t > t_stop {
                break;
            }
            // Only the states the output needs.
            let mut y = [0.0; N];
            dense.at_into(
                t,
                &[model::X, model::V, model::P1, model::P2, model::XV, model::PS],
                &mut y,
            );
            emit(&mut cycles, sink, next_out, t, &y)?;
            next_out += 1;
        }

        if let Some((_, kind, which)) = earliest {
            let te = solver.t;
            last_event = Some((which, te));
            let mut y = solver.y;
            let rec = EventRecord { t_s: te, y };
            match kind {
                EventKind::ContactOnset => {
                    model.contact_v_in.set(y[model::V]);
                    cycles.impact(&rec);
                    sink.impact(&rec).map_err(RunError::Sink)?;
                    events.impacts.push(rec);
                }
                EventKind::ContactEnd => {
                    cycles.contact_end(&rec);
                    events.contact_ends.push(rec);
                }
                EventKind::StrokeStart => {
                    cycles.stroke_start(&rec);
                    events.stroke_starts.push(rec);
                }
                EventKind::ValveLeftStop => {
                    y[model::XV] = 0.0;
                    y[model::VV] = 0.0;
                }
                EventKind::ValveRightStop => {
                    y[model::XV] = model.valve_travel_m;
                    y[model::VV] = 0.0;
                }
                EventKind::Kink | EventKind::VelocityZeroDown => {}
            }
            solver.restart(&model, te, y);
        }
    }
    // The last grid point may sit a rounding error past t_end.
    while next_out < n_out {
        let t = next_out as f64 * dt;
        emit(&mut cycles, sink, next_out, t, &solver.y)?;
        next_out += 1;
    }

    let stored = |y: &[f64; N]| y[model::M1] + y[model::M2] + model.line_mass_kg(y);
    let yf = solver.y;
    let drawn = yf[model::M_IN];
    let vented = yf[model::M_OUT];
    let stored_change = stored(&yf) - stored(&y0);
    let mass_balance = MassBalance {
        drawn_kg: drawn,
        vented_kg: vented,
        stored_change_kg: stored_change,
        residual_kg: drawn - vented - stored_change,
    };
    Ok(RunSummary {
        events,
        cycles: cycles.cycles,
        mass_balance,
        stats: solver.stats,
    })
}

/// The earliest event function that changes sign over the step.
fn first_event(
    fns: &[EventFn],
    dense: &Dense<N>,
    ya: &[f64; N],
    yb: &[f64; N],
    last: Option<(usize, f64)>,
) -> Option<(f64, EventKind, usize)> {
    let mut earliest: Option<(f64, EventKind, usize)> = None;
    for (which, f) in fns.iter().enumerate() {
        let g0 = ya[f.component] - f.level;
        let g1 = yb[f.component] - f.level;
        let kind = if g0 < 0.0 && g1 >= 0.0 {
            f.kind_up
        } else if g0 > 0.0 && g1 <= 0.0 {
            f.kind_down
        } else {
            None
        };
        if let Some(kind) = kind {
            let tr = locate(dense, dense.t0, dense.t1(), f.component, f.level, g0);
            if last.is_some_and(|(w, t)| w == which && tr - t < 1e-9) {
                continue;
            }
            if earliest.is_none_or(|(te, _, _)| tr < te) {
                earliest = Some((tr, kind, which));
            }
        }
    }
    earliest
}

/// Bisection on the dense output; returns the first time on the far side of the crossing.
fn locate(dense: &Dense<N>, t0: f64, t1: f64, c: usize, level: f64, g0: f64) -> f64 {
    let (mut lo, mut hi) = (t0, t1);
    for _ in 0..60 {
        let mid = 0.5 * (lo + hi);
        if mid <= lo || mid >= hi {
            break;
        }
        let g = dense.at(mid, c) - level;
        if (g < 0.0) == (g0 < 0.0) && g != 0.0 {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    hi
}

fn truth_sample(model: &HammerModel, index: usize, t: f64, y: &[f64; N]) -> TruthSample {
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
struct CycleTracker {
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
    cycles: Vec<CycleTruth>,
}

impl CycleTracker {
    fn new(model: &HammerModel) -> Self {
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

    fn sample(&mut self, s: &TruthSample) {
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

    fn contact_end(&mut self, e: &EventRecord) {
        if self.prev_impact.is_some() && self.contact_end.is_none() {
            self.contact_end = Some(*e);
            self.backhaul = FrictionSum::default();
        }
    }

    fn stroke_start(&mut self, e: &EventRecord) {
        if self.contact_end.is_some() {
            self.stroke_start = Some((*e, self.backhaul));
            self.stroke = FrictionSum::default();
        }
    }

    fn impact(&mut self, imp: &EventRecord) {
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
