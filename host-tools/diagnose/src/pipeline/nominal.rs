//! Stage 2, nominal: the nominal model at every operating point, and from
//! it the fit set: the fit points' measured means, weighed by their noise
//! and floors, the nuisance parameters' sensitivities, and the weights
//! inflated by the nominal model's measured form error.
//!
//! Everything an effect's fit needs is computed here once, so the ranking's
//! many fits only ever simulate the candidate effect.

use std::sync::atomic::{AtomicUsize, Ordering};

use super::group::Point;
use crate::features::{summarize, N_FEATURES};
use crate::fitset::{in_fit, model_form_group_name, sigmas, FitSet};
use crate::input::DiagnoseError;
use crate::model::{Candidate, Keep, ModelRunner, ModelTrace};
use crate::options::Options;
use crate::parallel::parallel;
use crate::report::ModelForm;
use hammer_sim::effects::Effects;

/// The nominal model at every operating point, in the points' order.
pub(crate) struct Nominal {
    pub(crate) bars: Vec<f64>,
    pub(crate) runs: Vec<ModelTrace>,
    pub(crate) features: Vec<Vec<f64>>,
}

/// Simulates the nominal model at every point; `step` is called once per point.
pub(crate) fn nominal(
    points: &[Point],
    runner: &ModelRunner,
    opts: &Options,
    step: &(dyn Fn(&str) + Sync),
) -> Result<Nominal, DiagnoseError> {
    let bars: Vec<f64> = points.iter().map(|p| p.supply_bar).collect();
    let results = parallel(opts.threads, bars.clone(), &|bar| {
        let r = runner.run(bar, &Effects::default(), Keep::All);
        step(&format!("nominal model at {bar} bar"));
        r
    });
    let mut runs = Vec::new();
    for (bar, r) in bars.iter().zip(results) {
        runs.push(r.map_err(|e| DiagnoseError::Model(*bar, e))?);
    }
    let nominal = Candidate::default();
    let mut features = Vec::new();
    for (bar, run) in bars.iter().zip(&runs) {
        features.push(
            runner
                .features_of_truth(run, &nominal.effects, *bar)
                .ok_or_else(|| DiagnoseError::Model(*bar, "no steady impact cycle".into()))?,
        );
    }
    Ok(Nominal { bars, runs, features })
}

/// The fit set of the fit points, with the model-form factors it was weighed by.
pub(crate) fn fit_set<'a>(
    points: &[Point],
    nominal: &Nominal,
    runner: &'a ModelRunner,
    opts: &Options,
) -> (FitSet<'a>, Vec<ModelForm>) {
    let fit_idx: Vec<usize> = (0..points.len()).filter(|&i| points[i].is_fit_point).collect();
    let fit_bars: Vec<f64> = fit_idx.iter().map(|&i| points[i].supply_bar).collect();
    let pressures = (
        fit_bars.iter().cloned().fold(f64::INFINITY, f64::min),
        fit_bars.iter().cloned().fold(f64::NEG_INFINITY, f64::max),
    );
    let mut fs = FitSet {
        runner,
        points: fit_idx
            .iter()
            .map(|&i| {
                let s = summarize(&points[i].fit);
                let mut sig = sigmas(&s, &nominal.features[i], &opts.floors);
                for (x, v) in sig.iter_mut().zip(&points[i].reference_var) {
                    *x = (*x * *x + v).sqrt();
                }
                (points[i].supply_bar, s, sig)
            })
            .collect(),
        nominal_truth: fit_idx.iter().map(|&i| nominal.runs[i].clone()).collect(),
        nominal_features: fit_idx.iter().map(|&i| nominal.features[i].clone()).collect(),
        pressures,
        distinct: fit_bars.len(),
        sims: AtomicUsize::new(points.len()),
        nuisance: Vec::new(),
        against_reference: points.iter().any(|p| !p.reference_var.is_empty()),
        reference_var: fit_idx.iter().map(|&i| points[i].reference_var.clone()).collect(),
    };
    if opts.nominal_uncertainty > 0.0 {
        let fit_features: Vec<&[f64]> = fit_idx.iter().map(|&i| nominal.features[i].as_slice()).collect();
        fs.nuisance = nuisance_sensitivities(&fs, &fit_features, opts);
        fs.sims
            .fetch_add(fs.points.len() * runner.nuisance.len(), Ordering::Relaxed);
    }
    let model_form = if opts.model_form {
        let factors = fs.model_form_factors(&Candidate::default());
        fs.inflate(&factors);
        factors
            .iter()
            .enumerate()
            .map(|(g, &factor)| ModelForm {
                group: model_form_group_name(g).to_string(),
                factor,
            })
            .collect()
    } else {
        Vec::new()
    };
    (fs, model_form)
}

