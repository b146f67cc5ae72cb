//! Stage 3b, confirm: against the model alone, an effect named on the
//! waveforms' fit alone must still earn its place once the nominal
//! parameters are refitted on the simulator itself.
//!
//! Why: the ranking profiles the nine nominal parameters out with one
//! linearisation at their nominal values ([`FitSet::profile`]). At a real
//! hammer's ±20 % the model is far from linear there, and what the
//! linearisation cannot take up looks like an effect: a sound hammer's
//! nominal values 20 % off were named a leak. The check refits the
//! nominal parameters by Gauss–Newton on the simulator (the held-out
//! stage's recalibration) without the effect and with it, and asks of the
//! difference what the ranking asks of its profile's: the score and the
//! share of what is left. Re-linearising the whole ranking there instead
//! was measured and dropped (`docs/diagnosis.md`): the recalibration run
//! alone first took unseen effects for the parameters' move; here each
//! side is refitted on its own, so neither is judged at the other's point.
//!
//! An effect the force balance sees is named on its own measured
//! signature and is not checked. Against a reference record the nominal
//! values cancel to first order (the record is of the same hammer) and the
//! check is not run.

use std::sync::atomic::Ordering;

use super::effect_fit::{at_measured_sizes, fit_over};
use super::held_out::CHECK_SEARCH;
use super::joint;
use super::rank::Ranking;
use crate::effects::free_params;
use crate::features::N_FEATURES;
use crate::fitset::{form_factors_of, model_form_group, FitSet, Recalibrated, RECALIBRATION_STEPS};
use crate::model::Candidate;
use crate::options::Options;
use crate::parallel::parallel;
use crate::report::{Confirmation, EffectResult, FittedParam, NominalMove};

/// A single or nothing: re-ranked ([`super::rerank`]). A pair: checks its
/// member the waveforms alone named (both, where both are), and drops one
/// that does not hold, leaving the other, which is then a single
/// ([`as_single`]).
///
/// `form` holds the model-form factors the fit set's weights carry (empty:
/// none): the check re-measures them on the verdict's refitted model (see
/// [`reweighed`]).
pub(crate) fn confirm(fs: &FitSet, ranking: &mut Ranking, form: &[f64], opts: &Options) -> Option<Confirmation> {
    if fs.against_reference || opts.nominal_uncertainty <= 0.0 {
        return None;
    }
    // A single, or nothing: every waveform-only single re-ranked jointly.
    if !ranking.verdict.as_ref().is_some_and(|v| v.name.contains('+')) {
        return super::rerank::rerank(fs, ranking, form, opts);
    }
    let verdict = ranking.verdict.clone()?;
    let names: Vec<&str> = verdict.name.split('+').collect();
    // The pair's member the waveforms alone named is checked (the second
    // if both are), the other kept: a supply restriction named first
    // beside a zero shift the force balance measures is checked too.
    let unseen = |n: &str| ranking.effects.iter().any(|e| e.name == n && e.model_free_z.is_none());
    let (other, last) = match names.as_slice() {
        [a, b] if unseen(b) => (*a, *b),
        [a, b] if unseen(a) => (*b, *a),
        _ => return None,
    };
    let min_share = opts.min_explained_pair;
    let c = check_member(fs, &verdict, last, form, opts)?;
    if !c.kept {
        drop_last(fs, ranking, &[other, last], &c, min_share, opts);
        return Some(as_single(fs, ranking, form, opts, c));
    }
    // Where both are waveform-only, the first is checked the same way once
    // the second holds: on the same-structure benchmark at ±20 % (seed 7,
    // case 67) a hidden heat exchange was named beside a supply
    // restriction no one had checked.
    if unseen(other) {
        if let Some(first) = check_member(fs, &verdict, other, form, opts).filter(|f| !f.kept) {
            drop_last(fs, ranking, &[last, other], &first, min_share, opts);
            return Some(as_single(fs, ranking, form, opts, first));
        }
    }
    Some(c)
}

