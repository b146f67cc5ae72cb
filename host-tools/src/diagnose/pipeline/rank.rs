//! Stage 3, rank: every effect of the catalogue fitted alone to the fit
//! set and ranked by its BIC score; the best named if it is significant;
//! pairs tried when the best leaves enough unexplained, and named only if
//! the second effect earns its parameters as a single earns its own.
//!
//! The decisions (significant? try pairs? does the pair win?) are small
//! functions of the scores alone, so they can be read and tested without a
//! simulation.

use super::effect_fit::fit_effects;
use crate::diagnose::engine::Options;
use crate::diagnose::features::N_FEATURES;
use crate::diagnose::fitset::FitSet;
use crate::diagnose::model::Candidate;
use crate::diagnose::parallel::parallel;
use crate::diagnose::report::{EffectResult, FittedParam, Verdict};
use hammer_sim::effects::EFFECT_NAMES;

pub(crate) struct Ranking {
    /// Single effects, best first.
    pub(crate) effects: Vec<EffectResult>,
    /// Pairs with the best single, best first (empty when not tried).
    pub(crate) pairs: Vec<EffectResult>,
    /// The named single effect or pair.
    pub(crate) verdict: Option<EffectResult>,
    pub(crate) reason: String,
    pub(crate) chi2_nominal: f64,
    pub(crate) features_compared: usize,
}

impl Ranking {
    /// The verdict as the report states it.
    pub(crate) fn verdict_report(&self) -> Verdict {
        match &self.verdict {
            Some(v) => Verdict {
                effects: v.name.split('+').map(str::to_string).collect(),
                params: v.params.clone(),
                score: v.score,
                reason: self.reason.clone(),
            },
            None => Verdict {
                effects: vec!["none".into()],
                params: serde_json::json!({}),
                score: self.effects.first().map_or(0.0, |e| e.score),
                reason: self.reason.clone(),
            },
        }
    }
}

/// Ranks the catalogue on `fs`; `step` is called once per effect and once for the pairs.
pub(crate) fn rank(fs: &FitSet, opts: &Options, step: &(dyn Fn(&str) + Sync)) -> Ranking {
    let ln_n = (fs.fit_cycles().max(2) as f64).ln();
    let chi2_nominal = fs.chi2(&Candidate::default()).unwrap_or(f64::INFINITY);
    let mut effects: Vec<EffectResult> = parallel(opts.threads, EFFECT_NAMES.to_vec(), &|name| {
        let r = fit_effects(fs, &[name], &[], chi2_nominal, ln_n, opts);
        step(&format!("fitted {name}"));
        r
    })
    .into_iter()
    .flatten()
    .collect();
    effects.sort_by(|a, b| b.score.total_cmp(&a.score));
    let n_compared = fs.points.len() * N_FEATURES;
    let mut pairs = Vec::new();
    let mut verdict = None;
    let reason = match effects.first() {
        Some(best) if significant(best, opts) => {
            verdict = Some(best.clone());
            let mut reason = single_reason(&effects);
            if needs_pair(best, n_compared, ln_n, opts) {
                pairs = fit_pairs(fs, &effects, chi2_nominal, ln_n, opts);
                if let Some((p, extra)) = pairs.first().and_then(|p| pair_gain(best, p, ln_n, opts).map(|x| (p, x))) {
                    reason = pair_reason(best, p, n_compared, extra);
                    verdict = Some(p.clone());
                }
            }
            reason
        }
        Some(best) => format!(
            "no effect explains a significant part of the gap: best {} (score {:.0}, {:.0} % explained; needs > {:.0} and {:.0} %)",
            best.name,
            best.score,
            100.0 * best.explained_fraction,
            opts.min_score,
            100.0 * opts.min_explained
        ),
        None => "no effect could be fitted".into(),
    };
    step("pairs");
    Ranking {
        effects,
        pairs,
        verdict,
        reason,
        chi2_nominal,
        features_compared: n_compared,
    }
}

/// Scores above the threshold and explains enough of the nominal χ².
fn significant(e: &EffectResult, opts: &Options) -> bool {
    e.score > opts.min_score && e.explained_fraction >= opts.min_explained
}

/// A pair can only be named if the single leaves more than the threshold
/// to explain: otherwise do not spend the simulations.
fn needs_pair(best: &EffectResult, n_compared: usize, ln_n: f64, opts: &Options) -> bool {
    let reduced = best.chi2 / n_compared.max(1) as f64;
    reduced > opts.pair_residual || best.chi2 > opts.min_score + 2.0 * ln_n
}

/// The pair's score over the single, if it wins: it must beat the single by
/// as much as a single beats nominal.
fn pair_gain(best: &EffectResult, pair: &EffectResult, ln_n: f64, opts: &Options) -> Option<f64> {
    let extra = best.chi2 - pair.chi2 - (pair.fitted.len() - best.fitted.len()) as f64 * ln_n;
    (extra > opts.min_score && (best.chi2 - pair.chi2) >= opts.min_explained * best.chi2).then_some(extra)
}

