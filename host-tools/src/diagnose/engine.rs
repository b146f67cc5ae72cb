//! The diagnosis: where the gap lies, which catalogued effect explains it,
//! and how far it shrinks on data the fit did not see.
//!
//! Statistics. Each operating point contributes the mean of its fit cycles'
//! features; a feature's variance is its cycle-to-cycle variance over the
//! number of cycles plus a **model floor**: the nominal model is never the
//! hammer (its parameters are known to a few percent), and a gap below that
//! floor is no evidence. An effect's score is a BIC difference on these
//! per-cycle features, χ²_nominal − χ²_effect − k·ln(cycles): samples within
//! a cycle are correlated, so raw samples would overstate the evidence.
//!
//! This module is the pipeline's entry point and its public vocabulary
//! (inputs, options, outcome); the stages live in `pipeline`, the
//! report's schema in [`super::report`], the statistics in `fitset`.

use std::sync::atomic::{AtomicUsize, Ordering};

use serde::{Deserialize, Serialize};

use super::features::{pressure_floor, Extractor};
use super::gap::CycleSignals;
use super::model::ModelRunner;
use super::pipeline::{floor, group, held_out, nominal, rank, reference, where_};
use super::stages::Stage;
use hammer_sim::effects::EFFECT_NAMES;
use hammer_sim::SimConfig;
use hammer_trace::trace::Trace;

pub use super::report::{
    EffectResult, FittedParam, InputInfo, ModelForm, ModelFreeStat, PointShrink, Recalibration, Remainder, Report,
    Shrink, Verdict, WhereCell,
};

/// One measured trace and its role.
#[derive(Debug, Clone)]
pub struct MeasuredInput {
    pub label: String,
    pub supply_bar: f64,
    pub trace: Trace,
    /// Part of the fit set (its later half of cycles is still held out).
    pub fit: bool,
}

/// Model-floor standard deviations (see the module docs), calibrated on
/// no-effect controls of `hammer diagnose-bench` whose nominal parameters
/// were jittered (docs/diagnosis.md).
#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
pub struct Floors {
    pub period_rel: f64,
    pub energy_rel: f64,
    pub force_offset_n: f64,
    pub viscous_n_s_per_m: f64,
    pub gain: f64,
    pub zero_shift_sq_m2ps4: f64,
    /// Relative to each waveform's RMS over the cycle.
    pub wave_rel: f64,
    /// The chamber characteristics: feed onsets, closed-phase exponents,
    /// feed areas (relative).
    #[serde(default = "default_feed_onset_floor_s")]
    pub feed_onset_s: f64,
    #[serde(default = "default_closed_exponent_floor")]
    pub closed_exponent: f64,
    #[serde(default = "default_feed_area_floor_rel")]
    pub feed_area_rel: f64,
}

fn default_feed_onset_floor_s() -> f64 {
    Floors::default().feed_onset_s
}

fn default_closed_exponent_floor() -> f64 {
    Floors::default().closed_exponent
}

fn default_feed_area_floor_rel() -> f64 {
    Floors::default().feed_area_rel
}

impl Default for Floors {
    fn default() -> Self {
        Self {
            period_rel: 0.002,
            energy_rel: 0.003,
            force_offset_n: 0.3,
            viscous_n_s_per_m: 0.2,
            gain: 0.002,
            zero_shift_sq_m2ps4: 9.0,
            wave_rel: 0.005,
            // How far the measured onset falls from its truth on a sound
            // hammer, RMS (docs/estimator.md): the same calculation on the
            // model's noise-free solution and on a measurement differs by it.
            feed_onset_s: 50e-6,
            closed_exponent: 0.002,
            feed_area_rel: 0.01,
        }
    }
}

