//! Stage 2, nominal: the nominal model at every operating point, and from
//! it the fit set: the fit points' measured means, weighed by their noise
//! and floors, the nuisance parameters' sensitivities, and the weights
//! inflated by the nominal model's measured form error.
//!
//! Everything an effect's fit needs is computed here once, so the ranking's
//! many fits only ever simulate the candidate effect.

use std::sync::atomic::AtomicUsize;
use std::sync::Arc;

use super::group::Point;
use crate::features::{summarize, N_FEATURES};
use crate::fitset::{in_fit, model_form_group_name, sigmas, FitSet};
use crate::input::DiagnoseError;
use crate::model::{Candidate, Keep, ModelRunner, ModelTrace, Pinned};
use crate::options::Options;
use crate::parallel::parallel;
use crate::report::ModelForm;
use hammer_sim::effects::Effects;

/// The nominal model at every operating point, in the points' order.
pub(crate) struct Nominal {
    pub(crate) bars: Vec<f64>,
    pub(crate) runs: Vec<ModelTrace>,
    pub(crate) features: Vec<Vec<f64>>,
    /// At each fit point (empty elsewhere), the model's features with one
    /// nuisance parameter moved by one prior standard deviation, one entry
    /// per parameter (`None`: that run failed).
    pub(crate) moved: Vec<Vec<Option<Vec<f64>>>>,
    /// The runs this took.
    pub(crate) simulations: usize,
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
    let moved = if opts.nominal_uncertainty > 0.0 {
        moved(points, runner, opts)
    } else {
        vec![Vec::new(); points.len()]
    };
    let simulations = bars.len() + moved.iter().map(Vec::len).sum::<usize>();
    Ok(Nominal {
        bars,
        runs,
        features,
        moved,
        simulations,
    })
}

/// The model's features at every fit point with each nuisance parameter
/// moved by one prior standard deviation (its own, or `nominal_uncertainty`).
fn moved(points: &[Point], runner: &ModelRunner, opts: &Options) -> Vec<Vec<Option<Vec<f64>>>> {
    let h = runner.prior_sds(opts.nominal_uncertainty);
    let n = h.len();
    let jobs: Vec<(usize, usize)> = (0..points.len())
        .filter(|&p| points[p].is_fit_point)
        .flat_map(|p| (0..n).map(move |k| (p, k)))
        .collect();
    let cols = parallel(opts.threads, jobs.clone(), &|(p, k)| {
        let bar = points[p].supply_bar;
        let run = runner
            .moved(k, 1.0 + h[k])
            .run(bar, &Effects::default(), Keep::All)
            .ok()?;
        runner.features_of_truth(&run, &Effects::default(), bar)
    });
    let mut moved = vec![Vec::new(); points.len()];
    for ((p, _), col) in jobs.into_iter().zip(cols) {
        moved[p].push(col);
    }
    moved
}

