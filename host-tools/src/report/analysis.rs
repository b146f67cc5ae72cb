//! The estimator's view of the trace, without drawing: the estimator run as
//! `hammer estimate` runs it, the summary over the valid cycles and, for a
//! simulated trace, the match with the simulator's truth.

use std::path::Path;

use anyhow::{anyhow, bail, Result};
use hammer_estimator::{Config, CycleReport};
use indicatif::ProgressBar;

use super::{stage, ReportArgs};
use hammer_sim::estimation::no_impact_note;
use hammer_sim::estimation::open_for_estimation;
use hammer_sim::simulate::{Sidecar, SimulationInfo};
use hammer_sim::{CycleTruth, SimConfig};
use hammer_trace::trace::Trace;

/// A report cycle and a truth cycle are the same impact when their impact
/// times agree this closely (two samples at 100 kS/s).
pub const MATCH_TOLERANCE_S: f64 = 20e-6;

/// Means over the valid cycles: what the report's summary table shows.
/// NaN where there is no valid cycle.
#[derive(Debug, Clone, PartialEq)]
pub struct Summary {
    pub cycles: usize,
    pub valid_cycles: usize,
    pub friction_mean_n: f64,
    /// Cycle-to-cycle standard deviation of the friction.
    pub friction_sd_n: f64,
    /// Mean expanded uncertainty the estimator states per cycle.
    pub friction_uncertainty_n: f64,
    pub energy_mean_j: f64,
    pub energy_sd_j: f64,
    pub energy_uncertainty_j: f64,
    /// What a friction-blind method (earlier studies) would report.
    pub energy_frictionless_mean_j: f64,
    pub frequency_mean_hz: f64,
    /// Stroke friction work over impact energy.
    pub friction_work_ratio: f64,
    /// Wear index after the last cycle (cumulative friction work).
    pub wear_index_j: f64,
    /// How often each flag was raised, in the estimator's flag order.
    pub flag_counts: Vec<(&'static str, usize)>,
}

/// The simulator's truth over the matched valid cycles, and the estimate's mean error.
#[derive(Debug, Clone, PartialEq)]
pub struct TruthSummary {
    pub matched_cycles: usize,
    pub friction_n: f64,
    pub friction_error_n: f64,
    pub energy_j: f64,
    pub energy_error_j: f64,
    pub frequency_hz: f64,
    pub frequency_error_hz: f64,
    pub friction_work_ratio: f64,
}

/// Where the supply pressure of the report came from.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum Supply {
    Flag(f64),
    Sidecar(f64),
    Unknown,
}

impl Supply {
    pub(super) fn bar(self) -> Option<f64> {
        match self {
            Supply::Flag(b) | Supply::Sidecar(b) => Some(b),
            Supply::Unknown => None,
        }
    }
}

/// Everything the report is drawn from.
pub(super) struct Analysis {
    /// The input's file name: the page shows no machine-specific path.
    pub(super) name: String,
    pub(super) config_file: Option<String>,
    pub(super) trace: Trace,
    pub(super) sidecar: Option<Sidecar>,
    pub(super) supply: Supply,
    pub(super) cfg: Config,
    pub(super) reports: Vec<CycleReport>,
}

impl Analysis {
    /// Report times count from the first sample; trace and truth times do not.
    pub(super) fn t0_s(&self) -> f64 {
        self.trace.t_s.first().copied().unwrap_or(0.0)
    }

    pub(super) fn simulation(&self) -> Option<&SimulationInfo> {
        self.sidecar.as_ref()?.simulation.as_ref()
    }

    pub(super) fn truth(&self) -> Option<&[CycleTruth]> {
        self.simulation().map(|s| s.cycles.as_slice()).filter(|c| !c.is_empty())
    }
}

/// Reads the trace and runs the estimator over it, configured exactly as
/// `hammer estimate` does (config file, then the sidecar's hammer and sensors).
pub(super) fn analyse(args: &ReportArgs, pb: &ProgressBar) -> Result<Analysis> {
    let file: SimConfig = crate::import::config_with_map(args.config.as_deref(), args.map.as_deref())?;
    // The reader's message already names the path and the OS error; as an anyhow
    // chain it would print the OS error twice.
    let input = open_for_estimation(&args.input, &file, args.supply_bar).map_err(|e| anyhow!("{e}"))?;
    let supply = match (args.supply_bar, input.supply_bar) {
        (Some(b), _) => Supply::Flag(b),
        (None, Some(b)) => Supply::Sidecar(b),
        (None, None) => Supply::Unknown,
    };
    let (trace, sidecar, cfg) = (input.trace, input.sidecar, input.config);
    stage(pb, "estimating");
    let reports = hammer_sim::estimation::run(&input.codes, cfg)?;
    let name = file_name(&args.input);
    if !reports.iter().any(|r| r.is_cycle()) {
        bail!(
            "{name}: no complete impact cycle in {} samples ({:.3} s): a cycle needs two impacts \
             (acceleration below −{} m/s²) at most {} s apart{}",
            trace.len(),
            trace.len() as f64 * trace.dt_s,
            cfg.impact_threshold_mps2,
            cfg.max_period_s,
            no_impact_note(&reports, &input.config)
        );
    }
    Ok(Analysis {
        name,
        config_file: args.config.as_deref().map(file_name),
        trace,
        sidecar,
        supply,
        cfg,
        reports,
    })
}

