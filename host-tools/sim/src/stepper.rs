//! The hammer's model advanced from outside: [`Stepper::advance_to`] takes
//! it to a communication point and hands every output sample up to it to a
//! sink, as a co-simulation master (an FMU's `doStep`) or a streamed run
//! asks. The integrator's own steps ignore the communication points: a step
//! that runs past one is kept, its samples beyond it handed out on the next
//! call, so the trajectory and every sample are the same however the run is
//! cut into pieces, and the same as [`crate::run::run_model`]'s, which is
//! one stepper advanced to the end.
//!
//! Events (impacts, contact ends, valve stops, the position kinks of ports
//! and outlets, the turning points) are located inside the steps by the
//! sign of their functions on the dense output, whatever the piece.

use super::model::{self, HammerModel, N, N_DYN};
use super::params::SimConfig;
use super::run::{
    output_len, truth_sample, CycleTracker, EventRecord, Events, MassBalance, RunError, RunSummary, TruthSample,
    TruthSink,
};
use super::solver::{Dense, Dopri5, MIN_STEP_S};

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

/// The state components each output sample is interpolated for: what the
/// truth sample needs. The others are not interpolated between steps (each
/// costs time on every sample).
const TRUTH: [usize; 6] = [model::X, model::V, model::P1, model::P2, model::XV, model::PS];

/// [`TRUTH`] and the chambers' masses, for a co-simulation's outputs (their
/// temperatures follow from p·V = m·R·T): [`Stepper::with_chamber_masses`].
pub const SAMPLED: [usize; 8] = [
    model::X,
    model::V,
    model::P1,
    model::P2,
    model::XV,
    model::PS,
    model::M1,
    model::M2,
];

/// The output side of a run: the grid, the cycles' truth, the last
/// sample's state. Apart from the integrator's fields so the hot loop reads
/// the step's interpolant in place (a step's interpolant is 0.7 KB: moved
/// in and out of an `Option` at every step it cost the run a tenth of its
/// speed).
struct Output {
    cycles: CycleTracker,
    next_out: usize,
    n_out: usize,
    dt: f64,
    /// The state at the last sample handed out ([`SAMPLED`] components),
    /// kept only [`Stepper::with_chamber_masses`].
    last_state: [f64; N],
    /// Whether each sample interpolates [`SAMPLED`] and keeps its state,
    /// or only [`TRUTH`].
    masses: bool,
}

impl Output {
    #[inline(always)]
    fn emit<S: TruthSink>(
        &mut self,
        model: &HammerModel,
        sink: &mut S,
        t: f64,
        y: &[f64; N],
    ) -> Result<(), RunError<S::Error>> {
        let s: TruthSample = truth_sample(model, self.next_out, t, y);
        self.cycles.sample(&s);
        if self.masses {
            self.last_state = *y;
        }
        self.next_out += 1;
        sink.sample(&s).map_err(RunError::Sink)
    }

    /// The time of the next output sample (past the last one: infinity).
    fn next_sample_s(&self) -> f64 {
        if self.next_out < self.n_out {
            self.next_out as f64 * self.dt
        } else {
            f64::INFINITY
        }
    }

    /// Hands `sink` the samples on `dense` up to `t_stop` (the step's end)
    /// and `t_s` (the communication point): the hot loop of every run.
    fn emit_step<S: TruthSink>(
        &mut self,
        model: &HammerModel,
        dense: &Dense<N>,
        t_stop: f64,
        t_s: f64,
        sink: &mut S,
    ) -> Result<(), RunError<S::Error>> {
        while self.next_out < self.n_out {
            let t = self.next_out as f64 * self.dt;
            if t > t_stop || t > t_s {
                break;
            }
            // Only the states the output needs.
            let mut y = [0.0; N];
            if self.masses {
                dense.at_into(t, &SAMPLED, &mut y);
            } else {
                dense.at_into(t, &TRUTH, &mut y);
            }
            self.emit(model, sink, t, &y)?;
        }
        Ok(())
    }
}

/// One run of the model, advanced piece by piece.
pub struct Stepper {
    model: HammerModel,
    solver: Dopri5<N>,
    fns: Vec<EventFn>,
    events: Events,
    /// The redone step may stop a rounding error short of the crossing; the
    /// same crossing must then not count twice.
    last_event: Option<(usize, f64)>,
    /// The interpolant of the last step taken.
    dense: Dense<N>,
    /// A step taken whose samples are not all handed out yet, or whose
    /// event is not yet applied: `Some` of its earliest event.
    pending: Option<Option<(f64, EventKind, usize)>>,
    y0: [f64; N],
    t_end: f64,
    out: Output,
}

