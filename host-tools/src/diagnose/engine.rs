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

use std::collections::BTreeMap;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;

use serde::{Deserialize, Serialize};

use super::effects::{diagnosis, pressure_reading_factors};
use super::features::{
    feature_name, steady_from, summarize, wave_index, wave_of, CycleFeatures, Extractor, Signals, Summary, BINS,
    ENERGY, F_BACKHAUL, F_STROKE, GAIN_FRONT, GAIN_REAR, N_FEATURES, PERIOD, VISCOUS, WAVE_SIGNALS, ZERO_SHIFT_SQ,
};
use super::fit::{levenberg_marquardt, FitResult};
use super::gap::{breakdown, measured_cycles, normalized, template, CycleSignals};
use super::model::{apply, catalogue_params, free_params, Candidate, ModelRunner, NUISANCE};
use super::stages::Stage;
use hammer_sim::effects::{Effects, EFFECT_NAMES};
use hammer_sim::run::TruthTrace;
use hammer_sim::{simulate_truth, SimConfig};
use hammer_trace::trace::Trace;

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
    /// An effect must score above this (BIC units) to be named.
    pub min_score: f64,
    /// ... and explain at least this fraction of the nominal χ².
    pub min_explained: f64,
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
            min_explained: 0.5,
            pair_residual: 2.0,
            pair_candidates: 5,
            threads: std::thread::available_parallelism().map_or(2, |n| n.get()),
            figures: true,
            model_form: true,
        }
    }
}

#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct InputInfo {
    pub label: String,
    pub supply_bar: f64,
    pub cycles: usize,
    /// Cycles dropped as start-up.
    pub startup_cycles: usize,
    pub fit_cycles: usize,
    pub held_out_cycles: usize,
}

#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct WhereCell {
    pub supply_bar: f64,
    pub signal: String,
    pub stage: Stage,
    pub bias: f64,
    pub rms: f64,
    pub relative_rms: f64,
    pub timing_shift_s: f64,
}

#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct FittedParam {
    pub key: String,
    pub value: f64,
    pub sd: f64,
}

#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct EffectResult {
    /// An effect of the catalogue, or two joined by `+`.
    pub name: String,
    /// In the catalogue's terms, ready for a config file.
    pub params: serde_json::Value,
    /// The free parameters as fitted, with their standard deviations.
    pub fitted: Vec<FittedParam>,
    pub chi2: f64,
    /// BIC difference against the nominal model: higher explains more.
    pub score: f64,
    pub explained_fraction: f64,
    pub evidence: Vec<String>,
    pub simulations: usize,
    #[serde(skip)]
    pub candidate: Candidate,
}

#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Verdict {
    /// Effect names, or `["none"]`.
    pub effects: Vec<String>,
    pub params: serde_json::Value,
    /// The named model's score (the best single effect's when `none`).
    pub score: f64,
    pub reason: String,
}

#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct PointShrink {
    pub supply_bar: f64,
    pub held_out_point: bool,
    pub cycles: usize,
    pub impact_energy_measured_j: f64,
    pub impact_energy_nominal_j: f64,
    pub impact_energy_fitted_j: f64,
    /// The nominal model with its uncertain parameters refitted, no effect.
    pub impact_energy_recalibrated_j: f64,
    pub frequency_measured_hz: f64,
    pub frequency_nominal_hz: f64,
    pub frequency_fitted_hz: f64,
    /// RMS of the binned waveform residual per signal, nominal and fitted model.
    pub rms_before: BTreeMap<String, f64>,
    pub rms_after: BTreeMap<String, f64>,
}

#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Shrink {
    /// Mean |simulated − measured| / measured over the held-out data, %.
    pub impact_energy_error_before: f64,
    pub impact_energy_error_after: f64,
    pub frequency_error_before: f64,
    pub frequency_error_after: f64,
    /// The control: nominal parameters refitted within their prior, no effect added.
    pub impact_energy_error_recalibrated_only: f64,
    /// Supply pressures (bar) not used for fitting.
    pub held_out_points: Vec<f64>,
    /// What the figures above were computed on.
    pub judged_on: String,
    pub points: Vec<PointShrink>,
}

/// The model-form error of one group of model-based features: how much
/// larger the recalibrated nominal model's residual is than the measurement
/// noise and floors allow. The group's weights are divided by it, so a model
/// whose valve or ports differ in form cannot make an effect out of that
/// difference, and the model-free force balance keeps its full weight.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ModelForm {
    pub group: String,
    /// RMS of the group's whitened residual (1 = within noise and floors).
    pub factor: f64,
}

/// A nominal parameter the fit moved: its value and standard deviation
/// after the fit, and how many prior standard deviations it moved.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Recalibration {
    pub parameter: String,
    pub nominal: f64,
    pub value: f64,
    pub sd: f64,
    pub prior_sds: f64,
    /// Moved beyond one prior standard deviation.
    pub beyond_prior: bool,
}

/// What neither the named effects nor the recalibration explain, by
/// signal × stage: where the model's form differs from the hammer's.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Remainder {
    pub supply_bar: f64,
    pub signal: String,
    pub stage: Stage,
    /// RMS of the residual after the verdict's model over the signal's RMS in that stage.
    pub relative_rms: f64,
    /// The same before (nominal model).
    pub relative_rms_nominal: f64,
    pub statement: String,
}