#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Options {
    pub floors: Floors,
    /// Relative standard deviation of the nominal parameters the model is
    /// unsure of ([`super::model::NUISANCE`]); 0 trusts them exactly.
    pub nominal_uncertainty: f64,
    pub max_iterations: usize,
    /// An effect the force balance cannot see must score above this (BIC
    /// units) to be named; one it sees needs a positive score and
    /// [`Options::min_model_free_z`].
    pub min_score: f64,
    /// An effect the force balance sees (friction, a gain error, a zero
    /// shift) is named only if its signature there stands this many standard
    /// errors off the nominal model: the force balance needs no valve or port
    /// model, so the model's form error cannot fake it, and however much of
    /// the gap has other causes, it does not hide it.
    #[serde(default = "default_min_model_free_z")]
    pub min_model_free_z: f64,
    /// An effect the force balance cannot see (leakage, valve delay, heat
    /// transfer, a supply restriction) has only the model-based features as
    /// evidence, and they carry the model's form error: it must explain at
    /// least this fraction of the nominal χ², because a smooth form error
    /// lends any effect a little of its shape.
    pub min_explained: f64,
    /// A pair's second effect, unseen by the force balance, must explain
    /// this fraction of what the first leaves: after the first effect the
    /// rest is mostly noise and form error, whose shape any effect fits a little.
    #[serde(default = "default_min_explained_pair")]
    pub min_explained_pair: f64,
    /// A named effect the force balance cannot see is flagged confusable
    /// with each other such effect scoring within this many BIC units of it:
    /// leakage, heat transfer and a supply restriction lower the same
    /// pressures (the isolability matrix), and on a hammer of another form
    /// the last few percent that part them are within the form error. Set
    /// on the structural benchmark's calibration seed (docs/diagnosis.md).
    #[serde(default = "default_confusable_margin")]
    pub confusable_margin: f64,
    /// Pairs are tried when the best single effect leaves a reduced χ² above this.
    pub pair_residual: f64,
    /// How many runners-up are tried as the second effect of a pair.
    pub pair_candidates: usize,
    pub threads: usize,
    /// Keep the waveforms for the figures.
    pub figures: bool,
    /// Estimate the model-form error of the model-based features from the
    /// recalibrated nominal model's residual (see [`ModelForm`]); off, the
    /// floors alone weigh them (a model whose form is the hammer's).
    pub model_form: bool,
}

impl Default for Options {
    fn default() -> Self {
        Self {
            floors: Floors::default(),
            nominal_uncertainty: 0.2,
            max_iterations: 12,
            min_score: 20.0,
            min_model_free_z: default_min_model_free_z(),
            min_explained: 0.4,
            min_explained_pair: default_min_explained_pair(),
            confusable_margin: default_confusable_margin(),
            pair_residual: 2.0,
            pair_candidates: 5,
            threads: std::thread::available_parallelism().map_or(2, |n| n.get()),
            figures: true,
            model_form: true,
        }
    }
}

fn default_min_model_free_z() -> f64 {
    3.0
}

fn default_confusable_margin() -> f64 {
    20.0
}