impl Stepper {
    /// The model of `cfg` at rest at t = 0, to run until `solver.duration_s`.
    pub fn new(cfg: &SimConfig) -> Self {
        let model = HammerModel::new(cfg);
        let y0 = model.initial_state(cfg.hammer.initial_position_m);
        let rtol = cfg.solver.rtol;
        let mut atol = [0.0; N];
        let scale = [0.05, 3.0, 1e-4, 5e5, 1e-4, 5e5, 2e-3, 2.0, 5e5, 30.0];
        for i in 0..N_DYN {
            atol[i] = rtol * scale[i];
        }
        let solver = Dopri5::new(&model, 0.0, y0, rtol, atol, N_DYN, cfg.solver.max_step_s);
        let fns = event_functions(&model);
        let cycles = CycleTracker::new(&model);
        Self {
            model,
            solver,
            fns,
            events: Events::default(),
            last_event: None,
            dense: Dense::constant(0.0, &y0),
            pending: None,
            y0,
            t_end: cfg.solver.duration_s,
            out: Output {
                cycles,
                next_out: 0,
                n_out: output_len(cfg),
                dt: cfg.solver.output_step_s,
                last_state: y0,
                masses: false,
            },
        }
    }

    /// Interpolates the chambers' masses at each sample too, for
    /// [`Stepper::last_sample_state`] ([`SAMPLED`]). The samples handed to
    /// the sink are the same.
    pub fn with_chamber_masses(mut self) -> Self {
        self.out.masses = true;
        self
    }

    /// The time of the next output sample (past the last one: infinity).
    pub fn next_sample_s(&self) -> f64 {
        self.out.next_sample_s()
    }

    /// The impacts so far, with the state at each.
    pub fn events(&self) -> &Events {
        &self.events
    }

    /// The state at the last output sample handed to a sink (before the
    /// first: the initial state). Only the [`SAMPLED`] components are meant
    /// to be read, and only [`Stepper::with_chamber_masses`].
    pub fn last_sample_state(&self) -> &[f64; N] {
        &self.out.last_state
    }

    /// The model this stepper runs.
    pub fn model(&self) -> &HammerModel {
        &self.model
    }

    /// Advances until every output sample at or before `t_s` (and before
    /// the run's end) has gone to `sink`, with each impact after the
    /// samples up to its time.
    pub fn advance_to<S: TruthSink>(&mut self, t_s: f64, sink: &mut S) -> Result<(), RunError<S::Error>> {
        if self.out.next_out == 0 && t_s >= 0.0 {
            let y0 = self.y0;
            self.out.emit(&self.model, sink, 0.0, &y0)?;
        }
        loop {
            if let Some(event) = self.pending {
                // The samples of the step taken, up to the communication point.
                let t_stop = self.solver.t;
                self.out.emit_step(&self.model, &self.dense, t_stop, t_s, sink)?;
                if self.out.next_sample_s() <= t_stop {
                    // The step runs past the communication point: kept for the next call.
                    return Ok(());
                }
                self.pending = None;
                if let Some((_, kind, which)) = event {
                    self.apply_event(kind, which, sink)?;
                }
            }
            if self.solver.t >= self.t_end || self.out.next_sample_s() > t_s {
                return Ok(());
            }
            self.take_step()?;
        }
    }

    /// One integrator step, redone to end at its earliest event.
    fn take_step<E>(&mut self) -> Result<(), RunError<E>> {
        let checkpoint = self.solver.checkpoint();
        let t0 = self.solver.t;
        let ya = self.solver.y;
        self.dense = self.solver.step(&self.model, self.t_end)?;
        let mut earliest = first_event(&self.fns, &self.dense, &ya, &self.solver.y, self.last_event);
        if let Some((te, _, _)) = earliest {
            // The step's later stages saw the far side of a discontinuity, so
            // its interpolant is polluted there: redo it to end at the event.
            if te - t0 >= MIN_STEP_S {
                self.solver.rewind(&checkpoint);
                self.dense = self.solver.step(&self.model, te)?;
                if self.solver.t < te {
                    earliest = None; // error control cut the step short; look again next step
                }
            } else {
                self.dense = Dense::constant(t0, &ya);
            }
        }
        self.pending = Some(earliest);
        Ok(())
    }