#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Report {
    pub tool: String,
    pub inputs: Vec<InputInfo>,
    pub fit_points: Vec<f64>,
    #[serde(rename = "where")]
    pub where_: Vec<WhereCell>,
    pub effects: Vec<EffectResult>,
    pub pairs: Vec<EffectResult>,
    pub verdict: Verdict,
    /// The nominal parameters as the verdict's fit left them.
    pub recalibration: Vec<Recalibration>,
    /// The unexplained remainder, largest first.
    pub remainder: Vec<Remainder>,
    pub model_form: Vec<ModelForm>,
    pub shrink: Shrink,
    pub chi2_nominal: f64,
    pub features_compared: usize,
    pub fit_cycles: usize,
    pub options: Options,
    pub simulations: usize,
    pub elapsed_s: f64,
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
}

/// Progress: (done, total, what is running).
pub type Progress<'a> = &'a (dyn Fn(usize, usize, &str) + Sync);

struct Point {
    supply_bar: f64,
    fit: Vec<CycleFeatures>,
    held: Vec<CycleFeatures>,
    is_fit_point: bool,
    inputs: Vec<usize>,
}

/// The fit set's data and its weights, shared by every effect's fit.
pub(super) struct FitSet<'a> {
    pub(super) runner: &'a ModelRunner,
    points: Vec<(f64, Summary, Vec<f64>)>, // bar, summary, sigma
    pub(super) nominal_truth: Vec<TruthTrace>,
    /// Lowest and highest supply pressure of the fit set, bar.
    pub(super) pressures: (f64, f64),
    pub(super) distinct: usize,
    sims: AtomicUsize,
    /// Whitened sensitivities of the fit features to each nuisance parameter
    /// (per unit of its prior standard deviation), concatenated over points.
    nuisance: Vec<Vec<f64>>,
}