fn default_min_explained_pair() -> f64 {
    0.5
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

#[derive(Debug, Clone)]
pub struct Outcome {
    pub report: Report,
    pub waves: Vec<PointWaves>,
}

#[derive(Debug, thiserror::Error)]
pub enum DiagnoseError {
    #[error("no measured trace given")]
    NoInput,
    #[error("{0}: no complete impact cycle found (is the accelerometer connected, does the hammer run?)")]
    NoCycles(String),
    #[error("{0}: supply pressure unknown: give it in the sidecar or with --supply-bar after the trace")]
    NoPressure(String),
    #[error("the nominal model does not run at {0} bar: {1}")]
    Model(f64, String),
    #[error("no reference record at {0} bar: with references, every operating point needs one")]
    NoReference(f64),
}

/// Progress: (done, total, what is running).
pub type Progress<'a> = &'a (dyn Fn(usize, usize, &str) + Sync);

/// The extractor for a trace recorded with `base`'s sensors and estimator thresholds.
pub fn extractor_for(base: &SimConfig) -> Extractor {
    let a = &base.sensors.accel;
    let clip = 0.98 * a.range_max.abs().min(a.range_min.abs());
    let mut ex = Extractor::new(
        base.hammer.geometry(),
        base.hammer.inclination_deg,
        base.estimator.impact_threshold_mps2,
        clip,
    );
    ex.zero_shift_tau_s = base.estimator.accel_zero_shift_tau_s;
    ex.chambers = Some(base.hammer.chambers());
    ex
}

/// The diagnosis of `inputs` against the nominal model `base`: the stages
/// group → nominal → rank → held-out → where, in that order (each needs the
/// one before), then the report assembled from their results.
pub fn diagnose(
    inputs: &[MeasuredInput],
    base: &SimConfig,
    opts: &Options,
    progress: Progress,
) -> Result<Outcome, DiagnoseError> {
    diagnose_against(inputs, &[], base, opts, progress)
}

/// [`diagnose`] of what changed since `references`, records of the same
/// hammer when it was known sound (one at least at every operating point
/// of `inputs`; none: [`diagnose`]). The model's form error is common to
/// both records and cancels; see [`super::pipeline::reference`].
pub fn diagnose_against(
    inputs: &[MeasuredInput],
    references: &[MeasuredInput],
    base: &SimConfig,
    opts: &Options,
    progress: Progress,
) -> Result<Outcome, DiagnoseError> {
    let started = std::time::Instant::now();
    if inputs.is_empty() {
        return Err(DiagnoseError::NoInput);
    }
    let mut extractor = extractor_for(base);
    let all = || inputs.iter().chain(references);
    let rear: Vec<&[f64]> = all().map(|i| i.trace.p_rear_pa.as_slice()).collect();
    let front: Vec<&[f64]> = all().map(|i| i.trace.p_front_pa.as_slice()).collect();
    extractor.pressure_floor_pa = [pressure_floor(&rear), pressure_floor(&front)];
    let runner = ModelRunner::new(base.clone(), extractor);
    let mut grouped = group::group(inputs, &runner.extractor)?;
    let total_steps = grouped.points.len() + EFFECT_NAMES.len() + 3;
    let done = AtomicUsize::new(0);
    let step = |what: &str| {
        let d = done.fetch_add(1, Ordering::Relaxed) + 1;
        progress(d.min(total_steps), total_steps, what);
    };
    progress(0, total_steps, "nominal model");
    let nominal = nominal::nominal(&grouped.points, &runner, opts, &step)?;
    let mut reference_infos = Vec::new();
    if !references.is_empty() {
        let (baselines, infos) = reference::baselines(references, &runner.extractor)?;
        reference::transplant(&mut grouped.points, &nominal.features, &baselines)?;
        reference_infos = infos;
    }
    let points = &grouped.points;
    // Against a reference the model's form error has cancelled: what the
    // nominal model misses is the change, and a form factor measured on it
    // would weigh the effects down by their own size.
    let fit_opts = Options {
        model_form: opts.model_form && references.is_empty(),
        ..opts.clone()
    };
    let (fs, model_form) = nominal::fit_set(points, &nominal, &runner, &fit_opts);
    let ranking = rank::rank(&fs, opts, &step);
    let detection_floors = floor::floors(&fs, &ranking, opts);
    step("detection floors");

    let models = held_out::models(&fs, &nominal.bars, ranking.verdict.as_ref(), opts);
    step("held-out check");
    let shrink = held_out::shrink(points, &nominal.features, &models);
    let located = where_::locate(inputs, &grouped, &nominal, &models, base, opts);
    let recalibration = held_out::recalibration(base, &models, opts.nominal_uncertainty);

    let simulations = fs.simulations() + models.simulations();
    Ok(Outcome {
        report: Report {
            tool: format!("hammer diagnose {}", env!("CARGO_PKG_VERSION")),
            inputs: grouped.infos,
            references: reference_infos,
            fit_points: fs.bars(),
            where_: located.where_,
            verdict: ranking.verdict_report(),
            effects: ranking.effects,
            pairs: ranking.pairs,
            recalibration,
            remainder: located.remainder,
            model_form,
            model_free: fs.model_free_stats(),
            chambers: fs.chamber_stats(),
            detection_floors,
            shrink,
            chi2_nominal: ranking.chi2_nominal,
            features_compared: ranking.features_compared,
            fit_cycles: fs.fit_cycles(),
            options: opts.clone(),
            simulations,
            elapsed_s: started.elapsed().as_secs_f64(),
        },
        waves: located.waves,
    })
}
