//! Offline use of the no_std estimator: traces in, per-cycle records out.
//! The same crate and the same code path as the firmware; only the sample
//! source differs (a trace file's physical values turned back into ADC codes).

use std::fmt::Write as _;

use hammer_estimator::{ChannelCal, ChannelSpec, Config, CycleReport, Estimator, RawSample};
use serde::{Deserialize, Serialize};

use crate::config::{check_range, ConfigError};
use crate::sim::params::HammerParams;
use crate::sim::sensor::{SensorChannel, SensorModel};
use crate::trace::{Sidecar, Trace};

/// The `[estimator]` table of a config file: thresholds and the sensors'
/// calibration accuracy (what the stated uncertainty is built from).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct EstimatorParams {
    pub impact_threshold_mps2: f64,
    pub blank_before_s: f64,
    pub blank_after_s: f64,
    pub min_period_s: f64,
    pub max_period_s: f64,
    /// Discharge time constant of the piezo accelerometer (0: no zero-shift fit).
    pub accel_zero_shift_tau_s: f64,
    pub coverage_factor: f64,
    pub residual_correlation_factor: f64,
    pub stuck_after_s: f64,
    pub pressure_gain_uncertainty: f64,
    pub pressure_offset_uncertainty_pa: f64,
    pub accel_gain_uncertainty: f64,
    pub accel_offset_uncertainty_mps2: f64,
    pub wear_budget_j: f64,
    pub baseline_cycles: u16,
    pub cusum_k: f64,
    pub cusum_h: f64,
}

impl Default for EstimatorParams {
    fn default() -> Self {
        let c = Config::default();
        Self {
            impact_threshold_mps2: c.impact_threshold_mps2 as f64,
            blank_before_s: c.blank_before_s as f64,
            blank_after_s: c.blank_after_s as f64,
            min_period_s: c.min_period_s as f64,
            max_period_s: c.max_period_s as f64,
            accel_zero_shift_tau_s: c.accel_zero_shift_tau_s as f64,
            coverage_factor: c.coverage_factor as f64,
            residual_correlation_factor: c.residual_correlation_factor as f64,
            stuck_after_s: c.stuck_after_s as f64,
            pressure_gain_uncertainty: c.rear_spec.gain_rel as f64,
            pressure_offset_uncertainty_pa: c.rear_spec.offset as f64,
            accel_gain_uncertainty: c.accel_spec.gain_rel as f64,
            accel_offset_uncertainty_mps2: c.accel_spec.offset as f64,
            wear_budget_j: c.wear.budget_j as f64,
            baseline_cycles: c.wear.baseline_cycles,
            cusum_k: c.wear.cusum_k as f64,
            cusum_h: c.wear.cusum_h as f64,
        }
    }
}

fn cal(ch: &SensorChannel) -> ChannelCal {
    ChannelCal::from_range(ch.range_min as f32, ch.range_max as f32, ch.adc_bits.min(16) as u8)
}

