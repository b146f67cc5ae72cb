//! Per-cycle chamber characteristics of a trace: the valve's switching, the
//! fills and the closed phases (`hammer_estimator::chambers`).
//!
//! The same calculation reads the measured pressures with the position
//! track of the measured acceleration (the force balance's in the blank
//! after each impact), or a simulator's true pressures and position: that
//! is a characteristic's truth (`docs/estimator.md`). Cycles come either as
//! the estimator's reports ([`characterise_cycles`]) or as spans between
//! impacts found elsewhere, with the friction and zero shift fitted there
//! ([`characterise_spans`]: the diagnosis' features).

use hammer_estimator::chambers::track::{self, PhaseFriction, Piston};
use hammer_estimator::chambers::{characterise, ChamberGeometry, Characteristics, Window, LOOK_AFTER_S, P_ATM_PA};
use hammer_estimator::{Config, CycleReport};

/// The pressures (gauge) and, for the truth, the position the
/// characteristics are read from; without a position the tracks of the
/// accelerometer and of the force balance are used.
#[derive(Debug, Clone, Copy)]
pub struct Signals<'a> {
    pub dt_s: f64,
    pub p_rear_pa: &'a [f64],
    pub p_front_pa: &'a [f64],
    /// The measured acceleration: where each impact's shock ends, and the track.
    pub accel_mps2: &'a [f64],
    pub x_m: Option<&'a [f64]>,
    /// How late the pressure channels' readings are (their transducers'
    /// and anti-alias filters' group delay, `SensorChannel::group_delay_s`;
    /// 0 for true pressures). The pressures are read this much earlier,
    /// interpolated between samples. Why: the piston's track is tied to
    /// the impact, where the front chamber is smallest and its pressure
    /// turns fastest; 4 µs of filter delay there lifted the closed phase's
    /// residual enough to read the front feed 0.026 ms early on the model
    /// (docs/estimator.md).
    pub pressure_lag_s: f64,
}

/// `v` read `lag` samples later (linear interpolation; the last samples
/// repeat the end): a delayed channel brought back in time.
fn advanced(v: &[f64], lag: f64) -> Vec<f32> {
    let n = v.len();
    if lag.is_nan() || lag <= 0.0 || n == 0 {
        return v.iter().map(|&x| x as f32).collect();
    }
    let (whole, frac) = (lag.floor() as usize, lag - lag.floor());
    (0..n)
        .map(|i| {
            let a = v[(i + whole).min(n - 1)];
            let b = v[(i + whole + 1).min(n - 1)];
            (a + frac * (b - a)) as f32
        })
        .collect()
}

/// How the signals are read: the piston, the estimator's settings the
/// tracks share, and the supply the fills are set against.
#[derive(Debug, Clone, Copy)]
pub struct Reading {
    pub piston: Piston,
    pub impact_threshold_mps2: f64,
    /// The accelerometer rings this long after a shock: the force balance
    /// stands in for it there.
    pub blank_after_s: f64,
    pub zero_shift_tau_s: f64,
    /// Gauge; NaN leaves the feed areas NaN.
    pub supply_pa: f64,
    /// Also fit each chamber's dead volume (a hammer's own record; see
    /// `hammer_estimator::chambers::Window::fit_dead_volume`).
    pub dead_volume: bool,
    /// Also read each cycle through the force balance's own track and widen
    /// the uncertainties by the difference (the track term). It doubles the
    /// reading's cost; the diagnosis reads the values only (its spreads
    /// come from the cycles' scatter), so it leaves this off.
    pub track_term: bool,
}

impl Reading {
    /// As the estimator configured by `c` reads (its supply pressure included).
    pub fn of(c: &Config) -> Self {
        Self {
            piston: Piston::of(c),
            impact_threshold_mps2: c.impact_threshold_mps2 as f64,
            blank_after_s: c.blank_after_s as f64,
            zero_shift_tau_s: c.accel_zero_shift_tau_s as f64,
            supply_pa: c.supply_pressure_pa as f64,
            dead_volume: false,
            track_term: true,
        }
    }
}

/// One impact-to-impact cycle and what its force balance fitted.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Span {
    pub open_s: f64,
    pub close_s: f64,
    pub friction: PhaseFriction,
    /// The accelerometer's zero shift at the opening impact, decaying with
    /// [`Reading::zero_shift_tau_s`] (NaN: none fitted).
    pub zero_shift_mps2: f32,
}

