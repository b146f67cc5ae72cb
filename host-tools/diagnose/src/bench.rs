//! The blind benchmark: measurements with a hidden effect (or none, or two)
//! at a random magnitude, made by a generator that is *not* the diagnosis'
//! model — nominal parameters jittered, a finer solver tolerance, a random
//! sensor bandwidth, noise and quantisation — then diagnosed without a hint.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use super::effects::diagnosis;
use super::engine::{diagnose_with, MeasuredInput, Options};
use super::model::{Builtin, Plant};
use hammer_sim::effects::{EffectSlot, Effects, ValveDelay, EFFECT_NAMES};
use hammer_sim::sensor::Rng;
use hammer_sim::simulate::simulate;
use hammer_sim::SimConfig;
use hammer_trace::trace::Trace;
use hammer_variants::{generate, Structure, VariantParams};
use physical::PointTruth;
use std::sync::Arc;

mod ceiling;
mod outcome;
mod physical;
mod summary;
pub use ceiling::{model_alone_ceiling, FormSpan, ModelAloneCeiling};
pub use outcome::{Named, Outcome};
pub use physical::{PhysicalSize, TrueSizes};
pub use summary::{above_floor, render, summarize, BenchSummary};

#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct BenchOptions {
    pub cases: usize,
    pub seed: u64,
    /// Operating points of every case, bar; the first and last are fitted.
    pub points: Vec<f64>,
    pub duration_s: f64,
    /// Relative half-width of the uniform jitter of the nominal parameters.
    pub jitter: f64,
    /// Measurements from the second model family (`hammer-variants`): one or
    /// two structural variants per case, its parameters jittered by `jitter`.
    #[serde(default)]
    pub structural: bool,
    /// Each case also records its hammer with no effect hidden (same
    /// structure and parameters, its own noise) at every point, and the
    /// diagnosis reads the case as a change from it
    /// ([`super::engine::diagnose_against`]).
    #[serde(default)]
    pub reference: bool,
    /// With `reference`: each case diagnosed against the model alone too,
    /// beside it (`CaseResult::alone`). The CLI's benchmark does; a test of
    /// one case need not pay for it.
    #[serde(default)]
    pub alone_beside: bool,
    /// The model diagnosed with, when not the built-in one: the FMU's
    /// identity (`report.json`'s `model`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub model: Option<serde_json::Value>,
    /// Each single's hammer of the diagnosis' own form also checked by the
    /// oracle ([`super::pipeline::oracle`]): would its truth pass the rule?
    /// Two recalibrations more a case.
    #[serde(default)]
    pub oracle: bool,
}

impl Default for BenchOptions {
    fn default() -> Self {
        Self {
            cases: 24,
            seed: 1,
            points: vec![4.0, 5.5, 7.0],
            duration_s: 1.0,
            jitter: 0.03,
            structural: false,
            reference: false,
            alone_beside: false,
            model: None,
            oracle: false,
        }
    }
}

impl BenchOptions {
    /// The generator's default jitter: ±10 % on the second family (its
    /// form differs from the model's anyway), ±3 % on the model's own.
    pub fn default_jitter(structural: bool) -> f64 {
        if structural {
            0.1
        } else {
            0.03
        }
    }

    /// The benchmark of `seed` as `hammer diagnose-bench` runs it by
    /// default, for one case at a time (examples, tests).
    pub fn of(seed: u64, structural: bool, reference: bool) -> Self {
        Self {
            seed,
            structural,
            reference,
            jitter: Self::default_jitter(structural),
            ..Self::default()
        }
    }
}

/// What a case hides.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub enum Hidden {
    None,
    One(String),
    Two(String, String),
}

impl Hidden {
    pub fn names(&self) -> Vec<String> {
        match self {
            Hidden::None => vec![],
            Hidden::One(a) => vec![a.clone()],
            Hidden::Two(a, b) => vec![a.clone(), b.clone()],
        }
    }

