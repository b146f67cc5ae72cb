//! Per-cycle estimator of an impact hammer's piston friction, impact energy,
//! frequency and wear, from two chamber pressures and the piston acceleration.
//!
//! `no_std`, allocation-free and bounded: the very same code runs in host
//! tests, in offline analysis (`hammer estimate`) and on the Cortex-M4F.
//! Feed raw ADC codes one sample-set at a time with [`Estimator::push`]; a
//! [`CycleReport`] comes out when an impact closes a cycle. The method is
//! described in `docs/estimator.md`.
#![no_std]
#![forbid(unsafe_code)]

pub mod config;
pub mod cycle;
pub mod geometry;
pub mod math;
pub mod report;
pub mod tare;
pub mod wear;

pub use config::{ChannelCal, ChannelSpec, Config, ConfigError, WearConfig};
pub use geometry::Geometry;
pub use report::{CycleReport, Flags};
pub use wear::{WearState, WearStateError};

use cycle::{CycleAcc, Derived};

/// One sample-set: raw ADC codes of rear pressure, front pressure, acceleration.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct RawSample {
    pub rear: u16,
    pub front: u16,
    pub accel: u16,
}

/// Longest pre-impact blanking in samples (the delay line's size).
pub const MAX_PRE_BLANK: usize = 64;

/// The highest accelerometer code that reads below −threshold, when the
/// calibration has a positive scale (the usual case); then detecting an
/// impact is one integer compare per sample.
fn impact_code(cfg: &Config) -> Option<u16> {
    let a = &cfg.accel;
    if a.scale <= 0.0 {
        return None;
    }
    let mut code: Option<u16> = None;
    // value(c) < −thr ⇔ c < zero − thr/scale; scan down from the estimate to be exact in f32.
    let est = a.zero_code - cfg.impact_threshold_mps2 / a.scale;
    let start = if est < 0.0 {
        0
    } else if est > a.full_scale_code as f32 {
        a.full_scale_code
    } else {
        est as u16
    };
    let mut c = start.saturating_add(2).min(a.full_scale_code);
    loop {
        if a.value(c) < -cfg.impact_threshold_mps2 {
            code = Some(c);
            break;
        }
        if c == 0 {
            break;
        }
        c -= 1;
    }
    // Code 0 (the bottom rail) is always an impact.
    Some(code.unwrap_or(0))
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Phase {
    /// Waiting for an impact to start a cycle.
    Searching,
    /// Discarding the shock; `left` samples to go; `in_shock` while the
    /// accelerometer still shows the contact.
    Blanking { left: u32, in_shock: bool },
    /// Accumulating the cycle.
    Collecting,
}

/// Running totals, for the status a device reports.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Counters {
    pub samples: u64,
    pub dropped_samples: u64,
    pub impacts: u64,
    pub cycles: u32,
    pub invalid_cycles: u32,
    /// Cycles abandoned because no impact came within `max_period_s`.
    pub stalls: u32,
}

pub struct Estimator {
    cfg: Config,
    d: Derived,
    phase: Phase,
    /// The newest `pre_samples` sample-sets, not yet processed, oldest first.
    delay: [RawSample; MAX_PRE_BLANK],
    delay_len: usize,
    cal: cycle::Calibration,
    /// Accelerometer codes at or below this are an impact (positive scale).
    impact_code: Option<u16>,
    acc: CycleAcc,
    pre_samples: usize,
    blank_samples: u32,
    stuck_limit: u32,
    max_period_samples: u64,
    last_impact: Option<u64>,
    next_index: u64,
    dropped_in_cycle: bool,
    /// Samples the shock of the last impact lasted (≈ the contact duration).
    contact_samples: u32,
    /// The same for the impact that opened the cycle under way.
    cycle_contact_samples: u32,
    friction_guess: f32,
    seq: u32,
    wear: WearState,
    counters: Counters,
}

impl Estimator {
    pub fn new(cfg: Config) -> Result<Self, ConfigError> {
        cfg.validate()?;
        let fs = cfg.sample_rate_hz;
        let pre = (math::round(cfg.blank_before_s * fs) as usize).min(MAX_PRE_BLANK - 1);
        Ok(Self {
            d: Derived::new(&cfg),
            phase: Phase::Searching,
            delay: [RawSample::default(); MAX_PRE_BLANK],
            delay_len: 0,
            cal: cycle::Calibration::new(&cfg),
            impact_code: impact_code(&cfg),
            acc: CycleAcc::new(),
            pre_samples: pre,
            blank_samples: math::round(cfg.blank_after_s * fs) as u32,
            stuck_limit: math::round(cfg.stuck_after_s * fs) as u32,
            max_period_samples: math::round(cfg.max_period_s * fs) as u64,
            last_impact: None,
            next_index: 0,
            dropped_in_cycle: false,
            contact_samples: 0,
            cycle_contact_samples: 0,
            friction_guess: 0.0,
            seq: 0,
            wear: WearState::default(),
            counters: Counters::default(),
            cfg,
        })
    }

    pub fn config(&self) -> &Config {
        &self.cfg
    }

