//! Stage 3c, oracle (benchmarks only): would the hammer's truth itself
//! pass the rule that names an effect the waveforms alone show?
//!
//! At a real hammer's ±20 % a single effect is sometimes left `none`: the
//! nominal values refitted without it explain the features about as well.
//! Whether that is the diagnosis' failing or the features' limit is a
//! question only a benchmark can answer, because only it knows the truth:
//! its hammer's nominal values and its effect at its size. This stage puts
//! exactly that into the diagnosis' own model, lets the nominal values
//! settle from there (the generator is the model of a finer solver and
//! another sensor chain, so the truth is a start, not the optimum), and
//! scores it against the nominal values refitted without any effect, with
//! the confirm stage's weights and rule ([`super::confirm`]). Where even
//! the truth does not pass, no reading of these features under this rule
//! names the effect: a measured ceiling, not a miss.

use super::confirm::{form_factors, reweighed};
use super::held_out::CHECK_SEARCH;
use crate::effects::free_params;
use crate::fitset::FitSet;
use crate::model::Candidate;
use crate::options::{Options, Oracle};
use crate::report::OracleCheck;

/// The truth's check against the model alone, for a hammer with one
/// effect (`opts.oracle`); `None` without an oracle, against a record (the
/// nominal values cancel there), for a hammer with none or two, or where a
/// recalibration fails.
pub(crate) fn check(fs: &FitSet, form: &[f64], opts: &Options) -> Option<OracleCheck> {
    let oracle: &Oracle = opts.oracle.as_ref()?;
    if fs.against_reference || opts.nominal_uncertainty <= 0.0 {
        return None;
    }
    let names = oracle.effects.active();
    let [name] = names.as_slice() else {
        return None;
    };
    let h = opts.nominal_uncertainty;
    let sds = fs.runner.prior_sds(h);
    if oracle.nuisance.len() != fs.runner.nuisance.len() {
        return None;
    }
    // The truth's nominal values in prior standard deviations.
    let truth: Vec<f64> = oracle
        .nuisance
        .iter()
        .zip(&fs.runner.nuisance)
        .zip(&sds)
        .map(|((t, n), sd)| (t / n - 1.0) / sd)
        .collect();
    let without = fs.recalibrate_with(&Candidate::default(), h, CHECK_SEARCH, opts.threads, Some(&truth))?;
    let cand = Candidate {
        effects: oracle.effects.clone(),
    };
    let with = fs.recalibrate_with(&cand, h, CHECK_SEARCH, opts.threads, Some(&truth))?;
    let factors = form_factors(&with, form);
    let (chi2_without, chi2_truth) = (reweighed(&without, form, &factors), reweighed(&with, form, &factors));
    let gain = chi2_without - chi2_truth;
    let score = gain - free_params(name, fs.distinct).len() as f64 * fs.ln_cycles();
    let explained = if chi2_without > 0.0 { gain / chi2_without } else { 0.0 };
    Some(OracleCheck {
        effect: name.to_string(),
        chi2_without,
        chi2_truth,
        score,
        explained_fraction: explained,
        passes: score > opts.min_score && explained >= opts.min_explained,
    })
}