    pub fn label(&self) -> String {
        match self {
            Hidden::None => "none".into(),
            Hidden::One(a) => a.clone(),
            Hidden::Two(..) => "pair".into(),
        }
    }
}

/// The case plan: every single effect of the catalogue, two controls and two
/// pairs in every `EFFECT_NAMES.len() + 4` cases (twelve for the eight
/// effects), so a short run still covers the catalogue.
pub fn hidden_for(index: usize, rng: &mut Rng) -> Hidden {
    let n = EFFECT_NAMES.len();
    let period = n + 4;
    match index % period {
        k if k < n => Hidden::One(EFFECT_NAMES[(k + index / period) % n].to_string()),
        k if k < n + 2 => Hidden::None,
        _ => {
            let a = (rng.next_u64() % n as u64) as usize;
            let b = (a + 1 + (rng.next_u64() % (n as u64 - 1)) as usize) % n;
            let (a, b) = (a.min(b), a.max(b));
            Hidden::Two(EFFECT_NAMES[a].to_string(), EFFECT_NAMES[b].to_string())
        }
    }
}

/// A random magnitude over the range a bench would meet (see [`super::effects`]).
pub fn draw_effect(effects: &mut Effects, name: &str, rng: &mut Rng) {
    if let Some(d) = diagnosis(name) {
        d.draw(effects, rng);
    }
}

/// The generator's hammer: the nominal one with its uncertain parameters
/// (valve, ports, dead volumes, contact) jittered, a finer solver tolerance
/// and a random sensor bandwidth. Mass and areas stay: the estimator and the
/// force balance rely on them, and they are measured to better than 0.1 %.
pub fn generator_config(base: &SimConfig, jitter: f64, rng: &mut Rng) -> SimConfig {
    let mut c = base.clone();
    for (_, field) in super::model::NUISANCE {
        *field(&mut c) *= 1.0 + jitter * (2.0 * rng.uniform() - 1.0);
    }
    c.solver.rtol = 1e-8;
    let bw = 10e3 + 30e3 * rng.uniform();
    for ch in [&mut c.sensors.rear, &mut c.sensors.front, &mut c.sensors.accel] {
        ch.bandwidth_hz = bw;
    }
    c
}

/// The second family's hammer for a case: one or two of its structural
/// variants (never none: the base variant still differs from the model in
/// its flow law and spool) and its uncertain parameters jittered. Mass and
/// geometry stay, as in [`generator_config`].
pub fn structural_generator(jitter: f64, rng: &mut Rng) -> (Structure, VariantParams) {
    let singles = Structure::singles();
    let first = (rng.next_u64() % singles.len() as u64) as usize;
    let mut structure = singles[first];
    if rng.next_u64() % 2 == 0 {
        let second = (first + 1 + (rng.next_u64() % (singles.len() as u64 - 1)) as usize) % singles.len();
        structure = structure.with(&singles[second]);
    }
    let mut p = VariantParams::default();
    for field in p.uncertain_mut() {
        *field *= 1.0 + jitter * (2.0 * rng.uniform() - 1.0);
    }
    (structure, p)
}

/// One effect's standing in a case's ranking.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Ranked {
    pub name: String,
    pub score: f64,
    pub explained_fraction: f64,
    pub model_free_z: Option<f64>,
    /// A measured change rules it out.
    #[serde(default)]
    pub contradicted: bool,
}

impl Ranked {
    fn of(e: &super::report::EffectResult) -> Self {
        Self {
            name: e.name.clone(),
            score: e.score,
            explained_fraction: e.explained_fraction,
            model_free_z: e.model_free_z,
            contradicted: e.contradicted_by.is_some(),
        }
    }
}

