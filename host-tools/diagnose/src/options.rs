//! The diagnosis' tunables: the model floors and the decision thresholds.
//! Apart from the engine because every stage reads them and `report.json`
//! records them, so they sit below both.

use serde::{Deserialize, Serialize};

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
    /// The front chamber's floor (`front_floor_pa`), Pa.
    #[serde(default = "default_front_floor_pa")]
    pub front_floor_pa: f64,
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

fn default_front_floor_pa() -> f64 {
    Floors::default().front_floor_pa
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
            // Two records of a sound hammer agree within their cycles' own
            // noise (the structural benchmark's controls: within 2 standard
            // errors); this keeps a change of 0.3 mbar from counting for
            // more than 3 however many cycles were read.
            front_floor_pa: 100.0,
        }
    }
}

#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Options {
    pub floors: Floors,
    /// Relative standard deviation of the nominal parameters the model is
    /// unsure of ([`crate::model::NUISANCE`]); 0 trusts them exactly.
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
    /// [`Options::min_explained`] against a reference record. There the
    /// form error has cancelled and nothing scores on a sound hammer (no
    /// unseen effect scored above `min_score` in any no-effect control of
    /// the structural and same-structure benchmarks against the record),
    /// but a change is read through the model's law for it, and on a
    /// hammer of another form that law explains only part of it: the
    /// second family's missed leaks 4–24 % of theirs. Set on the structural
    /// benchmark's calibration seed (docs/diagnosis.md).
    #[serde(default = "default_min_explained_reference")]
    pub min_explained_reference: f64,
    /// A pair's second effect, unseen by the force balance, must explain
    /// this fraction of what the first leaves: after the first effect the
    /// rest is mostly noise and form error, whose shape any effect fits a little.
    #[serde(default = "default_min_explained_pair")]
    pub min_explained_pair: f64,
    /// Two effects are one finding ("one of these two") when the
    /// runner-up scores within this fraction of the named one's score and
    /// no model-free evidence parts them (`rank::close_call`). Relative,
    /// because a score grows with the evidence: against a record scores
    /// run to thousands, and a margin in BIC units meant nothing there
    /// (leakage against heat exchange at 741 and 746). Set on seed 1 of
    /// the structural benchmarks, not on the seeds they are judged on
    /// (docs/diagnosis.md).
    #[serde(default = "default_close_call_margin")]
    pub close_call_margin: f64,
    /// A significant effect with a model-free signature is named before a
    /// better-scoring one without, if its score is within this fraction of
    /// that one's: that close, the waveforms' scores part them no better
    /// than the form error does (heat exchange and a leak fitted to a
    /// hammer of another form score within 0.4–15 % of each other on the
    /// structural benchmark), and the signature is measured. Set on the
    /// structural benchmark's calibration seed (docs/diagnosis.md).
    #[serde(default = "default_seen_margin")]
    pub seen_margin: f64,
    /// When no effect is significant, an effect whose model-free signature
    /// measures its own size (a valve delay: the front feed's shift since
    /// the reference) is named on that signature alone if it stands this
    /// many standard errors off and no other effect's signature stands at
    /// [`Options::min_model_free_z`]: the model's law for it may differ
    /// from the hammer's (a dead time against a lagging spool), so its fit
    /// to the waveforms may disagree however clear the change is. 5 is the
    /// drift alarm's pooled threshold (docs/fleet.md).
    #[serde(default = "default_chamber_alone_z")]
    pub chamber_alone_z: f64,
    /// Pairs are tried when the best single effect leaves a reduced χ² above this.
    pub pair_residual: f64,
    /// How many runners-up are tried as the second effect of a pair.
    pub pair_candidates: usize,
    pub threads: usize,
    /// Keep the waveforms for the figures.
    pub figures: bool,
    /// Estimate the model-form error of the model-based features from the
    /// recalibrated nominal model's residual (see [`crate::report::ModelForm`]); off, the
    /// floors alone weigh them (a model whose form is the hammer's).
    pub model_form: bool,
    /// The benchmark's hammer as it truly is (its nominal values and its
    /// effect), for the oracle's check ([`crate::pipeline::oracle`]): never
    /// a diagnosis' input, and never written to a report's options.
    #[serde(skip)]
    pub oracle: Option<Oracle>,
}

/// What only a benchmark knows of its hammer: its effects, and its nominal
/// values in the plant's order. The oracle's check asks whether the truth
/// itself, in the diagnosis' own model, would pass the rule that names an
/// effect: where it does not, no reading of these features names it.
#[derive(Debug, Clone, PartialEq)]
pub struct Oracle {
    pub effects: hammer_sim::effects::Effects,
    pub nuisance: Vec<f64>,
}

impl Default for Options {
    fn default() -> Self {
        Self {
            floors: Floors::default(),
            nominal_uncertainty: hammer_sim::params::NOMINAL_UNCERTAINTY,
            max_iterations: 12,
            min_score: 20.0,
            min_model_free_z: default_min_model_free_z(),
            min_explained: 0.4,
            min_explained_reference: default_min_explained_reference(),
            min_explained_pair: default_min_explained_pair(),
            close_call_margin: default_close_call_margin(),
            seen_margin: default_seen_margin(),
            chamber_alone_z: default_chamber_alone_z(),
            pair_residual: 2.0,
            pair_candidates: 5,
            threads: std::thread::available_parallelism().map_or(2, |n| n.get()),
            figures: true,
            model_form: true,
            oracle: None,
        }
    }
}

fn default_min_model_free_z() -> f64 {
    3.0
}

fn default_close_call_margin() -> f64 {
    0.02
}

fn default_seen_margin() -> f64 {
    0.2
}

fn default_chamber_alone_z() -> f64 {
    5.0
}

fn default_min_explained_reference() -> f64 {
    0.15
}

fn default_min_explained_pair() -> f64 {
    0.5
}
