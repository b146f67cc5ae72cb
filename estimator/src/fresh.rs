//! A new estimator: built ([`Estimator::new`]) or renewed in place
//! ([`Estimator::renew`], a board's `SetConfig` and tare), with the one
//! list of what a new estimator's state is in each.

use crate::cycle::{self, CycleAcc, Derived};
use crate::history::History;
use crate::wear::WearState;
use crate::*;

impl Estimator {
    pub fn new(cfg: Config) -> Result<Self, ConfigError> {
        cfg.validate()?;
        Ok(Self::build(cfg))
    }

    /// A new estimator for `cfg` in place of this one (its wear state and
    /// counters go with it), field by field ([`Self::reset`]): the
    /// estimator is ~8 KB, most of it the cycle's checkpoints, and
    /// `*self = Self::build(cfg)` built a new one and its accumulator
    /// beside the old, 11.6 KB deeper at a board's `SetConfig` (measured on
    /// the emulated board: 34 808 B, over the reference board's region).
    pub fn renew(&mut self, cfg: Config) -> Result<(), ConfigError> {
        cfg.validate()?;
        self.reset(cfg);
        Ok(())
    }

    /// [`Self::build`] in place. The pattern names every field, so one
    /// added and not reset here does not compile; a test holds the two to
    /// the same reports and counts. Never inlined: its temporaries would
    /// otherwise join the frame of the task that calls `renew`, on every
    /// poll.
    #[inline(never)]
    fn reset(&mut self, cfg: Config) {
        let Self {
            cfg: c,
            d,
            phase,
            delay,
            delay_len,
            cal,
            impact_code: code,
            acc,
            pre_samples,
            blank_samples,
            stuck_limit,
            min_shock,
            max_period_samples,
            cycle_start,
            opened_by_impact,
            kept_start,
            fault_reported,
            armed,
            held,
            held_len,
            last_good,
            pending,
            ready,
            history,
            next_index,
            dropped_in_cycle,
            contact_samples,
            cycle_contact_samples,
            friction_guess,
            seq,
            calibration_hash,
            sample_hz,
            wear,
            counters,
        } = self;
        let fs = cfg.sample_rate_hz;
        *pre_samples = (math::round(cfg.blank_before_s * fs) as usize).min(MAX_PRE_BLANK - 1);
        let shock = MIN_SHOCK_S * fs;
        *min_shock = (shock as usize + usize::from((shock as usize as f32) < shock)).clamp(1, MAX_CONFIRM);
        *d = Derived::new(&cfg);
        acc.start(d, u32::MAX / 2);
        *phase = Phase::Collecting;
        delay.fill(RawSample::default());
        *delay_len = 0;
        *cal = cycle::Calibration::new(&cfg);
        *code = impact_code(&cfg);
        *blank_samples = math::round(cfg.blank_after_s * fs) as u32;
        *stuck_limit = math::round(cfg.stuck_after_s * fs) as u32;
        *max_period_samples = math::round(cfg.max_period_s * fs) as u64;
        *cycle_start = 0;
        *opened_by_impact = false;
        *kept_start = 0;
        *fault_reported = false;
        *armed = true;
        held.fill(RawSample::default());
        *held_len = 0;
        *last_good = RawSample::default();
        *pending = None;
        ready.clear();
        *history = History::default();
        *next_index = 0;
        *dropped_in_cycle = false;
        *contact_samples = 0;
        *cycle_contact_samples = 0;
        *friction_guess = 0.0;
        *seq = 0;
        *calibration_hash = cfg.calibration_hash();
        *sample_hz = cfg.sample_hz();
        *wear = WearState::default();
        *counters = Counters::default();
        *c = cfg;
    }

    /// Never inlined, as [`Self::reset`] is not: inlined into `new`, and
    /// that into a board's start-up, the new estimator and its accumulator
    /// were built in the start-up's own frame, 9 KB deeper (measured).
    #[inline(never)]
    fn build(cfg: Config) -> Self {
        let fs = cfg.sample_rate_hz;
        let pre = (math::round(cfg.blank_before_s * fs) as usize).min(MAX_PRE_BLANK - 1);
        let shock = MIN_SHOCK_S * fs;
        let min_shock = (shock as usize + usize::from((shock as usize as f32) < shock)).clamp(1, MAX_CONFIRM);
        let d = Derived::new(&cfg);
        let mut acc = CycleAcc::new();
        acc.start(&d, u32::MAX / 2);
        Self {
            d,
            phase: Phase::Collecting,
            delay: [RawSample::default(); MAX_PRE_BLANK],
            delay_len: 0,
            cal: cycle::Calibration::new(&cfg),
            impact_code: impact_code(&cfg),
            acc,
            pre_samples: pre,
            blank_samples: math::round(cfg.blank_after_s * fs) as u32,
            stuck_limit: math::round(cfg.stuck_after_s * fs) as u32,
            min_shock,
            max_period_samples: math::round(cfg.max_period_s * fs) as u64,
            cycle_start: 0,
            opened_by_impact: false,
            kept_start: 0,
            fault_reported: false,
            armed: true,
            held: [RawSample::default(); MAX_CONFIRM],
            held_len: 0,
            last_good: RawSample::default(),
            pending: None,
            ready: heapless::Deque::new(),
            history: History::default(),
            next_index: 0,
            dropped_in_cycle: false,
            contact_samples: 0,
            cycle_contact_samples: 0,
            friction_guess: 0.0,
            seq: 0,
            calibration_hash: cfg.calibration_hash(),
            sample_hz: cfg.sample_hz(),
            wear: WearState::default(),
            counters: Counters::default(),
            cfg,
        }
    }
}