/// The estimator's configuration for a trace: hammer and sensors from the
/// config (or the simulator's sidecar), the sample rate from the trace.
pub fn estimator_config(
    hammer: &HammerParams,
    sensors: &SensorModel,
    p: &EstimatorParams,
    sample_rate_hz: f64,
    supply_bar: Option<f64>,
) -> Result<Config, ConfigError> {
    let to_err = |e: hammer_estimator::ConfigError| ConfigError::Invalid {
        field: "estimator".into(),
        message: e.to_string(),
    };
    check_range("estimator.coverage_factor", p.coverage_factor, 1.0, 5.0)?;
    for ch in [&sensors.rear, &sensors.front, &sensors.accel] {
        check_range("sensors.*.adc_bits", ch.adc_bits as f64, 8.0, 16.0)?;
    }
    let mut c = Config {
        sample_rate_hz: sample_rate_hz as f32,
        geometry: hammer.geometry(),
        inclination_deg: hammer.inclination_deg as f32,
        rear: cal(&sensors.rear),
        front: cal(&sensors.front),
        accel: cal(&sensors.accel),
        rear_spec: ChannelSpec {
            gain_rel: p.pressure_gain_uncertainty as f32,
            offset: p.pressure_offset_uncertainty_pa as f32,
        },
        front_spec: ChannelSpec {
            gain_rel: p.pressure_gain_uncertainty as f32,
            offset: p.pressure_offset_uncertainty_pa as f32,
        },
        accel_spec: ChannelSpec {
            gain_rel: p.accel_gain_uncertainty as f32,
            offset: p.accel_offset_uncertainty_mps2 as f32,
        },
        impact_threshold_mps2: p.impact_threshold_mps2 as f32,
        blank_before_s: p.blank_before_s as f32,
        blank_after_s: p.blank_after_s as f32,
        min_period_s: p.min_period_s as f32,
        max_period_s: p.max_period_s as f32,
        accel_zero_shift_tau_s: p.accel_zero_shift_tau_s as f32,
        coverage_factor: p.coverage_factor as f32,
        residual_correlation_factor: p.residual_correlation_factor as f32,
        stuck_after_s: p.stuck_after_s as f32,
        supply_pressure_pa: supply_bar.map_or(f32::NAN, |b| (b * 1e5) as f32),
        ..Config::default()
    };
    c.wear.budget_j = p.wear_budget_j as f32;
    c.wear.baseline_cycles = p.baseline_cycles;
    c.wear.cusum_k = p.cusum_k as f32;
    c.wear.cusum_h = p.cusum_h as f32;
    c.validate().map_err(to_err)?;
    Ok(c)
}

/// The sensor chain a trace was recorded with: from its sidecar when the
/// simulator wrote it, else the config's.
pub fn sensors_for(sidecar: Option<&Sidecar>, fallback: &SensorModel) -> SensorModel {
    sidecar
        .and_then(|s| s.simulation.as_ref())
        .map_or_else(|| fallback.clone(), |sim| sim.config.sensors.clone())
}

/// Physical values back to the ADC codes they came from.
pub fn to_codes(trace: &Trace, c: &Config) -> Vec<RawSample> {
    let code = |cal: &ChannelCal, v: f64| {
        let x = (v as f32 / cal.scale + cal.zero_code).round();
        if x.is_nan() {
            0
        } else {
            x.clamp(0.0, cal.full_scale_code as f32) as u16
        }
    };
    (0..trace.len())
        .map(|i| RawSample {
            rear: code(&c.rear, trace.p_rear_pa[i]),
            front: code(&c.front, trace.p_front_pa[i]),
            accel: code(&c.accel, trace.accel_mps2[i]),
        })
        .collect()
}

pub fn run(samples: &[RawSample], c: Config) -> Result<Vec<CycleReport>, ConfigError> {
    let mut est = Estimator::new(c).map_err(|e| ConfigError::Invalid {
        field: "estimator".into(),
        message: e.to_string(),
    })?;
    let mut out = Vec::new();
    est.push_block(samples, |r| out.push(r));
    Ok(out)
}

pub fn flag_names(r: &CycleReport) -> Vec<&'static str> {
    r.flags.names().collect()
}

/// One JSON object per cycle.
pub fn jsonl_record(r: &CycleReport) -> serde_json::Value {
    serde_json::json!({
        "seq": r.seq,
        "t_impact_s": r.t_impact_s,
        "period_s": r.period_s,
        "frequency_hz": r.frequency_hz,
        "friction_n": r.friction_n,
        "friction_stroke_n": r.friction_stroke_n,
        "friction_backhaul_n": r.friction_backhaul_n,
        "friction_uncertainty_n": r.friction_uncertainty_n,
        "friction_stroke_uncertainty_n": r.friction_stroke_uncertainty_n,
        "friction_backhaul_uncertainty_n": r.friction_backhaul_uncertainty_n,
        "impact_velocity_mps": r.impact_velocity_mps,
        "impact_velocity_frictionless_mps": r.impact_velocity_frictionless_mps,
        "impact_energy_j": r.impact_energy_j,
        "impact_energy_frictionless_j": r.impact_energy_frictionless_j,
        "impact_energy_uncertainty_j": r.impact_energy_uncertainty_j,
        "impact_energy_frictionless_uncertainty_j": r.impact_energy_frictionless_uncertainty_j,
        "friction_work_j": r.friction_work_j,
        "friction_work_ratio": r.friction_work_ratio,
        "stroke_m": r.stroke_m,
        "peak_rear_pa": r.peak_rear_pa,
        "peak_front_pa": r.peak_front_pa,
        "accel_zero_shift_mps2": r.accel_zero_shift_mps2,
        "wear_index": r.wear_index_j,
        "wear_remaining_fraction": r.wear_remaining_fraction,
        "remaining_life_cycles": r.remaining_life_cycles,
        "drift_score": r.drift_score,
        "valid": r.is_valid(),
        "flags": flag_names(r),
    })
}

