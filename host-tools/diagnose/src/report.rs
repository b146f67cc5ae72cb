//! The diagnosis report: what `report.json` holds, field for field. The
//! stages of the pipeline fill it; `output` renders it for people. Kept
//! apart from the computation so a reader of the JSON finds its schema in
//! one place, and a change of the schema shows in one file's diff.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use super::options::Options;
use super::stages::Stage;
use hammer_sim::effects::Effects;

/// A candidate model: physical effects for the simulator, sensor effects
/// applied to its ideal signals.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Candidate {
    pub effects: Effects,
}

impl Candidate {
    /// The effects the simulator must run; the sensor effects act on its output.
    pub fn physics(&self) -> Effects {
        self.effects.physics()
    }

    pub fn has_physics(&self) -> bool {
        self.physics() != Effects::default()
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
    /// How many standard errors the force balance's signature of the effect
    /// stands off the nominal model (see [`ModelFreeStat`]); `None` for an
    /// effect the force balance cannot see.
    #[serde(default)]
    pub model_free_z: Option<f64>,
    /// A measured change since the reference that the effect (a single)
    /// cannot make: it is not named (see `Diagnosed::contradicted`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub contradicted_by: Option<String>,
    pub simulations: usize,
    /// Where `fitted` holds sizes measured by the force balance (or the
    /// chamber characteristics) rather than fitted: the waveforms' own fit
    /// of those parameters, beside them (`docs/diagnosis.md`).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub waveform_fit: Vec<FittedParam>,
    #[serde(skip)]
    pub candidate: Candidate,
}

#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Verdict {
    /// The effects named outright, or `["none"]` (empty where the only
    /// finding is a group of `alternatives`).
    pub effects: Vec<String>,
    /// The parameters of `effects`.
    pub params: serde_json::Value,
    /// The named model's score (the best single effect's when `none`).
    pub score: f64,
    pub reason: String,
    /// Each close call as a group of effects, one of which is the cause
    /// (beside `effects`, for a pair's second): they score within
    /// [`Options::close_call_margin`] of each other and no model-free
    /// evidence parts them (docs/diagnosis.md). The first member is the
    /// ranking's choice.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub alternatives: Vec<Vec<Alternative>>,
    /// The check of an effect the waveforms alone named, with the nominal
    /// parameters refitted on the model itself (against the model alone;
    /// `pipeline::confirm`, docs/diagnosis.md).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub confirmation: Option<Confirmation>,
    /// Against a record: a close call of the change that the hammer's own
    /// waveforms, fitted by the model alone, part (`pipeline::part`). The
    /// member is named outright in `effects`, and the group is kept here.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub parted: Option<Parted>,
}

/// A close call against a record, parted by the model alone: both
/// diagnoses put the same member first, and the model alone's verdict
/// names it outright, with no close call of its own (docs/diagnosis.md).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Parted {
    /// The group the change since the record left, the named member first.
    pub group: Vec<String>,
    /// The model alone's score of each member (ΔBIC), in the group's order
    /// (`null` for one it did not fit).
    pub alone_scores: Vec<Option<f64>>,
    /// The model alone's verdict, as it named it.
    pub alone_effects: Vec<String>,
}

/// An effect named on the waveforms alone, checked with the nominal
/// parameters refitted on the model (Gauss–Newton, not the ranking's
/// profile linearised at nominal): without it and with it.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Confirmation {
    pub effect: String,
    /// χ² of the verdict's model without the effect and with it, each with
    /// its nominal parameters refitted (their prior's terms included).
    pub chi2_without: f64,
    pub chi2_with: f64,
    /// The model-form factors both are weighed with, re-measured on the
    /// model with the effect and its nominal values refitted (one per
    /// waveform, as `model_form`; empty without them).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub form_factors: Vec<f64>,
    /// What the effect adds in BIC units (its parameters' price paid), and
    /// its share of `chi2_without`.
    pub score: f64,
    pub explained_fraction: f64,
    /// Whether it held (the ranking's rule: `score` above `min_score` and
    /// the share at least the ranking's); if not, it was dropped from the verdict.
    pub kept: bool,
    /// The nominal values that moved most, without the effect, beyond half
    /// their prior's width: what stands in for the effect if it is dropped.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub nominal_moves: Vec<NominalMove>,
}

/// A nominal value refitted: its name in the model and its change, relative.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct NominalMove {
    pub parameter: String,
    pub relative_change: f64,
}

/// One member of a close call: its size, its score and its own held-out
/// check (the same check as the verdict's, with this member in the model).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Alternative {
    pub effect: String,
    /// In the catalogue's terms.
    pub params: serde_json::Value,
    pub score: f64,
    /// Held-out errors with this member in the model, % ([`Shrink`]).
    pub impact_energy_error_after: f64,
    pub frequency_error_after: f64,
    /// What, outside the waveforms, would tell it from the others.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub parting_test: Option<String>,
}