#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct CaseResult {
    pub index: usize,
    /// The generator's structural variants (structural benchmark only).
    #[serde(default)]
    pub variants: Vec<String>,
    pub hidden: Hidden,
    pub hidden_params: serde_json::Value,
    /// What the verdict named, raw: outright, and each close call's first
    /// member (the ranking's choice). The confusion matrix counts it.
    pub named: Vec<String>,
    /// The verdict's close calls, each a group of effect names.
    #[serde(default)]
    pub alternatives: Vec<Vec<String>>,
    /// Exact, a group holding the truth, none, or wrong ([`Outcome`]).
    #[serde(default)]
    pub outcome: Outcome,
    /// The raw naming is what was hidden.
    pub correct: bool,
    /// Relative error of each named-right effect's magnitude.
    pub param_errors: BTreeMap<String, f64>,
    /// A hidden valve delay's size in physical terms: how much later the
    /// front port opened after the impact than without it (the mean over
    /// the points). Beside τ it says what any reading of the port, the
    /// delay's model-free evidence, can give of τ on this hammer's law.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub true_port_delay_s: Option<f64>,
    /// A hidden heat exchange's and leakage's sizes in physical terms (the
    /// heat across the walls and the air leaked a cycle, the mean over the
    /// points).
    #[serde(default)]
    pub true_sizes: TrueSizes,
    pub score: f64,
    pub energy_error_before: f64,
    pub energy_error_after: f64,
    /// The named effects in the nominal model, nothing recalibrated.
    #[serde(default)]
    pub energy_error_effects_only: f64,
    pub frequency_error_before: f64,
    pub frequency_error_after: f64,
    /// The report warned that its refitted model predicts the held-out
    /// data worse than nominal ([`super::report::Shrink::caution`]).
    #[serde(default)]
    pub cautioned: bool,
    pub diagnose_s: f64,
    /// Every single effect as the ranking left it, best first: what a
    /// threshold was weighed against.
    #[serde(default)]
    pub ranking: Vec<Ranked>,
    /// The pairs with the best single, when they were tried, best first
    /// (`explained_fraction` of the nominal gap, as for the singles).
    #[serde(default)]
    pub pairs: Vec<Ranked>,
    /// The force balance against nominal, and the model-form factors.
    #[serde(default)]
    pub model_free: Vec<super::report::ModelFreeStat>,
    /// The chamber characteristics against nominal (or the reference).
    #[serde(default)]
    pub chambers: Vec<super::report::ModelFreeStat>,
    #[serde(default)]
    pub model_form: Vec<super::report::ModelForm>,
    /// How large each unseen effect would have had to be to be named.
    #[serde(default)]
    pub detection_floors: Vec<super::report::DetectionFloor>,
    /// The front dead volume the reference's closed phases gave, relative
    /// to the generator's (structural benchmark with references only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub front_dead_volume_error: Option<f64>,
    /// A named valve delay's size in physical terms against the truth's:
    /// the diagnosis model's front port shift at the named τ (the mean over
    /// the points) relative to the hammer's true shift, |error|.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub port_shift_error: Option<f64>,
    /// A named (or grouped) heat exchange's and leakage's sizes in
    /// physical terms, the verdict's model against the truth
    /// ([`physical`]).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub physical_sizes: Vec<PhysicalSize>,
    /// With a hidden friction named: whether the verdict's friction law
    /// lies within U of the force balance's reading at every operating
    /// point, the held-out one included.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub friction_within_u: Option<bool>,
    /// The confirm stage's check of an effect the waveforms alone named
    /// (against the model alone), kept or dropped.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub confirmation: Option<super::report::Confirmation>,
    /// With `oracle`: whether the hammer's truth passes the rule.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub oracle: Option<super::report::OracleCheck>,
    /// With references: the same case diagnosed against the model alone,
    /// side by side (a record must add evidence, never subtract it).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub alone: Option<Alone>,
    #[serde(skip)]
    pub report: Option<super::engine::Report>,
}

/// A case's diagnosis against the model alone, beside the one against its
/// record.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Alone {
    pub named: Vec<String>,
    pub alternatives: Vec<Vec<String>>,
    pub outcome: Outcome,
    pub param_errors: BTreeMap<String, f64>,
    pub energy_error_after: f64,
    pub diagnose_s: f64,
    /// Every single effect as its ranking left it, best first.
    #[serde(default)]
    pub ranking: Vec<Ranked>,
}

