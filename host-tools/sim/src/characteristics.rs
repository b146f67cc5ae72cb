//! Per-cycle chamber characteristics of a trace: the valve's switching, the
//! fills and the closed phases (`hammer_estimator::chambers`), cycle by
//! cycle of the estimator's reports.
//!
//! The same calculation reads the measured pressures with the position
//! track of the measured acceleration (the force balance's in the blank after
//! each impact), or a simulator's true pressures and position:
//! that is a characteristic's truth (`docs/estimator.md`).

use hammer_estimator::chambers::track::{self, PhaseFriction, Piston};
use hammer_estimator::chambers::{characterise, ChamberGeometry, Characteristics, Window, LOOK_AFTER_S};
use hammer_estimator::{Config, CycleReport};

/// The pressures (gauge) and, for the truth, the position the
/// characteristics are read from; without a position the force balance's
/// track is used.
#[derive(Debug, Clone, Copy)]
pub struct Signals<'a> {
    pub dt_s: f64,
    pub p_rear_pa: &'a [f64],
    pub p_front_pa: &'a [f64],
    /// The measured acceleration: where each impact's shock ends.
    pub accel_mps2: &'a [f64],
    pub x_m: Option<&'a [f64]>,
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

/// One cycle's characteristics, keyed by its report.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CycleFeeds {
    pub seq: u32,
    /// The impact that closes the cycle.
    pub t_impact_s: f64,
    pub feeds: Characteristics,
}

/// Sample index of a report's impact.
fn impact_index(r: &CycleReport, dt_s: f64) -> usize {
    (r.t_impact_s() / dt_s).round() as usize
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
    let n = s.p_rear_pa.len().min(s.p_front_pa.len());
    let after = (LOOK_AFTER_S as f64 / s.dt_s).ceil() as usize + 64;
    let supply_abs = config.supply_pressure_pa + hammer_estimator::chambers::P_ATM_PA;
    let piston = Piston::of(config);
    let mut out = Vec::new();
    // Each cycle with the one after it: the samples past its closing impact
    // (where a front feed may start) are tracked as the next cycle's.
    for trio in reports.windows(3) {
        let [prev, cur, next] = [&trio[0], &trio[1], &trio[2]];
        let follows = |a: &CycleReport, b: &CycleReport| b.seq == a.seq.wrapping_add(1) && a.is_valid() && b.is_valid();
        if !follows(prev, cur) || !follows(cur, next) {
            continue;
        }
        let [open, close, following] = [prev, cur, next].map(|r| impact_index(r, s.dt_s));
        if !(open < close && close < following && following < n) {
            continue;
        }
        let end = (close + after).min(following);
        let f32s = |v: &[f64]| v[open..=following].iter().map(|&x| x as f32).collect::<Vec<f32>>();
        let (p1, p2) = (f32s(s.p_rear_pa), f32s(s.p_front_pa));
        let window = |x: &'_ [f32], p1: &'_ [f32], p2: &'_ [f32]| {
            let w = Window {
                dt_s: s.dt_s as f32,
                p_rear_pa: &p1[..=end - open],
                p_front_pa: &p2[..=end - open],
                x_m: &x[..=end - open],
                open: 0,
                close: close - open,
            };
            characterise(&w, chambers, supply_abs)
        };
        let feeds = match s.x_m {
            Some(x) if x.len() > following => window(&f32s(x), &p1, &p2),
            Some(_) => continue,
            None => {
                // Two tracks: the accelerometer's (sees friction of any
                // form) and the force balance's; the first is read, their
                // spread widens its uncertainties.
                let accel = f32s(s.accel_mps2);
                let impact = chambers.impact_position_m as f32;
                let threshold = config.impact_threshold_mps2 as f64;
                let dt = s.dt_s as f32;
                let blank = (config.blank_after_s as f64 / s.dt_s).round() as usize;
                let mut x_acc = vec![f32::NAN; p1.len()];
                let mut x_force = vec![f32::NAN; p1.len()];
                for (a, b, r) in [(open, close, cur), (close, following, next)] {
                    let friction = PhaseFriction {
                        backhaul_n: r.friction_backhaul_n,
                        stroke_n: r.friction_stroke_n,
                    };
                    // The tracks start where the contact has ended; during
                    // it the piston is at the tool.
                    let a_end = shock_end(s.accel_mps2, a, threshold, s.dt_s).min(b - 1);
                    let (a, a_end, b) = (a - open, a_end - open, b - open);
                    x_acc[a..a_end].fill(impact);
                    x_force[a..a_end].fill(impact);
                    let balance = || track::force_balance(&p1, &p2, &piston, friction);
                    let tau = config.accel_zero_shift_tau_s;
                    let zs = r.accel_zero_shift_mps2;
                    let source = track::accelerometer(&accel, zs, tau, dt, a, a + blank, balance());
                    track::closed(dt, impact, a_end, b, &mut x_acc, source);
                    track::closed(dt, impact, a_end, b, &mut x_force, balance());
                }
                window(&x_acc, &p1, &p2).widened(&window(&x_force, &p1, &p2))
            }
        };
        out.push(CycleFeeds {
            seq: cur.seq,
            t_impact_s: cur.t_impact_s(),
            feeds,
        });
    }
    out
}