pub(super) fn file_name(p: &Path) -> String {
    p.file_name()
        .map_or_else(|| p.display().to_string(), |n| n.to_string_lossy().into_owned())
}

fn mean(xs: impl Iterator<Item = f64>) -> f64 {
    let (n, s) = xs.fold((0usize, 0.0), |(n, s), x| (n + 1, s + x));
    if n == 0 {
        f64::NAN
    } else {
        s / n as f64
    }
}

/// Sample standard deviation (n − 1); 0 for a single value, NaN for none.
fn sd(xs: &[f64]) -> f64 {
    if xs.is_empty() {
        return f64::NAN;
    }
    let m = mean(xs.iter().copied());
    let ss: f64 = xs.iter().map(|x| (x - m).powi(2)).sum();
    (ss / (xs.len() as f64 - 1.0).max(1.0)).sqrt()
}

/// The summary over the valid cycles of `reports`.
pub fn summarize(reports: &[CycleReport]) -> Summary {
    let valid: Vec<&CycleReport> = reports.iter().filter(|r| r.is_valid()).collect();
    let col = |f: fn(&CycleReport) -> f32| valid.iter().map(|r| f(r) as f64).collect::<Vec<f64>>();
    let avg = |f: fn(&CycleReport) -> f32| mean(col(f).into_iter());
    let flag_counts = hammer_estimator::Flags::NAMES
        .iter()
        .map(|&(flag, name)| (name, reports.iter().filter(|r| r.flags.contains(flag)).count()))
        .filter(|&(_, n)| n > 0)
        .collect();
    Summary {
        cycles: reports.len(),
        valid_cycles: valid.len(),
        friction_mean_n: avg(|r| r.friction_n),
        friction_sd_n: sd(&col(|r| r.friction_n)),
        friction_uncertainty_n: avg(|r| r.friction_uncertainty_n),
        energy_mean_j: avg(|r| r.impact_energy_j),
        energy_sd_j: sd(&col(|r| r.impact_energy_j)),
        energy_uncertainty_j: avg(|r| r.impact_energy_uncertainty_j),
        energy_frictionless_mean_j: avg(|r| r.impact_energy_frictionless_j),
        frequency_mean_hz: avg(|r| r.frequency_hz),
        friction_work_ratio: avg(|r| r.friction_work_ratio),
        wear_index_j: reports.last().map_or(f64::NAN, |r| r.wear_index_j as f64),
        flag_counts,
    }
}

/// A report cycle and the simulator's truth of the same impact.
#[derive(Debug, Clone, Copy)]
pub struct Matched<'a> {
    pub report: &'a CycleReport,
    pub truth: &'a CycleTruth,
}

/// Pairs every report with the truth cycle whose impact lies within
/// [`MATCH_TOLERANCE_S`]; `t0_s` is the trace's first sample time (report
/// times count from it, truth times do not).
pub fn match_truth<'a>(reports: &'a [CycleReport], truth: &'a [CycleTruth], t0_s: f64) -> Vec<Matched<'a>> {
    reports
        .iter()
        .filter_map(|r| {
            let t = r.t_impact_s() + t0_s;
            let truth = truth.iter().find(|c| (c.t_impact_s - t).abs() <= MATCH_TOLERANCE_S)?;
            Some(Matched { report: r, truth })
        })
        .collect()
}

/// Truth means and mean errors over the matched cycles whose estimate is valid.
pub fn truth_summary(matched: &[Matched]) -> TruthSummary {
    let valid: Vec<&Matched> = matched.iter().filter(|m| m.report.is_valid()).collect();
    let avg = |f: &dyn Fn(&Matched) -> f64| mean(valid.iter().map(|m| f(m)));
    let energy_j = avg(&|m| m.truth.impact_energy_j);
    TruthSummary {
        matched_cycles: valid.len(),
        friction_n: avg(&|m| m.truth.friction_cycle_n),
        friction_error_n: avg(&|m| m.report.friction_n as f64 - m.truth.friction_cycle_n),
        energy_j,
        energy_error_j: avg(&|m| m.report.impact_energy_j as f64 - m.truth.impact_energy_j),
        frequency_hz: avg(&|m| m.truth.frequency_hz),
        frequency_error_hz: avg(&|m| m.report.frequency_hz as f64 - m.truth.frequency_hz),
        friction_work_ratio: avg(&|m| m.truth.friction_work_stroke_j) / energy_j,
    }
}