/// A pair left with one member is a single like any other: where that
/// member is one only the waveforms show, it is re-ranked with every such
/// single ([`super::rerank`]), its size and the nominal values fitted
/// together and the others beside it, with a close call where one is as
/// good. The re-ranking's finding is returned; the dropped member's stays
/// in the reason. An effect the force balance sees stays named on its
/// signature, and `dropped` is returned.
///
/// Why: the member left was named unchecked. On the same structure at
/// ±10 % (seed 7, cases 49 and 90) a hidden supply restriction was dropped
/// from beside a leak and the leak named alone (re-ranked: the
/// restriction); at ±20 % (seed 13, case 26) a leak dropped from beside a
/// valve delay left a 7 ms delay named on a hammer with heat exchange
/// (re-ranked: the delay does not hold, and none is named).
fn as_single(fs: &FitSet, ranking: &mut Ranking, form: &[f64], opts: &Options, dropped: Confirmation) -> Confirmation {
    super::rerank::rerank(fs, ranking, form, opts).unwrap_or(dropped)
}

/// `member` of the pair `verdict` checked with the nominal values refitted
/// on the model itself: the pair against the pair without it, both at
/// their minimum, weighed alike.
fn check_member(
    fs: &FitSet,
    verdict: &EffectResult,
    member: &str,
    form: &[f64],
    opts: &Options,
) -> Option<Confirmation> {
    let mut without = verdict.candidate.clone();
    hammer_sim::effects::entry(member)?.turn_off(&mut without.effects);
    let h = opts.nominal_uncertainty;
    // Without it, to the minimum (the held-out check's search): stopped
    // short, the nominal values leave what the effect is credited with.
    let base = fs.recalibrate_with(&without, h, CHECK_SEARCH, opts.threads, None)?;
    // Two starts for the model with the effect, the better kept: the
    // ranking's size with the nominal parameters refitted from where they
    // went without it, and the size refitted there first (from the
    // ranking's size alone the two can settle in a local minimum where
    // the parameters hold up an effect the data do not need).
    let full = fs.recalibrate(
        &verdict.candidate,
        h,
        RECALIBRATION_STEPS,
        opts.threads,
        Some(&base.delta),
    )?;
    let refitted = refit(fs, &base, &without, verdict, member, opts)
        .and_then(|c| fs.recalibrate(&c, h, RECALIBRATION_STEPS, opts.threads, Some(&base.delta)));
    // And a third: the size and the nominal values moved together from
    // where the nominal values went without it (`joint`): the other two
    // move one with the other held, and at ±20 % each stops where the
    // other was left.
    let joint = joint::theta_of(fs, &verdict.fitted, member)
        .and_then(|t0| joint::fit(fs, &without, member, &t0, &base.delta, opts));
    let with = [Some(&full), refitted.as_ref(), joint.as_ref().map(|j| &j.recalibrated)]
        .into_iter()
        .flatten()
        .min_by(|a, b| a.cost.total_cmp(&b.cost))
        .unwrap_or(&full);
    let factors = form_factors(with, form);
    let (cost_without, cost_with) = (reweighed(&base, form, &factors), reweighed(with, form, &factors));
    let k = free_params(member, fs.distinct).len() as f64;
    let gain = cost_without - cost_with;
    let score = gain - k * fs.ln_cycles();
    let explained = if cost_without > 0.0 { gain / cost_without } else { 0.0 };
    let min_share = opts.min_explained_pair;
    let kept = score > opts.min_score && explained >= min_share;
    Some(Confirmation {
        effect: member.to_string(),
        chi2_without: cost_without,
        chi2_with: cost_with,
        form_factors: factors,
        score,
        explained_fraction: explained,
        kept,
        nominal_moves: largest_moves(fs, &base, h),
    })
}

/// The model-form factors re-measured on `with`, the verdict's model with
/// its nominal values refitted: the RMS of its residual over each
/// waveform, on the noise and floors alone, at least 1. The ranking's
/// factors were measured on the nominal model through the linearised
/// profile, so at a real hammer's ±20 % they hold what the linearisation
/// could not take up as well as the hammer's form (a sound hammer's
/// nominal values 20 % off gave factors of 3–9); what the best model
/// leaves is the form alone. Without factors (`form` empty) none.
pub(crate) fn form_factors(with: &Recalibrated, form: &[f64]) -> Vec<f64> {
    if form.is_empty() {
        return Vec::new();
    }
    form_factors_of(&with.residuals, &|g| form.get(g).copied().unwrap_or(1.0))
}