impl FitSet<'_> {
    /// Mean of feature `j` over the fit points.
    pub(super) fn avg(&self, j: usize) -> f64 {
        self.points.iter().map(|p| p.1.mean[j]).sum::<f64>() / self.points.len().max(1) as f64
    }

    /// Mean of feature `j` at the fit point at `bar` (0 without one).
    pub(super) fn mean_at(&self, bar: f64, j: usize) -> f64 {
        self.points
            .iter()
            .find(|p| (p.0 - bar).abs() < 1e-9)
            .map_or(0.0, |p| p.1.mean[j])
    }

    /// Mean of feature `j` over the fit points and its standard error.
    pub(super) fn mean_se(&self, j: usize) -> (f64, f64) {
        let n = self.points.len().max(1) as f64;
        let m = self.points.iter().map(|p| p.1.mean[j]).sum::<f64>() / n;
        let se = (self.points.iter().map(|p| p.2[j] * p.2[j]).sum::<f64>()).sqrt() / n;
        (m, se)
    }

    fn residuals(&self, cand: &Candidate) -> Option<Vec<f64>> {
        let mut r = Vec::with_capacity(self.points.len() * N_FEATURES);
        for ((bar, s, sigma), truth) in self.points.iter().zip(&self.nominal_truth) {
            if cand.has_physics() {
                self.sims.fetch_add(1, Ordering::Relaxed);
            }
            let m = self.runner.features(*bar, cand, Some(truth))?;
            for j in 0..N_FEATURES {
                r.push(residual(m[j], s.mean[j], sigma[j]));
            }
        }
        Some(self.profile(r))
    }

    /// Profiles the nuisance parameters out of whitened residuals `r`: the
    /// linearised model m + J·δ with prior δ ~ N(0, 1) is fitted in closed
    /// form, and the residual plus the prior's terms returned.
    fn profile(&self, mut r: Vec<f64>) -> Vec<f64> {
        let k = self.nuisance.len();
        if k == 0 {
            return r;
        }
        let (a, b) = prior_normal_equations(&self.nuisance, &r, &vec![0.0; k]);
        let Some(delta) = super::fit::solve(a, b) else {
            return r;
        };
        for (i, col) in self.nuisance.iter().enumerate() {
            for (x, c) in r.iter_mut().zip(col) {
                *x += delta[i] * c;
            }
        }
        r.extend(delta);
        r
    }

    /// The model-form factor of every group of model-based features: the
    /// RMS of `cand`'s whitened, profiled residual over the group, at least 1.
    fn model_form_factors(&self, cand: &Candidate) -> Vec<f64> {
        let mut sum = [0.0; MODEL_FORM_GROUPS];
        let mut n = [0usize; MODEL_FORM_GROUPS];
        if let Some(r) = self.residuals(cand) {
            for (i, x) in r.iter().take(self.points.len() * N_FEATURES).enumerate() {
                if let Some(g) = model_form_group(i % N_FEATURES) {
                    sum[g] += x * x;
                    n[g] += 1;
                }
            }
        }
        (0..MODEL_FORM_GROUPS)
            .map(|g| (sum[g] / n[g].max(1) as f64).sqrt().max(1.0))
            .collect()
    }

    /// Divides each model-based feature's weight by its group's factor.
    fn inflate(&mut self, factors: &[f64]) {
        for (p, point) in self.points.iter_mut().enumerate() {
            for j in 0..N_FEATURES {
                if let Some(g) = model_form_group(j) {
                    point.2[j] *= factors[g];
                    for col in &mut self.nuisance {
                        col[p * N_FEATURES + j] /= factors[g];
                    }
                }
            }
        }
    }

    /// The nominal parameters refitted with `cand`'s effects held:
    /// Gauss–Newton on the simulator itself, re-linearised at every step,
    /// each parameter's prior N(0, 1) in units of `h` of its nominal value.
    /// At a real hammer's ±20 % the model is far from linear, so the
    /// profile's one linearisation at nominal would overshoot.
    fn recalibrate(&self, cand: &Candidate, h: f64, steps: usize, threads: usize) -> Option<Recalibrated> {
        let k = NUISANCE.len();
        let runner_at = |d: &[f64]| {
            let mut r = self.runner.clone();
            for (i, x) in d.iter().enumerate() {
                *(NUISANCE[i].1)(&mut r.base) *= 1.0 + h * x;
            }
            r
        };
        let whitened = |d: &[f64]| -> Option<Vec<f64>> {
            let r = runner_at(d);
            let mut out = Vec::with_capacity(self.points.len() * N_FEATURES);
            for (bar, s, sigma) in &self.points {
                self.sims.fetch_add(1, Ordering::Relaxed);
                let m = r.features(*bar, cand, None)?;
                out.extend((0..N_FEATURES).map(|j| residual(m[j], s.mean[j], sigma[j])));
            }
            Some(out)
        };
        let cost = |r: &[f64], d: &[f64]| r.iter().chain(d).map(|x| x * x).sum::<f64>();
        // Finite-difference step, in prior standard deviations.
        const STEP: f64 = 0.25;
        let mut delta = vec![0.0; k];
        let mut r = whitened(&delta)?;
        let mut sd = vec![1.0; k];
        for _ in 0..steps {
            let jobs: Vec<usize> = (0..k).collect();
            let cols = parallel(threads, jobs, &|i| {
                let mut d = delta.clone();
                d[i] += STEP;
                whitened(&d).map(|ri| ri.iter().zip(&r).map(|(a, b)| (a - b) / STEP).collect::<Vec<f64>>())
            });
            let cols: Vec<Vec<f64>> = cols
                .into_iter()
                .map(|c| c.unwrap_or_else(|| vec![0.0; r.len()]))
                .collect();
            let (a, b) = prior_normal_equations(&cols, &r, &delta);
            sd = (0..k)
                .map(|i| {
                    let mut e = vec![0.0; k];
                    e[i] = 1.0;
                    super::fit::solve(a.clone(), e).map_or(1.0, |x| x[i].max(0.0).sqrt())
                })
                .collect();
            let Some(step) = super::fit::solve(a, b) else { break };
            // Halve the step until the cost falls (at most three times).
            let mut scale = 1.0;
            let mut moved = false;
            for _ in 0..3 {
                let d: Vec<f64> = delta
                    .iter()
                    .zip(&step)
                    .map(|(x, s)| (x + scale * s).clamp(-MAX_PRIOR_SDS, MAX_PRIOR_SDS))
                    .collect();
                if let Some(rn) = whitened(&d) {
                    if cost(&rn, &d) < cost(&r, &delta) {
                        delta = d;
                        r = rn;
                        moved = true;
                        break;
                    }
                }
                scale *= 0.5;
            }
            if !moved {
                break;
            }
        }
        Some(Recalibrated {
            runner: runner_at(&delta),
            delta,
            sd,
        })
    }

    fn chi2(&self, cand: &Candidate) -> Option<f64> {
        self.residuals(cand).map(|r| r.iter().map(|x| x * x).sum())
    }
}

/// The Gauss–Newton step for whitened residuals `r` with Jacobian columns
/// `cols` and a unit Gaussian prior on each parameter, taken from `at`:
/// (JᵀJ + I)·step = −(Jᵀr + at). The profile (from 0) and the
/// recalibration (from where it has got to) both solve it.
fn prior_normal_equations(cols: &[Vec<f64>], r: &[f64], at: &[f64]) -> (Vec<Vec<f64>>, Vec<f64>) {
    let dot = |x: &[f64], y: &[f64]| x.iter().zip(y).map(|(a, b)| a * b).sum::<f64>();
    let k = cols.len();
    let mut a = vec![vec![0.0; k]; k];
    let mut b = vec![0.0; k];
    for i in 0..k {
        for j in 0..k {
            a[i][j] = dot(&cols[i], &cols[j]);
        }
        a[i][i] += 1.0;
        b[i] = -(dot(&cols[i], r) + at[i]);
    }
    (a, b)
}

/// The nominal model recalibrated for a candidate.
struct Recalibrated {
    runner: ModelRunner,
    /// Each nuisance parameter's move and standard deviation, in prior standard deviations.
    delta: Vec<f64>,
    sd: Vec<f64>,
}

/// A recalibration stops at this many prior standard deviations: beyond,
/// the parameter is no longer the hammer's but a stand-in for a form error.
const MAX_PRIOR_SDS: f64 = 2.5;
/// Gauss–Newton steps of a recalibration.
const RECALIBRATION_STEPS: usize = 3;

/// A cell's residual below this share of the signal's RMS is not reported as a remainder.
const REMAINDER_MIN: f64 = 0.1;
/// Remainder cells kept in the report.
const REMAINDER_CELLS: usize = 8;

