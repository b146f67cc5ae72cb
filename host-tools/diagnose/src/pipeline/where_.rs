//! Stage 5, where: the gap by signal × stage of the cycle at every point,
//! against the nominal model (where it lies), and what is left of it after
//! the verdict's model (the unexplained remainder: where the model's form
//! differs from the hammer's); and the mean cycles the figures draw.
//!
//! Last because it needs the verdict's model; it changes no number of the
//! ranking, only says where to look.

use super::group::Grouped;
use super::held_out::Models;
use super::nominal::Nominal;
use crate::gap::PointWaves;
use crate::gap::{breakdown, measured_cycles, normalized, template, CycleSignals, GapCell};
use crate::input::MeasuredInput;
use crate::options::Options;
use crate::parallel::parallel;
use crate::report::{Remainder, WhereCell};
use hammer_sim::params::HammerParams;

/// A cell's residual below this share of the signal's RMS is not reported as a remainder.
const REMAINDER_MIN: f64 = 0.1;
/// Remainder cells kept in the report.
const REMAINDER_CELLS: usize = 8;

#[derive(Default)]
pub(crate) struct Located {
    /// Largest relative RMS first.
    pub(crate) where_: Vec<WhereCell>,
    /// Largest first, at most [`REMAINDER_CELLS`].
    pub(crate) remainder: Vec<Remainder>,
    pub(crate) waves: Vec<PointWaves>,
}

/// The gap and the remainder at every point whose nominal cycle could be cut out.
pub(crate) fn locate(
    inputs: &[MeasuredInput],
    grouped: &Grouped,
    nominal: &Nominal,
    models: &Models,
    hammer: &HammerParams,
    opts: &Options,
) -> Located {
    // Each point on its own (the cycles' alignment is most of the stage),
    // gathered in point order.
    let jobs: Vec<usize> = (0..grouped.points.len()).collect();
    let per_point = parallel(opts.threads, jobs, &|i| {
        locate_point(i, inputs, grouped, nominal, models, hammer, opts)
    });
    let mut out = Located::default();
    for p in per_point.into_iter().flatten() {
        out.where_.extend(p.where_);
        out.remainder.extend(p.remainder);
        out.waves.extend(p.waves);
    }
    out.where_.sort_by(|a, b| b.relative_rms.total_cmp(&a.relative_rms));
    out.remainder.sort_by(|a, b| b.relative_rms.total_cmp(&a.relative_rms));
    out.remainder.truncate(REMAINDER_CELLS);
    out
}

/// [`locate`] at point `i`; None where its nominal cycle cannot be cut out.
fn locate_point(
    i: usize,
    inputs: &[MeasuredInput],
    grouped: &Grouped,
    nominal: &Nominal,
    models: &Models,
    hammer: &HammerParams,
    opts: &Options,
) -> Option<Located> {
    let p = &grouped.points[i];
    let mut out = Located::default();
    let (mut tpl, stages) = template(&nominal.runs[i], hammer)?;
    models.read(&mut tpl, None);
    let mut meas = Vec::new();
    for &k in &p.inputs {
        meas.extend(measured_cycles(&inputs[k].trace, &grouped.steady_impacts[k]));
    }
    let nominal_cells = breakdown(&tpl, &stages, &meas);
    if let Some((mut after, after_stages)) = models.verdict_run(i).and_then(|r| template(r, hammer)) {
        models.read(&mut after, models.fitted_cand.as_ref());
        let after_cells = breakdown(&after, &after_stages, &meas);
        out.remainder
            .extend(remainder(p.supply_bar, after_cells, &nominal_cells));
    }
    out.where_.extend(nominal_cells.into_iter().map(|c| WhereCell {
        supply_bar: p.supply_bar,
        signal: c.signal,
        stage: c.stage,
        bias: c.bias,
        rms: c.rms,
        relative_rms: c.relative_rms,
        timing_shift_s: c.timing_shift_s,
    }));
    if opts.figures && !meas.is_empty() {
        let fitted = fitted_cycle(models, i, hammer);
        out.waves.push(PointWaves {
            supply_bar: p.supply_bar,
            t_s: (0..tpl.len()).map(|k| k as f64 * tpl.dt_s).collect(),
            stages: stages.clone(),
            measured: mean_cycle(&meas, tpl.len()),
            nominal: tpl,
            fitted,
        });
    }
    Some(out)
}

