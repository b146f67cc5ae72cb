//! Per-cycle estimator of an impact hammer's piston friction, impact energy,
//! frequency and wear, from two chamber pressures and the piston acceleration.
//!
//! `no_std`, allocation-free and bounded: the very same code runs in host
//! tests, in offline analysis (`hammer estimate`) and on the Cortex-M4F.
//! Feed raw ADC codes one sample-set at a time with [`Estimator::push`]; a
//! [`CycleReport`] comes out when an impact closes a cycle. The method is
//! described in `docs/estimator.md`.
//!
//! Module map (a sample's path, top to bottom):
//! - [`config`], [`geometry`], [`device`]: the runtime configuration, the
//!   piston's mass and areas, and its one mapping to the wire's `DeviceConfig`;
//! - [`tare`]: zero offsets from the hammer at rest;
//! - this file: [`Estimator`], impact detection (shock confirmation, spike
//!   rejection, blanking), the cycle's phases, stalls and gaps; `fresh`: a
//!   new estimator, built or renewed in place;
//! - [`cycle`]: the running sums of the cycle under way (exact integer sums
//!   of the codes per checkpoint, the per-sample pass in `cycle::pass`) and the
//!   sensor watches (rails, stuck channels, the accelerometer's force-balance slope);
//! - [`estimate`]: what a closed cycle's sums give (friction per phase, zero
//!   shift, impact velocity and energy, their uncertainties); `estimate::left`
//!   puts the samples at a pressure's rail, out of the fit, into the closure;
//! - `run`: the impact scan and the delay line's copies, as plain loops;
//! - `history`: the neighbour check on period and stroke;
//! - [`wear`]: the wear index, the drift CUSUM and their saved state;
//! - [`math`]: the one path for transcendental functions and float widths (host = target);
//! - [`chambers`]: the valve's switching, the fill and the closed phases of
//!   both chambers from one cycle's samples (on the host from raw traces;
//!   on a board at each cycle's close, `chambers::at_close`);
//! - [`clock`]: a sample's index as its time and back.
//!
//! The report and its flags are `hammer_types`' (re-exported here).
#![no_std]
#![forbid(unsafe_code)]

pub mod chambers;
pub mod clock;
pub mod config;
pub mod cycle;
pub mod device;
pub mod estimate;
mod fresh;
pub mod geometry;
mod history;
pub mod math;
mod run;
pub mod tare;
pub mod wear;

pub use config::{ChamberConfig, ChannelCal, ChannelSpec, Config, ConfigError, WearConfig, ADC_BITS_MAX, ADC_BITS_MIN};
pub use geometry::Geometry;
/// The canonical types the estimator produces and reads, defined once in
/// `hammer-types` and shared with the wire, the firmware and the host.
pub use hammer_types::{fields, ChannelCalibration, Codes, CycleReport, DeviceConfig, FeedFields, Flags, RawSample};
pub use wear::{WearState, WearStateError};

use cycle::{CycleAcc, Derived};
use history::History;
use run::{copy, first_at_or_below, impact_code};

/// Longest pre-impact blanking in samples (the delay line's size).
pub const MAX_PRE_BLANK: usize = 64;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Phase {
    /// An accelerometer sample crossed the impact threshold; the next few
    /// tell a shock from a spike. `trigger` is its index; the samples since
    /// are in `Estimator::held`.
    Confirming { trigger: u64 },
    /// Discarding the shock; `left` samples to go; `in_shock` while the
    /// accelerometer still shows the contact.
    Blanking { left: u32, in_shock: bool },
    /// Accumulating the cycle.
    Collecting,
}

