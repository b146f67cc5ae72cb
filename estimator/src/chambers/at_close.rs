//! One cycle's characteristics at its close, from the cycle's ADC codes and
//! its report: what a board computes, no_std and f32 from the codes on.
//!
//! The reading is the host's reading of a one-cycle raw capture
//! (`hammer_sim::characteristics::characterise_spans` with a tail), step for
//! step: the pressures read back by their group delay; the piston's track
//! closed between the cycle's two impacts, once from the accelerometer (the
//! value) and once from the force balance (its spread widens the
//! uncertainties); after the closing impact, where a front feed may start,
//! the accelerometer integrated from the rebound the cycle's own opening
//! impact gave (a steady hammer rebounds alike from each impact). Only the
//! samples of the cycle and [`LOOK_AFTER_S`] after it are needed, so the
//! report of a cycle can wait for them (`docs/estimator.md`).
//!
//! f32 throughout: the geometry comes from the configuration's f32 fields
//! ([`ChamberGeometry::of`]) and the dead-volume fit, the chambers' one use
//! of double precision, is not linked here (a hammer's record fits it, on
//! the host).
//!
//! The caller lends the room ([`Work`]): one float a sample of the window
//! for the position track, and one a sample of the cycle for the track's
//! source (the acceleration, converted from the codes once a sample and
//! read by the track's three passes), which the closed fits' logarithms
//! (two floats a sample of a closed phase) take over once the track is
//! done. The pressures are read from the codes where they are kept
//! ([`Codes`]: a board's ring), through their calibration and delay, by the
//! fits that read each sample once or twice; nothing is allocated. A window
//! longer than the room gives `None`, never a reading of part of it.

use super::track::{self, PhaseFriction, Piston};
use super::{
    characterise_with, each, ChamberGeometry, Characteristics, Feed, Part, Series, Window, LOOK_AFTER_S, P_ATM_PA,
};
use crate::{ChannelCal, Config, CycleReport, FeedFields, RawSample};

/// Samples kept after [`LOOK_AFTER_S`] past the closing impact (the host's
/// capture reader reads as far).
pub const AFTER_MARGIN: usize = 64;
/// The longest a shock is looked for after its impact (a contact lasts
/// tens of microseconds; the accelerometer's ringing a little longer).
const MAX_SHOCK_S: f32 = 0.5e-3;
/// How long after a shock the front chamber is taken as closed, to fit the
/// rebound of the tail's track when the cycle's own gave none.
const REBOUND_FIT_S: f32 = 0.5e-3;

/// Samples the window of a cycle of `cycle` samples takes at `dt_s`: the
/// cycle, both its impacts, and the look-after with its margin.
pub fn window_samples(cycle: usize, dt_s: f32) -> usize {
    cycle + 1 + look_after(dt_s) + AFTER_MARGIN
}

/// [`LOOK_AFTER_S`] in samples, rounded up.
fn look_after(dt_s: f32) -> usize {
    let x = LOOK_AFTER_S / dt_s;
    let whole = x as usize;
    if (whole as f32) < x {
        whole + 1
    } else {
        whole
    }
}

/// The room a reading works in: `x_m` at least as long as the window;
/// `room` at least the cycle's samples and its closing impact (`close + 1`
/// floats: a track's source, once a sample), then the closed fits'
/// logarithms where it holds two floats a sample of a closed phase (where
/// it is shorter they are computed as read: the same figures, slower).
pub struct Work<'a> {
    pub x_m: &'a mut [f32],
    pub room: &'a mut [f32],
}

/// A cycle's sample-sets where they are kept (a slice, a board's ring).
pub trait Codes {
    fn len(&self) -> usize;
    fn get(&self, i: usize) -> RawSample;
    fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// Channel `ch` (0 rear, 1 front, 2 accelerometer) of set `i`: what a
    /// reading asks for, one channel at a time (a packed ring decodes only
    /// that code).
    #[inline(always)]
    fn code(&self, i: usize, ch: usize) -> u16 {
        let s = self.get(i);
        match ch {
            0 => s.rear,
            1 => s.front,
            _ => s.accel,
        }
    }
}

impl Codes for [RawSample] {
    fn len(&self) -> usize {
        <[RawSample]>::len(self)
    }
    fn get(&self, i: usize) -> RawSample {
        self[i]
    }
}

