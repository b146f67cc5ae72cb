//! The valve, the supply and the chambers, read from the pressures and the
//! piston's track with no model of the valve, the ports or the supply line.
//!
//! The force balance pins friction on any hammer because it needs no model.
//! These characteristics do the same for what friction-style evidence cannot
//! see (`docs/estimator.md`, "Chamber characteristics"):
//! - a closed chamber holds p·Vⁿ constant; its fitted exponent `n` moves
//!   with heat exchange and leakage (`closed`);
//! - a feed starts where the chamber stops being closed: the onset of the
//!   rise of ln p + n·ln V, timed from the impact, is the valve's switching
//!   (`closed::onset`);
//! - the energy equation of the fill gives the feed's effective area, which
//!   a supply restriction or a worn valve makes smaller (`fill`).
//!
//! They run on one cycle's samples at a time (slices, no allocation), on the
//! host from a raw trace or capture, and at a cycle's close from its codes
//! (`at_close`: the reading of a one-cycle capture, no_std, for a board;
//! they need the samples around the impacts that the estimator's
//! checkpoint sums do not keep, so a board needs a ring of them: not wired
//! yet, `docs/firmware.md`, "Chamber characteristics on the board").
//!
//! Module map:
//! - this file: [`ChamberGeometry`], [`Feed`] and [`Characteristics`], and
//!   [`characterise`], which finds each chamber's closed phase in a cycle;
//! - `track`: the piston's position from the force balance, closed over the cycle;
//! - `closed`: the closed phase's polytropic fit and the feed onset after it,
//!   reading ln p and ln V from the caller's room where it gives one (`Cached`);
//! - `fill`: the effective feed area from the energy equation;
//! - `charge`: the air each chamber draws per cycle (an estimate);
//! - `at_close`: one cycle's characteristics from its ADC codes and its
//!   report, in room the caller lends (the board's reading).

pub mod at_close;
mod charge;
mod closed;
mod fill;
pub mod track;

pub use charge::Charge;
pub use closed::P_ATM_PA;

use crate::math;

/// Position at which the piston's striking face meets the tool, for the
/// paper's hammer (its 10 mm start + 42 mm stroke).
pub const PAPER_IMPACT_POSITION_M: f64 = 0.052;

/// What the characteristics need of the hammer beyond the force balance's
/// mass and areas: where the chambers' volumes start and where the piston
/// covers their outlets. Positions are of the piston's rear face from the
/// rear end of the bore (x grows in the stroke).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ChamberGeometry {
    pub rear_area_m2: f64,
    pub front_area_m2: f64,
    /// Rear chamber volume at x = 0.
    pub rear_dead_m3: f64,
    /// Front chamber volume at the impact position.
    pub front_dead_m3: f64,
    pub impact_position_m: f64,
    /// The rear outlet is uncovered above this position.
    pub rear_outlet_m: f64,
    /// The front outlet is uncovered below this position.
    pub front_outlet_m: f64,
}

impl ChamberGeometry {
    /// The paper's hammer (its dead volumes are estimates: `docs/model.md`).
    pub fn paper() -> Self {
        let g = crate::Geometry::PAPER;
        Self {
            rear_area_m2: g.rear_area_m2(),
            front_area_m2: g.front_area_m2(),
            rear_dead_m3: 14.5e-6,
            front_dead_m3: 19.9e-6,
            impact_position_m: PAPER_IMPACT_POSITION_M,
            rear_outlet_m: 0.030,
            front_outlet_m: 0.020,
        }
    }

    /// The volume laws in f32, converted once (a board converts a double
    /// in software: once a reading, not once a sample).
    fn volumes(&self) -> Volumes {
        Volumes {
            rear_dead_m3: self.rear_dead_m3 as f32,
            rear_area_m2: self.rear_area_m2 as f32,
            front_dead_m3: self.front_dead_m3 as f32,
            front_area_m2: self.front_area_m2 as f32,
            impact_position_m: self.impact_position_m as f32,
        }
    }

    /// True when every length and volume is finite and the chambers exist.
    pub fn is_valid(&self) -> bool {
        let all = [
            self.rear_area_m2,
            self.front_area_m2,
            self.rear_dead_m3,
            self.front_dead_m3,
            self.impact_position_m,
            self.rear_outlet_m,
            self.front_outlet_m,
        ];
        all.iter().all(|v| v.is_finite() && *v > 0.0)
            && self.front_outlet_m < self.impact_position_m
            && self.rear_outlet_m < self.impact_position_m
    }
}