/// The cells the verdict's model leaves above [`REMAINDER_MIN`], each with
/// the nominal model's value of the same cell.
fn remainder(supply_bar: f64, after: Vec<GapCell>, nominal: &[GapCell]) -> Vec<Remainder> {
    after
        .into_iter()
        .filter(|c| c.relative_rms >= REMAINDER_MIN)
        .map(|c| {
            let before = nominal
                .iter()
                .find(|n| n.signal == c.signal && n.stage == c.stage)
                .map_or(f64::NAN, |n| n.relative_rms);
            Remainder {
                supply_bar,
                statement: format!(
                    "{}, {}: {:.0} % of the signal's RMS unexplained; {}",
                    c.signal,
                    c.stage.name(),
                    100.0 * c.relative_rms,
                    form_cause(&c.signal)
                ),
                signal: c.signal,
                stage: c.stage,
                relative_rms: c.relative_rms,
                relative_rms_nominal: before,
            }
        })
        .collect()
}

/// The fitted model's cycle at point `i` as the sensors would read it
/// (a pressure gain error scales the readings, not the physics).
fn fitted_cycle(models: &Models, i: usize, hammer: &HammerParams) -> Option<CycleSignals> {
    models.fitted_runs[i]
        .as_ref()
        .and_then(|r| template(r, hammer))
        .map(|(mut f, _)| {
            models.read(&mut f, models.fitted_cand.as_ref());
            f
        })
}

/// What a residual left in a signal says about the model's form.
fn form_cause(signal: &str) -> &'static str {
    match signal {
        "p_rear_pa" | "p_front_pa" => "the valve or port model differs (or the chamber's thermodynamics)",
        "accel_mps2" => "the contact, friction or accelerometer model differs",
        _ => "the forces that drive the motion differ (pressures, friction or contact)",
    }
}

/// The average of measured cycles, each stretched onto `len` samples.
fn mean_cycle(meas: &[CycleSignals], len: usize) -> CycleSignals {
    let stretched: Vec<CycleSignals> = meas.iter().map(|m| normalized(m, len)).collect();
    let avg = |f: &dyn Fn(&CycleSignals) -> &Vec<f64>| -> Vec<f64> {
        (0..len)
            .map(|k| {
                let xs: Vec<f64> = stretched.iter().map(|c| f(c)[k]).filter(|x| x.is_finite()).collect();
                if xs.is_empty() {
                    f64::NAN
                } else {
                    xs.iter().sum::<f64>() / xs.len() as f64
                }
            })
            .collect()
    };
    CycleSignals {
        dt_s: stretched.first().map_or(1e-5, |c| c.dt_s),
        p_rear_pa: avg(&|c| &c.p_rear_pa),
        p_front_pa: avg(&|c| &c.p_front_pa),
        accel_mps2: avg(&|c| &c.accel_mps2),
        velocity_mps: avg(&|c| &c.velocity_mps),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::stages::Stage;

    fn ramp(n: usize, slope: f64) -> CycleSignals {
        let x: Vec<f64> = (0..n).map(|k| slope * k as f64 / (n - 1) as f64).collect();
        CycleSignals {
            dt_s: 1e-5,
            p_rear_pa: x.clone(),
            p_front_pa: x.clone(),
            accel_mps2: x.clone(),
            velocity_mps: x,
        }
    }

    /// Cycles of different periods are stretched onto one before they are
    /// averaged: the same ramp measured over 80 and over 120 samples
    /// averages to that ramp; a missing sample (NaN) in one cycle is filled
    /// by the others.
    #[test]
    fn mean_cycle_stretches_before_averaging() {
        let mut short = ramp(80, 1.0);
        short.velocity_mps[0] = f64::NAN;
        let m = mean_cycle(&[short, ramp(120, 1.0)], 100);
        assert_eq!(m.len(), 100);
        for (k, x) in m.p_rear_pa.iter().enumerate() {
            assert!((x - k as f64 / 99.0).abs() < 1e-9, "{k}: {x}");
        }
        assert!(m.velocity_mps[0].abs() < 1e-12);
    }

    fn cell(signal: &str, stage: Stage, relative_rms: f64) -> GapCell {
        GapCell {
            signal: signal.into(),
            stage,
            bias: 0.0,
            rms: relative_rms,
            relative_rms,
            timing_shift_s: 0.0,
            samples: 10,
        }
    }

    /// Only what the verdict's model leaves above a tenth of the signal is
    /// a remainder; a pressure residual points at the valve or ports.
    #[test]
    fn remainder_keeps_what_is_left_and_names_its_cause() {
        let nominal = [
            cell("p_rear_pa", Stage::StrokeClosed, 0.5),
            cell("accel_mps2", Stage::Impact, 0.3),
        ];
        let after = vec![
            cell("p_rear_pa", Stage::StrokeClosed, 0.2),
            cell("accel_mps2", Stage::Impact, 0.05),
        ];
        let r = remainder(4.0, after, &nominal);
        assert_eq!(r.len(), 1);
        assert_eq!(r[0].relative_rms_nominal, 0.5);
        assert!(
            r[0].statement.starts_with("p_rear_pa, stroke_closed: 20 % "),
            "{}",
            r[0].statement
        );
        assert!(r[0].statement.contains("valve or port"));
    }
}