/// Longest a real shock needs to prove itself, in samples.
/// The most samples an impact is confirmed over (the shock's minimum length).
pub const MAX_CONFIRM: usize = 8;
/// A contact lasts tens of microseconds (≈ 75 µs for the paper's hammer);
/// an accelerometer beyond the threshold for less than this is a spike.
const MIN_SHOCK_S: f32 = 25e-6;
/// Pressure swing that says the hammer runs while no impact comes.
const RUNNING_SWING_PA: f32 = 0.5e5;

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
    /// Accelerometer excursions too short to be a shock, held over.
    pub spikes: u32,
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
    min_shock: usize,
    max_period_samples: u64,
    /// Where the cycle under way began (an impact, or where the estimator
    /// started listening).
    cycle_start: u64,
    /// Whether that beginning was a confirmed impact: only such cycles are estimates.
    opened_by_impact: bool,
    /// Index of the cycle's first kept sample (after its blanking).
    kept_start: u64,
    /// An accelerometer fault was already reported for the cycle under way.
    fault_reported: bool,
    /// Impacts count only after the accelerometer left the impact region:
    /// one stuck beyond the threshold is one event, not a flood.
    armed: bool,
    /// Samples after a trigger, waiting for the shock to prove itself.
    held: [RawSample; MAX_CONFIRM],
    held_len: usize,
    /// The newest sample the cycle took: what a spike is replaced with.
    last_good: RawSample,
    /// The report of the cycle an impact closed, held until its shock has
    /// been seen to end (a shock that does not is no impact).
    pending: Option<CycleReport>,
    /// Reports ready to leave, oldest first (a sample can close a cycle and
    /// release the one before: two at most).
    ready: heapless::Deque<CycleReport, 3>,
    history: History,
    next_index: u64,
    dropped_in_cycle: bool,
    /// Samples the shock of the last impact lasted (≈ the contact duration).
    contact_samples: u32,
    /// The same for the impact that opened the cycle under way.
    cycle_contact_samples: u32,
    friction_guess: f32,
    seq: u32,
    /// Of the configuration's calibrations, for every report.
    calibration_hash: u32,
    /// The sample rate in whole Hz, for the reports' times.
    sample_hz: u64,
    wear: WearState,
    counters: Counters,
}

impl Estimator {
    pub fn config(&self) -> &Config {
        &self.cfg
    }

    /// Samples from the latest confirmed impact's first shock sample to the
    /// latest sample, inclusive: a capture that starts on an impact (seen
    /// through `counters().impacts`) starts that many samples back.
    pub fn samples_since_impact(&self) -> u64 {
        self.next_index.wrapping_sub(self.cycle_start)
    }