/// One channel of `codes` through its calibration, read `lag` samples
/// later (linear interpolation; the last samples repeat the end): a delayed
/// channel brought back in time, as the host's capture reading does it.
/// `ch` picks the channel (a function pointer there kept every read from
/// being inlined).
struct Channel<'a, C: Codes + ?Sized> {
    codes: &'a C,
    n: usize,
    cal: ChannelCal,
    ch: Pick,
    whole: usize,
    frac: f32,
    lagged: bool,
}

/// A sample-set's channels.
#[derive(Clone, Copy)]
enum Pick {
    Rear = 0,
    Front = 1,
    Accel = 2,
}

impl<'a, C: Codes + ?Sized> Channel<'a, C> {
    fn new(codes: &'a C, n: usize, cal: ChannelCal, ch: Pick, lag: f32) -> Self {
        let lagged = !(lag.is_nan() || lag <= 0.0);
        let whole = if lagged { lag as usize } else { 0 };
        Self {
            codes,
            n,
            cal,
            ch,
            whole,
            frac: if lagged { lag - whole as f32 } else { 0.0 },
            lagged,
        }
    }

    #[inline(always)]
    fn value(&self, i: usize) -> f32 {
        self.cal.value(self.codes.code(i, self.ch as usize))
    }
}

impl<C: Codes + ?Sized> Series for Channel<'_, C> {
    fn len(&self) -> usize {
        self.n
    }
    fn at(&self, i: usize) -> f32 {
        if !self.lagged {
            return self.value(i);
        }
        let a = self.value((i + self.whole).min(self.n - 1));
        let b = self.value((i + self.whole + 1).min(self.n - 1));
        a + self.frac * (b - a)
    }
    /// As [`Series::at`] sample by sample, each code read once: a sample's
    /// later neighbour is the next one's earlier.
    fn read_into(&self, start: usize, out: &mut [f32]) {
        if !self.lagged || out.is_empty() {
            for (k, v) in out.iter_mut().enumerate() {
                *v = self.value(start + k);
            }
            return;
        }
        let last = self.n - 1;
        let mut a = self.value((start + self.whole).min(last));
        for (k, v) in out.iter_mut().enumerate() {
            let b = self.value((start + k + self.whole + 1).min(last));
            *v = a + self.frac * (b - a);
            a = b;
        }
    }
}

impl ChamberGeometry {
    /// The chambers `c` describes: the piston's areas, the travel as the
    /// impact position, the dead volumes and outlets of `c.chambers`. The
    /// areas in the estimator's f32 arithmetic (a board has no double
    /// precision; the readings use them in f32 in any case).
    pub fn of(c: &Config) -> Self {
        let ch = &c.chambers;
        Self {
            rear_area_m2: c.rear_area_m2() as f64,
            front_area_m2: c.front_area_m2() as f64,
            rear_dead_m3: ch.rear_dead_m3 as f64,
            front_dead_m3: ch.front_dead_m3 as f64,
            impact_position_m: c.geometry.travel_m as f64,
            rear_outlet_m: ch.rear_outlet_m as f64,
            front_outlet_m: ch.front_outlet_m as f64,
        }
    }
}