/// A report judged against what was hidden: the naming, its outcome,
/// whether the raw naming is right, and each right-named effect's size error.
struct Judged {
    named: Named,
    outcome: Outcome,
    correct: bool,
    param_errors: BTreeMap<String, f64>,
}

fn judge(r: &super::engine::Report, hidden: &Hidden, truth: &Effects, points: &[f64]) -> Judged {
    let named = Named::of(r);
    let mut want = hidden.names();
    want.sort();
    let mut got = named.raw.clone();
    got.sort();
    let correct = want == got;
    let mut param_errors = BTreeMap::new();
    for name in want.iter().filter(|n| named.params.contains_key(*n)) {
        if let Some(e) = magnitude_error(truth, name, &named.params[name], points) {
            param_errors.insert(name.clone(), e);
        }
    }
    Judged {
        outcome: named.outcome(&hidden.names()),
        named,
        correct,
        param_errors,
    }
}

/// Whether the verdict's friction law lies within U of the force balance's
/// friction at every point; `None` without a friction named.
fn friction_within_u(r: &super::engine::Report, params: Option<&serde_json::Value>) -> Option<bool> {
    let p = params?;
    let (f0, k) = (p.get("f0_n")?.as_f64()?, p.get("k_n_per_bar")?.as_f64()?);
    let rows: Vec<bool> = r
        .force_balance
        .iter()
        .filter_map(|row| {
            let q = row.quantities.iter().find(|q| q.key.ends_with(".friction_n"))?;
            Some((f0 + k * row.supply_bar - q.value).abs() <= q.expanded_u)
        })
        .collect();
    (!rows.is_empty()).then(|| rows.iter().all(|x| *x))
}

/// A case as the plan draws it: what is hidden, the generator, and each
/// point's measured trace (and, with references, the same hammer's record
/// without the effect).
pub struct DrawnCase {
    pub hidden: Hidden,
    pub gen: SimConfig,
    /// The second family's structure and parameters (structural benchmark).
    pub structural: Option<(Structure, VariantParams)>,
    pub inputs: Vec<MeasuredInput>,
    pub references: Vec<MeasuredInput>,
    /// With a hidden valve delay: how much later the front port opened after
    /// the impact than in the same hammer without it, the mean over the
    /// points (the truth of the delay's size in physical terms).
    pub true_port_delay_s: Option<f64>,
    /// The hidden heat exchange's and leakage's sizes in physical terms.
    pub true_sizes: TrueSizes,
}