impl Span {
    /// The cycle `cur` closes, opened by the report before it, with the
    /// friction and zero shift the estimator fitted to it.
    pub fn between(prev: &CycleReport, cur: &CycleReport) -> Span {
        Span {
            open_s: prev.t_impact_s(),
            close_s: cur.t_impact_s(),
            friction: PhaseFriction {
                backhaul_n: cur.friction_backhaul_n,
                stroke_n: cur.friction_stroke_n,
            },
            zero_shift_mps2: cur.accel_zero_shift_mps2,
        }
    }
}

/// The longest a shock is looked for after its impact (a contact lasts
/// tens of microseconds; the accelerometer's ringing a little longer).
const MAX_SHOCK_S: f64 = 0.5e-3;

/// The first sample after the impact at `i` where the accelerometer has
/// left the impact region: the contact is over and the piston is back at
/// the impact position (the tool's elastic give, tens of µm, undone).
fn shock_end(accel: &[f64], i: usize, threshold_mps2: f64, dt_s: f64) -> usize {
    let last = (i + (MAX_SHOCK_S / dt_s) as usize).min(accel.len().saturating_sub(1));
    (i + 1..=last).find(|&k| accel[k].abs() < threshold_mps2).unwrap_or(i)
}

/// The characteristics of each span. The samples after a span's closing
/// impact, where a front feed may start, are tracked as the next span's
/// when it continues this one. Without one, with `tail` (a device's
/// one-cycle capture, whose only cycle has no next) the samples after the
/// impact are tracked on their own ([`tail_track`], less accurate: a rebound
/// fitted, not closed); else the span has none. `None` also where less
/// than half of [`LOOK_AFTER_S`] follows the closing impact.
pub fn characterise_spans(
    s: &Signals,
    spans: &[Span],
    r: &Reading,
    chambers: &ChamberGeometry,
    tail: bool,
) -> Vec<Option<Characteristics>> {
    let n = s.p_rear_pa.len().min(s.p_front_pa.len()).min(s.accel_mps2.len());
    let index = |t: f64| (t / s.dt_s).round() as usize;
    let look = (LOOK_AFTER_S as f64 / s.dt_s).ceil() as usize;
    let after = look + 64;
    let supply_abs = (r.supply_pa + P_ATM_PA as f64) as f32;
    let f32s = |v: &[f64]| v[..n].iter().map(|&x| x as f32).collect::<Vec<f32>>();
    let lag = s.pressure_lag_s / s.dt_s;
    let (p1, p2) = (advanced(&s.p_rear_pa[..n], lag), advanced(&s.p_front_pa[..n], lag));
    // Each span's tracks once: a cycle reads its own and the next one's, so
    // tracking per cycle would track every span twice.
    let tracked = s.x_m.is_none().then(|| {
        let accel = f32s(s.accel_mps2);
        let t = span_tracks(s, r, chambers, (&p1, &p2, &accel), spans);
        (accel, t)
    });
    // The closed fits' logarithms, two floats a sample of the longest window.
    let room = std::cell::RefCell::new(vec![0.0f32; 2 * n]);
    (0..spans.len())
        .map(|k| {
            let cur = spans[k];
            let [open, close] = [cur.open_s, cur.close_s].map(index);
            // The next span, if it continues this one; else the tail.
            let next = spans
                .get(k + 1)
                .copied()
                .filter(|nx| index(nx.open_s) == close && index(nx.close_s) < n);
            if next.is_none() && !tail {
                return None;
            }
            let following = next.map_or((close + after).min(n.saturating_sub(1)), |nx| index(nx.close_s));
            // Half the look-after holds any feed within a few ms of the impact.
            if !(open < close && close + look / 2 <= following && following < n) {
                return None;
            }
            let end = (close + after).min(following);
            let window = |x: &[f32]| {
                let w = Window {
                    dt_s: s.dt_s as f32,
                    p_rear_pa: &p1[open..=end],
                    p_front_pa: &p2[open..=end],
                    x_m: &x[..=end - open],
                    open: 0,
                    close: close - open,
                    fit_dead_volume: r.dead_volume,
                };
                characterise(&w, chambers, supply_abs, &mut room.borrow_mut())
            };
            match (s.x_m, &tracked) {
                (Some(x), _) if x.len() > following => {
                    let x: Vec<f32> = x[open..=following].iter().map(|&v| v as f32).collect();
                    Some(window(&x))
                }
                (Some(_), _) | (None, None) => None,
                (None, Some((accel, (all_acc, all_force, rebounds)))) => {
                    let mut x_acc = all_acc[open..=following].to_vec();
                    let mut x_force = r.track_term.then(|| all_force[open..=following].to_vec());
                    if next.is_none() {
                        let a_end = shock_end(s.accel_mps2, close, r.impact_threshold_mps2, s.dt_s) - open;
                        let (accel, p2) = (&accel[open..=following], &p2[open..=following]);
                        let (dt, c) = (s.dt_s as f32, close - open);
                        tail_track(accel, p2, dt, chambers, c, a_end, rebounds[k][0], &mut x_acc);
                        if let Some(x_force) = x_force.as_mut() {
                            tail_track(accel, p2, dt, chambers, c, a_end, rebounds[k][1], x_force);
                        }
                    }
                    // The accelerometer's track is read; the spread to the
                    // force balance's widens the uncertainties.
                    let read = window(&x_acc);
                    Some(x_force.map_or(read, |x_force| read.widened(&window(&x_force))))
                }
            }
        })
        .collect()
}

