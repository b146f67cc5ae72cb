//! Where the gap lies: measured cycles against the simulated one, aligned at
//! the impact, broken down by signal and stage into bias, RMS and the time
//! shift that best aligns them.

use serde::{Deserialize, Serialize};

use super::stages::{stage_of, Edges, Stage, STAGES};
use crate::model::ModelTrace;
use hammer_sim::params::HammerParams;
use hammer_trace::trace::Trace;

/// The compared signals, in the order of [`CycleSignals::get`].
pub const SIGNALS: [&str; 4] = ["p_rear_pa", "p_front_pa", "accel_mps2", "velocity_mps"];

/// The shock is left out of the acceleration and velocity comparisons: a
/// contact model gets its energy right, not its pulse (field notes).
pub const IMPACT_WINDOW_S: f64 = 1.0e-3;

/// One cycle's signals from its impact on, uniformly sampled.
#[derive(Debug, Clone)]
pub struct CycleSignals {
    pub dt_s: f64,
    pub p_rear_pa: Vec<f64>,
    pub p_front_pa: Vec<f64>,
    pub accel_mps2: Vec<f64>,
    pub velocity_mps: Vec<f64>,
}

impl CycleSignals {
    pub fn len(&self) -> usize {
        self.p_rear_pa.len()
    }

    pub fn is_empty(&self) -> bool {
        self.p_rear_pa.is_empty()
    }

    pub fn get(&self, signal: usize) -> &[f64] {
        match signal {
            0 => &self.p_rear_pa,
            1 => &self.p_front_pa,
            2 => &self.accel_mps2,
            _ => &self.velocity_mps,
        }
    }
}

/// Velocity from the acceleration, outside the shock: the constant is fixed
/// by the piston returning to the impact position (the displacement over the
/// cycle closes), so an accelerometer offset does not become a ramp's start.
pub fn velocity_from_accel(accel_mps2: &[f64], dt_s: f64) -> Vec<f64> {
    let w = (IMPACT_WINDOW_S / dt_s).round() as usize;
    let n = accel_mps2.len();
    let mut v = vec![0.0; n];
    for i in (w + 1).min(n)..n {
        v[i] = v[i - 1] + 0.5 * (accel_mps2[i] + accel_mps2[i - 1]) * dt_s;
    }
    // ∫v over the cycle = 0, the shock window moving at the first kept velocity.
    let kept = n.saturating_sub(w).max(1) as f64;
    let mean_after = v[w.min(n)..].iter().sum::<f64>() / kept;
    let c = -mean_after * kept / n.max(1) as f64;
    for (i, x) in v.iter_mut().enumerate() {
        *x = if i < w { f64::NAN } else { *x + c };
    }
    v
}

/// The simulated reference cycle: the last complete cycle of a steady run,
/// its ideal signals and the stage of every sample.
pub fn template(run: &ModelTrace, hammer: &HammerParams) -> Option<(CycleSignals, Vec<Stage>)> {
    let c = run.impacts.last()?;
    let t = run;
    let motion = t.motion.as_ref()?;
    let i0 = ((c.t_impact_s - c.period_s) / t.dt_s).ceil() as usize;
    let i1 = ((c.t_impact_s / t.dt_s).ceil() as usize)
        .min(t.len())
        .min(motion.v_mps.len());
    if i1 <= i0 + 10 {
        return None;
    }
    let edges = Edges {
        front_outlet_m: hammer.front_outlet_opens_m,
        rear_outlet_m: hammer.rear_outlet_opens_m,
    };
    let stages = (i0..i1)
        .map(|i| {
            stage_of(
                &edges,
                motion.x_m[i],
                motion.v_mps[i],
                (i - i0) as f64 * t.dt_s,
                IMPACT_WINDOW_S,
            )
        })
        .collect();
    let mut v = motion.v_mps[i0..i1].to_vec();
    let w = (IMPACT_WINDOW_S / t.dt_s).round() as usize;
    for x in v.iter_mut().take(w) {
        *x = f64::NAN;
    }
    Some((
        CycleSignals {
            dt_s: t.dt_s,
            p_rear_pa: t.p_rear_pa[i0..i1].to_vec(),
            p_front_pa: t.p_front_pa[i0..i1].to_vec(),
            accel_mps2: t.accel_mps2[i0..i1].to_vec(),
            velocity_mps: v,
        },
        stages,
    ))
}

/// The measured cycles between consecutive impacts.
pub fn measured_cycles(trace: &Trace, impacts_s: &[f64]) -> Vec<CycleSignals> {
    impacts_s
        .windows(2)
        .filter_map(|w| {
            let i0 = (w[0] / trace.dt_s).round() as usize;
            let i1 = ((w[1] / trace.dt_s).round() as usize).min(trace.len());
            (i1 > i0 + 10).then(|| CycleSignals {
                dt_s: trace.dt_s,
                p_rear_pa: trace.p_rear_pa[i0..i1].to_vec(),
                p_front_pa: trace.p_front_pa[i0..i1].to_vec(),
                accel_mps2: trace.accel_mps2[i0..i1].to_vec(),
                velocity_mps: velocity_from_accel(&trace.accel_mps2[i0..i1], trace.dt_s),
            })
        })
        .collect()
}