/// Draws case `index` of the plan and records its traces.
pub fn draw_case(opts: &BenchOptions, index: usize) -> anyhow::Result<DrawnCase> {
    let mut rng = Rng::new(opts.seed.wrapping_mul(0x9E37_79B9).wrapping_add(index as u64));
    let hidden = hidden_for(index, &mut rng);
    let mut gen = generator_config(&SimConfig::default(), opts.jitter, &mut rng);
    for name in hidden.names() {
        draw_effect(&mut gen.effects, &name, &mut rng);
    }
    gen.solver.duration_s = opts.duration_s;
    let structural = opts.structural.then(|| structural_generator(opts.jitter, &mut rng));
    let mut inputs = Vec::new();
    let mut references = Vec::new();
    let last = opts.points.len().saturating_sub(1);
    // A trace, and its truth in physical terms (the front port's opening
    // after the impact, the heat and the leak a cycle).
    let record = |effects: &Effects, bar: f64, seed: u64| -> anyhow::Result<(Trace, PointTruth)> {
        Ok(match &structural {
            Some((structure, params)) => {
                let g = generate(params, *structure, effects, bar, opts.duration_s, seed);
                let truth = PointTruth::of_variant(&g);
                (g.trace, truth)
            }
            None => {
                let mut c = gen.clone();
                c.effects = effects.clone();
                c.supply.pressure_bar = bar;
                c.seed = seed;
                let sim = simulate(&c)?;
                let truth = PointTruth::of_model(&sim.run, &c);
                (sim.trace(), truth)
            }
        })
    };
    let mut point_truths = Vec::new();
    let delayed = hidden.names().iter().any(|n| n == ValveDelay::NAME);
    let mut port_delays = Vec::new();
    for (k, &bar) in opts.points.iter().enumerate() {
        let seed = rng.next_u64();
        let (trace, truth) = record(&gen.effects, bar, seed)?;
        let opening = truth.port_opening_s;
        point_truths.push(truth);
        inputs.push(MeasuredInput {
            label: format!("case {index} at {bar} bar"),
            supply_bar: bar,
            trace,
            fit: k == 0 || k == last,
        });
        let mut sound_opening = None;
        if opts.reference {
            // Its own noise, without drawing from the case's generator:
            // the cases stay those of the benchmark without references.
            let (trace, truth) = record(&Effects::default(), bar, seed ^ 0x5EED_5EED_5EED_5EED)?;
            sound_opening = truth.port_opening_s;
            references.push(MeasuredInput {
                label: format!("case {index} reference at {bar} bar"),
                supply_bar: bar,
                trace,
                fit: false,
            });
        }
        if delayed {
            // The truth of a delay's size: the same hammer without it (a
            // pair's other effect kept), which a single's reference is.
            let mut without = gen.effects.clone();
            without.valve_delay = None;
            if !(opts.reference && without.active().is_empty()) {
                sound_opening = record(&without, bar, seed)?.1.port_opening_s;
            }
            port_delays.push(opening.zip(sound_opening).map(|(d, s)| d - s));
        }
    }
    let true_port_delay_s = port_delays
        .iter()
        .copied()
        .collect::<Option<Vec<f64>>>()
        .filter(|v| !v.is_empty())
        .map(|v| v.iter().sum::<f64>() / v.len() as f64);
    let true_sizes = TrueSizes::of(&point_truths, &hidden.names());
    Ok(DrawnCase {
        hidden,
        gen,
        structural,
        inputs,
        references,
        true_port_delay_s,
        true_sizes,
    })
}

/// Runs case `index` of the plan against the built-in model.
pub fn run_case(opts: &BenchOptions, index: usize, diag: &Options) -> anyhow::Result<CaseResult> {
    run_case_with(opts, index, diag, None)
}

/// The model a case is diagnosed with, given the case's drawn structure
/// (None: a hammer of the diagnosis' own family).
pub type PlantFor<'a> = &'a (dyn Fn(Option<&Structure>) -> Arc<dyn Plant> + Sync);