/// The force balance at one operating point (`force_balance` in report.json):
/// each quantity it measures as the change since the nominal model, or
/// with a record since the record, with its standard uncertainty `u` (the
/// cycles' scatter over their number, and the record's) and the expanded
/// `U = 2u` (docs/diagnosis.md).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ForceBalancePoint {
    pub supply_bar: f64,
    pub fit_point: bool,
    pub against_record: bool,
    pub cycles: usize,
    pub quantities: Vec<ForceBalanceQuantity>,
}

#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ForceBalanceQuantity {
    /// `effect.quantity`, e.g. the friction force in N.
    pub key: String,
    pub value: f64,
    pub u: f64,
    pub expanded_u: f64,
}

#[derive(Debug, Clone, Serialize, Deserialize)]
/// One point's check, in both modes on the hammer's own measurements (not
/// the change read against a record, `engine::own_fit_set`): its measured
/// energy and frequency, and each model's prediction of them.
pub struct PointShrink {
    pub supply_bar: f64,
    pub held_out_point: bool,
    pub cycles: usize,
    pub impact_energy_measured_j: f64,
    pub impact_energy_nominal_j: f64,
    pub impact_energy_fitted_j: f64,
    /// The nominal model with its uncertain parameters refitted, no effect.
    pub impact_energy_recalibrated_j: f64,
    /// The named effects in the nominal model, nothing refitted (nominal
    /// when no effect was named).
    #[serde(default)]
    pub impact_energy_effects_only_j: f64,
    pub frequency_measured_hz: f64,
    pub frequency_nominal_hz: f64,
    pub frequency_fitted_hz: f64,
    /// RMS of the binned waveform residual per signal, nominal and fitted model.
    pub rms_before: BTreeMap<String, f64>,
    pub rms_after: BTreeMap<String, f64>,
}

#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Shrink {
    /// Mean |predicted − measured| / measured over the held-out data, %,
    /// of the hammer's measured energy in both modes ([`PointShrink`]).
    pub impact_energy_error_before: f64,
    pub impact_energy_error_after: f64,
    pub frequency_error_before: f64,
    pub frequency_error_after: f64,
    /// The control: nominal parameters refitted within their prior, no effect added.
    pub impact_energy_error_recalibrated_only: f64,
    /// The other side: the named effects in the nominal model, nothing
    /// refitted (the paper's own check; nominal when no effect was named).
    #[serde(default)]
    pub impact_energy_error_effects_only: f64,
    /// Supply pressures (bar) not used for fitting.
    pub held_out_points: Vec<f64>,
    /// What the figures above were computed on.
    pub judged_on: String,
    pub points: Vec<PointShrink>,
    /// The verdict's waveform-only sizes as the check refitted them with
    /// the nominal values on the fit points (empty where they were held).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub refitted: Vec<FittedParam>,
}

/// How much worse (percentage points) the verdict's model may predict the
/// held-out data than the nominal model before the report says so: above the
/// impact energy's own floor (0.3 %) and the cycle-to-cycle scatter of a
/// second's mean.
const WORSE_BY_PCT: f64 = 0.5;

impl Shrink {
    /// A warning when the verdict's model predicts the held-out data worse
    /// than the nominal model. On a hammer of another form the recalibration
    /// bends the nominal parameters to the fit points' form error (they end
    /// at the prior's edge), and that need not carry to another pressure:
    /// the user must not take the refitted model for a better predictor
    /// there. It says nothing against a named effect's own evidence.
    pub fn caution(&self) -> Option<String> {
        let mut worse = Vec::new();
        if self.impact_energy_error_after > self.impact_energy_error_before + WORSE_BY_PCT {
            worse.push(format!(
                "impact energy error {:.1} % → {:.1} %",
                self.impact_energy_error_before, self.impact_energy_error_after
            ));
        }
        if self.frequency_error_after > self.frequency_error_before + WORSE_BY_PCT {
            worse.push(format!(
                "frequency error {:.1} % → {:.1} %",
                self.frequency_error_before, self.frequency_error_after
            ));
        }
        (!worse.is_empty()).then(|| {
            format!(
                "the refitted model predicts the held-out data worse than the nominal model ({}): its \
                 recalibrated nominal parameters absorb form error at the fit points that does not carry \
                 there; do not use it to predict other operating points (a named effect's evidence stands \
                 apart from this)",
                worse.join(", ")
            )
        })
    }
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

/// The oracle's check (benchmarks only, `pipeline::oracle`): the hammer's
/// truth in the diagnosis' own model, its nominal values settled from the
/// true ones, against the nominal values refitted without any effect,
/// weighed and judged as the confirm stage weighs and judges.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct OracleCheck {
    pub effect: String,
    pub chi2_without: f64,
    pub chi2_truth: f64,
    /// What the true effect adds in BIC units, its parameters' price paid,
    /// and its share of `chi2_without`.
    pub score: f64,
    pub explained_fraction: f64,
    /// The truth passes the rule that names an effect: a diagnosis that
    /// leaves it `none` missed what the features hold.
    pub passes: bool,
}

