//! One fit of one effect (or a pair) to the fit set: Levenberg–Marquardt on
//! the catalogue's free parameters, scored by BIC against the nominal model,
//! with the evidence a person can check (the force balance's signature and
//! where the gap closed).

use std::collections::BTreeMap;
use std::sync::atomic::Ordering;

use crate::effects::{apply, catalogue_params, diagnosis, free_params};
use crate::features::{feature_name, wave_of, Extractor, BINS, N_FEATURES, WAVE_SIGNALS};
use crate::fit::{levenberg_marquardt, FitResult};
use crate::fitset::{residual, FitSet};
use crate::model::Candidate;
use crate::model::ModelTrace;
use crate::options::Options;
use crate::report::{EffectResult, FittedParam};
use crate::stages::Stage;

/// Start values from what the measurement shows directly.
fn start_values(fs: &FitSet, name: &str) -> Vec<f64> {
    diagnosis(name).map_or_else(Vec::new, |d| d.start_values(fs))
}

/// Fits `names` together (one or two effects); `init` overrides start values.
pub(crate) fn fit_effects(
    fs: &FitSet,
    names: &[&str],
    init: &[FittedParam],
    chi2_nominal: f64,
    ln_n: f64,
    opts: &Options,
) -> Option<EffectResult> {
    fit_over(fs, None, names, init, chi2_nominal, ln_n, opts)
}

/// Fits `names` over `held` (effects already in the model at sizes not
/// fitted here, with their parameters, counted in the BIC penalty).
pub(crate) fn fit_over(
    fs: &FitSet,
    held: Option<(&Candidate, &[FittedParam])>,
    names: &[&str],
    init: &[FittedParam],
    chi2_nominal: f64,
    ln_n: f64,
    opts: &Options,
) -> Option<EffectResult> {
    let mut specs = Vec::new();
    let mut theta0 = Vec::new();
    let mut owner = Vec::new();
    for (k, name) in names.iter().enumerate() {
        let sp = free_params(name, fs.distinct);
        let st = start_values(fs, name);
        for (s, v) in sp.iter().zip(st) {
            let v = init
                .iter()
                .find(|p| p.key == format!("{name}.{}", s.key))
                .map_or(v, |p| p.value);
            specs.push(*s);
            theta0.push(v);
            owner.push(k);
        }
    }
    let base = held.map_or_else(Candidate::default, |h| h.0.clone());
    let build = |theta: &[f64]| {
        let mut c = base.clone();
        for (k, name) in names.iter().enumerate() {
            let t: Vec<f64> = theta
                .iter()
                .zip(&owner)
                .filter(|(_, &o)| o == k)
                .map(|(x, _)| *x)
                .collect();
            apply(&mut c.effects, name, &t, fs.pressures);
        }
        c
    };
    let sims_before = fs.sims.load(Ordering::Relaxed);
    let fit: FitResult = levenberg_marquardt(&specs, &theta0, opts.max_iterations, &mut |t| fs.residuals(&build(t)))?;
    let cand = build(&fit.theta);
    let mut fitted: Vec<FittedParam> = held.map_or_else(Vec::new, |h| h.1.to_vec());
    fitted.extend(
        specs
            .iter()
            .zip(&owner)
            .zip(fit.theta.iter().zip(&fit.sd))
            .map(|((s, &o), (&v, &sd))| FittedParam {
                key: format!("{}.{}", names[o], s.key),
                value: v,
                sd,
            }),
    );
    let scored = Scored {
        chi2: fit.chi2,
        chi2_nominal,
        penalty: fitted.len() as f64 * ln_n,
    };
    let mut all: Vec<&str> = held.map_or_else(Vec::new, |h| h.0.effects.active());
    all.extend(names);
    Some(result(fs, &all, cand, fitted, scored, sims_before))
}

/// Effect `name` at the size its model-free signature measures
/// ([`crate::effects`]' `measured_size`), beside a fitted `first` effect if
/// given, nothing more fitted: scored on the waveforms as a fit is (its
/// parameter counted in the penalty), so the report says how well the
/// model's law for it agrees.
pub(crate) fn at_measured_size(
    fs: &FitSet,
    first: Option<&EffectResult>,
    name: &str,
    chi2_nominal: f64,
    ln_n: f64,
) -> Option<EffectResult> {
    let (theta, sd) = diagnosis(name)?.measured_size(fs)?;
    let specs = free_params(name, fs.distinct);
    let mut cand = first.map_or_else(Candidate::default, |f| f.candidate.clone());
    apply(&mut cand.effects, name, &theta, fs.pressures);
    let sims_before = fs.sims.load(Ordering::Relaxed);
    let chi2 = fs.chi2(&cand)?;
    let mut fitted = first.map_or_else(Vec::new, |f| f.fitted.clone());
    fitted.extend(
        specs
            .iter()
            .zip(theta.iter().zip(&sd))
            .map(|(s, (&value, &sd))| FittedParam {
                key: format!("{name}.{}", s.key),
                value,
                sd,
            }),
    );
    let scored = Scored {
        chi2,
        chi2_nominal,
        penalty: fitted.len() as f64 * ln_n,
    };
    let mut names: Vec<&str> = first.map_or_else(Vec::new, |f| f.name.split('+').collect());
    names.push(name);
    Some(result(fs, &names, cand, fitted, scored, sims_before))
}