/// `rc`'s χ² (its prior's terms included) with each waveform's weight
/// carrying `factors` instead of the fit set's `form`. Not refitted under
/// them: both sides of the check are weighed alike.
pub(crate) fn reweighed(rc: &Recalibrated, form: &[f64], factors: &[f64]) -> f64 {
    let prior: f64 = rc.delta.iter().map(|d| d * d).sum();
    let data: f64 = rc
        .residuals
        .iter()
        .enumerate()
        .map(|(i, x)| match model_form_group(i % N_FEATURES) {
            Some(g) if g < form.len() && g < factors.len() => (x * form[g] / factors[g]).powi(2),
            _ => x * x,
        })
        .sum();
    data + prior
}

/// The two nominal values `rc` moved most, if beyond half a prior width.
pub(crate) fn largest_moves(fs: &FitSet, rc: &Recalibrated, h: f64) -> Vec<NominalMove> {
    let sds = fs.runner.prior_sds(h);
    let names = fs.runner.plant.nuisance();
    let mut moves: Vec<(f64, NominalMove)> = rc
        .delta
        .iter()
        .zip(&sds)
        .zip(names)
        .filter(|((d, _), _)| d.abs() > 0.5)
        .map(|((d, sd), p)| {
            let m = NominalMove {
                parameter: p.name.clone(),
                relative_change: d * sd,
            };
            (d.abs(), m)
        })
        .collect();
    moves.sort_by(|a, b| b.0.total_cmp(&a.0));
    moves.into_iter().take(2).map(|m| m.1).collect()
}

/// The pair `names` without its second: the first (as fitted beside it)
/// named alone.
fn drop_last(fs: &FitSet, ranking: &mut Ranking, names: &[&str], c: &Confirmation, min_share: f64, opts: &Options) {
    let moves: Vec<String> = c
        .nominal_moves
        .iter()
        .map(|m| format!("{} {:+.0} %", m.parameter, 100.0 * m.relative_change))
        .collect();
    let stand_in = if moves.is_empty() {
        String::new()
    } else {
        format!(" (without it the nominal values moved: {})", moves.join(", "))
    };
    let why = format!(
        "{} did not hold with the nominal values refitted on the model itself (not linearised): it adds {:.0} (needs {:.0}) and explains {:.0} % of what is left without it (needs {:.0} %){stand_in}",
        c.effect,
        c.score,
        opts.min_score,
        100.0 * c.explained_fraction,
        100.0 * min_share
    );
    ranking.close_call = None;
    let first = match names {
        [first, _] => ranking.effects.iter().find(|e| e.name == *first).cloned(),
        _ => None,
    };
    // The first keeps the size its model-free signature measures, as the
    // ranking gave it beside the second.
    let ln_n = fs.ln_cycles();
    let measured = first
        .as_ref()
        .and_then(|f| at_measured_sizes(fs, f, &ranking.effects, opts, ranking.chi2_nominal, ln_n));
    ranking.reason = match (&first, &measured) {
        (Some(_), Some((m, sized))) => format!("{}; {why}: {} named alone; {sized}", ranking.reason, m.name),
        (Some(f), None) => format!("{}; {why}: {} named alone", ranking.reason, f.name),
        (None, _) => format!("{}; {why}: none named", ranking.reason),
    };
    ranking.verdict = measured.map(|m| m.0).or(first);
}