/// What a residual left in a signal says about the model's form.
fn form_cause(signal: &str) -> &'static str {
    match signal {
        "p_rear_pa" | "p_front_pa" => "the valve or port model differs (or the chamber's thermodynamics)",
        "accel_mps2" => "the contact, friction or accelerometer model differs",
        _ => "the forces that drive the motion differ (pressures, friction or contact)",
    }
}

/// Groups of model-based features whose weight the model's form limits:
/// one per waveform. The period and the impact energy keep their floors
/// (the recalibration must meet them), and the force balance's features
/// are model-free.
const MODEL_FORM_GROUPS: usize = WAVE_SIGNALS.len();

fn model_form_group(feature: usize) -> Option<usize> {
    wave_of(feature).map(|(signal, _)| signal)
}

fn model_form_group_name(g: usize) -> &'static str {
    WAVE_SIGNALS[g]
}

/// Missing on the model side where the measurement has it: a clear miss.
fn residual(model: f64, meas: f64, sigma: f64) -> f64 {
    match (model.is_finite(), meas.is_finite() && sigma.is_finite() && sigma > 0.0) {
        (true, true) => (model - meas) / sigma,
        (false, true) => 5.0,
        _ => 0.0,
    }
}

fn sigmas(s: &Summary, nominal: &[f64], f: &Floors) -> Vec<f64> {
    let n = s.cycles.max(1) as f64;
    let mut wave_scale = [0.0; 4];
    for (si, scale) in wave_scale.iter_mut().enumerate() {
        let xs: Vec<f64> = (0..BINS)
            .map(|b| nominal[wave_index(si, b)])
            .filter(|x| x.is_finite())
            .collect();
        *scale = (xs.iter().map(|x| x * x).sum::<f64>() / xs.len().max(1) as f64).sqrt();
    }
    (0..N_FEATURES)
        .map(|j| {
            let floor = match j {
                PERIOD => f.period_rel * nominal[PERIOD].abs(),
                ENERGY => f.energy_rel * nominal[ENERGY].abs(),
                F_STROKE | F_BACKHAUL => f.force_offset_n,
                VISCOUS => f.viscous_n_s_per_m,
                GAIN_REAR | GAIN_FRONT => f.gain,
                ZERO_SHIFT_SQ => f.zero_shift_sq_m2ps4,
                _ => f.wave_rel * wave_scale[wave_of(j).map_or(0, |w| w.0)],
            };
            let sd = if s.sd[j].is_finite() { s.sd[j] } else { 0.0 };
            (sd * sd / n + floor * floor).sqrt()
        })
        .collect()
}

/// Runs `jobs` on up to `threads` threads, results in job order.
fn parallel<T: Send, R: Send>(threads: usize, jobs: Vec<T>, f: &(dyn Fn(T) -> R + Sync)) -> Vec<R> {
    let n = jobs.len();
    let queue = Mutex::new(jobs.into_iter().enumerate().collect::<Vec<_>>());
    let out = Mutex::new((0..n).map(|_| None).collect::<Vec<Option<R>>>());
    std::thread::scope(|s| {
        for _ in 0..threads.clamp(1, n.max(1)) {
            s.spawn(|| loop {
                let job = queue.lock().unwrap().pop();
                let Some((i, job)) = job else { break };
                let r = f(job);
                out.lock().unwrap()[i] = Some(r);
            });
        }
    });
    out.into_inner()
        .unwrap()
        .into_iter()
        .map(|r| r.expect("every job ran"))
        .collect()
}

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
    ex
}