/// Standard deviations (the fit's and the measurement's, combined) by
/// which a chamber-read effect's fitted size must differ from the size its
/// signature measures for the verdict to take the measured one.
const MEASURED_DISAGREE_Z: f64 = 3.0;
/// And the factor by which it must differ: where the model's law is the
/// hammer's, the two sizes differ by degree (the model's feed moves up to
/// a fifth further than its dead time at 7 bar, docs/estimator.md), and
/// its fit is the better size; a law of another kind misses by a factor
/// (three of the second family's delays were fitted at 3–22 % of their
/// shift).
const MEASURED_DISAGREE_FACTOR: f64 = 2.0;

/// The named `verdict` with each named effect whose model-free signature
/// measures its size put at that size, if its signature stands
/// ([`Options::min_model_free_z`], read from `singles`), and the other
/// named effect (a pair's) refitted beside it. `None` where no named
/// effect is so sized.
///
/// - An effect the force balance sees (friction, viscous friction, a gain
///   error, a zero shift) is always sized there: the force balance
///   measures it directly, in both modes, where the waveforms' fit reads
///   it through the model's valve and port laws. Against a record on a
///   hammer of another form that fit put the friction 18–22 % low and γ
///   6.5–67 % off, where the force balance was within 1 % (issue 44). The
///   waveforms' fit is kept beside it (`waveform_fit`), and the verdict
///   scores at the measured size.
/// - An effect read in the chamber characteristics (a valve delay: the
///   front feed's shift) is sized there only where its fit put it more
///   than [`MEASURED_DISAGREE_Z`] standard deviations and a factor of
///   [`MEASURED_DISAGREE_FACTOR`] away: the feed's shift is the change
///   itself, but the model's law, where it is the hammer's, sizes better.
///   At seed 8 of the structural benchmark against a record, before this
///   rule, eight of the thirteen delays named were 78–98 % off τ.
pub(crate) fn at_measured_sizes(
    fs: &FitSet,
    verdict: &EffectResult,
    singles: &[EffectResult],
    opts: &Options,
    chi2_nominal: f64,
    ln_n: f64,
) -> Option<(EffectResult, String)> {
    let names: Vec<&str> = verdict.name.split('+').collect();
    let stands = |n: &str| {
        singles
            .iter()
            .find(|e| e.name == n)
            .and_then(|e| e.model_free_z)
            .is_some_and(|z| z >= opts.min_model_free_z)
    };
    let fitted_of = |name: &str| -> Vec<FittedParam> {
        verdict
            .fitted
            .iter()
            .filter(|f| f.key.split('.').next() == Some(name))
            .cloned()
            .collect()
    };
    let mut measured: Vec<(&str, Vec<f64>, Vec<f64>)> = Vec::new();
    let mut kept: Vec<&str> = Vec::new();
    for &name in names.iter().filter(|n| stands(n)) {
        let Some(d) = diagnosis(name) else { continue };
        let Some((theta, sd)) = d.measured_size(fs) else {
            continue;
        };
        let fitted = fitted_of(name);
        let disagree = fitted.len() == theta.len()
            && fitted.iter().zip(theta.iter().zip(&sd)).any(|(f, (&m, &sm))| {
                let factor = (f.value / m).max(m / f.value);
                (f.value - m).abs() > MEASURED_DISAGREE_Z * (f.sd * f.sd + sm * sm).sqrt()
                    && !(factor <= MEASURED_DISAGREE_FACTOR)
            });
        if !d.seen_in_chambers() || disagree {
            measured.push((name, theta, sd));
        } else {
            // Its fit agrees with its signature (or the ranking put it at
            // the measured size already): it stays as the verdict has it.
            kept.push(name);
        }
    }
    if measured.is_empty() {
        return None;
    }
    let mut cand = Candidate::default();
    let mut params = Vec::new();
    for name in &kept {
        let p = fitted_of(name);
        let theta: Vec<f64> = p.iter().map(|f| f.value).collect();
        apply(&mut cand.effects, name, &theta, fs.pressures);
        params.extend(p);
    }
    for (name, theta, sd) in &measured {
        apply(&mut cand.effects, name, theta, fs.pressures);
        params.extend(
            free_params(name, fs.distinct)
                .iter()
                .zip(theta.iter().zip(sd))
                .map(|(s, (&value, &sd))| FittedParam {
                    key: format!("{name}.{}", s.key),
                    value,
                    sd,
                }),
        );
    }
    let rest: Vec<&str> = names
        .iter()
        .copied()
        .filter(|n| !measured.iter().any(|m| m.0 == *n) && !kept.contains(n))
        .collect();
    let sized = if rest.is_empty() {
        let sims_before = fs.sims.load(Ordering::Relaxed);
        let chi2 = fs.chi2(&cand)?;
        let scored = Scored {
            chi2,
            chi2_nominal,
            penalty: params.len() as f64 * ln_n,
        };
        result(fs, &names, cand, params, scored, sims_before)
    } else {
        fit_over(
            fs,
            Some((&cand, &params)),
            &rest,
            &verdict.fitted,
            chi2_nominal,
            ln_n,
            opts,
        )?
    };
    let waveform_fit: Vec<FittedParam> = measured.iter().flat_map(|m| fitted_of(m.0)).collect();
    let why = measured_sizes_reason(fs, &measured, &fitted_of);
    let why = format!(
        "{why}: reported at the measured size (it scores {:.0} there)",
        sized.score
    );
    Some((
        EffectResult {
            // Named in the verdict's order (a pair's last is its second).
            name: verdict.name.clone(),
            waveform_fit,
            ..sized
        },
        why,
    ))
}