    pub fn counters(&self) -> Counters {
        self.counters
    }

    pub fn wear_state(&self) -> &WearState {
        &self.wear
    }

    /// Continues from a saved wear state (after a reset or power cycle).
    pub fn restore_wear(&mut self, state: WearState) {
        self.wear = state;
    }

    /// Forgets the drift baselines (after a repair); the wear index stays.
    pub fn rebaseline(&mut self) {
        self.wear.rebaseline();
    }

    #[inline]
    fn is_impact(&self, s: &RawSample) -> bool {
        match self.impact_code {
            Some(max) => s.accel <= max,
            None => s.accel == 0 || self.cfg.accel.value(s.accel) < -self.cfg.impact_threshold_mps2,
        }
    }

    /// Feeds a block of samples; `on_report` is called for every closed cycle.
    /// The same results as [`Estimator::push`] one sample at a time, faster:
    /// the stretches between impacts go through the hot loop in one piece.
    pub fn push_block(&mut self, block: &[RawSample], mut on_report: impl FnMut(CycleReport)) {
        let mut i = 0;
        while i < block.len() {
            if self.phase == Phase::Collecting {
                let rest = &block[i..];
                // Up to the next impact, and short of the sample that would stall the cycle.
                let to_stall = self.last_impact.map_or(u64::MAX, |last| {
                    (last + self.max_period_samples + 1).saturating_sub(self.next_index)
                });
                let limit = rest.len().min(to_stall.min(usize::MAX as u64) as usize);
                let n = rest[..limit].iter().position(|s| self.is_impact(s)).unwrap_or(limit);
                if n > 0 {
                    self.next_index = self.next_index.wrapping_add(n as u64);
                    self.counters.samples = self.counters.samples.wrapping_add(n as u64);
                    self.collect(&rest[..n]);
                    i += n;
                    continue;
                }
            }
            if let Some(r) = self.push(block[i]) {
                on_report(r);
            }
            i += 1;
        }
    }

    /// Feeds one sample-set. Returns the report of the cycle an impact closes.
    pub fn push(&mut self, s: RawSample) -> Option<CycleReport> {
        let index = self.next_index;
        self.next_index = self.next_index.wrapping_add(1);
        self.counters.samples = self.counters.samples.wrapping_add(1);
        let impact = self.is_impact(&s);
        match self.phase {
            Phase::Searching => {
                if impact {
                    self.begin_cycle(index);
                }
                None
            }
            Phase::Blanking { left, in_shock } => {
                let still = in_shock && impact;
                if still {
                    self.contact_samples = self.contact_samples.saturating_add(1);
                }
                self.phase = if left <= 1 {
                    self.start_collecting()
                } else {
                    Phase::Blanking {
                        left: left - 1,
                        in_shock: still,
                    }
                };
                None
            }
            Phase::Collecting => {
                if impact {
                    let report = self.close_cycle(index);
                    self.begin_cycle(index);
                    return Some(report);
                }
                if let Some(last) = self.last_impact {
                    if index.wrapping_sub(last) > self.max_period_samples {
                        self.counters.stalls = self.counters.stalls.wrapping_add(1);
                        self.phase = Phase::Searching;
                        self.last_impact = None;
                        return None;
                    }
                }
                self.collect(core::slice::from_ref(&s));
                None
            }
        }
    }

    /// Reports samples that never arrived (ADC overrun, link gap): the cycle
    /// under way cannot be estimated and is flagged; timing stays right.
    pub fn push_gap(&mut self, missing: u32) {
        self.next_index = self.next_index.wrapping_add(missing as u64);
        self.counters.dropped_samples = self.counters.dropped_samples.wrapping_add(missing as u64);
        match self.phase {
            Phase::Collecting => self.dropped_in_cycle = true,
            Phase::Blanking { left, .. } => {
                self.phase = if left <= missing {
                    self.start_collecting()
                } else {
                    Phase::Blanking {
                        left: left - missing,
                        in_shock: false,
                    }
                };
                self.dropped_in_cycle = true;
            }
            Phase::Searching => {}
        }
    }

    fn begin_cycle(&mut self, index: u64) {
        self.counters.impacts = self.counters.impacts.wrapping_add(1);
        self.last_impact = Some(index);
        self.delay_len = 0;
        self.dropped_in_cycle = false;
        self.contact_samples = 1;
        self.phase = if self.blank_samples == 0 {
            self.start_collecting()
        } else {
            Phase::Blanking {
                left: self.blank_samples,
                in_shock: true,
            }
        };
    }

    fn start_collecting(&mut self) -> Phase {
        self.cycle_contact_samples = self.contact_samples;
        self.acc.start(&self.d, self.blank_samples + 1);
        Phase::Collecting
    }