/// Runs case `index` of the plan against the model `plant` gives for its
/// structure (None: the built-in model of the default config).
pub fn run_case_with(
    opts: &BenchOptions,
    index: usize,
    diag: &Options,
    plant: Option<PlantFor>,
) -> anyhow::Result<CaseResult> {
    let DrawnCase {
        hidden,
        gen,
        structural,
        inputs,
        references,
        true_port_delay_s,
        true_sizes,
    } = draw_case(opts, index)?;
    let base = SimConfig::default();
    let builtin = plant.is_none();
    let plant = match plant {
        Some(f) => f(structural.as_ref().map(|(s, _)| s)),
        None => Arc::new(Builtin::new(base.clone())),
    };
    // The oracle knows the truth only where it is the model's own form.
    let oracle_for = (opts.oracle && structural.is_none() && builtin).then(|| super::options::Oracle {
        effects: gen.effects.clone(),
        nuisance: super::model::NUISANCE
            .iter()
            .map(|(_, f)| *f(&mut gen.clone()))
            .collect(),
    });
    let with_oracle;
    let diag = match oracle_for {
        Some(o) => {
            with_oracle = Options {
                oracle: Some(o),
                ..diag.clone()
            };
            &with_oracle
        }
        None => diag,
    };
    let t = std::time::Instant::now();
    let out = diagnose_with(&inputs, &references, &base, plant.clone(), diag, &|_, _, _| {})?;
    let diagnose_s = t.elapsed().as_secs_f64();
    let r = &out.report;
    let j = judge(r, &hidden, &gen.effects, &opts.points);
    let friction = hammer_sim::effects::CoulombFriction::NAME;
    let friction_within_u =
        friction_within_u(r, j.named.params.get(friction)).filter(|_| hidden.names().iter().any(|n| n == friction));
    // Physical sizes are read off the verdict's built-in model.
    let verdict_model = physical::verdict_config(&base, r);
    let port_shift_error = true_port_delay_s.filter(|_| builtin).and_then(|truth| {
        let named = physical::named_params(r, ValveDelay::NAME)?;
        let tau = named.get("tau_s")?.as_f64()?;
        Some((physical::model_port_shift_s(&verdict_model, tau, &opts.points)? - truth).abs() / truth)
    });
    let physical_sizes = if builtin {
        physical::heat_and_leak(&verdict_model, r, &true_sizes, &opts.points)
    } else {
        Vec::new()
    };
    let alone = if references.is_empty() || !opts.alone_beside {
        None
    } else {
        let t = std::time::Instant::now();
        let out = diagnose_with(&inputs, &[], &base, plant.clone(), diag, &|_, _, _| {})?;
        let diagnose_s = t.elapsed().as_secs_f64();
        let a = judge(&out.report, &hidden, &gen.effects, &opts.points);
        Some(Alone {
            named: a.named.raw,
            alternatives: a.named.groups,
            outcome: a.outcome,
            param_errors: a.param_errors,
            energy_error_after: out.report.shrink.impact_energy_error_after,
            diagnose_s,
            ranking: out.report.effects.iter().map(Ranked::of).collect(),
        })
    };
    let s = &r.shrink;
    let front_dead_volume_error = match (&structural, r.dead_volumes.iter().find(|d| d.chamber == "front")) {
        (Some((_, p)), Some(d)) => Some(d.used_m3 / p.front_dead_m3 - 1.0),
        _ => None,
    };
    Ok(CaseResult {
        index,
        variants: structural.map_or_else(Vec::new, |(st, _)| {
            st.variants().into_iter().map(String::from).collect()
        }),
        hidden_params: serde_json::to_value(&gen.effects).unwrap_or_default(),
        hidden,
        named: j.named.raw,
        alternatives: j.named.groups,
        outcome: j.outcome,
        correct: j.correct,
        param_errors: j.param_errors,
        true_port_delay_s,
        true_sizes,
        score: r.verdict.score,
        energy_error_before: s.impact_energy_error_before,
        energy_error_after: s.impact_energy_error_after,
        energy_error_effects_only: s.impact_energy_error_effects_only,
        frequency_error_before: s.frequency_error_before,
        frequency_error_after: s.frequency_error_after,
        cautioned: s.caution().is_some(),
        diagnose_s,
        ranking: r.effects.iter().map(Ranked::of).collect(),
        pairs: r.pairs.iter().map(Ranked::of).collect(),
        model_free: r.model_free.clone(),
        chambers: r.chambers.clone(),
        model_form: r.model_form.clone(),
        detection_floors: r.detection_floors.clone(),
        front_dead_volume_error,
        friction_within_u,
        confirmation: r.verdict.confirmation.clone(),
        oracle: r.oracle.clone(),
        port_shift_error,
        physical_sizes,
        alone,
        report: Some(out.report),
    })
}

/// Relative error of the fitted magnitude: friction force over the points,
/// the one parameter otherwise, the worse of the two gains (see [`super::effects`]).
fn magnitude_error(truth: &Effects, name: &str, fitted: &serde_json::Value, points: &[f64]) -> Option<f64> {
    diagnosis(name)?.magnitude_error(truth, fitted, points)
}