/// Both tracks over the whole trace: the accelerometer's and the force
/// balance's, each span's from where its opening contact ends to its
/// closing impact (NaN where no span is), and each span's rebound on each
/// (its velocity where the contact has ended), for a tail after its
/// closing impact ([`tail_track`]).
type Tracks = (Vec<f32>, Vec<f32>, Vec<[Option<f32>; 2]>);

fn span_tracks(
    s: &Signals,
    r: &Reading,
    chambers: &ChamberGeometry,
    (p1, p2, accel): (&[f32], &[f32], &[f32]),
    spans: &[Span],
) -> Tracks {
    let index = |t: f64| (t / s.dt_s).round() as usize;
    let n = p1.len();
    let impact = chambers.impact_position_m as f32;
    let dt = s.dt_s as f32;
    let blank = (r.blank_after_s / s.dt_s).round() as usize;
    let mut x_acc = vec![f32::NAN; n];
    let mut x_force = vec![f32::NAN; n];
    let mut rebounds = vec![[None; 2]; spans.len()];
    let (mut before, mut after) = (vec![0.0f32; n], vec![0.0f32; n]);
    for (j, span) in spans.iter().enumerate() {
        let (a, b) = (index(span.open_s), index(span.close_s));
        if !(a < b && b < n) {
            continue;
        }
        // The tracks start where the contact has ended; during it the
        // piston is at the tool.
        let a_end = shock_end(s.accel_mps2, a, r.impact_threshold_mps2, s.dt_s).min(b - 1);
        x_acc[a..a_end].fill(impact);
        x_force[a..a_end].fill(impact);
        let balance = || track::force_balance(p1, p2, &r.piston, span.friction);
        let tau = r.zero_shift_tau_s as f32;
        // The source once a sample (the accelerometer's, its zero shift's
        // decay carried from sample to sample; the force balance's while it
        // rings), read by the track's three passes: before the turn and
        // after it. It depends on the turn only in the blank, where the
        // force balance's friction changes sign.
        track::accelerometer(accel, span.zero_shift_mps2, tau, dt, a, a_end, &mut before[a_end..=b]);
        let force = balance();
        for i in a_end..=b {
            after[i] = if i < a + blank { force(i, 0) } else { before[i] };
            if i < a + blank {
                before[i] = force(i, usize::MAX);
            }
        }
        let kept = |i: usize, turn: usize| if i < turn { before[i] } else { after[i] };
        track::closed(dt, impact, a_end, b, &mut x_acc, kept);
        if r.track_term {
            track::closed(dt, impact, a_end, b, &mut x_force, balance());
        }
        if a_end + 1 < b {
            rebounds[j] = [&x_acc, &x_force].map(|x| Some((x[a_end + 1] - x[a_end]) / dt).filter(|v| v.is_finite()));
        }
    }
    (x_acc, x_force, rebounds)
}

/// How long after a shock the front chamber is taken as closed, to fit the
/// rebound of a tail's track.
const REBOUND_FIT_S: f64 = 0.5e-3;

