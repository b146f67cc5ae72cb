//! Stage 4, held-out: how far the gap shrinks on data the fit did not see.
//! The verdict's model, with the nominal parameters as its fit left them
//! (within their prior), is run at every operating point and compared with
//! the held-out cycles. The nominal model recalibrated alone is the
//! control: the shrink must come from the effect, not the recalibration.
//! The named effects in the nominal model as it stands (the paper's own
//! check) are the other side: what the effects do without any refit.

use std::collections::BTreeMap;

use super::group::Point;
use super::joint;
use crate::features::{summarize, wave_index, BINS, ENERGY, PERIOD, WAVE_SIGNALS};
use crate::fitset::{FitSet, Recalibrated, Search};
use crate::gap::CycleSignals;
use crate::model::{Candidate, Keep, ModelRunner, ModelTrace};
use crate::options::Options;
use crate::parallel::parallel;
use crate::report::{EffectResult, FittedParam, PointShrink, Recalibration, Shrink};

/// The models the check compares, each run at every operating point.
pub(crate) struct Models {
    /// The verdict's effects; None when no effect was named.
    pub(crate) fitted_cand: Option<Candidate>,
    pub(crate) fitted_runner: ModelRunner,
    /// None everywhere when no effect was named.
    pub(crate) fitted_runs: Vec<Option<ModelTrace>>,
    /// The nominal model recalibrated alone (the control).
    pub(crate) recal_runner: ModelRunner,
    pub(crate) recal_runs: Vec<Option<ModelTrace>>,
    /// The verdict's effects in the nominal model, nothing refitted; None
    /// everywhere when no effect was named.
    pub(crate) effects_only_runs: Vec<Option<ModelTrace>>,
    pub(crate) recal_nominal: Option<Recalibrated>,
    pub(crate) recal_verdict: Option<Recalibrated>,
    /// The verdict's waveform-only sizes as the check refitted them
    /// (empty where they were held).
    pub(crate) refit_sizes: Vec<FittedParam>,
}

impl Models {
    pub(crate) fn simulations(&self) -> usize {
        [&self.fitted_runs, &self.recal_runs, &self.effects_only_runs]
            .iter()
            .map(|runs| runs.iter().flatten().count())
            .sum()
    }

    /// The verdict's model at point `i`: the fitted one, or with no effect
    /// named, the recalibrated nominal one.
    pub(crate) fn verdict_run(&self, i: usize) -> Option<&ModelTrace> {
        if self.fitted_cand.is_some() {
            self.fitted_runs[i].as_ref()
        } else {
            self.recal_runs[i].as_ref()
        }
    }

    /// A model cycle's pressures as the measurement's transducers read
    /// them ([`ModelRunner::read_pressures`]), with `cand`'s sensor effects.
    pub(crate) fn read(&self, cycle: &mut CycleSignals, cand: Option<&Candidate>) {
        let none = Default::default();
        let effects = cand.map_or(&none, |c| &c.effects);
        self.recal_runner
            .read_pressures(effects, &mut cycle.p_rear_pa, &mut cycle.p_front_pa);
    }

    /// The recalibration the verdict's model carries.
    fn verdict_recalibration(&self) -> Option<&Recalibrated> {
        if self.fitted_cand.is_some() {
            self.recal_verdict.as_ref()
        } else {
            self.recal_nominal.as_ref()
        }
    }
}

/// How the check recalibrates: to the minimum of the fit points' cost, a
/// Gauss–Newton step the line search could not use retried damped, and
/// steps enough to get there. The confirm stage's eight undamped steps
/// stopped short of it, wherever a step was misjudged or the steps ran
/// out, and where they stopped turned on the verdict's sizes to a percent:
/// the structural benchmark's case 18 (seed 7), the same verdict with and
/// without the record, sizes 0.1 % apart, stopped at χ² 1793 against 334,
/// and the held-out energy was 3.3 % off against 0.1 %. Damped and given
/// twenty steps, it is 0.09 % off against 0.08 %. A lower cost on the fit
/// points is not always a better held-out energy: the search's end is the
/// fit's, chosen on the fit points alone.
pub(crate) const CHECK_SEARCH: Search = Search {
    steps: 20,
    damped: true,
};