    fn apply_event<S: TruthSink>(
        &mut self,
        kind: EventKind,
        which: usize,
        sink: &mut S,
    ) -> Result<(), RunError<S::Error>> {
        let te = self.solver.t;
        self.last_event = Some((which, te));
        let mut y = self.solver.y;
        let rec = EventRecord { t_s: te, y };
        match kind {
            EventKind::ContactOnset => {
                self.model.contact_v_in.set(y[model::V]);
                self.out.cycles.impact(&rec);
                sink.impact(&rec).map_err(RunError::Sink)?;
                self.events.impacts.push(rec);
            }
            EventKind::ContactEnd => {
                self.out.cycles.contact_end(&rec);
                self.events.contact_ends.push(rec);
            }
            EventKind::StrokeStart => {
                self.out.cycles.stroke_start(&rec);
                self.events.stroke_starts.push(rec);
            }
            EventKind::ValveLeftStop => {
                y[model::XV] = 0.0;
                y[model::VV] = 0.0;
            }
            EventKind::ValveRightStop => {
                y[model::XV] = self.model.valve_travel_m;
                y[model::VV] = 0.0;
            }
            EventKind::Kink | EventKind::VelocityZeroDown => {}
        }
        self.solver.restart(&self.model, te, y);
        Ok(())
    }

    /// Ends the run: the samples left to its end (the last grid point may
    /// sit a rounding error past it), the cycles and the mass balance.
    pub fn finish<S: TruthSink>(mut self, sink: &mut S) -> Result<RunSummary, RunError<S::Error>> {
        self.advance_to(f64::INFINITY, sink)?;
        while self.out.next_out < self.out.n_out {
            let t = self.out.next_out as f64 * self.out.dt;
            let y = self.solver.y;
            self.out.emit(&self.model, sink, t, &y)?;
        }
        let model = &self.model;
        let stored = |y: &[f64; N]| y[model::M1] + y[model::M2] + model.line_mass_kg(y);
        let yf = self.solver.y;
        let drawn = yf[model::M_IN];
        let vented = yf[model::M_OUT];
        let stored_change = stored(&yf) - stored(&self.y0);
        let mass_balance = MassBalance {
            drawn_kg: drawn,
            vented_kg: vented,
            stored_change_kg: stored_change,
            residual_kg: drawn - vented - stored_change,
        };
        Ok(RunSummary {
            events: self.events,
            cycles: self.out.cycles.cycles,
            mass_balance,
            stats: self.solver.stats,
        })
    }
}

/// The event functions of `model`: its position kinks (contact among them),
/// the valve's kinks and stops, and the piston's turning points.
fn event_functions(model: &HammerModel) -> Vec<EventFn> {
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
    fns
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::run::{run_model, TruthTrace};

    fn config() -> SimConfig {
        let mut cfg = SimConfig::default();
        cfg.solver.duration_s = 0.25;
        cfg.effects.apply_spec("coulomb_friction").unwrap();
        cfg
    }

    fn bits(t: &TruthTrace) -> Vec<[u64; 6]> {
        (0..t.len())
            .map(|i| {
                let s = t.sample(i);
                [s.t_s, s.x_m, s.v_mps, s.p_rear_pa, s.accel_mps2, s.valve_m].map(f64::to_bits)
            })
            .collect()
    }

    /// Advanced in pieces of any size (communication steps that are and
    /// are not multiples of the output step, shorter and longer than the
    /// integrator's steps), the run gives the whole run's samples, impacts
    /// and cycles bit for bit.
    #[test]
    fn the_trajectory_does_not_depend_on_how_it_is_cut() {
        let cfg = config();
        let mut whole = TruthTrace::with_capacity_for(&cfg);
        let summary = run_model(&cfg, &mut whole).unwrap();
        assert!(summary.cycles.len() >= 3, "{} cycles", summary.cycles.len());
        for piece_s in [10e-6, 37e-6, 1e-3, 3.3e-3, 0.05] {
            let mut stepper = Stepper::new(&cfg);
            let mut pieces = TruthTrace::with_capacity_for(&cfg);
            let mut t = 0.0;
            let mut impacts_seen = Vec::new();
            while t < cfg.solver.duration_s {
                t += piece_s;
                stepper.advance_to(t, &mut pieces).unwrap();
                assert!(stepper.next_sample_s() > t, "every sample up to {t} s handed out");
                impacts_seen.push(stepper.events().impacts.len());
            }
            let s = stepper.finish(&mut pieces).unwrap();
            assert_eq!(bits(&pieces), bits(&whole), "pieces of {piece_s} s");
            assert_eq!(s.cycles, summary.cycles, "pieces of {piece_s} s");
            assert_eq!(s.stats, summary.stats, "the integrator's steps ignore the pieces");
            assert!(impacts_seen.windows(2).all(|w| w[0] <= w[1]));
        }
    }
}