/// One quantity of the measurement's force balance over the fit points
/// against the nominal model's: it needs no valve, port or chamber model,
/// so a structural difference of the model cannot fake it, and an effect
/// that shows here is pinned by it.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ModelFreeStat {
    pub feature: String,
    /// Mean over the fit points: the measurement's and the nominal model's.
    pub measured: f64,
    pub nominal: f64,
    /// Standard error of the difference (noise and floor).
    pub se: f64,
    /// (measured − nominal) / se.
    pub z: f64,
    /// The nominal model with its uncertain parameters refitted, no effect
    /// (the chamber characteristics only): what of the difference the
    /// recalibration closes, and so what the model's form leaves.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub recalibrated: Option<f64>,
    /// The reference record's own mean over the fit points (the chamber
    /// characteristics, against a reference only): `measured` is then the
    /// nominal model's value plus the change, and the hammer's own value
    /// now is this plus the change.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reference: Option<f64>,
    /// Whether any fit point read it (a chamber characteristic is not read
    /// where, say, no feed onset stood out): unread, `measured` is the
    /// nominal model's and `z` 0, which is no evidence either way.
    #[serde(default = "read_by_default")]
    pub read: bool,
}

fn read_by_default() -> bool {
    true
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

/// The weakest magnitude of an effect that the ranking would have named on
/// this data (`pipeline::floor`): below it, the verdict cannot exclude the
/// effect.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct DetectionFloor {
    pub effect: String,
    /// The catalogue parameter the floor is on (the effect's one free parameter).
    pub parameter: String,
    /// `None` when no value in the catalogue's range would be named.
    pub value: Option<f64>,
    /// A larger value is a stronger effect (a gap, a delay); false for an orifice.
    pub stronger_above: bool,
    /// The signature χ² the naming rule asks of it here (the force balance's
    /// effects: `min_model_free_z`², their rule being in standard errors).
    pub chi2_needed: f64,
    /// Found from the force balance's standard errors, not the waveforms.
    #[serde(default)]
    pub model_free: bool,
    /// The model cannot carry the effect (a user's model whose map gives
    /// it no parameter): it was not ranked, and no floor is known.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub not_modelled: bool,
    pub statement: String,
}

/// A chamber's dead volume as the hammer's records were read through it
/// (`features::Extractor::calibrated`): against a reference, the one its
/// closed phases ask for.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct DeadVolume {
    /// `rear` or `front`.
    pub chamber: String,
    /// The configuration's (a drawing's estimate).
    pub nominal_m3: f64,
    /// The one the records were read through.
    pub used_m3: f64,
}

#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Report {
    pub tool: String,
    /// The model fitted when it is not the built-in simulator: a user's
    /// FMU's name, GUID, FMI version, generation tool and the map's hash.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub model: Option<serde_json::Value>,
    pub inputs: Vec<InputInfo>,
    /// Records of the same hammer the inputs were read against, as changes
    /// from them (empty: against the model alone).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub references: Vec<InputInfo>,
    /// The chambers' dead volumes the measurement and the references were
    /// read through (empty: the configuration's, against the model alone).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub dead_volumes: Vec<DeadVolume>,
    pub fit_points: Vec<f64>,
    #[serde(rename = "where")]
    pub where_: Vec<WhereCell>,
    pub effects: Vec<EffectResult>,
    pub pairs: Vec<EffectResult>,
    pub verdict: Verdict,
    /// The nominal parameters as the verdict's fit left them.
    pub recalibration: Vec<Recalibration>,
    /// Nuisance parameters held at nominal and not fitted: no fitted
    /// feature moved when they did, at any fit point (a map's parameter
    /// that does not act in this configuration of the model).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub held_nuisance: Vec<String>,
    /// A benchmark's check of its hammer's truth (never in a diagnosis of
    /// a measurement).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub oracle: Option<OracleCheck>,
    /// The unexplained remainder, largest first.
    pub remainder: Vec<Remainder>,
    pub model_form: Vec<ModelForm>,
    /// The force balance's model-free quantities, measured against nominal.
    #[serde(default)]
    pub model_free: Vec<ModelFreeStat>,
    /// The force balance at every operating point ([`ForceBalancePoint`]).
    #[serde(default)]
    pub force_balance: Vec<ForceBalancePoint>,
    /// The chamber characteristics (valve switching, fills, closed phases),
    /// measured against nominal; with references, their change since them.
    #[serde(default)]
    pub chambers: Vec<ModelFreeStat>,
    /// How large each effect would have to be to be named here (for an
    /// effect the verdict names: a further one, against what it leaves).
    #[serde(default)]
    pub detection_floors: Vec<DetectionFloor>,
    pub shrink: Shrink,
    pub chi2_nominal: f64,
    pub features_compared: usize,
    pub fit_cycles: usize,
    pub options: Options,
    pub simulations: usize,
    pub elapsed_s: f64,
}