/// Recalibrates the nominal model alone and with the verdict's effects,
/// and runs both at every point of `bars`. Made here in both modes, not
/// taken from the confirm stage (which searches as the ranking does), so
/// the check is the same with a record and without it.
pub(crate) fn models(fs: &FitSet, bars: &[f64], verdict: Option<&EffectResult>, opts: &Options) -> Models {
    let fitted_cand = verdict.map(|v| v.candidate.clone());
    let h = opts.nominal_uncertainty;
    let recalibrated = |cand: &Candidate, from: Option<&[f64]>| -> Option<Recalibrated> {
        if h > 0.0 {
            fs.recalibrate_with(cand, h, CHECK_SEARCH, opts.threads, from)
        } else {
            None
        }
    };
    let model_runs = |recal: &Option<Recalibrated>, cand: &Candidate| -> (ModelRunner, Vec<Option<ModelTrace>>) {
        let r = recal.as_ref().map_or_else(|| fs.runner.clone(), |x| x.runner.clone());
        let runs = parallel(opts.threads, bars.to_vec(), &|bar| {
            r.run(bar, &cand.effects, Keep::All).ok()
        });
        (r, runs)
    };
    let none = || bars.iter().map(|_| None).collect::<Vec<_>>();
    let nominal = Candidate::default();
    let recal_nominal = recalibrated(&nominal, None);
    // The verdict's model starts where the nominal one got to (if that is
    // better than nominal for it): the effects move the nominal parameters
    // less than the hammer's form does. From there its waveform-only sizes
    // are refitted with the nominal values, kept where that lowers the fit
    // points' cost (it cannot raise it), held otherwise.
    let held = fitted_cand
        .as_ref()
        .and_then(|c| recalibrated(c, recal_nominal.as_ref().map(|r| r.delta.as_slice())));
    let refitted = match (verdict, &held) {
        (Some(v), Some(held)) => refit(fs, v, &held.delta, opts).filter(|r| r.1.cost < held.cost),
        _ => None,
    };
    let refit_sizes = refitted.as_ref().map_or_else(Vec::new, |r| r.2.clone());
    let (fitted_cand, recal_verdict) = match refitted {
        Some((cand, recal, _)) => (Some(cand), Some(recal)),
        None => (fitted_cand, held),
    };
    let (fitted_runner, fitted_runs) = match &fitted_cand {
        Some(c) => model_runs(&recal_verdict, c),
        None => (fs.runner.clone(), none()),
    };
    let (recal_runner, recal_runs) = model_runs(&recal_nominal, &nominal);
    let effects_only_runs = fitted_cand.as_ref().map_or_else(none, |c| model_runs(&None, c).1);
    Models {
        fitted_cand,
        fitted_runner,
        fitted_runs,
        recal_runner,
        recal_runs,
        effects_only_runs,
        recal_nominal,
        recal_verdict,
        refit_sizes,
    }
}

/// The verdict's waveform-only effects refitted on the check's own fit
/// points, each in turn with the nominal values ([`super::joint`]), from
/// the verdict's sizes and the nominal values `from`; the candidate, its
/// recalibration and every refitted size. None where the verdict has no
/// such effect or a fit cannot run.
///
/// Why: against a record, an effect is sized on the change since the
/// record, and held at that size the check measured how well the record's
/// size fits this hammer's own form, not how well the effect predicts:
/// the structural benchmark's case 107 (seed 7), the same supply
/// restriction named in both modes at 1.82 mm with the record and 1.52 mm
/// without, missed the held-out energy by 3.5 % against 0.15 %; refitted,
/// 0.33 % against 0.15 %. Refitted in both modes, the check asks the same
/// in both: the model with the named effects, fitted to the fit points,
/// at the points it did not see. Sizes the force balance measured (friction, viscous friction,
/// the pressure gain and zero) are that measurement in both modes and are
/// held.
fn refit(
    fs: &FitSet,
    v: &EffectResult,
    from: &[f64],
    opts: &Options,
) -> Option<(Candidate, Recalibrated, Vec<FittedParam>)> {
    let measured = |name: &str| v.waveform_fit.iter().any(|p| p.key.starts_with(&format!("{name}.")));
    let (mut cand, mut delta, mut sizes) = (v.candidate.clone(), from.to_vec(), Vec::new());
    let mut last = None;
    for name in v.name.split('+').filter(|n| !measured(n)) {
        let theta0 = joint::theta_of(fs, &v.fitted, name)?;
        let j = joint::fit(fs, &cand, name, &theta0, &delta, opts)?;
        delta.clone_from(&j.recalibrated.delta);
        cand = j.candidate;
        sizes.extend(j.fitted);
        last = Some(j.recalibrated);
    }
    Some((cand, last?, sizes))
}