pub fn diagnose(
    inputs: &[MeasuredInput],
    base: &SimConfig,
    opts: &Options,
    progress: Progress,
) -> Result<Outcome, DiagnoseError> {
    let started = std::time::Instant::now();
    if inputs.is_empty() {
        return Err(DiagnoseError::NoInput);
    }
    let extractor = extractor_for(base);
    let runner = ModelRunner::new(base.clone(), extractor);
    let any_fit = inputs.iter().any(|i| i.fit);

    // Cycles of every input, grouped by operating point.
    let mut infos = Vec::new();
    let mut points: Vec<Point> = Vec::new();
    let mut steady_impacts: Vec<Vec<f64>> = Vec::new();
    for (k, inp) in inputs.iter().enumerate() {
        if !(inp.supply_bar.is_finite() && inp.supply_bar > 0.0) {
            return Err(DiagnoseError::NoPressure(inp.label.clone()));
        }
        let s = Signals {
            dt_s: inp.trace.dt_s,
            p_rear_pa: &inp.trace.p_rear_pa,
            p_front_pa: &inp.trace.p_front_pa,
            accel_mps2: &inp.trace.accel_mps2,
        };
        let all = extractor.cycles(&s);
        let st = steady_from(&all);
        let steady = &all[st..];
        if steady.is_empty() {
            return Err(DiagnoseError::NoCycles(inp.label.clone()));
        }
        let mut imps: Vec<f64> = steady.iter().map(|c| c.t_impact_s).collect();
        if let Some(last) = steady.last() {
            imps.push(last.t_impact_s + last.values[PERIOD]);
        }
        steady_impacts.push(imps);
        let is_fit = inp.fit || (!any_fit && k == 0);
        let (fit, held) = if !is_fit {
            (Vec::new(), steady.to_vec())
        } else if steady.len() >= 2 {
            let h = steady.len().div_ceil(2);
            (steady[..h].to_vec(), steady[h..].to_vec())
        } else {
            (steady.to_vec(), steady.to_vec())
        };
        infos.push(InputInfo {
            label: inp.label.clone(),
            supply_bar: inp.supply_bar,
            cycles: all.len(),
            startup_cycles: st,
            fit_cycles: fit.len(),
            held_out_cycles: held.len(),
        });
        let key = (inp.supply_bar * 100.0).round() / 100.0;
        match points.iter_mut().find(|p| (p.supply_bar - key).abs() < 1e-9) {
            Some(p) => {
                p.fit.extend(fit);
                p.held.extend(held);
                p.is_fit_point |= is_fit;
                p.inputs.push(k);
            }
            None => points.push(Point {
                supply_bar: key,
                fit,
                held,
                is_fit_point: is_fit,
                inputs: vec![k],
            }),
        }
    }
    points.sort_by(|a, b| a.supply_bar.total_cmp(&b.supply_bar));

    // The nominal model at every point.
    let total_steps = points.len() + EFFECT_NAMES.len() + 2;
    let done = AtomicUsize::new(0);
    let step = |what: &str| {
        let d = done.fetch_add(1, Ordering::Relaxed) + 1;
        progress(d.min(total_steps), total_steps, what);
    };
    progress(0, total_steps, "nominal model");
    let bars: Vec<f64> = points.iter().map(|p| p.supply_bar).collect();
    let nominal_runs = parallel(opts.threads, bars.clone(), &|bar| {
        let r = simulate_truth(&runner.config(bar, &Effects::default()));
        step(&format!("nominal model at {bar} bar"));
        r
    });
    let mut nominal_runs_ok = Vec::new();
    for (bar, r) in bars.iter().zip(nominal_runs) {
        nominal_runs_ok.push(r.map_err(|e| DiagnoseError::Model(*bar, e.to_string()))?);
    }
    let nominal = Candidate::default();
    let mut nominal_features = Vec::new();
    for (bar, run) in bars.iter().zip(&nominal_runs_ok) {
        nominal_features.push(
            runner
                .features_of_truth(&run.truth, &nominal.effects)
                .ok_or_else(|| DiagnoseError::Model(*bar, "no steady impact cycle".into()))?,
        );
    }

    let fit_idx: Vec<usize> = (0..points.len()).filter(|&i| points[i].is_fit_point).collect();
    let fit_bars: Vec<f64> = fit_idx.iter().map(|&i| points[i].supply_bar).collect();
    let pressures = (
        fit_bars.iter().cloned().fold(f64::INFINITY, f64::min),
        fit_bars.iter().cloned().fold(f64::NEG_INFINITY, f64::max),
    );
    let fs = FitSet {
        runner: &runner,
        points: fit_idx
            .iter()
            .map(|&i| {
                let s = summarize(&points[i].fit);
                let sig = sigmas(&s, &nominal_features[i], &opts.floors);
                (points[i].supply_bar, s, sig)
            })
            .collect(),
        nominal_truth: fit_idx.iter().map(|&i| nominal_runs_ok[i].truth.clone()).collect(),
        pressures,
        distinct: fit_bars.len(),
        sims: AtomicUsize::new(points.len()),
        nuisance: Vec::new(),
    };
    let mut fs = fs;
    if opts.nominal_uncertainty > 0.0 {
        let h = opts.nominal_uncertainty;
        let jobs: Vec<(usize, usize)> = (0..fs.points.len())
            .flat_map(|p| (0..NUISANCE.len()).map(move |k| (p, k)))
            .collect();
        let runner = &runner;
        let fsr = &fs;
        let cols = parallel(opts.threads, jobs.clone(), &|(p, k)| {
            let mut c = runner.config(fsr.points[p].0, &Effects::default());
            *(NUISANCE[k].1)(&mut c) *= 1.0 + h;
            simulate_truth(&c)
                .ok()
                .and_then(|run| runner.features_of_truth(&run.truth, &Effects::default()))
        });
        let mut nuisance = vec![Vec::with_capacity(fs.points.len() * N_FEATURES); NUISANCE.len()];
        for ((p, k), col) in jobs.into_iter().zip(cols) {
            let nom = &nominal_features[fit_idx[p]];
            let sigma = &fs.points[p].2;
            for j in 0..N_FEATURES {
                // One prior standard deviation's change of the feature, whitened.
                let d = col.as_ref().map_or(f64::NAN, |f| (f[j] - nom[j]) / sigma[j]);
                nuisance[k].push(if d.is_finite() { d } else { 0.0 });
            }
        }
        fs.sims.fetch_add(fs.points.len() * NUISANCE.len(), Ordering::Relaxed);
        fs.nuisance = nuisance;
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
    let fs = fs;
    let fit_cycles: usize = fs.points.iter().map(|p| p.1.cycles).sum();
    let ln_n = (fit_cycles.max(2) as f64).ln();
    let chi2_nominal = fs.chi2(&nominal).unwrap_or(f64::INFINITY);

    // Which: every effect of the catalogue, fitted alone.
    let singles: Vec<EffectResult> = parallel(opts.threads, EFFECT_NAMES.to_vec(), &|name| {
        let r = fit_effects(&fs, &[name], &[], chi2_nominal, ln_n, opts);
        step(&format!("fitted {name}"));
        r
    })
    .into_iter()
    .flatten()
    .collect();
    let mut effects = singles;
    effects.sort_by(|a, b| b.score.total_cmp(&a.score));

    let significant = |e: &EffectResult| e.score > opts.min_score && e.explained_fraction >= opts.min_explained;
    let n_compared = fs.points.len() * N_FEATURES;
    let mut pairs = Vec::new();
    let mut verdict_cand = None;
    let mut reason;
    match effects.first() {
        Some(best) if significant(best) => {
            verdict_cand = Some(best.clone());
            let reduced = best.chi2 / n_compared.max(1) as f64;
            reason = format!(
                "{} explains {:.0} % of the nominal gap (score {:.0}, next {} at {:.0})",
                best.name,
                100.0 * best.explained_fraction,
                best.score,
                effects.get(1).map_or("-", |e| e.name.as_str()),
                effects.get(1).map_or(0.0, |e| e.score)
            );
            // A pair can only be named if the single leaves more than the
            // threshold to explain: otherwise do not spend the simulations.
            if reduced > opts.pair_residual || best.chi2 > opts.min_score + 2.0 * ln_n {
                let first = best.name.clone();
                let start: Vec<FittedParam> = best.fitted.clone();
                // The next effects by their own score: a second effect shows
                // there first, and each pair costs a fit.
                let others: Vec<&EffectResult> = effects.iter().skip(1).take(opts.pair_candidates).collect();
                let jobs: Vec<(String, Vec<FittedParam>)> =
                    others.iter().map(|o| (o.name.clone(), o.fitted.clone())).collect();
                pairs = parallel(opts.threads, jobs, &|(other, other_start)| {
                    let mut init = start.clone();
                    init.extend(other_start);
                    fit_effects(&fs, &[first.as_str(), other.as_str()], &init, chi2_nominal, ln_n, opts)
                })
                .into_iter()
                .flatten()
                .collect();
                pairs.sort_by(|a, b| b.score.total_cmp(&a.score));
                if let Some(p) = pairs.first() {
                    // The pair must beat the single by as much as a single beats nominal.
                    let extra = best.chi2 - p.chi2 - (p.fitted.len() - best.fitted.len()) as f64 * ln_n;
                    if extra > opts.min_score && (best.chi2 - p.chi2) >= opts.min_explained * best.chi2 {
                        reason = format!(
                            "{} leaves a reduced χ² of {reduced:.1}; adding the second effect removes {:.0} % of the rest (score +{extra:.0})",
                            best.name,
                            100.0 * (best.chi2 - p.chi2) / best.chi2
                        );
                        verdict_cand = Some(p.clone());
                    }
                }
            }
            step("pairs");
        }
        Some(best) => {
            reason = format!(
                "no effect explains a significant part of the gap: best {} (score {:.0}, {:.0} % explained; needs > {:.0} and {:.0} %)",
                best.name,
                best.score,
                100.0 * best.explained_fraction,
                opts.min_score,
                100.0 * opts.min_explained
            );
            step("pairs");
        }
        None => {
            reason = "no effect could be fitted".into();
            step("pairs");
        }
    }

    // How far: the verdict's model, with the nominal parameters as its fit
    // left them (within their prior), against the held-out data. The nominal
    // model recalibrated alone is the control: the shrink must come from the effect.
    let fitted_cand = verdict_cand.as_ref().map(|v| v.candidate.clone());
    let h = opts.nominal_uncertainty;
    let recalibrated = |cand: &Candidate| -> Option<Recalibrated> {
        if h > 0.0 {
            fs.recalibrate(cand, h, RECALIBRATION_STEPS, opts.threads)
        } else {
            None
        }
    };
    let model_runs =
        |recal: &Option<Recalibrated>, cand: &Candidate| -> (ModelRunner, Vec<Option<hammer_sim::SimRun>>) {
            let r = recal.as_ref().map_or_else(|| runner.clone(), |x| x.runner.clone());
            let physics = cand.physics();
            let runs = parallel(opts.threads, bars.clone(), &|bar| {
                simulate_truth(&r.config(bar, &physics)).ok()
            });
            (r, runs)
        };
    let recal_nominal = recalibrated(&nominal);
    let recal_verdict = fitted_cand.as_ref().and_then(|c| recalibrated(c));
    let (fitted_runner, fitted_runs) = match &fitted_cand {
        Some(c) => model_runs(&recal_verdict, c),
        None => (runner.clone(), bars.iter().map(|_| None).collect()),
    };
    let (recal_runner, recal_runs) = model_runs(&recal_nominal, &nominal);
    step("held-out check");
    let held_out_points: Vec<f64> = points
        .iter()
        .filter(|p| !p.is_fit_point)
        .map(|p| p.supply_bar)
        .collect();
    let mut shrink_points = Vec::new();
    for (i, p) in points.iter().enumerate() {
        let s = summarize(&p.held);
        if s.cycles == 0 {
            continue;
        }
        let nom = &nominal_features[i];
        let fitted = match (&fitted_cand, &fitted_runs[i]) {
            (Some(c), Some(run)) => fitted_runner.features_of_truth(&run.truth, &c.effects),
            _ => None,
        };
        let recal = recal_runs[i]
            .as_ref()
            .and_then(|run| recal_runner.features_of_truth(&run.truth, &nominal.effects))
            .unwrap_or_else(|| nom.clone());
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
        shrink_points.push(PointShrink {
            supply_bar: p.supply_bar,
            held_out_point: !p.is_fit_point,
            cycles: s.cycles,
            impact_energy_measured_j: s.mean[ENERGY],
            impact_energy_nominal_j: nom[ENERGY],
            impact_energy_fitted_j: fitted[ENERGY],
            impact_energy_recalibrated_j: recal[ENERGY],
            frequency_measured_hz: 1.0 / s.mean[PERIOD],
            frequency_nominal_hz: 1.0 / nom[PERIOD],
            frequency_fitted_hz: 1.0 / fitted[PERIOD],
            rms_before: rms(nom),
            rms_after: rms(&fitted),
        });
    }
    let judged: Vec<&PointShrink> = if held_out_points.is_empty() {
        shrink_points.iter().collect()
    } else {
        shrink_points.iter().filter(|p| p.held_out_point).collect()
    };
    let mean_err = |f: &dyn Fn(&PointShrink) -> f64| {
        100.0 * judged.iter().map(|p| f(p).abs()).sum::<f64>() / judged.len().max(1) as f64
    };
    let shrink = Shrink {
        impact_energy_error_before: mean_err(&|p| {
            (p.impact_energy_nominal_j - p.impact_energy_measured_j) / p.impact_energy_measured_j
        }),
        impact_energy_error_after: mean_err(&|p| {
            (p.impact_energy_fitted_j - p.impact_energy_measured_j) / p.impact_energy_measured_j
        }),
        frequency_error_before: mean_err(&|p| {
            (p.frequency_nominal_hz - p.frequency_measured_hz) / p.frequency_measured_hz
        }),
        frequency_error_after: mean_err(&|p| {
            (p.frequency_fitted_hz - p.frequency_measured_hz) / p.frequency_measured_hz
        }),
        impact_energy_error_recalibrated_only: mean_err(&|p| {
            (p.impact_energy_recalibrated_j - p.impact_energy_measured_j) / p.impact_energy_measured_j
        }),
        held_out_points: held_out_points.clone(),
        judged_on: if held_out_points.is_empty() {
            "the later half of the cycles of every trace (one operating point: no held-out pressure)".into()
        } else {
            "every steady cycle at the held-out pressures".into()
        },
        points: shrink_points,
    };

    // Where: the gap by signal × stage at every point, nominal model; and
    // what is left of it after the verdict's model (recalibrated, with the
    // named effects): the unexplained remainder.
    let mut where_ = Vec::new();
    let mut remainder = Vec::new();
    let mut waves = Vec::new();
    for (i, p) in points.iter().enumerate() {
        let Some((tpl, stages)) = template(&nominal_runs_ok[i], &base.hammer) else {
            continue;
        };
        let mut meas = Vec::new();
        for &k in &p.inputs {
            meas.extend(measured_cycles(&inputs[k].trace, &steady_impacts[k]));
        }
        let nominal_cells = breakdown(&tpl, &stages, &meas);
        let after_run = if fitted_cand.is_some() {
            fitted_runs[i].as_ref()
        } else {
            recal_runs[i].as_ref()
        };
        if let Some((after, after_stages)) = after_run.and_then(|r| template(r, &base.hammer)) {
            for c in breakdown(&after, &after_stages, &meas) {
                let before = nominal_cells
                    .iter()
                    .find(|n| n.signal == c.signal && n.stage == c.stage)
                    .map_or(f64::NAN, |n| n.relative_rms);
                if c.relative_rms >= REMAINDER_MIN {
                    remainder.push(Remainder {
                        supply_bar: p.supply_bar,
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
                    });
                }
            }
        }
        for c in nominal_cells {
            where_.push(WhereCell {
                supply_bar: p.supply_bar,
                signal: c.signal,
                stage: c.stage,
                bias: c.bias,
                rms: c.rms,
                relative_rms: c.relative_rms,
                timing_shift_s: c.timing_shift_s,
            });
        }
        if opts.figures && !meas.is_empty() {
            let fitted = fitted_runs[i]
                .as_ref()
                .and_then(|r| template(r, &base.hammer))
                .map(|(mut f, _)| {
                    if let Some(c) = &fitted_cand {
                        let (f1, f2) = pressure_reading_factors(&c.effects);
                        if f1 != 1.0 || f2 != 1.0 {
                            f.p_rear_pa.iter_mut().for_each(|x| *x *= f1);
                            f.p_front_pa.iter_mut().for_each(|x| *x *= f2);
                        }
                    }
                    f
                });
            waves.push(PointWaves {
                supply_bar: p.supply_bar,
                t_s: (0..tpl.len()).map(|k| k as f64 * tpl.dt_s).collect(),
                stages: stages.clone(),
                measured: mean_cycle(&meas, tpl.len()),
                nominal: tpl,
                fitted,
            });
        }
    }
    where_.sort_by(|a, b| b.relative_rms.total_cmp(&a.relative_rms));
    remainder.sort_by(|a, b| b.relative_rms.total_cmp(&a.relative_rms));
    remainder.truncate(REMAINDER_CELLS);

    // The recalibration: the nominal parameters as the verdict's fit left them.
    let recalibration = match if fitted_cand.is_some() {
        &recal_verdict
    } else {
        &recal_nominal
    } {
        Some(rc) => {
            let mut nominal_cfg = base.clone();
            NUISANCE
                .iter()
                .zip(rc.delta.iter().zip(&rc.sd))
                .map(|((name, field), (&d, &sd))| {
                    let v0 = *field(&mut nominal_cfg);
                    Recalibration {
                        parameter: name.to_string(),
                        nominal: v0,
                        value: v0 * (1.0 + h * d),
                        sd: (v0 * h * sd).abs(),
                        prior_sds: d,
                        beyond_prior: d.abs() > 1.0,
                    }
                })
                .collect()
        }
        None => Vec::new(),
    };

    let verdict = match &verdict_cand {
        Some(v) => Verdict {
            effects: v.name.split('+').map(str::to_string).collect(),
            params: v.params.clone(),
            score: v.score,
            reason,
        },
        None => Verdict {
            effects: vec!["none".into()],
            params: serde_json::json!({}),
            score: effects.first().map_or(0.0, |e| e.score),
            reason,
        },
    };
    let simulations =
        fs.sims.load(Ordering::Relaxed) + fitted_runs.iter().flatten().count() + recal_runs.iter().flatten().count();
    Ok(Outcome {
        report: Report {
            tool: format!("hammer diagnose {}", env!("CARGO_PKG_VERSION")),
            inputs: infos,
            fit_points: fit_bars,
            where_,
            effects,
            pairs,
            verdict,
            recalibration,
            remainder,
            model_form,
            shrink,
            chi2_nominal,
            features_compared: n_compared,
            fit_cycles,
            options: opts.clone(),
            simulations,
            elapsed_s: started.elapsed().as_secs_f64(),
        },
        waves,
    })
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

/// Start values from what the measurement shows directly.
fn start_values(fs: &FitSet, name: &str) -> Vec<f64> {
    diagnosis(name).map_or_else(Vec::new, |d| d.start_values(fs))
}

/// Fits `names` together (one or two effects); `init` overrides start values.
fn fit_effects(
    fs: &FitSet,
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
    let build = |theta: &[f64]| {
        let mut c = Candidate::default();
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
    let k = specs.len() as f64;
    let score = chi2_nominal - fit.chi2 - k * ln_n;
    let explained = if chi2_nominal > 0.0 {
        ((chi2_nominal - fit.chi2) / chi2_nominal).max(0.0)
    } else {
        0.0
    };
    let mut params = serde_json::Map::new();
    for name in names {
        params.insert(name.to_string(), catalogue_params(&cand.effects, name));
    }
    let fitted = specs
        .iter()
        .zip(&owner)
        .zip(fit.theta.iter().zip(&fit.sd))
        .map(|((s, &o), (&v, &sd))| FittedParam {
            key: format!("{}.{}", names[o], s.key),
            value: v,
            sd,
        })
        .collect();
    let evidence = evidence(fs, names, &cand);
    Some(EffectResult {
        name: names.join("+"),
        params: if names.len() == 1 {
            params.remove(names[0]).unwrap_or_default()
        } else {
            serde_json::Value::Object(params)
        },
        fitted,
        chi2: fit.chi2,
        score,
        explained_fraction: explained,
        evidence,
        simulations: fs.sims.load(Ordering::Relaxed) - sims_before,
        candidate: cand,
    })
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
        .map(|t| bin_stages(t, &fs.runner.base.hammer, &fs.runner.extractor));
    for ((bar, s, sigma), truth) in fs.points.iter().zip(&fs.nominal_truth) {
        let (Some(m0), Some(m1)) = (
            fs.runner.features(*bar, &nominal, Some(truth)),
            fs.runner.features(*bar, cand, Some(truth)),
        ) else {
            continue;
        };
        for j in 0..N_FEATURES {
            let r0 = residual(m0[j], s.mean[j], sigma[j]);
            let r1 = residual(m1[j], s.mean[j], sigma[j]);
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
fn bin_stages(truth: &TruthTrace, hammer: &hammer_sim::params::HammerParams, extractor: &Extractor) -> Vec<Stage> {
    let edges = super::stages::Edges {
        front_outlet_m: hammer.front_outlet_opens_m,
        rear_outlet_m: hammer.rear_outlet_opens_m,
    };
    // The last cycle of the solution, its impacts found as the measurement's are.
    let signals = super::features::Signals {
        dt_s: truth.dt_s,
        p_rear_pa: &truth.p_rear_pa,
        p_front_pa: &truth.p_front_pa,
        accel_mps2: &truth.accel_mps2,
    };
    let imps: Vec<usize> = extractor
        .impacts(&signals)
        .iter()
        .map(|t| (t / truth.dt_s).ceil() as usize)
        .collect();
    let (i0, i1) = match imps.len() {
        n if n >= 2 => (imps[n - 2], imps[n - 1].min(truth.len())),
        _ => return vec![Stage::StrokeIntake; BINS],
    };
    let n = i1 - i0;
    (0..BINS)
        .map(|b| {
            let mut count: BTreeMap<Stage, usize> = BTreeMap::new();
            for k in (b * n / BINS)..((b + 1) * n / BINS) {
                let i = i0 + k;
                let st = super::stages::stage_of(
                    &edges,
                    truth.x_m[i],
                    truth.v_mps[i],
                    k as f64 * truth.dt_s,
                    super::gap::IMPACT_WINDOW_S,
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