/// `runner` with the nuisance parameters no fitted feature responded to,
/// at any fit point, held at nominal ([`Pinned`]), and `nominal`'s moved
/// runs cut to the parameters left free; the held parameters' names. A
/// parameter whose moved run failed is kept (the fit finds its failure).
pub(crate) fn hold_unresponsive(runner: ModelRunner, mut nominal: Nominal) -> (ModelRunner, Nominal, Vec<String>) {
    let n = runner.nuisance.len();
    let same = |a: &[f64], b: &[f64]| {
        (0..N_FEATURES)
            .filter(|&j| in_fit(j))
            .all(|j| a[j].to_bits() == b[j].to_bits())
    };
    let responds = |k: usize| {
        nominal
            .moved
            .iter()
            .zip(&nominal.features)
            .filter(|(m, _)| !m.is_empty())
            .any(|(m, f)| m.get(k).is_none_or(|c| c.as_ref().is_none_or(|c| !same(c, f))))
    };
    let kept: Vec<usize> = (0..n).filter(|&k| responds(k)).collect();
    let Some(pinned) = Pinned::new(runner.plant.clone(), kept.clone()) else {
        return (runner, nominal, Vec::new());
    };
    let held = pinned.held().to_vec();
    for m in nominal.moved.iter_mut().filter(|m| !m.is_empty()) {
        *m = kept.iter().map(|&k| m[k].take()).collect();
    }
    let runner = ModelRunner {
        plant: Arc::new(pinned),
        nuisance: kept.iter().map(|&k| runner.nuisance[k]).collect(),
        ..runner
    };
    (runner, nominal, held)
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
        sims: AtomicUsize::new(nominal.simulations),
        nuisance: Vec::new(),
        against_reference: points.iter().any(|p| !p.reference_var.is_empty()),
        reference_var: fit_idx.iter().map(|&i| points[i].reference_var.clone()).collect(),
    };
    if opts.nominal_uncertainty > 0.0 {
        fs.nuisance = nuisance_sensitivities(&fs, &fit_idx, nominal);
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
/// over the fit points `fit_idx`); a feature the moved model loses counts
/// as no change.
fn nuisance_sensitivities(fs: &FitSet, fit_idx: &[usize], nominal: &Nominal) -> Vec<Vec<f64>> {
    let n = fs.runner.nuisance.len();
    let mut nuisance = vec![Vec::with_capacity(fs.points.len() * N_FEATURES); n];
    for (p, &i) in fit_idx.iter().enumerate() {
        let nom = &nominal.features[i];
        let sigma = &fs.points[p].2;
        for (k, col) in nuisance.iter_mut().enumerate() {
            let moved = nominal.moved[i].get(k).and_then(Option::as_ref);
            for j in 0..N_FEATURES {
                // One prior standard deviation's change of the feature, whitened.
                let d = moved.map_or(f64::NAN, |f| (f[j] - nom[j]) / sigma[j]);
                let d = if in_fit(j) { d } else { 0.0 };
                col.push(if d.is_finite() { d } else { 0.0 });
            }
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

    /// The built-in model with one more nuisance parameter that it ignores
    /// (a map's parameter that does not act in the model's configuration).
    #[derive(Debug)]
    struct Ignoring {
        inner: crate::model::Builtin,
        params: Vec<crate::model::NuisanceParam>,
    }

    impl crate::model::Plant for Ignoring {
        fn nuisance(&self) -> &[crate::model::NuisanceParam] {
            &self.params
        }
        fn carries(&self, name: &str) -> bool {
            self.inner.carries(name)
        }
        fn run(&self, bar: f64, nuisance: &[f64], e: &Effects, d: f64, keep: Keep) -> Result<ModelTrace, String> {
            self.inner.run(bar, &nuisance[..nuisance.len() - 1], e, d, keep)
        }
    }

    /// The ignored parameter is held, and named; the fit set the diagnosis
    /// then builds is the built-in model's own to the bit: the same
    /// sensitivity columns, the same count of runs less the held one's.
    #[test]
    fn a_parameter_the_model_ignores_is_held_at_nominal() {
        use crate::model::{Builtin, NuisanceParam, Plant};
        let plain = nominal_runner();
        let inner = Builtin::new(hammer_sim::SimConfig::default());
        let mut params = inner.nuisance().to_vec();
        params.push(NuisanceParam {
            name: "params.unused".into(),
            nominal: 2.0,
            relative_uncertainty: Some(0.2),
        });
        let wide = ModelRunner::with_plant(
            Arc::new(Ignoring { inner, params }),
            plain.hammer.clone(),
            plain.extractor.clone(),
        );
        let inputs = [measured(4.0, true), measured(7.0, false)];
        let g = group(&inputs, &plain.extractor).unwrap();
        let opts = options();
        let nom = nominal(&g.points, &wide, &opts, &quiet).unwrap();
        assert_eq!(nom.moved[0].len(), crate::model::NUISANCE.len() + 1);
        let (held_runner, nom, held) = hold_unresponsive(wide, nom);
        assert_eq!(held, ["params.unused"]);
        assert_eq!(held_runner.nuisance, plain.nuisance);
        let (fs, _) = fit_set(&g.points, &nom, &held_runner, &opts);
        let own = nominal(&g.points, &plain, &opts, &quiet).unwrap();
        let (fs_plain, _) = fit_set(&g.points, &own, &plain, &opts);
        let bits = |c: &[Vec<f64>]| c.iter().flatten().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&fs.nuisance), bits(&fs_plain.nuisance));
        assert_eq!(fs.simulations(), fs_plain.simulations() + 1);
        // A model that responds to every parameter holds none.
        let (_, _, none) = hold_unresponsive(plain, own);
        assert!(none.is_empty());
    }
}