/// The recalibrated nominal model's features at point `i` (at `bar`), as
/// the measurement is read; None where its run failed.
pub(crate) fn recalibrated_features(models: &Models, i: usize, bar: f64) -> Option<Vec<f64>> {
    let run = models.recal_runs.get(i)?.as_ref()?;
    models
        .recal_runner
        .features_of_truth(run, &Candidate::default().effects, bar)
}

/// The shrink at every point with held-out cycles, judged on the held-out points.
pub(crate) fn shrink(points: &[Point], nominal_features: &[Vec<f64>], models: &Models) -> Shrink {
    let held_out_points: Vec<f64> = points
        .iter()
        .filter(|p| !p.is_fit_point)
        .map(|p| p.supply_bar)
        .collect();
    let shrink_points = points
        .iter()
        .enumerate()
        .filter_map(|(i, p)| point_shrink(i, p, &nominal_features[i], models))
        .collect();
    Shrink {
        refitted: models.refit_sizes.clone(),
        ..judged(shrink_points, held_out_points)
    }
}

/// The three models against one point's held-out cycles; None without any.
fn point_shrink(i: usize, p: &Point, nom: &[f64], models: &Models) -> Option<PointShrink> {
    let s = summarize(&p.held);
    if s.cycles == 0 {
        return None;
    }
    let nominal = Candidate::default();
    let fitted = match (&models.fitted_cand, &models.fitted_runs[i]) {
        (Some(c), Some(run)) => models.fitted_runner.features_of_truth(run, &c.effects, p.supply_bar),
        _ => None,
    };
    let recal = models.recal_runs[i]
        .as_ref()
        .and_then(|run| {
            models
                .recal_runner
                .features_of_truth(run, &nominal.effects, p.supply_bar)
        })
        .unwrap_or_else(|| nom.to_vec());
    // Any runner reads a solution alike (one extractor, one settling time).
    let effects_only = match (&models.fitted_cand, &models.effects_only_runs[i]) {
        (Some(c), Some(run)) => models.recal_runner.features_of_truth(run, &c.effects, p.supply_bar),
        _ => None,
    }
    .unwrap_or_else(|| nom.to_vec());
    // With no effect named, the verdict's model is the recalibrated nominal one.
    let fitted = fitted.unwrap_or_else(|| recal.clone());
    let rms = |m: &[f64]| -> BTreeMap<String, f64> {
        WAVE_SIGNALS
            .iter()
            .enumerate()
            .map(|(si, name)| {
                let d: Vec<f64> = (0..BINS)
                    .map(|b| m[wave_index(si, b)] - s.mean[wave_index(si, b)])
                    .filter(|x| x.is_finite())
                    .collect();
                let r = (d.iter().map(|x| x * x).sum::<f64>() / d.len().max(1) as f64).sqrt();
                (name.to_string(), r)
            })
            .collect()
    };
    Some(PointShrink {
        supply_bar: p.supply_bar,
        held_out_point: !p.is_fit_point,
        cycles: s.cycles,
        impact_energy_measured_j: s.mean[ENERGY],
        impact_energy_nominal_j: nom[ENERGY],
        impact_energy_fitted_j: fitted[ENERGY],
        impact_energy_recalibrated_j: recal[ENERGY],
        impact_energy_effects_only_j: effects_only[ENERGY],
        frequency_measured_hz: 1.0 / s.mean[PERIOD],
        frequency_nominal_hz: 1.0 / nom[PERIOD],
        frequency_fitted_hz: 1.0 / fitted[PERIOD],
        rms_before: rms(nom),
        rms_after: rms(&fitted),
    })
}

/// Mean errors over the held-out points, or with none, over every point
/// (their later half of cycles is still unseen by the fit).
fn judged(shrink_points: Vec<PointShrink>, held_out_points: Vec<f64>) -> Shrink {
    let judged: Vec<&PointShrink> = if held_out_points.is_empty() {
        shrink_points.iter().collect()
    } else {
        shrink_points.iter().filter(|p| p.held_out_point).collect()
    };
    let mean_err = |f: &dyn Fn(&PointShrink) -> f64| {
        100.0 * judged.iter().map(|p| f(p).abs()).sum::<f64>() / judged.len().max(1) as f64
    };
    let energy = |p: &PointShrink, model: f64| (model - p.impact_energy_measured_j) / p.impact_energy_measured_j;
    let frequency = |p: &PointShrink, model: f64| (model - p.frequency_measured_hz) / p.frequency_measured_hz;
    Shrink {
        impact_energy_error_before: mean_err(&|p| energy(p, p.impact_energy_nominal_j)),
        impact_energy_error_after: mean_err(&|p| energy(p, p.impact_energy_fitted_j)),
        frequency_error_before: mean_err(&|p| frequency(p, p.frequency_nominal_hz)),
        frequency_error_after: mean_err(&|p| frequency(p, p.frequency_fitted_hz)),
        impact_energy_error_recalibrated_only: mean_err(&|p| energy(p, p.impact_energy_recalibrated_j)),
        impact_energy_error_effects_only: mean_err(&|p| energy(p, p.impact_energy_effects_only_j)),
        judged_on: if held_out_points.is_empty() {
            "the later half of the cycles of every trace (one operating point: no held-out pressure)".into()
        } else {
            "every steady cycle at the held-out pressures".into()
        },
        held_out_points,
        points: shrink_points,
        refitted: Vec::new(),
    }
}