/// The best single with each runner-up; the next effects by their own
/// score: a second effect shows there first, and each pair costs a fit.
fn fit_pairs(fs: &FitSet, effects: &[EffectResult], chi2_nominal: f64, ln_n: f64, opts: &Options) -> Vec<EffectResult> {
    let best = &effects[0];
    let first = best.name.clone();
    let start: Vec<FittedParam> = best.fitted.clone();
    let jobs: Vec<(String, Vec<FittedParam>)> = effects
        .iter()
        .skip(1)
        .take(opts.pair_candidates)
        .map(|o| (o.name.clone(), o.fitted.clone()))
        .collect();
    let mut pairs: Vec<EffectResult> = parallel(opts.threads, jobs, &|(other, other_start)| {
        let mut init = start.clone();
        init.extend(other_start);
        fit_effects(fs, &[first.as_str(), other.as_str()], &init, chi2_nominal, ln_n, opts)
    })
    .into_iter()
    .flatten()
    .collect();
    pairs.sort_by(|a, b| b.score.total_cmp(&a.score));
    pairs
}

fn single_reason(effects: &[EffectResult]) -> String {
    let best = &effects[0];
    format!(
        "{} explains {:.0} % of the nominal gap (score {:.0}, next {} at {:.0})",
        best.name,
        100.0 * best.explained_fraction,
        best.score,
        effects.get(1).map_or("-", |e| e.name.as_str()),
        effects.get(1).map_or(0.0, |e| e.score)
    )
}

fn pair_reason(best: &EffectResult, pair: &EffectResult, n_compared: usize, extra: f64) -> String {
    let reduced = best.chi2 / n_compared.max(1) as f64;
    format!(
        "{} leaves a reduced χ² of {reduced:.1}; adding the second effect removes {:.0} % of the rest (score +{extra:.0})",
        best.name,
        100.0 * (best.chi2 - pair.chi2) / best.chi2
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn result(name: &str, params: usize, chi2: f64, chi2_nominal: f64, ln_n: f64) -> EffectResult {
        let fitted = (0..params)
            .map(|i| FittedParam {
                key: format!("{name}.p{i}"),
                value: 1.0,
                sd: 0.1,
            })
            .collect();
        EffectResult {
            name: name.into(),
            params: serde_json::json!({}),
            fitted,
            chi2,
            score: chi2_nominal - chi2 - params as f64 * ln_n,
            explained_fraction: ((chi2_nominal - chi2) / chi2_nominal).max(0.0),
            evidence: Vec::new(),
            simulations: 0,
            candidate: Candidate::default(),
        }
    }

    /// A large gap closed by a third is evidence of something, not an
    /// explanation: a high score alone does not name an effect.
    #[test]
    fn an_effect_must_explain_most_of_the_gap() {
        let opts = Options::default();
        let ln_n = 20f64.ln();
        assert!(significant(&result("a", 1, 100.0, 1000.0, ln_n), &opts));
        let partial = result("b", 1, 700.0, 1000.0, ln_n);
        assert!(partial.score > opts.min_score);
        assert!(!significant(&partial, &opts));
        assert!(
            !significant(&result("c", 1, 90.0, 100.0, ln_n), &opts),
            "score below threshold"
        );
    }

    /// A single that leaves only noise spends no simulations on pairs; one
    /// that leaves much does.
    #[test]
    fn pairs_only_when_the_single_leaves_something() {
        let opts = Options::default();
        let ln_n = 20f64.ln();
        let n = 88;
        assert!(!needs_pair(&result("a", 1, 10.0, 1000.0, ln_n), n, ln_n, &opts));
        assert!(needs_pair(&result("a", 1, 400.0, 1000.0, ln_n), n, ln_n, &opts));
    }

    /// Occam: a pair's lower χ² wins only when the second effect pays for
    /// its parameters as a single does against nominal, and removes most of the rest.
    #[test]
    fn a_pair_must_earn_its_parameters() {
        let opts = Options::default();
        let ln_n = 20f64.ln();
        let best = result("a", 1, 400.0, 1000.0, ln_n);
        let slightly = result("a+b", 3, 385.0, 1000.0, ln_n);
        assert!(slightly.chi2 < best.chi2);
        assert_eq!(pair_gain(&best, &slightly, ln_n, &opts), None);
        let most = result("a+b", 3, 40.0, 1000.0, ln_n);
        let extra = pair_gain(&best, &most, ln_n, &opts).unwrap();
        assert!((extra - (360.0 - 2.0 * ln_n)).abs() < 1e-9);
        assert!(pair_reason(&best, &most, 88, extra).contains("removes 90 %"));
    }
}