/// [`ChamberGeometry`]'s volume laws, in f32.
#[derive(Debug, Clone, Copy)]
struct Volumes {
    rear_dead_m3: f32,
    rear_area_m2: f32,
    front_dead_m3: f32,
    front_area_m2: f32,
    impact_position_m: f32,
}

impl Volumes {
    fn rear_m3(&self, x: f32) -> f32 {
        self.rear_dead_m3 + self.rear_area_m2 * x
    }

    fn front_m3(&self, x: f32) -> f32 {
        self.front_dead_m3 + self.front_area_m2 * (self.impact_position_m - x)
    }
}

/// One chamber's feed in one cycle and the closed phase before it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Feed {
    /// Onset of the feed from the reference impact, signed (negative:
    /// before it). The front chamber's reference is the impact that closes
    /// the cycle, the rear chamber's the one that opens it.
    pub onset_s: f32,
    /// Expanded uncertainty (k = 2) of the onset, random terms only.
    pub onset_uncertainty_s: f32,
    /// The chamber state at the onset (what the valve switched on).
    pub x_m: f32,
    pub p_rear_pa: f32,
    pub p_front_pa: f32,
    /// Polytropic exponent of the closed phase before the feed (1.4 sealed
    /// and adiabatic; heat exchange pulls it towards 1, a leak moves it).
    pub closed_exponent: f32,
    pub closed_exponent_uncertainty: f32,
    /// Effective area of the feed over the millisecond after its rise is
    /// established (`fill`), from the
    /// energy equation against the supply pressure (NaN without one).
    pub feed_area_m2: f32,
    pub feed_area_uncertainty_m2: f32,
    /// The correction to the chamber's dead volume its closed phase asks
    /// for (`closed::dead_volume_offset`), m³; NaN where it cannot tell or
    /// was not asked (`Window::fit_dead_volume`).
    pub dead_volume_offset_m3: f32,
}

/// Both chambers' feeds of one cycle; `None` where a chamber showed no
/// closed phase long enough to read, or no feed after it.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Characteristics {
    pub front: Option<Feed>,
    pub rear: Option<Feed>,
    /// The air the chambers drew, where both feeds were found.
    pub charge: Option<Charge>,
}

impl Feed {
    /// This feed's uncertainties widened by how far `other` (the same
    /// chamber read along another position track) lies from it: the spread
    /// between two independent tracks stands for the track's own error,
    /// which the noise terms do not hold.
    fn widened(self, other: &Feed) -> Feed {
        let add = |u: f32, d: f32| if d.is_finite() { math::sqrt(u * u + d * d) } else { u };
        Feed {
            onset_uncertainty_s: add(self.onset_uncertainty_s, self.onset_s - other.onset_s),
            closed_exponent_uncertainty: add(
                self.closed_exponent_uncertainty,
                self.closed_exponent - other.closed_exponent,
            ),
            feed_area_uncertainty_m2: add(self.feed_area_uncertainty_m2, self.feed_area_m2 - other.feed_area_m2),
            ..self
        }
    }
}

impl Characteristics {
    /// [`Feed::widened`] per chamber; a chamber the other track did not
    /// read keeps its own uncertainties.
    pub fn widened(self, other: &Characteristics) -> Characteristics {
        let w = |a: Option<Feed>, b: Option<Feed>| match (a, b) {
            (Some(a), Some(b)) => Some(a.widened(&b)),
            (a, _) => a,
        };
        Characteristics {
            front: w(self.front, other.front),
            rear: w(self.rear, other.rear),
            charge: self.charge,
        }
    }
}

/// One channel of a cycle's window, read sample by sample: a slice, or a
/// board's ADC codes read through their calibration where they are kept
/// (`at_close`: no room for the pressures as floats).
pub trait Series {
    fn len(&self) -> usize;
    fn at(&self, i: usize) -> f32;
    fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// `out[k] = self.at(start + k)`, read in order: where a sample costs
    /// a reading of codes, a series can carry what the next one shares.
    fn read_into(&self, start: usize, out: &mut [f32]) {
        for (k, v) in out.iter_mut().enumerate() {
            *v = self.at(start + k);
        }
    }
}

impl Series for [f32] {
    fn len(&self) -> usize {
        <[f32]>::len(self)
    }
    fn at(&self, i: usize) -> f32 {
        self[i]
    }
}