/// The verdict with `last`'s parameters refitted at `at`'s nominal values
/// (no profile: they are the recalibration's), the others held.
fn refit(
    fs: &FitSet,
    at: &Recalibrated,
    without: &Candidate,
    verdict: &EffectResult,
    last: &str,
    opts: &Options,
) -> Option<Candidate> {
    let jobs: Vec<usize> = (0..fs.points.len()).collect();
    let truths = parallel(opts.threads, jobs, &|k| {
        at.runner.truth(fs.points[k].0, &Candidate::default())
    });
    let moved = fs.moved_to(&at.runner, truths.into_iter().collect::<Option<Vec<_>>>()?);
    let held: Vec<FittedParam> = verdict
        .fitted
        .iter()
        .filter(|f| f.key.split('.').next() != Some(last))
        .cloned()
        .collect();
    let init: Vec<FittedParam> = verdict
        .fitted
        .iter()
        .filter(|f| f.key.split('.').next() == Some(last))
        .cloned()
        .collect();
    let held = (!without.effects.active().is_empty()).then_some((without, held.as_slice()));
    let r = fit_over(&moved, held, &[last], &init, f64::INFINITY, fs.ln_cycles(), opts);
    fs.sims
        .fetch_add(moved.simulations() + fs.points.len(), Ordering::Relaxed);
    r.map(|r| r.candidate)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::input::MeasuredInput;
    use crate::pipeline::effect_fit::fit_effects;
    use crate::pipeline::group::group;
    use crate::pipeline::nominal::{fit_set, nominal};
    use crate::pipeline::rank::rank;
    use crate::pipeline::tests::hammer_at_4_and_7 as hammer;
    use crate::pipeline::tests::{nominal_runner, options, quiet};

    /// The ranking and the check on `inputs`, the ranking's verdict
    /// replaced by `forced`'s effects fitted together where it names any.
    fn diagnosed(inputs: &[MeasuredInput], forced: &[&str]) -> (Option<Confirmation>, Ranking) {
        let (runner, opts) = (nominal_runner(), options());
        let g = group(inputs, &runner.extractor).unwrap();
        let nom = nominal(&g.points, &runner, &opts, &quiet).unwrap();
        let (fs, form) = fit_set(&g.points, &nom, &runner, &opts);
        let mut ranking = rank(&fs, &opts, &quiet);
        if !forced.is_empty() {
            let fitted = fit_effects(&fs, forced, &[], ranking.chi2_nominal, fs.ln_cycles(), &opts).unwrap();
            ranking.verdict = Some(fitted);
        }
        let form: Vec<f64> = form.iter().map(|m| m.factor).collect();
        let checked = confirm(&fs, &mut ranking, &form, &opts);
        (checked, ranking)
    }

    /// A hammer with heat exchange at the catalogue's default.
    fn heat_hammer() -> Vec<MeasuredInput> {
        hammer(&|c| {
            let e = hammer_sim::effects::entry("heat_transfer").unwrap();
            e.set(&mut c.effects, e.default_params()).unwrap();
        })
    }

    /// A sound hammer whose valve opens 15 % less and whose front dead
    /// volume is 15 % larger than nominal (within the ±20 % the diagnosis
    /// allows): a leak fitted to it does not hold once the nominal values
    /// are refitted on the simulator, nor does any other waveform-only
    /// effect, and the verdict falls back to none.
    /// A hammer with heat exchange at the catalogue's default keeps it:
    /// the check drops what the nominal values explain, not every effect.
    #[test]
    fn a_leak_the_nominal_values_explain_is_dropped_and_heat_exchange_kept() {
        let sound = hammer(&|c| {
            c.valve.full_open_area_m2 *= 0.85;
            c.hammer.front_dead_volume_m3 *= 1.15;
        });
        let (checked, ranking) = diagnosed(&sound, &["leakage"]);
        // The leak forced as the ranking's single is re-ranked with every
        // waveform-only effect (`rerank`): none holds.
        let c = checked.expect("a leak is named on the waveforms alone: checked");
        assert!(!c.kept, "{c:?}");
        assert!(ranking.verdict.is_none());
        assert!(ranking.reason.contains("none holds"), "{}", ranking.reason);

        let (checked, ranking) = diagnosed(&heat_hammer(), &[]);
        let c = checked.expect("heat exchange is named on the waveforms alone: checked");
        assert_eq!(c.effect, "heat_transfer");
        assert!(c.kept && c.score > options().min_score, "{c:?}");
        assert_eq!(ranking.verdict.map(|v| v.name).as_deref(), Some("heat_transfer"));
    }

    /// A pair one of whose members does not hold leaves the other a
    /// single, and that single is re-ranked like the ranking's own: on a
    /// hammer with heat exchange, a valve delay and a leak forced as the
    /// ranking's pair lose the delay, and the re-ranking names heat
    /// exchange in place of the leak the pair was left with (before, the
    /// leak was named unchecked).
    #[test]
    fn a_pair_left_with_one_member_is_re_ranked_as_a_single() {
        let (checked, ranking) = diagnosed(&heat_hammer(), &["valve_delay", "leakage"]);
        assert!(
            ranking.reason.contains("valve_delay did not hold") && ranking.reason.contains("leakage named alone"),
            "{}",
            ranking.reason
        );
        let c = checked.expect("the single left is re-ranked");
        assert_eq!(c.effect, "heat_transfer", "{c:?}");
        assert!(c.kept, "{c:?}");
        assert_eq!(ranking.verdict.map(|v| v.name).as_deref(), Some("heat_transfer"));
    }
}
