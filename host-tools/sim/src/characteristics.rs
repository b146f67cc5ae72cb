//! Per-cycle chamber characteristics of a trace: the valve's switching, the
//! fills and the closed phases (`hammer_estimator::chambers`), cycle by
//! cycle of the estimator's reports.
//!
//! The same calculation reads the measured pressures with the force
//! balance's position track, or a simulator's true pressures and position:
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
    pub x_m: Option<&'a [f64]>,
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
        let x = match s.x_m {
            Some(x) if x.len() > following => f32s(x),
            Some(_) => continue,
            None => {
                let mut x = vec![f32::NAN; p1.len()];
                let impact = chambers.impact_position_m as f32;
                for (a, b, r) in [(open, close, cur), (close, following, next)] {
                    let friction = PhaseFriction {
                        backhaul_n: r.friction_backhaul_n,
                        stroke_n: r.friction_stroke_n,
                    };
                    let dt = s.dt_s as f32;
                    track::position(&p1, &p2, dt, &piston, friction, impact, a - open, b - open, &mut x);
                }
                x
            }
        };
        let (p1, p2, x) = (&p1[..=end - open], &p2[..=end - open], &x[..=end - open]);
        let w = Window {
            dt_s: s.dt_s as f32,
            p_rear_pa: p1,
            p_front_pa: p2,
            x_m: x,
            open: 0,
            close: close - open,
        };
        out.push(CycleFeeds {
            seq: cur.seq,
            t_impact_s: cur.t_impact_s(),
            feeds: characterise(&w, chambers, supply_abs),
        });
    }
    out
}