pub const CSV_HEADER: &str = "seq,t_impact_s,frequency_hz,friction_n,friction_stroke_n,friction_backhaul_n,friction_uncertainty_n,impact_velocity_mps,impact_energy_j,impact_energy_frictionless_j,impact_energy_uncertainty_j,friction_work_j,stroke_m,wear_index,drift_score,valid,flags";

pub fn csv_record(r: &CycleReport) -> String {
    format!(
        "{},{:.6},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{}",
        r.seq,
        r.t_impact_s,
        r.frequency_hz,
        r.friction_n,
        r.friction_stroke_n,
        r.friction_backhaul_n,
        r.friction_uncertainty_n,
        r.impact_velocity_mps,
        r.impact_energy_j,
        r.impact_energy_frictionless_j,
        r.impact_energy_uncertainty_j,
        r.friction_work_j,
        r.stroke_m,
        r.wear_index_j,
        r.drift_score,
        r.is_valid(),
        flag_names(r).join("|")
    )
}

/// A human-readable table with a summary line over the valid cycles.
pub fn table(reports: &[CycleReport]) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "{:>4} {:>9} {:>7} {:>15} {:>7} {:>7} {:>15} {:>8} {:>7} {:>7}  flags",
        "seq", "t_imp_s", "f_hz", "friction_n", "F_str", "F_back", "energy_j", "E_nofr", "stroke", "wear_j"
    );
    for r in reports {
        let _ = writeln!(
            s,
            "{:>4} {:>9.4} {:>7.3} {:>7.2} ± {:<5.2} {:>7.2} {:>7.2} {:>7.3} ± {:<5.3} {:>8.3} {:>5.1}mm {:>7.1}  {}",
            r.seq,
            r.t_impact_s,
            r.frequency_hz,
            r.friction_n,
            r.friction_uncertainty_n,
            r.friction_stroke_n,
            r.friction_backhaul_n,
            r.impact_energy_j,
            r.impact_energy_uncertainty_j,
            r.impact_energy_frictionless_j,
            r.stroke_m * 1e3,
            r.wear_index_j,
            flag_names(r).join(",")
        );
    }
    let valid: Vec<&CycleReport> = reports.iter().filter(|r| r.is_valid()).collect();
    if !valid.is_empty() {
        let n = valid.len() as f32;
        let mean = |f: fn(&CycleReport) -> f32| valid.iter().map(|r| f(r)).sum::<f32>() / n;
        let sd = |f: fn(&CycleReport) -> f32| {
            let m = mean(f);
            (valid.iter().map(|r| (f(r) - m).powi(2)).sum::<f32>() / (n - 1.0).max(1.0)).sqrt()
        };
        let _ = writeln!(
            s,
            "summary: {} of {} cycles valid; friction {:.3} N (cycle-to-cycle sd {:.3}), energy {:.4} J (sd {:.4}), friction-blind energy {:.4} J, frequency {:.3} Hz, friction work {:.1} % of impact energy",
            valid.len(),
            reports.len(),
            mean(|r| r.friction_n),
            sd(|r| r.friction_n),
            mean(|r| r.impact_energy_j),
            sd(|r| r.impact_energy_j),
            mean(|r| r.impact_energy_frictionless_j),
            mean(|r| r.frequency_hz),
            100.0 * mean(|r| r.friction_work_ratio)
        );
    } else {
        let _ = writeln!(s, "summary: no valid cycle among {}", reports.len());
    }
    s
}