/// Whitened change of every fit feature when one nuisance parameter moves
/// by one prior standard deviation (one column per parameter, concatenated
/// over the fit points); a feature the moved model loses counts as no change.
fn nuisance_sensitivities(fs: &FitSet, nominal_features: &[&[f64]], opts: &Options) -> Vec<Vec<f64>> {
    let h = fs.runner.prior_sds(opts.nominal_uncertainty);
    let n = h.len();
    let jobs: Vec<(usize, usize)> = (0..fs.points.len()).flat_map(|p| (0..n).map(move |k| (p, k))).collect();
    let runner = fs.runner;
    let cols = parallel(opts.threads, jobs.clone(), &|(p, k)| {
        let bar = fs.points[p].0;
        let run = runner
            .moved(k, 1.0 + h[k])
            .run(bar, &Effects::default(), Keep::All)
            .ok()?;
        runner.features_of_truth(&run, &Effects::default(), bar)
    });
    let mut nuisance = vec![Vec::with_capacity(fs.points.len() * N_FEATURES); n];
    for ((p, k), col) in jobs.into_iter().zip(cols) {
        let nom = nominal_features[p];
        let sigma = &fs.points[p].2;
        for j in 0..N_FEATURES {
            // One prior standard deviation's change of the feature, whitened.
            let d = col.as_ref().map_or(f64::NAN, |f| (f[j] - nom[j]) / sigma[j]);
            let d = if in_fit(j) { d } else { 0.0 };
            nuisance[k].push(if d.is_finite() { d } else { 0.0 });
        }
    }
    nuisance
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::features::{ENERGY, PERIOD};
    use crate::pipeline::group::group;
    use crate::pipeline::tests::{measured, nominal_runner, options, quiet};

    /// The nominal model hits harder and faster at 7 bar than at 4; the fit
    /// set holds the fit point only, every weight at least its floor, one
    /// sensitivity column per nuisance parameter, and form factors of at
    /// least 1 (the model is never credited beyond the noise).
    #[test]
    fn nominal_model_and_fit_set() {
        let runner = nominal_runner();
        let inputs = [measured(4.0, true), measured(7.0, false)];
        let g = group(&inputs, &runner.extractor).unwrap();
        let opts = options();
        let nom = nominal(&g.points, &runner, &opts, &quiet).unwrap();
        assert_eq!(nom.bars, [4.0, 7.0]);
        assert!(nom.features[1][ENERGY] > nom.features[0][ENERGY]);
        assert!(nom.features[1][PERIOD] < nom.features[0][PERIOD]);
        let (fs, form) = fit_set(&g.points, &nom, &runner, &opts);
        assert_eq!(fs.bars(), [4.0]);
        assert_eq!(fs.pressures, (4.0, 4.0));
        let floor = opts.floors.period_rel * nom.features[0][PERIOD];
        assert!(fs.points[0].2[PERIOD] >= floor);
        assert_eq!(fs.nuisance.len(), crate::model::NUISANCE.len());
        assert!(fs.nuisance.iter().all(|c| c.len() == N_FEATURES));
        assert!(!form.is_empty() && form.iter().all(|m| m.factor >= 1.0));
        assert_eq!(fs.simulations(), 2 + crate::model::NUISANCE.len());
    }
}