/// What [`at_measured_sizes`] put at a measured size, against the
/// waveforms' fit (`fitted_of` an effect's fitted parameters), in words.
fn measured_sizes_reason(
    fs: &FitSet,
    measured: &[(&str, Vec<f64>, Vec<f64>)],
    fitted_of: &dyn Fn(&str) -> Vec<FittedParam>,
) -> String {
    measured
        .iter()
        .map(|(name, theta, sd)| {
            let keys = free_params(name, fs.distinct);
            let list = |v: &dyn Fn(usize) -> f64| {
                keys.iter()
                    .enumerate()
                    .map(|(i, s)| format!("{} = {:.4e}", s.key, v(i)))
                    .collect::<Vec<_>>()
                    .join(", ")
            };
            let fitted = fitted_of(name);
            let by = if diagnosis(name).is_some_and(|d| d.seen_in_chambers()) {
                "its chamber characteristics measure"
            } else {
                "the force balance measures"
            };
            format!(
                "{by} {name} at {} (± {}), where the waveforms' fit sized it at {}",
                list(&|i| theta[i]),
                sd.iter().map(|v| format!("{v:.1e}")).collect::<Vec<_>>().join(", "),
                list(&|i| fitted.get(i).map_or(f64::NAN, |f| f.value)),
            )
        })
        .collect::<Vec<_>>()
        .join("; ")
}

/// A candidate's χ² beside the nominal model's, and its BIC penalty.
struct Scored {
    chi2: f64,
    chi2_nominal: f64,
    penalty: f64,
}

/// The result of `names` as `cand`, with its parameters, score and evidence.
fn result(
    fs: &FitSet,
    names: &[&str],
    cand: Candidate,
    fitted: Vec<FittedParam>,
    s: Scored,
    sims_before: usize,
) -> EffectResult {
    let score = s.chi2_nominal - s.chi2 - s.penalty;
    let explained = if s.chi2_nominal > 0.0 {
        ((s.chi2_nominal - s.chi2) / s.chi2_nominal).max(0.0)
    } else {
        0.0
    };
    let mut params = serde_json::Map::new();
    for name in names {
        params.insert(name.to_string(), catalogue_params(&cand.effects, name));
    }
    let evidence = evidence(fs, names, &cand);
    // A pair is seen by the force balance as well as its clearer member.
    let model_free_z = names
        .iter()
        .filter_map(|n| diagnosis(n).and_then(|d| d.model_free_z(fs)))
        .reduce(f64::max);
    let contradicted_by = match names {
        [name] => diagnosis(name).and_then(|d| d.contradicted(fs)),
        _ => None,
    };
    EffectResult {
        name: names.join("+"),
        params: if names.len() == 1 {
            params.remove(names[0]).unwrap_or_default()
        } else {
            serde_json::Value::Object(params)
        },
        fitted,
        chi2: s.chi2,
        score,
        explained_fraction: explained,
        evidence,
        model_free_z,
        contradicted_by,
        simulations: fs.sims.load(Ordering::Relaxed) - sims_before,
        waveform_fit: Vec::new(),
        candidate: cand,
    }
}

