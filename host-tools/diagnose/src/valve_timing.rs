//! When the valve starts feeding the front chamber, relative to the impact:
//! a marker read the same way on any hammer whose true piston position is
//! known (the model's truth, the second model family's truth columns).
//!
//! The diagnosis' `valve_delay` is a delay against its own valve; on a
//! hammer whose valve is of another form the question is first whether
//! that valve is earlier or later than the model's at all. Air entering a
//! closed chamber is the one thing every valve does: the front chamber's
//! p·V^κ, flat while it is closed, rises once the valve feeds it.
//! `docs/diagnosis.md` (why the structural benchmark never names a
//! `valve_delay`) and `examples/valve_timing.rs` use it.
//!
//! Where the valve's truth is known, the front supply port's opening is
//! read off it ([`front_port_opening_of_model`],
//! [`front_port_opening_of_variant`]): how much later the port opens after
//! the impact than in the same hammer without a valve delay is that
//! delay's size in physical terms, what the front feed's onset measures.
//! It is not τ: a parameter belongs to its law. The second family's delay
//! lags a step of the spool's command, the model's lags a pilot force that
//! moves like a ramp: at the same τ the second family's port opens about
//! ln 2·τ later, the model's about τ later (the tests below). The
//! benchmark prints each hidden delay's port shift beside its τ: how far
//! a reading of the port can be from τ on that hammer's law.

use hammer_sim::characteristics::{mean_opening_after_impact_s, opening_times_s};
use hammer_sim::run::{SimRun, TruthTrace};
use hammer_sim::SimConfig;
use hammer_trace::trace::Trace;
use hammer_variants::{Generated, VariantParams};

/// Mean signed time from an impact after `settle_s` to the front supply
/// port's opening in the model's solution: the valve opens that port while
/// it sits within `valve.opening_m` of its front end.
pub fn front_port_opening_of_model(run: &SimRun, cfg: &SimConfig, settle_s: f64) -> Option<f64> {
    let valve = &run.truth.valve_m;
    let opening = cfg.valve.opening_m;
    let openings = opening_times_s(run.truth.dt_s, valve.len(), |i| valve[i] < opening);
    settled_opening(run.cycles.iter().map(|c| c.t_impact_s), settle_s, &openings)
}

/// The same on a second-family hammer's truth: its spool opens the front
/// port below the middle of its travel (`spool` column, 0 feeds the front).
pub fn front_port_opening_of_variant(g: &Generated, settle_s: f64) -> Option<f64> {
    let spool = g.trace.extra.get("spool")?;
    let openings = opening_times_s(g.trace.dt_s, spool.len(), |i| spool[i] < 0.5);
    settled_opening(g.truth.cycles.iter().map(|c| c.t_impact_s), settle_s, &openings)
}

/// [`mean_opening_after_impact_s`] over the impacts after `settle_s`.
fn settled_opening(impacts_s: impl Iterator<Item = f64>, settle_s: f64, openings_s: &[f64]) -> Option<f64> {
    let impacts: Vec<f64> = impacts_s.filter(|&t| t >= settle_s).collect();
    mean_opening_after_impact_s(&impacts, openings_s)
}

/// One run's true position and front pressure, with the chamber's geometry.
#[derive(Debug, Clone, Copy)]
pub struct FrontChamberRun<'a> {
    pub t_s: &'a [f64],
    pub x_m: &'a [f64],
    pub v_mps: &'a [f64],
    /// Gauge.
    pub p_front_pa: &'a [f64],
    pub front_area_m2: f64,
    pub front_dead_m3: f64,
    pub x_impact_m: f64,
}

impl<'a> FrontChamberRun<'a> {
    /// A run of the diagnosis' model, with `cfg`'s geometry.
    pub fn of_model(t: &'a TruthTrace, cfg: &SimConfig) -> Self {
        Self {
            t_s: &t.t_s,
            x_m: &t.x_m,
            v_mps: &t.v_mps,
            p_front_pa: &t.p_front_pa,
            front_area_m2: cfg.hammer.geometry().front_area_m2(),
            front_dead_m3: cfg.hammer.front_dead_volume_m3,
            x_impact_m: cfg.hammer.impact_position_m,
        }
    }

    /// A trace of the second model family with its truth columns (`x_m`,
    /// `v_mps`) and `p`'s geometry; `None` without them.
    pub fn of_variant(t: &'a Trace, p: &VariantParams) -> Option<Self> {
        Some(Self {
            t_s: &t.t_s,
            x_m: t.extra.get("x_m")?,
            v_mps: t.extra.get("v_mps")?,
            p_front_pa: &t.p_front_pa,
            front_area_m2: 0.25 * std::f64::consts::PI * (p.bore_m * p.bore_m - p.rod_m * p.rod_m),
            front_dead_m3: p.front_dead_m3,
            x_impact_m: p.x_impact_m,
        })
    }
}

/// The stroke position from which the front chamber is read: its outlet
/// covered, the valve not yet feeding it on either family.
pub const CLOSED_AT_M: f64 = 0.030;
/// A rise of p·V^1.4 by this much (2 %) marks the feed: heat and leaks
/// move it by less over a stroke.
pub const FEED_RISE: f64 = 0.02;
/// How long after the impact a feed is still looked for.
const LOOK_AFTER_S: f64 = 8e-3;

