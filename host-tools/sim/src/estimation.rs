//! The one path from a trace to the estimator's input: the calibration that
//! reads the sensor chain's ADC codes, and the codes themselves. `hammer
//! estimate`, `report`, `diagnose`, the app's tests and the end-to-end tests
//! all open traces through here.

use hammer_estimator::{ChannelCal, ChannelSpec, Config, CycleReport, Estimator, RawSample};
use hammer_trace::config::{check_range, ConfigError};
use std::path::Path;

use hammer_trace::trace::{read_csv, Trace, TraceError};
use hammer_trace::EstimatorParams;

use crate::params::HammerParams;
use crate::sensor::{SensorChannel, SensorModel};
use crate::simulate::{read_simulated_sidecar, Sidecar};
use crate::SimConfig;

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

/// A trace file opened for the estimator: the samples back as the ADC codes
/// they came from, and the configuration that reads them.
#[derive(Debug, Clone)]
pub struct EstimationInput {
    pub trace: Trace,
    pub sidecar: Option<Sidecar>,
    /// The operating point used: the caller's, else the sidecar's.
    pub supply_bar: Option<f64>,
    pub config: Config,
    pub codes: Vec<RawSample>,
}

#[derive(Debug, thiserror::Error)]
pub enum OpenError {
    #[error(transparent)]
    Trace(#[from] TraceError),
    #[error(transparent)]
    Config(#[from] ConfigError),
}

/// Opens `path` (and its sidecar) for estimation: the hammer and sensors the
/// simulator recorded in the sidecar win over `file`'s, the estimator table
/// comes from `file`, the supply pressure from `supply_bar` or the sidecar.
pub fn open_for_estimation(
    path: &Path,
    file: &SimConfig,
    supply_bar: Option<f64>,
) -> Result<EstimationInput, OpenError> {
    let trace = read_csv(path)?;
    let sidecar = read_simulated_sidecar(path)?;
    let supply_bar = supply_bar.or(sidecar.as_ref().and_then(|s| s.supply_pressure_bar));
    let sensors = sensors_for(sidecar.as_ref(), &file.sensors);
    let hammer = sidecar
        .as_ref()
        .and_then(|s| s.simulation.as_ref())
        .map_or(&file.hammer, |s| &s.config.hammer);
    let config = estimator_config(hammer, &sensors, &file.estimator, 1.0 / trace.dt_s, supply_bar)?;
    let codes = to_codes(&trace, &config);
    Ok(EstimationInput {
        trace,
        sidecar,
        supply_bar,
        config,
        codes,
    })
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