/// The track after an impact that no later impact closes (a device's
/// one-cycle capture, a trace's last cycle): the accelerometer integrated
/// from the end of the shock, its start velocity the `rebound` the closed
/// track of the cycle's own opening impact gave (a steady hammer rebounds
/// alike from each impact; this reads the front feed's onset about as
/// closely as a closed track: docs/estimator.md). Without one, the rebound
/// is fitted to the front chamber's first half millisecond, when it is
/// still closed on the model's valve timing and its p·V^1.4 gives the
/// position by itself; on a hammer whose valve feeds the front chamber
/// before the impact that fit is off, and so is the tail.
#[allow(clippy::too_many_arguments)]
fn tail_track(
    accel: &[f32],
    p2: &[f32],
    dt: f32,
    chambers: &ChamberGeometry,
    close: usize,
    a_end: usize,
    rebound: Option<f32>,
    x: &mut [f32],
) {
    let n = accel.len().min(p2.len()).min(x.len());
    let impact = chambers.impact_position_m as f32;
    let (v_dead, a2) = (chambers.front_dead_m3 as f32, chambers.front_area_m2 as f32);
    let a_end = a_end.clamp(close, n);
    x[close..a_end].fill(impact);
    if a_end + 2 >= n {
        return;
    }
    // u: the displacement the accelerometer gives from rest at the shock's end.
    let mut u = vec![0.0f32; n - a_end];
    let mut v = 0.0f32;
    for k in 1..u.len() {
        let i = a_end + k;
        let v_next = v + 0.5 * dt * (accel[i - 1] + accel[i]);
        u[k] = u[k - 1] + 0.5 * dt * (v + v_next);
        v = v_next;
    }
    if let Some(v0) = rebound {
        for (k, uk) in u.iter().enumerate() {
            x[a_end + k] = (impact + v0 * k as f32 * dt + uk).min(impact);
        }
        return;
    }
    // The closed chamber's position: V = V_dead·(p0/p)^(1/1.4).
    let p_abs = |i: usize| p2[i] + P_ATM_PA;
    let fit = ((REBOUND_FIT_S as f32 / dt) as usize).clamp(2, u.len() - 1);
    let (mut num, mut den) = (0.0f32, 0.0f32);
    for (k, uk) in u.iter().enumerate().take(fit + 1).skip(1) {
        let ratio = p_abs(a_end) / p_abs(a_end + k);
        let x_closed = impact - v_dead * (ratio.powf(1.0 / 1.4) - 1.0) / a2;
        let tk = k as f32 * dt;
        num += (x_closed - impact - uk) * tk;
        den += tk * tk;
    }
    let v0 = if den > 0.0 { (num / den).min(0.0) } else { 0.0 };
    for (k, uk) in u.iter().enumerate() {
        x[a_end + k] = (impact + v0 * k as f32 * dt + uk).min(impact);
    }
}

/// One cycle's characteristics, keyed by its report.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CycleFeeds {
    pub seq: u32,
    /// The impact that closes the cycle.
    pub t_impact_s: f64,
    pub feeds: Characteristics,
}

/// The characteristics of every cycle between two valid reports that follow
/// each other and are followed by a third (a cycle after a lost or invalid
/// one has no trusted start; the last one has no samples after its end).
pub fn characterise_cycles(
    s: &Signals,
    reports: &[CycleReport],
    config: &Config,
    chambers: &ChamberGeometry,
) -> Vec<CycleFeeds> {
    let reading = Reading::of(config);
    let mut out = Vec::new();
    // Runs of reports that follow each other, valid; each report closes a span.
    let mut run: Vec<(&CycleReport, Span)> = Vec::new();
    let mut flush = |run: &mut Vec<(&CycleReport, Span)>| {
        let spans: Vec<Span> = run.iter().map(|r| r.1).collect();
        for ((r, _), c) in run.iter().zip(characterise_spans(s, &spans, &reading, chambers, false)) {
            if let Some(feeds) = c {
                out.push(CycleFeeds {
                    seq: r.seq,
                    t_impact_s: r.t_impact_s(),
                    feeds,
                });
            }
        }
        run.clear();
    };
    for pair in reports.windows(2) {
        let (prev, cur) = (&pair[0], &pair[1]);
        if cur.seq != prev.seq.wrapping_add(1) || !prev.is_valid() || !cur.is_valid() {
            flush(&mut run);
            continue;
        }
        run.push((cur, Span::between(prev, cur)));
    }
    flush(&mut run);
    out
}

