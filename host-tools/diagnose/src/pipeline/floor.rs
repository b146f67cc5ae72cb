//! Stage 3b, detection floors: for every effect, the weakest magnitude
//! the ranking would have named on this data.
//!
//! A `none` verdict on a hammer whose model differs in form says "nothing
//! above the form error", and the form error here can be ten times the
//! noise: a small leak or a slight supply restriction hides in it. The
//! floor says how small. For an effect the force balance cannot see: the
//! magnitude at which its own signature — what no nominal parameter can
//! absorb, in the fit set's weights — would meet the naming rule against
//! what is left unexplained now. For one it sees: the magnitude at which
//! its force-balance signature stands `min_model_free_z` standard errors
//! off nominal, which no form error moves. Below the floor the verdict
//! cannot exclude the effect; above it, it would have named it.

use super::rank::Ranking;
use crate::effects::{apply, diagnosis, free_params};
use crate::fitset::FitSet;
use crate::model::Candidate;
use crate::options::Options;
use crate::parallel::parallel;
use crate::report::DetectionFloor;
use hammer_sim::effects::EFFECT_NAMES;

/// The floor of an effect the model cannot carry: none is known.
fn not_modelled(name: &str) -> DetectionFloor {
    DetectionFloor {
        effect: name.to_string(),
        parameter: String::new(),
        value: None,
        stronger_above: true,
        chi2_needed: 0.0,
        model_free: false,
        not_modelled: true,
        statement: format!(
            "{name}: not modelled: the model's map gives it no parameter, so it was not ranked and could hide in the gap at any size"
        ),
    }
}

/// Bisection steps on the parameter's (log) scale: the catalogue's ranges
/// span up to five decades, 2⁻⁸ of that is a few percent.
const STEPS: usize = 8;

/// The floor of every effect of the ranking, in the catalogue's order
/// (an unseen effect's only if it has one free parameter).
pub(crate) fn floors(fs: &FitSet, ranking: &Ranking, opts: &Options) -> Vec<DetectionFloor> {
    let seen = |name: &str| {
        ranking
            .effects
            .iter()
            .find(|e| e.name == name)
            .map(|e| e.model_free_z.is_some())
    };
    let needed = chi2_needed(fs, ranking, opts);
    let names: Vec<&str> = EFFECT_NAMES.iter().copied().filter(|n| seen(n).is_some()).collect();
    let mut floors: Vec<DetectionFloor> = parallel(opts.threads, names, &|name| match seen(name) {
        // A chamber characteristic's change has no magnitude law: the
        // model's floor stands for it.
        Some(true) => model_free_floor(fs, name, opts.min_model_free_z)
            .or_else(|| needed.and_then(|needed| floor_of(fs, name, needed))),
        _ => needed.and_then(|needed| floor_of(fs, name, needed)),
    })
    .into_iter()
    .flatten()
    .collect();
    floors.extend(
        EFFECT_NAMES
            .iter()
            .filter(|n| !fs.runner.plant.carries(n))
            .map(|n| not_modelled(n)),
    );
    floors
}

/// A force-balance effect's floor: its signature at `z_min` standard errors.
fn model_free_floor(fs: &FitSet, name: &str, z_min: f64) -> Option<DetectionFloor> {
    let (key, value) = diagnosis(name)?.model_free_floor(fs, z_min)?;
    Some(DetectionFloor {
        effect: name.to_string(),
        parameter: key.to_string(),
        value: Some(value),
        stronger_above: true,
        chi2_needed: z_min * z_min,
        model_free: true,
        not_modelled: false,
        statement: format!(
            "{name} with {key} ≥ {value:.3e} would have been named (its model-free signature, the force balance's or against a reference the chamber characteristics', at {z_min:.0} standard errors); below that it is within that signature's uncertainty"
        ),
    })
}

/// The signature χ² an unseen effect must bring to be named now: a score
/// above `min_score` for its parameter, and the share of the gap the rule
/// asks — of the nominal χ² with no verdict, of what the named single
/// leaves as a pair's second — assuming the effect's signature adds to
/// what is there (it is orthogonal to the form error, or the form error
/// would have lent it a score already).
fn chi2_needed(fs: &FitSet, ranking: &Ranking, opts: &Options) -> Option<f64> {
    let ln_n = fs.ln_cycles();
    let (rest, share) = match &ranking.verdict {
        Some(v) => (v.chi2, opts.min_explained_pair),
        None => (ranking.chi2_nominal, opts.min_explained),
    };
    if !rest.is_finite() || !(0.0..1.0).contains(&share) {
        return None;
    }
    Some((opts.min_score + ln_n).max(rest * share / (1.0 - share)))
}