/// `f(i, s[i])` for `i` in `a..b`, in order, the series read a block at a
/// time ([`Series::read_into`]: a board's channels from its codes, each
/// code once).
pub(crate) fn each<S: Series + ?Sized>(s: &S, a: usize, b: usize, mut f: impl FnMut(usize, f32)) {
    const BLOCK: usize = 64;
    let mut buf = [0.0f32; BLOCK];
    let mut i = a;
    while i < b {
        let m = (b - i).min(BLOCK);
        s.read_into(i, &mut buf[..m]);
        for (k, &v) in buf[..m].iter().enumerate() {
            f(i + k, v);
        }
        i += m;
    }
}

/// `inner[start..end]`, of any series.
pub struct Part<'a, S: Series + ?Sized> {
    inner: &'a S,
    start: usize,
    len: usize,
}

impl<'a, S: Series + ?Sized> Part<'a, S> {
    pub fn new(inner: &'a S, start: usize, end: usize) -> Self {
        let end = end.min(inner.len());
        Self {
            inner,
            start: start.min(end),
            len: end - start.min(end),
        }
    }
}

impl<S: Series + ?Sized> Series for Part<'_, S> {
    fn len(&self) -> usize {
        self.len
    }
    fn at(&self, i: usize) -> f32 {
        self.inner.at(self.start + i)
    }
    fn read_into(&self, start: usize, out: &mut [f32]) {
        self.inner.read_into(self.start + start, out)
    }
}

/// One cycle's samples and the indices of its two impacts. All channels
/// have the same length and reach past `close` far enough to see a feed
/// that starts after the closing impact ([`LOOK_AFTER_S`]); pressures gauge.
pub struct Window<'a, P: Series + ?Sized = [f32]> {
    pub dt_s: f32,
    pub p_rear_pa: &'a P,
    pub p_front_pa: &'a P,
    /// The piston's position: the [`track`] of the force balance, or a
    /// simulator's truth.
    pub x_m: &'a [f32],
    pub open: usize,
    pub close: usize,
    /// Also fit each chamber's dead volume (`Feed::dead_volume_offset_m3`,
    /// NaN otherwise): a further pass over each closed phase, wanted only
    /// where a hammer's own record is read, not in every model run.
    pub fit_dead_volume: bool,
}

impl<P: Series + ?Sized> Clone for Window<'_, P> {
    fn clone(&self) -> Self {
        *self
    }
}

impl<P: Series + ?Sized> Copy for Window<'_, P> {}

/// How long after the closing impact a front feed is still looked for.
pub const LOOK_AFTER_S: f32 = 8e-3;
/// Distance from an outlet edge at which the chamber counts as closed (a
/// port opens over its diameter's ramp; the paper's are 5 mm).
const EDGE_GUARD_M: f32 = 2e-3;

/// The characteristics of one cycle. `supply_abs_pa` is the supply pressure
/// (absolute) that the fill is set against; NaN leaves the feed areas NaN.
/// `room` keeps the closed fits' logarithms ([`closed::Cached`]: two floats
/// a sample of the window); where it is shorter they are computed as read,
/// with the same figures, several times slower.
pub fn characterise<P: Series + ?Sized>(
    w: &Window<P>,
    geo: &ChamberGeometry,
    supply_abs_pa: f32,
    room: &mut [f32],
) -> Characteristics {
    if w.fit_dead_volume {
        characterise_with::<true, P>(w, geo, supply_abs_pa, room)
    } else {
        characterise_with::<false, P>(w, geo, supply_abs_pa, room)
    }
}

/// [`characterise`] with the dead-volume fit decided at build time: a
/// reading without it (`DEAD_VOLUME` false, the board's) links none of the
/// fit's double-precision sums.
pub(crate) fn characterise_with<const DEAD_VOLUME: bool, P: Series + ?Sized>(
    w: &Window<P>,
    geo: &ChamberGeometry,
    supply_abs_pa: f32,
    room: &mut [f32],
) -> Characteristics {
    let n = w.p_rear_pa.len().min(w.p_front_pa.len()).min(w.x_m.len());
    if !(w.open < w.close && w.close < n && w.dt_s > 0.0 && geo.is_valid()) {
        return Characteristics::default();
    }
    let look_after = (LOOK_AFTER_S / w.dt_s) as usize;
    let vol = geo.volumes();
    // Front: closed once the stroke has covered its outlet, until the feed.
    let front_edge = geo.front_outlet_m as f32 + EDGE_GUARD_M;
    let front = (w.open..w.close)
        .rev()
        .find(|&i| w.x_m[i] <= front_edge)
        .map(|i| i + 1)
        .and_then(|start| {
            let end = (w.close + look_after).min(n);
            let p = Part::new(w.p_front_pa, start, end);
            let x = &w.x_m[start..end];
            feed::<DEAD_VOLUME, P>(w, &p, x, |x| vol.front_m3(x), start, w.close, supply_abs_pa, room)
        });
    // Rear: closed once the backhaul has covered its outlet, until the feed;
    // the search ends where the stroke uncovers it again.
    let rear_edge = geo.rear_outlet_m as f32 - EDGE_GUARD_M;
    let rear = (w.open..w.close).find(|&i| w.x_m[i] < rear_edge).and_then(|start| {
        let turn = (start..w.close).fold(start, |m, i| if w.x_m[i] < w.x_m[m] { i } else { m });
        let end = (turn..w.close).find(|&i| w.x_m[i] >= rear_edge).unwrap_or(w.close);
        let p = Part::new(w.p_rear_pa, start, end);
        let x = &w.x_m[start..end];
        feed::<DEAD_VOLUME, P>(w, &p, x, |x| vol.rear_m3(x), start, w.open, supply_abs_pa, room)
    });
    let found = Characteristics {
        front,
        rear,
        charge: None,
    };
    Characteristics {
        charge: charge::charge(w, geo, &found, supply_abs_pa),
        ..found
    }
}