/// What in the measurement the effect matched: its signature in the force
/// balance, and the features whose gap it closed most.
fn evidence(fs: &FitSet, names: &[&str], cand: &Candidate) -> Vec<String> {
    let mut out: Vec<String> = names
        .iter()
        .filter_map(|name| diagnosis(name).and_then(|d| d.evidence(fs)))
        .collect();
    // The features whose gap the candidate closed most, grouped by signal and stage.
    let nominal = Candidate::default();
    let mut gains: BTreeMap<String, f64> = BTreeMap::new();
    let stages_of_bins = fs
        .nominal_truth
        .first()
        .map(|t| bin_stages(t, &fs.runner.hammer, &fs.runner.extractor));
    for ((bar, s, sigma), truth) in fs.points.iter().zip(&fs.nominal_truth) {
        let (Some(m0), Some(m1)) = (
            fs.runner.features(*bar, &nominal, Some(truth)),
            fs.runner.features(*bar, cand, Some(truth)),
        ) else {
            continue;
        };
        for j in 0..N_FEATURES {
            let r0 = residual(j, m0[j], s.mean[j], sigma[j]);
            let r1 = residual(j, m1[j], s.mean[j], sigma[j]);
            let label = match (wave_of(j), &stages_of_bins) {
                (Some((si, b)), Some(st)) => format!("{} in {}", WAVE_SIGNALS[si], st[b].name()),
                _ => feature_name(j),
            };
            *gains.entry(label).or_default() += r0 * r0 - r1 * r1;
        }
    }
    let mut g: Vec<(String, f64)> = gains.into_iter().filter(|(_, v)| *v > 0.0).collect();
    g.sort_by(|a, b| b.1.total_cmp(&a.1));
    let total: f64 = g.iter().map(|x| x.1).sum();
    if total > 0.0 {
        let top: Vec<String> = g
            .iter()
            .take(4)
            .map(|(k, v)| format!("{k} ({:.0} %)", 100.0 * v / total))
            .collect();
        out.push(format!("closes the gap mostly in: {}", top.join(", ")));
    }
    out
}

/// The dominant stage of each waveform bin of the nominal cycle.
fn bin_stages(truth: &ModelTrace, hammer: &hammer_sim::params::HammerParams, extractor: &Extractor) -> Vec<Stage> {
    let edges = crate::stages::Edges {
        front_outlet_m: hammer.front_outlet_opens_m,
        rear_outlet_m: hammer.rear_outlet_opens_m,
    };
    // The last cycle of the solution, its impacts found as the measurement's are.
    let signals = crate::features::Signals {
        dt_s: truth.dt_s,
        p_rear_pa: &truth.p_rear_pa,
        p_front_pa: &truth.p_front_pa,
        accel_mps2: &truth.accel_mps2,
        supply_pa: f64::NAN,
    };
    let imps: Vec<usize> = extractor
        .impacts(&signals)
        .iter()
        .map(|t| (t / truth.dt_s).ceil() as usize)
        .collect();
    let (i0, i1, motion) = match (imps.len(), &truth.motion) {
        (n, Some(m)) if n >= 2 => (imps[n - 2], imps[n - 1].min(truth.len()).min(m.v_mps.len()), m),
        _ => return vec![Stage::StrokeIntake; BINS],
    };
    let n = i1 - i0;
    (0..BINS)
        .map(|b| {
            let mut count: BTreeMap<Stage, usize> = BTreeMap::new();
            for k in (b * n / BINS)..((b + 1) * n / BINS) {
                let i = i0 + k;
                let st = crate::stages::stage_of(
                    &edges,
                    motion.x_m[i],
                    motion.v_mps[i],
                    k as f64 * truth.dt_s,
                    crate::gap::IMPACT_WINDOW_S,
                );
                *count.entry(st).or_default() += 1;
            }
            count
                .into_iter()
                .max_by_key(|x| x.1)
                .map_or(Stage::StrokeIntake, |x| x.0)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pipeline::tests::nominal_runner;

    /// The nominal cycle's bins, from the impact on, run through the cycle
    /// in its physical order: the backhaul before the stroke, the stroke
    /// into the next impact, and no stage of the backhaul once the stroke began.
    #[test]
    fn bins_follow_the_cycle() {
        let runner = nominal_runner();
        let run = runner.truth(4.0, &Candidate::default()).unwrap();
        let st = bin_stages(&run, &runner.hammer, &runner.extractor);
        assert_eq!(st.len(), BINS);
        let stroke = |s: &Stage| matches!(s, Stage::StrokeIntake | Stage::StrokeClosed | Stage::StrokeVenting);
        assert!(!stroke(&st[0]), "{st:?}");
        assert!(stroke(&st[BINS - 1]), "{st:?}");
        let first_stroke = st.iter().position(stroke).unwrap();
        assert!(st[first_stroke..].iter().all(stroke), "{st:?}");
        assert!(st[..first_stroke].contains(&Stage::BackhaulFed), "{st:?}");
    }
}