/// The characteristics of the cycle `report` closes. `codes` starts at the
/// cycle's opening impact (its first shock sample, index 0) and holds the
/// closing one at `close` and at least half the look-after past it (all of
/// it and [`AFTER_MARGIN`] are read where there). With `track_term` the
/// cycle is also read along the force balance's track, whose spread widens
/// the uncertainties (the host's reading of a capture does); without, the
/// values are the same and the reading costs half. `None` where the window
/// does not fit `work`, the cycle is not a valid one, or the samples after
/// it are too few.
pub fn characterise_cycle<C: Codes + ?Sized>(
    cfg: &Config,
    geo: &ChamberGeometry,
    codes: &C,
    close: usize,
    report: &CycleReport,
    track_term: bool,
    work: &mut Work,
) -> Option<Characteristics> {
    let dt = cfg.dt_s();
    let look = look_after(dt);
    let following = (close + look + AFTER_MARGIN).min(codes.len().checked_sub(1)?);
    let n = following + 1;
    if !(work.x_m.len() >= n && report.is_valid() && 0 < close && close + look / 2 <= following && geo.is_valid()) {
        return None;
    }
    // The pressures, read back by the channels' group delay.
    let lag = cfg.chambers.pressure_group_delay_s / dt;
    let p1 = Channel::new(codes, n, cfg.rear, Pick::Rear, lag);
    let p2 = Channel::new(codes, n, cfg.front, Pick::Front, lag);
    let accel = Channel::new(codes, n, cfg.accel, Pick::Accel, 0.0);
    let piston = Piston::of(cfg);
    let friction = PhaseFriction {
        backhaul_n: report.friction_backhaul_n,
        stroke_n: report.friction_stroke_n,
    };
    let impact = geo.impact_position_m as f32;
    let threshold = cfg.impact_threshold_mps2;
    let blank = crate::math::round(cfg.blank_after_s / dt) as usize;
    let a_end = shock_end(&accel, 0, threshold, dt).min(close - 1);
    let tail_end = shock_end(&accel, close, threshold, dt);
    let end = (close + look + AFTER_MARGIN).min(following);
    let supply_abs = cfg.supply_pressure_pa + P_ATM_PA;
    let tau = cfg.accel_zero_shift_tau_s;
    let with_friction = track::WithFriction::new(&piston, friction);
    let x = &mut work.x_m[..n];
    let room = &mut *work.room;
    // Each track in turn in the one room: the force balance's (its spread
    // widens the uncertainties), then the accelerometer's (the value).
    let mut read = |by_force: bool| {
        x.fill(f32::NAN);
        x[..a_end].fill(impact);
        let balanced = if by_force {
            close + 1
        } else {
            blank.clamp(a_end, close + 1)
        };
        if room.len() > close {
            // The track's source once a sample, in the room the closed fits'
            // logarithms take after it (the track reads it three times
            // over): the accelerometer's, its zero shift's decay carried
            // from sample to sample; the pressure force where the force
            // balance stands in (the accelerometer's blank after the shock,
            // or all of the force balance's track), friction's sign split
            // at the turn as it is read.
            let source = &mut room[..=close];
            if balanced <= close {
                track::accelerometer(
                    &accel,
                    report.accel_zero_shift_mps2,
                    tau,
                    dt,
                    0,
                    a_end,
                    &mut source[a_end..],
                );
            }
            for (i, f) in source.iter_mut().enumerate().take(balanced).skip(a_end) {
                *f = track::pressure_force(&p1, &p2, &piston, i);
            }
            let source = &*source;
            // (No panic path: `closed` reads `..=close`, all in `source`.)
            let acc = |i: usize, turn: usize| {
                let s = source.get(i).copied().unwrap_or(f32::NAN);
                if i < balanced {
                    with_friction.acceleration(s, i, turn)
                } else {
                    s
                }
            };
            track::closed(dt, impact, a_end, close, x, acc);
        } else {
            // No room for the source: each of the track's three passes
            // reads it from the codes, in order, the zero shift's decay
            // carried from `a_end` as `track::accelerometer` carries it
            // (through the force balance's samples too), so the values are
            // the room's, bit for bit, at about 1.5 times the work.
            let mut decay = track::Decay::new(report.accel_zero_shift_mps2, tau, dt);
            let mut next = usize::MAX;
            let acc = |i: usize, turn: usize| {
                if i != next {
                    decay.start(0, i);
                }
                next = i + 1;
                let shift = decay.step();
                if i < balanced {
                    with_friction.acceleration(track::pressure_force(&p1, &p2, &piston, i), i, turn)
                } else {
                    accel.value(i) - shift
                }
            };
            track::closed(dt, impact, a_end, close, x, acc);
        }
        let rebound = if a_end + 1 < close {
            Some((x[a_end + 1] - x[a_end]) / dt).filter(|v| v.is_finite())
        } else {
            None
        };
        // After the closing impact: the tail's track from the rebound.
        tail(&accel, &p2, dt, geo, close, tail_end, rebound, x);
        let w = Window {
            dt_s: dt,
            p_rear_pa: &Part::new(&p1, 0, end + 1),
            p_front_pa: &Part::new(&p2, 0, end + 1),
            x_m: &x[..=end],
            open: 0,
            close,
            fit_dead_volume: false,
        };
        // No dead-volume fit (a record's, on the host): none of its
        // double-precision sums in a board's image.
        characterise_with::<false, _>(&w, geo, supply_abs, room)
    };
    let by_force = if track_term { Some(read(true)) } else { None };
    let value = read(false);
    Some(by_force.map_or(value, |f| value.widened(&f)))
}