/// One chamber: the closed fit, the onset, the state there and the fill.
#[allow(clippy::too_many_arguments)]
fn feed<const DEAD_VOLUME: bool, P: Series + ?Sized>(
    w: &Window<P>,
    p: &Part<P>,
    x: &[f32],
    volume: impl Fn(f32) -> f32,
    start: usize,
    reference: usize,
    supply_abs_pa: f32,
    room: &mut [f32],
) -> Option<Feed> {
    let o = match closed::Cached::fill(p, x, &volume, room) {
        Some(logs) => closed::onset_of(&logs, w.dt_s),
        None => closed::onset(p, x, &volume, w.dt_s),
    }?;
    // A feed of this cycle starts after the impact that opened it. A slow
    // rise (a leak feeding the closed chamber) can have a tangent so
    // shallow that it meets zero cycles earlier: no onset of this cycle.
    // A feed that began a little before its chamber closed is kept.
    if !(o.onset_s >= -((start - w.open) as f32) * w.dt_s) {
        return None;
    }
    // Onset time from the reference impact.
    let t_ref = (reference as f32 - start as f32) * w.dt_s;
    let k = o.onset_s / w.dt_s;
    // The fill is read from where the rise is established (the port's first
    // opening passes little air, and when exactly it began is the onset's
    // uncertainty, not the fill's).
    let area = fill::feed_area(p, x, &volume, w.dt_s, o.rise_s, supply_abs_pa, o.noise_ln);
    // The fill read from a start one sample either side: how far the
    // window's placement moves the area.
    let early = fill::feed_area(p, x, &volume, w.dt_s, o.rise_s - w.dt_s, supply_abs_pa, o.noise_ln);
    let late = fill::feed_area(p, x, &volume, w.dt_s, o.rise_s + w.dt_s, supply_abs_pa, o.noise_ln);
    let u_onset = 0.5 * math::abs(late.area_m2 - early.area_m2);
    let u_area = 2.0 * math::sqrt(area.sigma_m2 * area.sigma_m2 + u_onset * u_onset);
    Some(Feed {
        onset_s: o.onset_s - t_ref,
        onset_uncertainty_s: o.onset_uncertainty_s,
        x_m: interpolate(w.x_m, start, k),
        p_rear_pa: interpolate(w.p_rear_pa, start, k),
        p_front_pa: interpolate(w.p_front_pa, start, k),
        closed_exponent: o.exponent,
        closed_exponent_uncertainty: o.exponent_uncertainty,
        feed_area_m2: area.area_m2,
        feed_area_uncertainty_m2: u_area,
        dead_volume_offset_m3: if DEAD_VOLUME && w.fit_dead_volume {
            closed::dead_volume_offset(p, x, &volume, w.dt_s, &o).unwrap_or(f32::NAN)
        } else {
            f32::NAN
        },
    })
}

/// `s` at the fractional sample `start + k`, linearly interpolated.
fn interpolate<S: Series + ?Sized>(s: &S, start: usize, k: f32) -> f32 {
    let k = if k > 0.0 { k } else { 0.0 };
    let i = start + k as usize;
    let frac = k - (k as usize) as f32;
    let n = s.len();
    if i + 1 < n {
        let (a, b) = (s.at(i), s.at(i + 1));
        a + frac * (b - a)
    } else if i < n {
        s.at(i)
    } else {
        f32::NAN
    }
}