    /// The index the next sample-set will have: samples counted from the
    /// first, lost ones included (a report's impact is the edge of its
    /// index, [`clock::edge_us`]). Starts over at 0 with a new configuration.
    pub fn next_index(&self) -> u64 {
        self.next_index
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
            if self.phase == Phase::Collecting && self.armed {
                let rest = &block[i..];
                // Up to the next impact, short of the sample that would stall
                // the cycle, and no further than the next checkpoint.
                let to_stall = (self.cycle_start + self.max_period_samples + 1).saturating_sub(self.next_index);
                let to_cp = self.acc.to_checkpoint(&self.d) as usize + self.pre_samples.saturating_sub(self.delay_len);
                let limit = rest.len().min(to_stall.min(usize::MAX as u64) as usize).min(to_cp);
                let scan = &rest[..limit];
                let n = match self.impact_code {
                    // The common case: one integer compare per sample.
                    Some(max) => first_at_or_below(scan, max),
                    None => scan.iter().position(|s| self.is_impact(s)),
                }
                .unwrap_or(limit);
                if n > 0 {
                    self.next_index = self.next_index.wrapping_add(n as u64);
                    self.counters.samples = self.counters.samples.wrapping_add(n as u64);
                    self.collect(&rest[..n]);
                    self.accel_fault_record();
                    while let Some(r) = self.ready.pop_front() {
                        on_report(r);
                    }
                    i += n;
                    continue;
                }
            }
            self.step(block[i]);
            while let Some(r) = self.ready.pop_front() {
                on_report(r);
            }
            i += 1;
        }
    }

    /// Feeds one sample-set. Returns a report when one is ready (a cycle
    /// closed, or a fault record); a second one ready at the same sample
    /// comes with the next call.
    pub fn push(&mut self, s: RawSample) -> Option<CycleReport> {
        self.step(s);
        self.ready.pop_front()
    }

    fn emit(&mut self, r: Option<CycleReport>) {
        if let Some(r) = r {
            // Bounded: at most two are made per sample and each call drains.
            let _ = self.ready.push_back(r);
        }
    }

    fn step(&mut self, s: RawSample) {
        let index = self.next_index;
        self.next_index = self.next_index.wrapping_add(1);
        self.counters.samples = self.counters.samples.wrapping_add(1);
        let beyond = self.is_impact(&s);
        match self.phase {
            Phase::Confirming { trigger } => self.confirm(trigger, s, beyond),
            Phase::Blanking { left, in_shock } => self.blank(left, in_shock, beyond),
            Phase::Collecting => {
                if !beyond {
                    self.armed = true;
                }
                if beyond && self.armed {
                    self.held[0] = s;
                    self.held_len = 1;
                    if self.min_shock <= 1 {
                        self.impact(index);
                    } else {
                        self.phase = Phase::Confirming { trigger: index };
                    }
                    return;
                }
                if index.wrapping_sub(self.cycle_start) > self.max_period_samples {
                    self.stall(index, s);
                    return;
                }
                self.collect(core::slice::from_ref(&s));
                self.accel_fault_record();
            }
        }
    }

    /// Reports samples that never arrived (ADC overrun, link gap): the cycle
    /// under way cannot be estimated and is flagged; timing stays right.
    #[inline(never)]
    pub fn push_gap(&mut self, missing: u32) {
        self.next_index = self.next_index.wrapping_add(missing as u64);
        self.counters.dropped_samples = self.counters.dropped_samples.wrapping_add(missing as u64);
        match self.phase {
            Phase::Collecting => self.dropped_in_cycle = true,
            Phase::Confirming { trigger } => {
                // The shock cannot be judged across a hole: take it as an impact.
                self.held_len = 1;
                self.impact(trigger);
                self.dropped_in_cycle = true;
            }
            Phase::Blanking { left, .. } => {
                self.phase = if left <= missing {
                    let r = self.pending.take().map(|r| self.finalize(r));
                    self.emit(r);
                    self.start_collecting()
                } else {
                    Phase::Blanking {
                        left: left - missing,
                        in_shock: false,
                    }
                };
                self.dropped_in_cycle = true;
            }
        }
    }

    /// One more sample after a trigger: a shock is confirmed once
    /// `min_shock` samples of it have been seen, a spike once the
    /// accelerometer fell back before that.
    #[inline(never)]
    fn confirm(&mut self, trigger: u64, s: RawSample, beyond: bool) {
        self.held[self.held_len] = s;
        self.held_len += 1;
        if !beyond {
            // A spike: hold the accelerometer over it, keep the pressures.
            self.counters.spikes = self.counters.spikes.wrapping_add(1);
            let held_len = self.held_len;
            let mut held = self.held;
            for h in &mut held[..held_len - 1] {
                h.accel = self.last_good.accel;
            }
            self.phase = Phase::Collecting;
            self.held_len = 0;
            self.collect(&held[..held_len]);
            self.accel_fault_record();
            return;
        }
        if self.held_len >= self.min_shock {
            self.impact(trigger);
        }
    }

    /// A confirmed impact at `trigger`: the cycle under way closes (its
    /// report waits for the shock to end), the next one opens, and the
    /// samples held since the trigger are the first of its blanking.
    #[inline(never)]
    fn impact(&mut self, trigger: u64) {
        let earlier = self.pending.take().map(|r| self.finalize(r));
        self.emit(earlier);
        if self.opened_by_impact {
            self.pending = Some(self.close_cycle(trigger));
        }
        self.begin_cycle(trigger);
        let held_len = self.held_len;
        self.held_len = 0;
        for k in 1..held_len {
            let s = self.held[k];
            let beyond = self.is_impact(&s);
            match self.phase {
                Phase::Blanking { left, in_shock } => self.blank(left, in_shock, beyond),
                _ => self.collect(core::slice::from_ref(&s)),
            }
        }
        if self.phase == Phase::Collecting {
            // No blanking configured: nothing to wait for.
            let r = self.pending.take().map(|r| self.finalize(r));
            self.emit(r);
        }
    }

    #[inline(never)]
    fn blank(&mut self, left: u32, in_shock: bool, beyond: bool) {
        let still = in_shock && beyond;
        if still {
            self.contact_samples = self.contact_samples.saturating_add(1);
        }
        if left > 1 {
            self.phase = Phase::Blanking {
                left: left - 1,
                in_shock: still,
            };
            return;
        }
        self.phase = self.start_collecting();
        let mut r = self.pending.take();
        if still {
            // Beyond the threshold for the whole blanking: no contact lasts
            // that long. The accelerometer is railed or stuck there; what
            // closed the previous cycle was not an impact.
            self.armed = false;
            self.opened_by_impact = false;
            if let Some(r) = r.as_mut() {
                r.flags.insert(Flags::ACCEL_FAULT);
            }
        }
        let r = r.map(|r| self.finalize(r));
        self.emit(r);
    }

    #[inline(never)]
    fn begin_cycle(&mut self, index: u64) {
        self.counters.impacts = self.counters.impacts.wrapping_add(1);
        self.cycle_start = index;
        self.opened_by_impact = true;
        self.fault_reported = false;
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
        self.kept_start = self.next_index;
        self.cycle_contact_samples = self.contact_samples;
        self.acc.start(&self.d, self.blank_samples + 1);
        Phase::Collecting
    }

    /// A cycle that did not open at an impact (start-up, after a stall or a
    /// fault): accumulated for the fault checks, never an estimate.
    #[inline(never)]
    fn open_without_impact(&mut self, index: u64) {
        self.cycle_start = index;
        self.kept_start = index;
        self.opened_by_impact = false;
        self.delay_len = 0;
        self.dropped_in_cycle = false;
        self.acc.start(&self.d, u32::MAX / 2);
        self.phase = Phase::Collecting;
    }

    /// Samples of the cycle under way, none of them an impact. The newest
    /// `pre_samples` wait in the delay line: if the next sample is an impact,
    /// they hold its leading edge and are discarded; the rest are processed.
    fn collect(&mut self, run: &[RawSample]) {
        if let Some(last) = run.last() {
            self.last_good = *last;
        }
        let pre = self.pre_samples;
        let total = self.delay_len + run.len();
        if total <= pre {
            copy(&mut self.delay[self.delay_len..total], run);
            self.delay_len = total;
            return;
        }
        let n_proc = total - pre;
        let from_delay = self.delay_len.min(n_proc);
        let from_run = n_proc - from_delay;
        self.acc.push_run(
            &self.d,
            &self.cal,
            [&self.delay[..from_delay], &run[..from_run]],
            self.stuck_limit,
        );
        // The new delay line: what is left of the old one, then the run's tail.
        let keep_old = self.delay_len - from_delay;
        for k in 0..keep_old {
            self.delay[k] = self.delay[from_delay + k];
        }
        let tail = &run[from_run..];
        copy(&mut self.delay[keep_old..keep_old + tail.len()], tail);
        self.delay_len = keep_old + tail.len();
    }

    /// An accelerometer fault seen in the cycle under way is reported at
    /// once (the cycle cannot close on an impact the sensor will not show),
    /// then the estimator listens on without an impact; once per cycle.
    #[inline(always)]
    fn accel_fault_record(&mut self) {
        if self.fault_reported {
            return;
        }
        let Some(at) = self.acc.accel_fault_at else {
            return;
        };
        let index = self.kept_start + u64::from(at);
        let flags = self.acc.flags;
        let r = self.record(index.min(self.next_index), flags | Flags::NO_IMPACT);
        self.open_without_impact(self.next_index);
        self.fault_reported = true;
        self.emit(Some(r));
    }

    /// No impact within `max_period_s`. A hammer that stands still (its
    /// pressures flat) is only counted; one whose pressures keep cycling has
    /// a silent accelerometer, and that is reported.
    #[inline(never)]
    fn stall(&mut self, index: u64, s: RawSample) {
        if self.opened_by_impact {
            self.counters.stalls = self.counters.stalls.wrapping_add(1);
        }
        let running = self.acc.recent_pressure_swing_pa() > RUNNING_SWING_PA;
        let r = (running || self.acc.flags.intersects(Flags::ACCEL_FAULT))
            .then(|| self.record(index, self.acc.flags | Flags::NO_IMPACT));
        let reported = self.fault_reported;
        self.open_without_impact(index);
        self.fault_reported = reported && r.is_none();
        self.emit(r);
        self.collect(core::slice::from_ref(&s));
        self.accel_fault_record();
    }

    /// A record with flags and no numbers: what happened instead of a cycle.
    #[inline(never)]
    fn record(&mut self, index: u64, mut flags: Flags) -> CycleReport {
        self.acc.settle(&self.d, &self.cal);
        let period_s = index.wrapping_sub(self.cycle_start) as f32 * self.d.dt;
        let n = self.acc.samples.max(1.0);
        if self.acc.rail.iter().any(|&r| r as f32 > 0.9 * n) {
            flags.insert(Flags::DISCONNECTED);
        }
        let finite = |x: f32| if math::is_finite(x) { x } else { 0.0 };
        let mut r = CycleReport {
            seq: self.seq,
            t_impact_us: clock::edge_us(index, self.sample_hz),
            period_s,
            frequency_hz: 0.0,
            peak_rear_pa: finite(self.acc.peak_p1),
            peak_front_pa: finite(self.acc.peak_p2),
            wear_index_j: self.wear.wear_index_j(),
            drift_score: self.wear.cusum,
            calibration_hash: self.calibration_hash,
            flags,
            ..Default::default()
        };
        r.mark_chambers_unread();
        self.counters.cycles = self.counters.cycles.wrapping_add(1);
        self.counters.invalid_cycles = self.counters.invalid_cycles.wrapping_add(1);
        self.seq = self.seq.wrapping_add(1);
        r
    }

    #[inline(never)]
    fn close_cycle(&mut self, index: u64) -> CycleReport {
        self.acc.settle(&self.d, &self.cal);
        let start = self.cycle_start;
        let period_s = index.wrapping_sub(start) as f32 * self.d.dt;
        let tail = self.delay_len as u32;
        let mut e = estimate::estimate(
            &self.acc,
            &self.cfg,
            &self.d,
            self.blank_samples,
            self.cycle_contact_samples,
            tail,
            self.friction_guess,
        );
        let n = self.acc.samples.max(1.0);
        if self.acc.rail.iter().any(|&r| r as f32 > 0.9 * n) {
            e.flags.insert(Flags::DISCONNECTED);
        }
        if self.dropped_in_cycle {
            e.flags.insert(Flags::DROPPED_SAMPLES);
        }
        if period_s < self.cfg.min_period_s
            || period_s > self.cfg.max_period_s
            || self.history.contradicts(period_s, e.stroke_m)
        {
            e.flags.insert(Flags::IMPLAUSIBLE);
        }
        let m = self.d.m;
        let mut r = CycleReport {
            seq: self.seq,
            t_impact_us: clock::edge_us(index, self.sample_hz),
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
            wear_index_j: self.wear.wear_index_j(),
            wear_remaining_fraction: 0.0,
            remaining_life_cycles: 0.0,
            drift_score: self.wear.cusum,
            calibration_hash: self.calibration_hash,
            flags: e.flags,
            ..Default::default()
        };
        // Read at the cycle's close by a reader that holds its codes (a
        // board's `hammer_app::chamber_reading`), not here.
        r.mark_chambers_unread();
        if r.impact_energy_j > 0.0 {
            r.friction_work_ratio = e.friction_work_stroke_j / r.impact_energy_j;
        }
        self.counters.cycles = self.counters.cycles.wrapping_add(1);
        self.seq = self.seq.wrapping_add(1);
        r
    }

    /// The bookkeeping that depends on a closed cycle's validity, done when
    /// its report leaves (after its closing shock was seen to end).
    #[inline(never)]
    fn finalize(&mut self, mut r: CycleReport) -> CycleReport {
        if r.is_valid() {
            self.history.push(r.period_s, r.stroke_m);
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
        r
    }
}