    /// Samples of the cycle under way, none of them an impact. The newest
    /// `pre_samples` wait in the delay line: if the next sample is an impact,
    /// they hold its leading edge and are discarded; the rest are processed.
    fn collect(&mut self, run: &[RawSample]) {
        let pre = self.pre_samples;
        let total = self.delay_len + run.len();
        if total <= pre {
            self.delay[self.delay_len..total].copy_from_slice(run);
            self.delay_len = total;
            return;
        }
        let n_proc = total - pre;
        let from_delay = self.delay_len.min(n_proc);
        if from_delay > 0 {
            let held = self.delay;
            self.acc
                .push_run(&self.d, &self.cal, &held[..from_delay], self.stuck_limit);
        }
        let from_run = n_proc - from_delay;
        self.acc
            .push_run(&self.d, &self.cal, &run[..from_run], self.stuck_limit);
        // The new delay line: what is left of the old one, then the run's tail.
        let keep_old = self.delay_len - from_delay;
        self.delay.copy_within(from_delay..from_delay + keep_old, 0);
        let tail = &run[from_run..];
        self.delay[keep_old..keep_old + tail.len()].copy_from_slice(tail);
        self.delay_len = keep_old + tail.len();
    }

    fn close_cycle(&mut self, index: u64) -> CycleReport {
        let start = self.last_impact.unwrap_or(index);
        let period_s = index.wrapping_sub(start) as f32 * self.d.dt;
        let tail = self.delay_len as u32;
        let mut e = cycle::estimate(
            &self.acc,
            &self.cfg,
            &self.d,
            self.blank_samples,
            self.cycle_contact_samples,
            tail,
            self.friction_guess,
        );
        let n = self.acc.cur.n.max(1.0);
        if self.acc.rail.iter().any(|&r| r as f32 > 0.9 * n) {
            e.flags.insert(Flags::DISCONNECTED);
        }
        if self.dropped_in_cycle {
            e.flags.insert(Flags::DROPPED_SAMPLES);
        }
        if period_s < self.cfg.min_period_s || period_s > self.cfg.max_period_s {
            e.flags.insert(Flags::IMPLAUSIBLE);
        }
        let m = self.d.m;
        let mut r = CycleReport {
            seq: self.seq,
            t_impact_s: (index as f64 - 0.5) / self.cfg.sample_rate_hz as f64,
            period_s,
            frequency_hz: 1.0 / period_s,
            friction_n: e.friction_n,
            friction_stroke_n: e.friction_stroke_n,
            friction_backhaul_n: e.friction_backhaul_n,
            friction_uncertainty_n: e.u_friction_n,
            friction_stroke_uncertainty_n: e.u_friction_stroke_n,
            friction_backhaul_uncertainty_n: e.u_friction_backhaul_n,
            impact_velocity_mps: e.v_impact_mps,
            impact_velocity_frictionless_mps: e.v_impact_frictionless_mps,
            impact_energy_j: 0.5 * m * e.v_impact_mps * e.v_impact_mps,
            impact_energy_frictionless_j: 0.5 * m * e.v_impact_frictionless_mps * e.v_impact_frictionless_mps,
            impact_energy_uncertainty_j: m * math::abs(e.v_impact_mps) * e.u_v_impact_mps,
            impact_energy_frictionless_uncertainty_j: m
                * math::abs(e.v_impact_frictionless_mps)
                * e.u_v_frictionless_mps,
            friction_work_j: e.friction_work_j,
            friction_work_ratio: 0.0,
            stroke_m: e.stroke_m,
            peak_rear_pa: self.acc.peak_p1,
            peak_front_pa: self.acc.peak_p2,
            accel_zero_shift_mps2: e.zero_shift_mps2,
            wear_index_j: self.wear.friction_work_j as f32,
            wear_remaining_fraction: 0.0,
            remaining_life_cycles: 0.0,
            drift_score: self.wear.cusum,
            flags: e.flags,
        };
        if r.impact_energy_j > 0.0 {
            r.friction_work_ratio = e.friction_work_stroke_j / r.impact_energy_j;
        }
        if r.is_valid() {
            let op = if self.cfg.supply_pressure_pa.is_nan() {
                r.peak_rear_pa
            } else {
                self.cfg.supply_pressure_pa
            };
            let w = self.wear.update(&self.cfg.wear, r.friction_n, r.friction_work_j, op);
            r.wear_index_j = w.wear_index_j;
            r.wear_remaining_fraction = w.remaining_fraction;
            r.remaining_life_cycles = w.remaining_cycles;
            r.drift_score = w.drift_score;
            if w.alarm {
                r.flags.insert(Flags::DRIFT_ALARM);
            }
            self.friction_guess = r.friction_n;
        } else {
            self.counters.invalid_cycles = self.counters.invalid_cycles.wrapping_add(1);
        }
        self.counters.cycles = self.counters.cycles.wrapping_add(1);
        self.seq = self.seq.wrapping_add(1);
        r
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn impact_code_matches_the_float_threshold() {
        for thr in [100.0f32, 1500.0, 1999.0, 5000.0] {
            let mut cfg = Config::default();
            cfg.impact_threshold_mps2 = thr;
            let max = impact_code(&cfg).unwrap();
            for c in 0..=4095u16 {
                let float = c == 0 || cfg.accel.value(c) < -thr;
                assert_eq!(c <= max, float, "thr {thr}, code {c}, max {max}");
            }
        }
    }
}