/// Mean feed onset relative to the impact in ms (negative: before it) over
/// the cycles of the run's later two thirds, and how many had one.
pub fn front_feed_onset_ms(r: &FrontChamberRun) -> Option<(f64, usize)> {
    let n = r.t_s.len().min(r.x_m.len()).min(r.v_mps.len()).min(r.p_front_pa.len());
    if n < 2 {
        return None;
    }
    let y = |i: usize| {
        let volume = r.front_dead_m3 + r.front_area_m2 * (r.x_impact_m - r.x_m[i]);
        (r.p_front_pa[i] + hammer_sim::gas::P_ATM_PA).ln() + 1.4 * volume.ln()
    };
    let dt = r.t_s[1] - r.t_s[0];
    let after = (LOOK_AFTER_S / dt) as usize;
    let (mut sum, mut count) = (0.0, 0usize);
    let mut i = n / 3;
    while i + 1 < n {
        if !(r.v_mps[i] > 0.5 && r.x_m[i] <= CLOSED_AT_M && r.x_m[i + 1] > CLOSED_AT_M) {
            i += 1;
            continue;
        }
        // The impact: where the stroke ends.
        let Some(impact) = (i..n).find(|&k| r.v_mps[k] <= 0.0) else {
            break;
        };
        let y0 = y(i);
        if let Some(j) = (i..(impact + after).min(n)).find(|&j| y(j) >= y0 + FEED_RISE) {
            sum += r.t_s[j] - r.t_s[impact];
            count += 1;
        }
        i = impact + 1;
    }
    (count > 0).then(|| (1e3 * sum / count as f64, count))
}

#[cfg(test)]
mod tests {
    use super::*;
    use hammer_sim::effects::Effects;
    use hammer_variants::{generate, Structure};

    fn model_port_s(bar: f64, tau_s: f64) -> f64 {
        let mut c = SimConfig::nominal(bar);
        c.solver.duration_s = 0.45;
        if tau_s > 0.0 {
            c.effects
                .apply_spec(&format!("valve_delay:tau_s={tau_s}"))
                .expect("catalogue effect");
        }
        let run = hammer_sim::simulate_truth(&c).expect("the model runs");
        front_port_opening_of_model(&run, &c, crate::model::SETTLE_S).expect("the port opens")
    }

    fn variant_port_s(bar: f64, tau_s: f64) -> f64 {
        let mut e = Effects::default();
        if tau_s > 0.0 {
            e.apply_spec(&format!("valve_delay:tau_s={tau_s}"))
                .expect("catalogue effect");
        }
        let g = generate(&VariantParams::default(), Structure::BASE, &e, bar, 0.45, 3);
        front_port_opening_of_variant(&g, crate::model::SETTLE_S).expect("the port opens")
    }

    /// The model's delay lags a pilot force that moves like a ramp: its
    /// port opens about τ later (+1.53 ms for 1.5 ms at 4 bar in
    /// docs/estimator.md). The second family's lags a step of the spool's
    /// command, so its spool reaches the port's edge, half way, ln 2·τ
    /// later where the command's lag dominates (+1.01 ms).
    #[test]
    fn a_delay_moves_each_familys_port_by_its_own_law() {
        let tau = 1.5e-3;
        let m = model_port_s(4.0, tau) - model_port_s(4.0, 0.0);
        assert!((m / tau - 1.0).abs() < 0.1, "model: {m}");
        let v = variant_port_s(4.0, tau) - variant_port_s(4.0, 0.0);
        assert!((v / tau - 2f64.ln()).abs() < 0.1, "variant: {v}");
    }

    /// A closed adiabatic chamber compressed at 5 m/s, fed from a known
    /// time on (its p·V^1.4 rising 5 % per ms), the piston turning at the
    /// impact position: the onset is where the rise reaches 2 %.
    #[test]
    fn a_feed_is_found_where_the_chamber_stops_being_closed() {
        let (dt, speed, a2, dead, x_imp): (f64, f64, f64, f64, f64) = (1e-5, 5.0, 7e-4, 2e-5, 0.052);
        let t_feed = 0.0065; // s into each stroke; the impact is at 6.4 ms
        let (mut t, mut x, mut v, mut p) = (vec![], vec![], vec![], vec![]);
        let c = 101_325.0 * (dead + a2 * (x_imp - 0.020)).powf(1.4);
        for cycle in 0..6 {
            for k in 0..1000 {
                let tk = k as f64 * dt;
                let (xk, vk) = if tk <= 0.0064 {
                    (0.020 + speed * tk, speed)
                } else {
                    (x_imp - speed * (tk - 0.0064), -speed)
                };
                let gain = 1.0 + 50.0 * (tk - t_feed).max(0.0);
                t.push((cycle * 1000 + k) as f64 * dt);
                x.push(xk);
                v.push(vk);
                p.push(gain * c / (dead + a2 * (x_imp - xk)).powf(1.4) - hammer_sim::gas::P_ATM_PA);
            }
        }
        let run = FrontChamberRun {
            t_s: &t,
            x_m: &x,
            v_mps: &v,
            p_front_pa: &p,
            front_area_m2: a2,
            front_dead_m3: dead,
            x_impact_m: x_imp,
        };
        let (ms, n) = front_feed_onset_ms(&run).expect("found");
        // ln(1 + 50·Δt) = 0.02 → Δt = 0.404 ms after the feed, 0.1 ms after the impact.
        let expected = 1e3 * (t_feed + (0.02f64.exp() - 1.0) / 50.0 - 0.0064);
        assert!(n >= 3, "{n} cycles");
        assert!((ms - expected).abs() < 0.03, "{ms:.3} ms, expected {expected:.3}");
    }
}