/// The gap of one signal in one stage, over all compared cycles.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct GapCell {
    pub signal: String,
    pub stage: Stage,
    /// Mean of measured − simulated, in the signal's unit.
    pub bias: f64,
    pub rms: f64,
    /// RMS over the signal's own RMS in the simulated cycle: comparable across signals.
    pub relative_rms: f64,
    /// Shift of the measurement (positive: later) that best aligns this stage, s.
    pub timing_shift_s: f64,
    pub samples: usize,
}

/// Largest time shift searched, s.
const MAX_SHIFT_S: f64 = 2.0e-3;

/// A measured cycle stretched onto `len` samples (linear interpolation): the
/// difference of period is reported apart, so that what remains is shape and
/// local timing.
pub fn normalized(m: &CycleSignals, len: usize) -> CycleSignals {
    let scale = (m.len().max(2) - 1) as f64 / (len.max(2) - 1) as f64;
    let stretch = |x: &[f64]| -> Vec<f64> {
        (0..len)
            .map(|i| {
                let t = i as f64 * scale;
                let k = (t.floor() as usize).min(x.len().saturating_sub(2));
                let f = t - k as f64;
                x[k] * (1.0 - f) + x[k + 1] * f
            })
            .collect()
    };
    CycleSignals {
        dt_s: m.dt_s / scale,
        p_rear_pa: stretch(&m.p_rear_pa),
        p_front_pa: stretch(&m.p_front_pa),
        accel_mps2: stretch(&m.accel_mps2),
        velocity_mps: stretch(&m.velocity_mps),
    }
}

/// Breaks the gap down by signal × stage, largest relative RMS first. Each
/// measured cycle is first stretched onto the simulated cycle's length.
pub fn breakdown(template: &CycleSignals, stages: &[Stage], measured: &[CycleSignals]) -> Vec<GapCell> {
    let measured: Vec<CycleSignals> = measured
        .iter()
        .filter(|m| m.len() > 10)
        .map(|m| normalized(m, template.len()))
        .collect();
    let measured = &measured[..];
    let mut cells = Vec::new();
    for (si, name) in SIGNALS.iter().enumerate() {
        let sim = template.get(si);
        let scale = rms_of(
            sim.iter()
                .zip(stages)
                .filter(|(x, s)| x.is_finite() && **s != Stage::Impact)
                .map(|(x, _)| *x),
        );
        for stage in STAGES {
            if si >= 2 && stage == Stage::Impact {
                continue; // the shock itself is not compared (see IMPACT_WINDOW_S)
            }
            let idx: Vec<usize> = (0..sim.len())
                .filter(|&i| stages[i] == stage && sim[i].is_finite())
                .collect();
            if idx.is_empty() {
                continue;
            }
            let residuals = |shift: isize| {
                let mut acc = (0usize, 0.0f64, 0.0f64);
                for m in measured {
                    let meas = m.get(si);
                    for &i in &idx {
                        let j = i as isize + shift;
                        if j < 0 || j as usize >= meas.len() || !meas[j as usize].is_finite() {
                            continue;
                        }
                        let r = meas[j as usize] - sim[i];
                        acc.0 += 1;
                        acc.1 += r;
                        acc.2 += r * r;
                    }
                }
                acc
            };
            let (n, sum, sum2) = residuals(0);
            if n == 0 {
                continue;
            }
            let rms = (sum2 / n as f64).sqrt();
            let max_shift = (MAX_SHIFT_S / template.dt_s).round() as isize;
            let step = (max_shift / 20).max(1);
            let best = (-max_shift..=max_shift)
                .step_by(step as usize)
                .map(|s| {
                    let (k, _, q) = residuals(s);
                    (s, if k > 0 { q / k as f64 } else { f64::INFINITY })
                })
                .min_by(|a, b| a.1.total_cmp(&b.1))
                .map_or(0, |(s, _)| s);
            cells.push(GapCell {
                signal: name.to_string(),
                stage,
                bias: sum / n as f64,
                rms,
                relative_rms: if scale > 0.0 { rms / scale } else { f64::INFINITY },
                timing_shift_s: best as f64 * template.dt_s,
                samples: n,
            });
        }
    }
    cells.sort_by(|a, b| b.relative_rms.total_cmp(&a.relative_rms));
    cells
}

fn rms_of(xs: impl Iterator<Item = f64>) -> f64 {
    let (n, s) = xs.fold((0usize, 0.0), |(n, s), x| (n + 1, s + x * x));
    if n == 0 {
        0.0
    } else {
        (s / n as f64).sqrt()
    }
}

/// Waveforms of one operating point for the figures: mean measured cycle,
/// nominal and fitted model, on the simulated cycle's time base.
#[derive(Debug, Clone)]
pub struct PointWaves {
    pub supply_bar: f64,
    pub t_s: Vec<f64>,
    pub stages: Vec<Stage>,
    pub measured: CycleSignals,
    pub nominal: CycleSignals,
    pub fitted: Option<CycleSignals>,
}