/// The nominal parameters as the verdict's fit left them.
pub(crate) fn recalibration(models: &Models, h: f64) -> Vec<Recalibration> {
    models
        .verdict_recalibration()
        .map_or_else(Vec::new, |rc| recalibration_table(rc, h))
}

fn recalibration_table(rc: &Recalibrated, h: f64) -> Vec<Recalibration> {
    let h = rc.runner.prior_sds(h);
    rc.runner
        .plant
        .nuisance()
        .iter()
        .zip(h)
        .zip(rc.delta.iter().zip(&rc.sd))
        .map(|((p, h), (&d, &sd))| {
            let v0 = p.nominal;
            Recalibration {
                parameter: p.name.clone(),
                nominal: v0,
                value: v0 * (1.0 + h * d),
                sd: (v0 * h * sd).abs(),
                prior_sds: d,
                beyond_prior: d.abs() > 1.0,
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn point(bar: f64, held_out: bool, energy: (f64, f64, f64), freq: (f64, f64, f64)) -> PointShrink {
        PointShrink {
            supply_bar: bar,
            held_out_point: held_out,
            cycles: 10,
            impact_energy_measured_j: energy.0,
            impact_energy_nominal_j: energy.1,
            impact_energy_fitted_j: energy.2,
            impact_energy_recalibrated_j: energy.1,
            impact_energy_effects_only_j: energy.1,
            frequency_measured_hz: freq.0,
            frequency_nominal_hz: freq.1,
            frequency_fitted_hz: freq.2,
            rms_before: BTreeMap::new(),
            rms_after: BTreeMap::new(),
        }
    }

    /// The fit point does not judge the model that was fitted to it: with a
    /// held-out pressure, only it counts; over- and undershoot count alike.
    #[test]
    fn judged_on_what_the_fit_did_not_see() {
        let fit = point(4.0, false, (10.0, 11.0, 10.0), (30.0, 33.0, 30.0));
        let held = point(7.0, true, (20.0, 16.0, 21.0), (40.0, 42.0, 40.4));
        let s = judged(vec![fit.clone(), held.clone()], vec![7.0]);
        assert!((s.impact_energy_error_before - 20.0).abs() < 1e-9);
        assert!((s.impact_energy_error_after - 5.0).abs() < 1e-9);
        assert!((s.frequency_error_after - 1.0).abs() < 1e-9);
        assert!(s.judged_on.contains("held-out"));
        let all = judged(vec![fit, held], vec![]);
        assert!((all.impact_energy_error_before - 15.0).abs() < 1e-9);
    }

    /// A parameter moved 1.5 prior standard deviations up sits above its
    /// nominal value by 1.5 × the prior's width and is flagged; one moved
    /// half a standard deviation down is not.
    #[test]
    fn recalibration_in_the_parameters_units() {
        let base = hammer_sim::SimConfig::default();
        let n = crate::model::NUISANCE.len();
        let mut delta = vec![0.0; n];
        delta[0] = 1.5;
        delta[1] = -0.5;
        let rc = Recalibrated {
            runner: ModelRunner::new(base.clone(), crate::features::extractor_for(&base)),
            delta,
            sd: vec![0.5; n],
            cost: 0.0,
            residuals: Vec::new(),
        };
        let t = recalibration_table(&rc, 0.2);
        assert_eq!(t.len(), n);
        assert!(t[0].beyond_prior && !t[1].beyond_prior);
        assert!((t[0].value / t[0].nominal - 1.3).abs() < 1e-12);
        assert!(t[1].value < t[1].nominal);
        assert!((t[0].sd - 0.1 * t[0].nominal.abs()).abs() < 1e-12);
    }
}