/// One effect's floor by bisection between the ends of its catalogue range.
fn floor_of(fs: &FitSet, name: &str, needed: f64) -> Option<DetectionFloor> {
    let specs = free_params(name, fs.distinct);
    let [spec] = specs.as_slice() else {
        return None;
    };
    // A simulation that fails (a hammer stalled by the effect) is as seen
    // as an effect can be.
    let signature = |u: f64| {
        let mut c = Candidate::default();
        apply(&mut c.effects, name, &[spec.from_u(u)], fs.pressures);
        fs.signature_chi2(&c).unwrap_or(f64::INFINITY)
    };
    let (lo, hi) = (spec.to_u(spec.lo), spec.to_u(spec.hi));
    let (s_lo, s_hi) = (signature(lo), signature(hi));
    let stronger_above = s_hi >= s_lo;
    let (mut weak, mut strong) = if stronger_above { (lo, hi) } else { (hi, lo) };
    let value = if s_hi.max(s_lo) < needed {
        None
    } else if s_hi.min(s_lo) >= needed {
        Some(spec.from_u(weak))
    } else {
        for _ in 0..STEPS {
            let mid = 0.5 * (weak + strong);
            if signature(mid) >= needed {
                strong = mid;
            } else {
                weak = mid;
            }
        }
        Some(spec.from_u(strong))
    };
    Some(DetectionFloor {
        effect: name.to_string(),
        parameter: spec.key.to_string(),
        value,
        stronger_above,
        chi2_needed: needed,
        model_free: false,
        not_modelled: false,
        statement: statement(name, spec.key, value, stronger_above, (spec.lo, spec.hi)),
    })
}

fn statement(name: &str, key: &str, value: Option<f64>, stronger_above: bool, range: (f64, f64)) -> String {
    let (dir, weaker) = if stronger_above {
        ("≥", "below")
    } else {
        ("≤", "above")
    };
    match value {
        Some(v) => format!(
            "{name} with {key} {dir} {v:.3e} would have been named; {weaker} that it can hide in what is unexplained"
        ),
        None => format!(
            "{name} could not be named anywhere in {key} {:.3e}…{:.3e}: its signature stays within what is unexplained",
            range.0, range.1
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pipeline::tests::{measured, nominal_runner, options, quiet};
    use crate::pipeline::{group, nominal, rank};

    /// On the nominal hammer itself (noise only), an unseen effect's floor
    /// is a bracket the rule's own threshold closes: the signature at the
    /// floor meets what is needed, a few percent weaker does not, and a leak
    /// of the bench's range (12–35 µm) is above it.
    #[test]
    fn a_floor_is_where_the_signature_meets_the_rule() {
        let runner = nominal_runner();
        let inputs = [measured(4.0, true), measured(7.0, true)];
        let grouped = group::group(&inputs, &runner.extractor).unwrap();
        let opts = options();
        let nom = nominal::nominal(&grouped.points, &runner, &opts, &quiet).unwrap();
        let (fs, _) = nominal::fit_set(&grouped.points, &nom, &runner, &opts);
        let ranking = rank::rank(&fs, &opts, &quiet);
        let needed = chi2_needed(&fs, &ranking, &opts).unwrap();
        let floors = floors(&fs, &ranking, &opts);
        let leak = floors
            .iter()
            .find(|f| f.effect == "leakage")
            .expect("leakage has a floor");
        let gap = leak.value.expect("a leak is seen somewhere in the catalogue's range");
        println!("leakage floor {gap:.3e} m at χ² {needed:.1}; all: {floors:#?}");
        assert!(leak.stronger_above);
        assert!(
            gap < 12e-6,
            "a bench-sized leak hides on the model's own hammer: floor {gap:.3e}"
        );
        let sig = |g: f64| {
            let mut c = Candidate::default();
            apply(&mut c.effects, "leakage", &[g], fs.pressures);
            fs.signature_chi2(&c).unwrap()
        };
        assert!(sig(gap) >= needed);
        assert!(sig(gap * 0.95) < needed);
        // Every effect of the catalogue has its floor, the force balance's
        // from their standard errors: the paper's friction (10.27 N at
        // 4 bar) is more than ten times its floor.
        let names: Vec<&str> = floors.iter().map(|f| f.effect.as_str()).collect();
        assert_eq!(names, EFFECT_NAMES);
        let friction = floors.iter().find(|f| f.effect == "coulomb_friction").unwrap();
        assert!(friction.model_free && friction.value.unwrap() < 1.0, "{friction:?}");
        assert!(!leak.model_free);
    }
}