/// One chamber's reading as a report carries it ([`FeedFields::NAN`] where
/// the chamber showed nothing to read).
pub fn fields(feed: Option<Feed>) -> FeedFields {
    feed.map_or(FeedFields::NAN, |f| FeedFields {
        feed_s: f.onset_s,
        feed_uncertainty_s: f.onset_uncertainty_s,
        feed_x_m: f.x_m,
        feed_p_rear_pa: f.p_rear_pa,
        feed_p_front_pa: f.p_front_pa,
        closed_exponent: f.closed_exponent,
        closed_exponent_uncertainty: f.closed_exponent_uncertainty,
        feed_area_m2: f.feed_area_m2,
        feed_area_uncertainty_m2: f.feed_area_uncertainty_m2,
    })
}

/// The first sample after the impact at `i` where the accelerometer has
/// left the impact region (`i` itself if it never does within the shock's
/// longest).
fn shock_end(accel: &impl Series, i: usize, threshold_mps2: f32, dt_s: f32) -> usize {
    let last = (i + (MAX_SHOCK_S / dt_s) as usize).min(accel.len().saturating_sub(1));
    (i + 1..=last)
        .find(|&k| crate::math::abs(accel.at(k)) < threshold_mps2)
        .unwrap_or(i)
}

/// The track after the closing impact, from the end of its shock: the
/// accelerometer integrated from `rebound`; without one, the rebound fitted
/// to the front chamber's first half millisecond, closed at the adiabatic
/// exponent. The displacement is integrated as it is written (no room of
/// its own), twice where the fit needs it first.
#[allow(clippy::too_many_arguments)]
fn tail(
    accel: &impl Series,
    p2: &impl Series,
    dt: f32,
    geo: &ChamberGeometry,
    close: usize,
    a_end: usize,
    rebound: Option<f32>,
    x: &mut [f32],
) {
    let n = accel.len().min(p2.len()).min(x.len());
    let impact = geo.impact_position_m as f32;
    let a_end = a_end.clamp(close, n);
    x[close..a_end].fill(impact);
    if a_end + 2 >= n {
        return;
    }
    let len = n - a_end;
    let v0 = match rebound {
        Some(v0) => v0,
        None => {
            let (v_dead, a2) = (geo.front_dead_m3 as f32, geo.front_area_m2 as f32);
            let p_abs = |i: usize| p2.at(i) + P_ATM_PA;
            let fit = ((REBOUND_FIT_S / dt) as usize).clamp(2, len - 1);
            let (mut num, mut den) = (0.0f32, 0.0f32);
            displacement(accel, dt, a_end, len, |k, uk| {
                if (1..=fit).contains(&k) {
                    let ratio = p_abs(a_end) / p_abs(a_end + k);
                    let x_closed = impact - v_dead * (crate::math::powf(ratio, 1.0 / 1.4) - 1.0) / a2;
                    let tk = k as f32 * dt;
                    num += (x_closed - impact - uk) * tk;
                    den += tk * tk;
                }
            });
            if den > 0.0 {
                (num / den).min(0.0)
            } else {
                0.0
            }
        }
    };
    displacement(accel, dt, a_end, len, |k, uk| {
        x[a_end + k] = (impact + v0 * k as f32 * dt + uk).min(impact);
    });
}

/// `f(k, u)` for the `len` samples from `a_end`: u the displacement the
/// accelerometer gives from rest at `a_end` (the trapezoid, twice).
fn displacement(accel: &impl Series, dt: f32, a_end: usize, len: usize, mut f: impl FnMut(usize, f32)) {
    let (mut u, mut v) = (0.0f32, 0.0f32);
    f(0, 0.0);
    let mut a_prev = f32::NAN;
    // Each sample read once, carried to the next step.
    each(accel, a_end, a_end + len, |i, a| {
        if i > a_end {
            let v_next = v + 0.5 * dt * (a_prev + a);
            u += 0.5 * dt * (v + v_next);
            v = v_next;
            f(i - a_end, u);
        }
        a_prev = a;
    });
}