/// A port's true openings: the times, from sample 0, at which `open(i)`
/// turns true (the spool's or the valve's crossing of the port's edge, in
/// a truth column sampled every `dt_s`).
pub fn opening_times_s(dt_s: f64, n: usize, open: impl Fn(usize) -> bool) -> Vec<f64> {
    (1..n)
        .filter(|&i| open(i) && !open(i - 1))
        .map(|i| i as f64 * dt_s)
        .collect()
}

/// How far from an impact a port's opening is still taken for that impact's.
const OPENING_NEAR_IMPACT_S: f64 = 10e-3;

/// Mean signed time from each impact to the port opening nearest it (within
/// 10 ms; before the impact negative), over the impacts that have one: the
/// valve's switching as the port sees it. A valve delay's size in physical
/// terms is this time's shift, which no law for the delay changes the
/// meaning of (`None` without an opening near any impact).
pub fn mean_opening_after_impact_s(impacts_s: &[f64], openings_s: &[f64]) -> Option<f64> {
    let v: Vec<f64> = impacts_s
        .iter()
        .filter_map(|&t| {
            openings_s
                .iter()
                .map(|&o| o - t)
                .filter(|d| d.abs() < OPENING_NEAR_IMPACT_S)
                .min_by(|a, b| a.abs().total_cmp(&b.abs()))
        })
        .collect();
    (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A channel late by a filter's delay is read that much later: a ramp
    /// moves by the slope times the lag, whole and fractional samples
    /// alike, the end repeats, and no lag leaves it as it is.
    #[test]
    fn a_late_channel_is_read_back_by_its_delay() {
        let ramp: Vec<f64> = (0..10).map(|i| 3.0 * i as f64).collect();
        let a = advanced(&ramp, 0.4);
        assert!((a[2] - 7.2).abs() < 1e-6 && (a[8] - 25.2).abs() < 1e-5, "{a:?}");
        let b = advanced(&ramp, 1.5);
        assert!((b[0] - 4.5).abs() < 1e-6 && b[9] == 27.0, "{b:?}");
        assert_eq!(advanced(&ramp, 0.0), ramp.iter().map(|&x| x as f32).collect::<Vec<_>>());
        let sensors = crate::sensor_model::SensorModel::default();
        let d = sensors.front.group_delay_s(1e-5);
        assert!((d / 1e-5 - 0.398).abs() < 0.002, "{d}");
    }

    #[test]
    fn a_port_opening_is_read_against_the_impact_nearest_it() {
        // A column that opens at samples 3 and 13 (dt 1 ms), closed between.
        let col = [0, 0, 0, 1, 1, 0, 0, 0, 0, 0, 0, 0, 0, 1, 1];
        let opens = opening_times_s(1e-3, col.len(), |i| col[i] == 1);
        assert_eq!(opens.len(), 2);
        assert!((opens[0] - 3e-3).abs() < 1e-12 && (opens[1] - 13e-3).abs() < 1e-12);
        // Impacts at 2 ms (opens 1 ms after) and 14 ms (opened 1 ms before);
        // one at 40 ms has no opening within 10 ms and is left out.
        let m = mean_opening_after_impact_s(&[2e-3, 14e-3, 40e-3], &opens).expect("two impacts read");
        assert!(m.abs() < 1e-12, "{m}");
        assert_eq!(mean_opening_after_impact_s(&[40e-3], &opens), None);
    }
    use crate::SimConfig;

    /// The board's reading at a cycle's close (`chambers::at_close`, no_std
    /// f32 from the codes) is the host's reading of the same cycle as a
    /// one-cycle raw capture (its codes converted as `hammer capture` does,
    /// read with a tail): every cycle read by one is read by the other, and
    /// every value and uncertainty is the same, bit for bit (compared as
    /// their shortest decimals, so the NaN of an unread dead volume matches),
    /// with the closed fits' logarithms kept or computed where read; the
    /// pressures and the acceleration read from the codes as needed.
    #[test]
    fn the_boards_reading_at_close_is_the_one_cycle_captures() {
        use hammer_estimator::chambers::at_close::{characterise_cycle, window_samples, Work};
        let mut cfg = SimConfig::nominal(5.0);
        cfg.solver.duration_s = 1.0;
        let config = cfg.estimator_config(Some(5.0)).expect("nominal config");
        let trace = crate::simulate(&cfg).expect("simulation").trace();
        let codes = crate::estimation::to_codes(&trace, &config);
        let reports = crate::estimation::run(&codes, config).expect("estimator");
        let value = |cal: &hammer_estimator::ChannelCal, c: u16| cal.value(c) as f64;
        let p1: Vec<f64> = codes.iter().map(|s| value(&config.rear, s.rear)).collect();
        let p2: Vec<f64> = codes.iter().map(|s| value(&config.front, s.front)).collect();
        let acc: Vec<f64> = codes.iter().map(|s| value(&config.accel, s.accel)).collect();
        let s = Signals {
            dt_s: trace.dt_s,
            p_rear_pa: &p1,
            p_front_pa: &p2,
            accel_mps2: &acc,
            x_m: None,
            pressure_lag_s: config.chambers.pressure_group_delay_s as f64,
        };
        let geo = ChamberGeometry::of(&config);
        // The board's f32 chambers are the hammer's as the reading uses them
        // (in f32; the areas computed in f32, within an ulp of the f64 ones).
        let h = cfg.hammer.chambers();
        let f32s = |g: &ChamberGeometry| {
            [
                g.rear_area_m2,
                g.front_area_m2,
                g.rear_dead_m3,
                g.front_dead_m3,
                g.impact_position_m,
                g.rear_outlet_m,
                g.front_outlet_m,
            ]
            .map(|v| v as f32)
        };
        for (k, (a, b)) in f32s(&geo).into_iter().zip(f32s(&h)).enumerate() {
            assert!(if k < 2 { (a / b - 1.0).abs() < 2e-7 } else { a == b }, "{k}: {a} {b}");
        }
        let reading = Reading::of(&config);
        let one_track = Reading {
            track_term: false,
            ..reading
        };
        let n = window_samples(6_000, config.dt_s());
        let (mut x_buf, mut logs_buf) = (vec![0.0f32; n], vec![0.0f32; 2 * n]);
        let mut work = Work {
            x_m: &mut x_buf,
            room: &mut logs_buf,
        };
        let (mut read, mut worst) = (0, [0.0f32; 3]);
        for pair in reports.windows(2) {
            let (prev, cur) = (&pair[0], &pair[1]);
            if !(prev.is_valid() && cur.is_valid() && cur.seq == prev.seq + 1) {
                continue;
            }
            let span = Span::between(prev, cur);
            let host = characterise_spans(&s, &[span], &reading, &geo, true)[0];
            let [open, close] = [span.open_s, span.close_s].map(|t| (t / trace.dt_s).round() as usize);
            let board = characterise_cycle(&config, &geo, &codes[open..], close - open, cur, true, &mut work);
            assert_eq!(board.is_some(), host.is_some(), "cycle {}", cur.seq);
            // One track (the accelerometer's), as the host reads without the track term.
            let one = characterise_cycle(&config, &geo, &codes[open..], close - open, cur, false, &mut work);
            let host_one = characterise_spans(&s, &[span], &one_track, &geo, true)[0];
            assert_eq!(
                format!("{one:?}"),
                format!("{host_one:?}"),
                "cycle {} on one track",
                cur.seq
            );
            let (Some(board), Some(host)) = (board, host) else {
                continue;
            };
            assert_eq!(format!("{board:?}"), format!("{host:?}"), "cycle {}", cur.seq);
            for (b, h) in [(board.front, host.front), (board.rear, host.rear)] {
                assert_eq!(b.is_some(), h.is_some(), "cycle {}", cur.seq);
                let (Some(b), Some(h)) = (b, h) else { continue };
                read += 1;
                let d = [
                    (b.onset_s - h.onset_s).abs(),
                    (b.closed_exponent / h.closed_exponent - 1.0).abs(),
                    (b.feed_area_m2 / h.feed_area_m2 - 1.0).abs(),
                ];
                for k in 0..3 {
                    worst[k] = worst[k].max(d[k]);
                }
                assert_eq!(b.x_m.is_finite(), h.x_m.is_finite());
            }
        }
        // A window longer than the room lent is not read at all (never in part).
        let (mut x_small, mut logs_small) = (vec![0.0f32; 2_000], vec![0.0f32; 2 * 2_000]);
        let mut tight = Work {
            x_m: &mut x_small,
            room: &mut logs_small,
        };
        let cur = reports.iter().rposition(|r| r.is_valid()).expect("a valid cycle");
        let close = (reports[cur].t_impact_s() / trace.dt_s).round() as usize;
        let open = (reports[cur - 1].t_impact_s() / trace.dt_s).round() as usize;
        assert!(close - open > 2_000);
        assert!(characterise_cycle(
            &config,
            &geo,
            &codes[open..],
            close - open,
            &reports[cur],
            true,
            &mut tight
        )
        .is_none());
        // Where the room cannot hold the track's source over the cycle (a
        // board's reading, with no room at all), the track's passes read it
        // from the codes: the same reading, bit for bit.
        let c = &reports[cur];
        let roomy = characterise_cycle(&config, &geo, &codes[open..], close - open, c, true, &mut work);
        assert!(roomy.is_some_and(|r| r.front.is_some() && r.rear.is_some()));
        for room_len in [close - open, 0] {
            let mut short = vec![0.0f32; room_len];
            let mut short_room = Work {
                x_m: &mut x_buf,
                room: &mut short,
            };
            let streamed = characterise_cycle(&config, &geo, &codes[open..], close - open, c, true, &mut short_room);
            assert_eq!(format!("{streamed:?}"), format!("{roomy:?}"), "room of {room_len}");
        }
        println!(
            "{read} feeds read; worst |Δ onset| {:.3e} s, |Δn/n| {:.2e}, |ΔA/A| {:.2e}",
            worst[0], worst[1], worst[2]
        );
        assert!(read >= 20, "{read}");
        assert_eq!(worst, [0.0; 3]);
    }

    /// Without the track term (the diagnosis' reading) every value is the
    /// one read with it, bit for bit, and only the uncertainties are
    /// narrower or equal: the force balance's track widens them, it moves
    /// no value.
    #[test]
    fn the_track_term_moves_no_value() {
        let mut cfg = SimConfig::nominal(5.0);
        cfg.solver.duration_s = 0.3;
        let config = cfg.estimator_config(Some(5.0)).expect("nominal config");
        let trace = crate::simulate(&cfg).expect("simulation").trace();
        let reports = crate::estimation::run(&crate::estimation::to_codes(&trace, &config), config).expect("estimator");
        let spans: Vec<Span> = reports
            .windows(2)
            .filter(|w| w[0].is_valid() && w[1].is_valid())
            .map(|w| Span::between(&w[0], &w[1]))
            .collect();
        let s = Signals {
            dt_s: trace.dt_s,
            p_rear_pa: &trace.p_rear_pa,
            p_front_pa: &trace.p_front_pa,
            accel_mps2: &trace.accel_mps2,
            x_m: None,
            pressure_lag_s: cfg.sensors.front.group_delay_s(trace.dt_s),
        };
        let with = Reading::of(&config);
        let without = Reading {
            track_term: false,
            ..with
        };
        let chambers = cfg.hammer.chambers();
        let (a, b) = (
            characterise_spans(&s, &spans, &with, &chambers, true),
            characterise_spans(&s, &spans, &without, &chambers, true),
        );
        assert!(
            a.iter()
                .flatten()
                .filter(|c| c.front.is_some() && c.rear.is_some())
                .count()
                >= 3
        );
        for (a, b) in a.iter().zip(&b) {
            let (Some(a), Some(b)) = (a, b) else {
                assert_eq!(a.is_some(), b.is_some());
                continue;
            };
            for (fa, fb) in [(a.front, b.front), (a.rear, b.rear)] {
                let (Some(fa), Some(fb)) = (fa, fb) else {
                    assert_eq!(fa.is_some(), fb.is_some());
                    continue;
                };
                assert_eq!(
                    (fa.onset_s, fa.closed_exponent, fa.feed_area_m2),
                    (fb.onset_s, fb.closed_exponent, fb.feed_area_m2)
                );
                assert!(fb.onset_uncertainty_s <= fa.onset_uncertainty_s);
                assert!(fb.closed_exponent_uncertainty <= fa.closed_exponent_uncertainty);
                assert!(fb.feed_area_uncertainty_m2 <= fa.feed_area_uncertainty_m2);
            }
        }
    }
}
