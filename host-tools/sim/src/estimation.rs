//! The one path from a trace to the estimator's input: the calibration that
//! reads the sensor chain's ADC codes, and the codes themselves. `hammer
//! estimate`, `report`, `diagnose`, the app's tests and the end-to-end tests
//! all open traces through here.

use hammer_estimator::{Config, CycleReport, Estimator, RawSample};
use hammer_trace::config::ConfigError;
use std::path::Path;

use hammer_trace::import::inspect::{RailScan, ABSOLUTE_MIN_GAUGE_PA};
use hammer_trace::import::{self, Understood};
use hammer_trace::rows::{Item, Row, Uniform};
use hammer_trace::trace::{parse_sidecar_as, Gap, Trace, TraceError};
use hammer_trace::EstimatorParams;

use crate::params::HammerParams;
use crate::sensor::SensorModel;
use crate::simulate::{read_simulated_sidecar, Sidecar};
use crate::SimConfig;

/// The estimator's configuration for a trace: hammer and sensors from the
/// config (or the simulator's sidecar), the sample rate from the trace.
pub fn estimator_config(
    hammer: &HammerParams,
    sensors: &SensorModel,
    p: &EstimatorParams,
    sample_rate_hz: f64,
    supply_bar: Option<f64>,
) -> Result<Config, ConfigError> {
    sensors.validate()?;
    let mut c = Config {
        sample_rate_hz: sample_rate_hz as f32,
        geometry: hammer.geometry(),
        inclination_deg: hammer.inclination_deg as f32,
        rear: sensors.rear.calibration(),
        front: sensors.front.calibration(),
        accel: sensors.accel.calibration(),
        supply_pressure_pa: supply_bar.map_or(f32::NAN, |b| (b * 1e5) as f32),
        chambers: hammer_estimator::ChamberConfig {
            rear_dead_m3: hammer.rear_dead_volume_m3 as f32,
            front_dead_m3: hammer.front_dead_volume_m3 as f32,
            rear_outlet_m: hammer.rear_outlet_opens_m as f32,
            front_outlet_m: hammer.front_outlet_opens_m as f32,
            pressure_group_delay_s: sensors.front.group_delay_s(1.0 / sample_rate_hz) as f32,
        },
        ..Config::default()
    };
    p.apply(&mut c);
    c.validate().map_err(in_user_terms)?;
    if sample_rate_hz < MIN_SAMPLE_RATE_HZ {
        return Err(ConfigError::Invalid {
            field: "sample rate".into(),
            message: format!(
                "{} kS/s is below the {} kS/s this estimator needs: the impact's contact lasts about 80 µs, and below that rate it can fall between samples, so impacts are missed and cycles merge (docs/estimator.md, \"Sample rate\"); record at {} kS/s or more",
                sample_rate_hz / 1e3,
                MIN_SAMPLE_RATE_HZ / 1e3,
                MIN_SAMPLE_RATE_HZ / 1e3
            ),
        });
    }
    Ok(c)
}

impl SimConfig {
    /// The estimator configuration that reads this run's codes
    /// ([`crate::Simulation::codes`]) as the board would: the hammer and
    /// sensors simulated, the `[estimator]` table, the output rate, and the
    /// supply pressure if the board is told it (`None`: unknown, as on a
    /// board nobody configured).
    pub fn estimator_config(&self, supply_bar: Option<f64>) -> Result<hammer_estimator::Config, ConfigError> {
        estimator_config(
            &self.hammer,
            &self.sensors,
            &self.estimator,
            1.0 / self.solver.output_step_s,
            supply_bar,
        )
    }
}

/// The lowest sample rate a trace is estimated at. The impact (steel on
/// steel) lasts about 80 µs: at 20 kS/s (50 µs) every contact holds at least
/// one sample, with margin for a recorder's anti-alias filter, which at
/// 16.7 kS/s already loses impacts (docs/estimator.md, "Sample rate").
pub const MIN_SAMPLE_RATE_HZ: f64 = 20e3;

/// Shortest trace on which both chambers staying above
/// [`ABSOLUTE_MIN_GAUGE_PA`] means absolute pressure: several cycles long.
pub const ABSOLUTE_CHECK_MIN_S: f64 = 0.05;

/// Refuses pressures that are absolute where gauge is expected: a running
/// hammer vents each chamber to atmosphere every cycle, so its lowest gauge
/// pressure is near 0; both chambers staying above half a bar over several
/// cycles is atmosphere left in.
pub fn check_gauge(path: &Path, min_rear_pa: f64, min_front_pa: f64, duration_s: f64) -> Result<(), OpenError> {
    if duration_s >= ABSOLUTE_CHECK_MIN_S && min_rear_pa > ABSOLUTE_MIN_GAUGE_PA && min_front_pa > ABSOLUTE_MIN_GAUGE_PA
    {
        return Err(OpenError::Refused(format!(
            "{}: both chambers stay above {} bar gauge (lowest: rear {:.3} bar, front {:.3} bar); a running hammer vents each chamber to about 0 gauge every cycle, so these pressures look absolute. Give them as gauge: `absolute = true` under [import.p_rear] and [import.p_front] (--map FILE.toml or the config's [import]; docs/trace-format.md)",
            path.display(),
            ABSOLUTE_MIN_GAUGE_PA / 1e5,
            min_rear_pa / 1e5,
            min_front_pa / 1e5
        )));
    }
    Ok(())
}

/// The config-file key each estimator field is built from in
/// [`estimator_config`]; the estimator's own names mean nothing to a user.
const ESTIMATOR_FIELD_KEYS: [(&str, &str); 29] = [
    ("geometry.travel_m", "hammer.impact_position_m"),
    ("chambers.rear_dead_m3", "hammer.rear_dead_volume_m3"),
    ("chambers.front_dead_m3", "hammer.front_dead_volume_m3"),
    ("chambers.rear_outlet_m", "hammer.rear_outlet_opens_m"),
    ("chambers.front_outlet_m", "hammer.front_outlet_opens_m"),
    (
        "chambers.pressure_group_delay_s",
        "sensors.front.bandwidth_hz (its filter's group delay, s)",
    ),
    ("geometry.piston_mass_kg", "hammer.piston_mass_kg"),
    ("geometry.bore_diameter_m", "hammer.bore_diameter_m"),
    ("geometry.rod_diameter_m", "hammer.rod_diameter_m"),
    ("inclination_deg", "hammer.inclination_deg"),
    ("rear_spec.gain_rel", "estimator.pressure_gain_uncertainty"),
    ("front_spec.gain_rel", "estimator.pressure_gain_uncertainty"),
    ("accel_spec.gain_rel", "estimator.accel_gain_uncertainty"),
    ("rear_spec.offset", "estimator.pressure_offset_uncertainty_pa"),
    ("front_spec.offset", "estimator.pressure_offset_uncertainty_pa"),
    ("accel_spec.offset", "estimator.accel_offset_uncertainty_mps2"),
    ("impact_threshold_mps2", "estimator.impact_threshold_mps2"),
    ("blank_before_s", "estimator.blank_before_s"),
    ("blank_after_s", "estimator.blank_after_s"),
    ("min_period_s", "estimator.min_period_s"),
    ("max_period_s", "estimator.max_period_s"),
    ("accel_zero_shift_tau_s", "estimator.accel_zero_shift_tau_s"),
    ("coverage_factor", "estimator.coverage_factor"),
    ("residual_correlation_factor", "estimator.residual_correlation_factor"),
    ("stuck_after_s", "estimator.stuck_after_s"),
    ("wear.baseline_cycles", "estimator.baseline_cycles"),
    ("wear.cusum_k", "estimator.cusum_k"),
    ("wear.cusum_h", "estimator.cusum_h"),
    ("wear.budget_j", "estimator.wear_budget_j"),
];

/// An f32 as the shortest decimal that reads back as it (`0.1`, not `0.10000000149011612`).
fn shortest(v: f32) -> f64 {
    v.to_string().parse().unwrap_or(v as f64)
}

/// An estimator refusal re-worded with the key, flag and units the user wrote.
fn in_user_terms(e: hammer_estimator::ConfigError) -> ConfigError {
    use hammer_estimator::ConfigError as E;
    match e {
        E::OutOfRange { field, value, min, max } => {
            // Two values no config key holds: they come from a flag or the trace.
            let derived = match field {
                "supply_pressure_pa" => Some((
                    "supply pressure",
                    "bar (--supply-bar, else the sidecar's supply_pressure_bar)",
                    "bar",
                    1e5,
                )),
                "sample_rate_hz" => Some((
                    "sample rate",
                    "Hz (1 / the trace's sample interval, or 1 / solver.output_step_s)",
                    "Hz",
                    1.0,
                )),
                _ => None,
            };
            if let Some((name, source, unit, per_unit)) = derived {
                return ConfigError::Invalid {
                    field: name.into(),
                    message: format!(
                        "{} {source} is out of range: allowed {} ..= {} {unit}",
                        shortest(value) / per_unit,
                        shortest(min) / per_unit,
                        shortest(max) / per_unit
                    ),
                };
            }
            if let Some((channel, what)) = field
                .split_once('.')
                .filter(|(_, w)| *w == "zero_code" || *w == "scale")
            {
                let meaning = if what == "zero_code" {
                    "puts zero at ADC code"
                } else {
                    "gives a step per ADC code of"
                };
                return ConfigError::Invalid {
                    field: format!("sensors.{channel}.range_min, sensors.{channel}.range_max"),
                    message: format!(
                        "the range {meaning} {}, outside what the estimator reads ({} ..= {})",
                        shortest(value),
                        shortest(min),
                        shortest(max)
                    ),
                };
            }
            let key = ESTIMATOR_FIELD_KEYS
                .iter()
                .find(|(f, _)| *f == field)
                .map_or_else(|| format!("estimator setting {field}"), |(_, k)| k.to_string());
            ConfigError::OutOfRange {
                field: key,
                value: shortest(value),
                min: shortest(min),
                max: shortest(max),
            }
        }
        E::PeriodTooLongForMemory { max_period_s, limit_s } => ConfigError::Invalid {
            field: "estimator.max_period_s".into(),
            message: format!(
                "{} s is longer than the {} s the estimator's checkpoint memory holds at this sample rate",
                shortest(max_period_s),
                shortest(limit_s)
            ),
        },
    }
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
    /// What the file was read as (format, columns, units).
    pub understood: Understood,
}

#[derive(Debug, thiserror::Error)]
pub enum OpenError {
    #[error(transparent)]
    Trace(#[from] TraceError),
    #[error(transparent)]
    Config(#[from] ConfigError),
    /// A trace that cannot be read right as it is (the message names the fix).
    #[error("{0}")]
    Refused(String),
}

/// Opens `path` (and its sidecar) for estimation: any format
/// `hammer_trace::import` reads, through `file`'s `[import]` mapping. The
/// hammer and sensors the simulator recorded in the sidecar win over
/// `file`'s, the estimator table comes from `file`, the supply pressure from
/// `supply_bar`, else the sidecar, else the mapping.
pub fn open_for_estimation(
    path: &Path,
    file: &SimConfig,
    supply_bar: Option<f64>,
) -> Result<EstimationInput, OpenError> {
    let (trace, understood, embedded) = import::read_trace(path, file.import.as_ref())?;
    let (sidecar, supply_bar, config) = config_for(path, embedded.as_deref(), file, supply_bar, 1.0 / trace.dt_s)?;
    let (config, codes) = checked_codes(&trace, config, path)?;
    Ok(EstimationInput {
        trace,
        sidecar,
        supply_bar,
        config,
        codes,
        understood,
    })
}

/// The sidecar of the trace at `path`, the operating point (the caller's,
/// else the sidecar's) and the estimator configuration that reads it.
/// `embedded` is a sidecar the file carried inside (a Parquet capture's),
/// used when none lies beside it.
fn config_for(
    path: &Path,
    embedded: Option<&str>,
    file: &SimConfig,
    supply_bar: Option<f64>,
    sample_rate_hz: f64,
) -> Result<(Option<Sidecar>, Option<f64>, Config), OpenError> {
    let sidecar = match (read_simulated_sidecar(path)?, embedded) {
        (Some(s), _) => Some(s),
        (None, Some(text)) => Some(parse_sidecar_as(
            text,
            &format!("{} (embedded sidecar)", path.display()),
        )?),
        (None, None) => None,
    };
    let supply_bar = supply_bar
        .or(sidecar.as_ref().and_then(|s| s.supply_pressure_bar))
        .or(file.import.as_ref().and_then(|m| m.supply_pressure_bar));
    let sensors = sensors_for(sidecar.as_ref(), &file.sensors);
    let hammer = sidecar
        .as_ref()
        .and_then(|s| s.simulation.as_ref())
        .map_or(&file.hammer, |s| &s.config.hammer);
    let config = estimator_config(hammer, &sensors, &file.estimator, sample_rate_hz, supply_bar)?;
    Ok((sidecar, supply_bar, config))
}

/// The sensor chain a trace was recorded with: from its sidecar when the
/// simulator wrote it, else the config's.
pub fn sensors_for(sidecar: Option<&Sidecar>, fallback: &SensorModel) -> SensorModel {
    sidecar
        .and_then(|s| s.simulation.as_ref())
        .map_or_else(|| fallback.clone(), |sim| sim.config.sensors.clone())
}

/// The rails a recorder clipped each channel to (rear, front, accel), from
/// a first pass over the file (`inspect::clipped_at`'s rule, streamed).
fn scan_rails(path: &Path, file: &SimConfig) -> Result<[RailScan; 3], OpenError> {
    let mut u = Uniform::new(import::open(path, file.import.as_ref(), false)?.source)?;
    let mut scans: [RailScan; 3] = Default::default();
    while let Some(item) = u.next_item()? {
        if let Item::Sample(r) = item {
            scan_row(&mut scans, [r.p_rear_pa, r.p_front_pa, r.accel_mps2]);
        }
    }
    Ok(scans)
}

/// One sample-set into the three channels' scans (rear, front, accel).
fn scan_row(scans: &mut [RailScan; 3], row: [f64; 3]) {
    for (scan, v) in scans.iter_mut().zip(row) {
        scan.push(v);
    }
}

/// A value a recorder clipped a channel to is a rail, as the board's ADC
/// rails are: the channel's range is moved to end there (its step kept), so
/// that those samples read as code 0 or the top code. The estimator then
/// treats them as it treats its own: a pressure at a rail leaves the
/// friction fit (a vented chamber's dip clipped at 0 gauge by a recorder
/// set to 0–10 bar), an accelerometer at its bottom rail is an impact.
/// Only a rail inside the configured range moves it; one outside already
/// reads as a rail.
pub fn at_recorder_rails(c: &mut Config, scans: &[RailScan; 3]) {
    for (cal, scan) in [&mut c.rear, &mut c.front, &mut c.accel].into_iter().zip(scans) {
        let (lo, hi) = cal.range();
        let [bottom, top] = scan.rails();
        if let Some(v) = bottom.map(|r| r.value as f32).filter(|&v| v > lo && v < hi) {
            // value(0) = −zero·scale = v.
            cal.zero_code = -v / cal.scale;
        }
        let (lo, hi) = cal.range();
        if let Some(v) = top.map(|r| r.value as f32).filter(|&v| v > lo && v < hi) {
            cal.scale = (v - lo) / cal.full_scale_code as f32;
            cal.zero_code = -lo / cal.scale;
        }
    }
}

fn row_codes(c: &Config, r: &Row) -> RawSample {
    RawSample {
        rear: c.rear.code(r.p_rear_pa),
        front: c.front.code(r.p_front_pa),
        accel: c.accel.code(r.accel_mps2),
    }
}

/// A trace file's physical values as the ADC codes of the calibration in
/// `c` (a file holds values; the estimator reads codes). A simulation in
/// memory has its codes already: [`crate::Simulation::codes`].
pub fn to_codes(trace: &Trace, c: &Config) -> Vec<RawSample> {
    (0..trace.len())
        .map(|i| {
            let r = Row {
                t_s: trace.t_s[i],
                p_rear_pa: trace.p_rear_pa[i],
                p_front_pa: trace.p_front_pa[i],
                accel_mps2: trace.accel_mps2[i],
            };
            row_codes(c, &r)
        })
        .collect()
}

fn estimator(c: Config) -> Result<Estimator, ConfigError> {
    Estimator::new(c).map_err(refused)
}

pub(crate) fn refused(e: hammer_estimator::ConfigError) -> ConfigError {
    ConfigError::Invalid {
        field: "estimator".into(),
        message: e.to_string(),
    }
}

pub fn run(samples: &[RawSample], c: Config) -> Result<Vec<CycleReport>, ConfigError> {
    run_with_gaps(samples, &[], c)
}

/// [`run`] over a trace with rows missing: the estimator is told of each gap
/// (it flags the cycle the gap falls in and keeps the timing right).
pub fn run_with_gaps(samples: &[RawSample], gaps: &[Gap], c: Config) -> Result<Vec<CycleReport>, ConfigError> {
    let mut est = estimator(c)?;
    let mut out = Vec::new();
    between_gaps(samples, gaps, |part, missing| {
        est.push_block(part, |r| out.push(r));
        if let Some(n) = missing {
            est.push_gap(n);
        }
    });
    Ok(out)
}

/// `f(stretch, samples missing after it)` for each stretch of `samples`
/// between `gaps`, in order; the last with none after it.
pub(crate) fn between_gaps(samples: &[RawSample], gaps: &[Gap], mut f: impl FnMut(&[RawSample], Option<u32>)) {
    let mut at = 0;
    for g in gaps {
        let upto = g.before.min(samples.len());
        f(&samples[at..upto], Some(g.missing.min(u32::MAX as u64) as u32));
        at = upto;
    }
    f(&samples[at..], None);
}

impl EstimationInput {
    /// The estimator over the whole trace, gaps included.
    pub fn run(&self) -> Result<Vec<CycleReport>, ConfigError> {
        run_with_gaps(&self.codes, &self.trace.gaps, self.config)
    }
}

/// What a streamed estimation went through.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StreamSummary {
    pub samples: u64,
    /// Sample periods with no row (gaps in the file's timestamps).
    pub missing_samples: u64,
    pub sample_rate_hz: f64,
    pub supply_bar: Option<f64>,
    /// The configuration the estimator ran with (its geometry names the hammer).
    pub config: Config,
}

/// Sample-sets converted and handed to the estimator at a time.
const STREAM_BLOCK: usize = 4096;

/// The estimator over a trace file of any length in bounded memory: rows are
/// read, converted to codes and pushed block by block, only the required
/// columns parsed (text streams; a binary recorder's file is read whole). Same configuration rules as [`open_for_estimation`];
/// `on_report` sees each cycle as a board would send it: after the
/// chambers' reader has read it (`hammer_app::chambers::Pipeline`, the
/// same bytes as the board's on the same codes; the last cycle, whose
/// 8 ms after it the file does not hold, unread).
pub fn stream_estimation(
    path: &Path,
    file: &SimConfig,
    supply_bar: Option<f64>,
    mut on_report: impl FnMut(CycleReport),
) -> Result<StreamSummary, OpenError> {
    let scans = scan_rails(path, file)?;
    let opened = import::open(path, file.import.as_ref(), false)?;
    let embedded = opened.embedded_sidecar;
    let mut u = Uniform::new(opened.source)?;
    let (_, supply_bar, mut config) = config_for(path, embedded.as_deref(), file, supply_bar, 1.0 / u.dt_s())?;
    at_recorder_rails(&mut config, &scans);
    let mut est = crate::board_reading::pipeline(config)?;
    let mut block = Vec::with_capacity(STREAM_BLOCK);
    let mut summary = StreamSummary {
        samples: 0,
        missing_samples: 0,
        sample_rate_hz: 1.0 / u.dt_s(),
        supply_bar,
        config,
    };
    let (mut min_rear, mut min_front) = (f64::INFINITY, f64::INFINITY);
    while let Some(item) = u.next_item()? {
        match item {
            Item::Sample(r) => {
                min_rear = min_rear.min(r.p_rear_pa);
                min_front = min_front.min(r.p_front_pa);
                block.push(row_codes(&config, &r));
                summary.samples += 1;
                if block.len() == STREAM_BLOCK {
                    est.push_block(&block, &mut on_report);
                    block.clear();
                }
            }
            Item::Gap { missing } => {
                est.push_block(&block, &mut on_report);
                block.clear();
                est.push_gap(missing.min(u32::MAX as u64) as u32);
                summary.missing_samples += missing;
            }
        }
    }
    est.push_block(&block, &mut on_report);
    est.finish(&mut on_report);
    check_gauge(
        path,
        min_rear,
        min_front,
        summary.samples as f64 / summary.sample_rate_hz,
    )?;
    Ok(summary)
}

/// A `--map` file holding its table under `[import]` (else at its top level).
#[derive(serde::Deserialize)]
struct Wrapped {
    import: import::ImportMap,
}

/// Why a configuration or a recorder's mapping was refused.
#[derive(Debug, thiserror::Error)]
pub enum MapError {
    #[error(transparent)]
    Config(#[from] ConfigError),
    /// The mapping file at `path` holds a value out of its range.
    #[error("{path}: {error}")]
    Map { path: String, error: ConfigError },
}

/// The project configuration at `config` (the defaults without one) with
/// the `[import]` table of the mapping file at `map` in place of its own:
/// what `hammer estimate --config --map` and the Python package read.
pub fn config_with_map(config: Option<&Path>, map: Option<&Path>) -> Result<SimConfig, MapError> {
    let mut cfg: SimConfig = match config {
        Some(p) => hammer_trace::config::load_toml(p)?,
        None => SimConfig::default(),
    };
    if let Some(p) = map {
        // Which of the two forms decides how it is read, so an error inside
        // `[import]` is reported as itself, not as "unknown field `import`".
        let wrapped = hammer_trace::config::load_toml::<toml::Table>(p)?.contains_key("import");
        let map = if wrapped {
            hammer_trace::config::load_toml::<Wrapped>(p)?.import
        } else {
            hammer_trace::config::load_toml::<import::ImportMap>(p)?
        };
        map.validate().map_err(|error| MapError::Map {
            path: p.display().to_string(),
            error,
        })?;
        cfg.import = Some(map);
    }
    Ok(cfg)
}

/// The estimator over a trace held in memory (a script's arrays), read with
/// `file`'s hammer, sensors and estimator table and the rules of
/// [`open_for_estimation`] (gauge check, the recorder's rails); `label`
/// names it in messages. With the records, what the run went through, as
/// [`stream_estimation`] tells it.
pub fn estimate_trace(
    trace: &Trace,
    file: &SimConfig,
    supply_bar: Option<f64>,
    label: &str,
) -> Result<(Vec<CycleReport>, StreamSummary), OpenError> {
    if trace.len() < 2 || !(trace.dt_s > 0.0) {
        return Err(OpenError::Refused(format!(
            "{label}: {} samples: a trace needs at least two, evenly spaced in time",
            trace.len()
        )));
    }
    let supply_bar = supply_bar.or(file.import.as_ref().and_then(|m| m.supply_pressure_bar));
    let config = estimator_config(
        &file.hammer,
        &file.sensors,
        &file.estimator,
        1.0 / trace.dt_s,
        supply_bar,
    )?;
    let (config, codes) = checked_codes(trace, config, Path::new(label))?;
    let reports = crate::board_reading::run_with_gaps(&codes, &trace.gaps, config)?;
    let summary = StreamSummary {
        samples: trace.len() as u64,
        missing_samples: trace.gaps.iter().map(|g| g.missing).sum(),
        sample_rate_hz: 1.0 / trace.dt_s,
        supply_bar,
        config,
    };
    Ok((reports, summary))
}

/// A trace in memory checked for gauge pressures, `config` set to the
/// recorder's rails it shows, and its samples as that configuration's codes.
fn checked_codes(trace: &Trace, mut config: Config, path: &Path) -> Result<(Config, Vec<RawSample>), OpenError> {
    let min = |x: &[f64]| x.iter().copied().fold(f64::INFINITY, f64::min);
    check_gauge(
        path,
        min(&trace.p_rear_pa),
        min(&trace.p_front_pa),
        trace.len() as f64 * trace.dt_s,
    )?;
    let mut scans: [RailScan; 3] = Default::default();
    for i in 0..trace.len() {
        scan_row(
            &mut scans,
            [trace.p_rear_pa[i], trace.p_front_pa[i], trace.accel_mps2[i]],
        );
    }
    at_recorder_rails(&mut config, &scans);
    let codes = to_codes(trace, &config);
    Ok((config, codes))
}

/// What the estimator's no-impact records blame, for an error that would
/// otherwise only say "no cycle".
/// When no cycle is valid and the records say the force balance is far off
/// (the accelerometer at odds with the pressure force, or cycles whose
/// friction is implausible), the likeliest cause on sound sensors is the
/// wrong hammer: names the geometry in use and how to give the right one.
pub fn geometry_hint(reports: &[hammer_estimator::CycleReport], config: &hammer_estimator::Config) -> Option<String> {
    use hammer_estimator::Flags;
    if reports.is_empty() || reports.iter().any(|r| r.is_valid()) {
        return None;
    }
    let off = reports
        .iter()
        .all(|r| r.flags.contains(Flags::ACCEL_FAULT) || (r.is_cycle() && r.flags.contains(Flags::IMPLAUSIBLE)));
    if !off {
        return None;
    }
    let g = config.geometry;
    let paper = g == hammer_estimator::Geometry::PAPER;
    Some(format!(
        "the force balance (pressures × areas against mass × acceleration) is far off with the hammer geometry in use: piston {} kg, bore {} mm, rod {} mm{}; give your hammer's [hammer] piston_mass_kg, bore_diameter_m, rod_diameter_m with --config FILE",
        g.piston_mass_kg,
        g.bore_diameter_m * 1e3,
        g.rod_diameter_m * 1e3,
        if paper { " (the paper's hammer, the default)" } else { "" }
    ))
}

pub fn no_impact_note(reports: &[hammer_estimator::CycleReport], config: &hammer_estimator::Config) -> String {
    let flags = reports
        .iter()
        .filter(|r| !r.is_cycle())
        .fold(hammer_estimator::Flags::default(), |f, r| f | r.flags);
    if reports.is_empty() {
        return String::new();
    }
    let mut note = format!(
        "; {} no-impact record(s) flagged {}",
        reports.len(),
        flags.names().collect::<Vec<_>>().join(",")
    );
    if let Some(hint) = geometry_hint(reports, config) {
        note.push_str("; ");
        note.push_str(&hint);
    }
    note
}

/// `hammer estimate`'s refusal of a trace in which no impact cycle closed
/// (its no-impact records are still given first), naming what they blame;
/// `None` when a cycle closed.
pub fn no_cycle_message(path: &Path, summary: &StreamSummary, reports: &[CycleReport]) -> Option<String> {
    if reports.iter().any(|r| r.is_cycle()) {
        return None;
    }
    Some(format!(
        "{}: no impact cycle in {} samples ({:.3} s): no impact reached the estimator's threshold{}",
        path.display(),
        summary.samples,
        (summary.samples + summary.missing_samples) as f64 / summary.sample_rate_hz,
        no_impact_note(reports, &summary.config)
    ))
}

/// `hammer estimate`'s refusal of a trace in which cycles closed but none
/// is valid (their records are still given first): how many, what flagged
/// them, and the wrong hammer when the force balance points to it; `None`
/// when a cycle is valid or none closed ([`no_cycle_message`] says that).
/// A run that gives no number to use is not a success.
pub fn no_valid_message(path: &Path, reports: &[CycleReport], config: &Config) -> Option<String> {
    let mut cycles = reports.iter().filter(|r| r.is_cycle()).peekable();
    cycles.peek()?;
    let (n, flags) = cycles.try_fold((0usize, hammer_estimator::Flags::default()), |(n, f), r| {
        (!r.is_valid()).then_some((n + 1, f | r.flags))
    })?;
    let mut m = format!(
        "{}: no valid cycle among {n} cycle(s), flagged {}",
        path.display(),
        flags.names().collect::<Vec<_>>().join(",")
    );
    if let Some(hint) = geometry_hint(reports, config) {
        m.push_str("; ");
        m.push_str(&hint);
    }
    Some(m)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The estimator's default chambers (what a board runs until it is
    /// told its hammer, and what an old stored record is given) are the
    /// default hammer's and its transducers' delay at 100 kS/s; a hammer's
    /// own reach the board's configuration.
    #[test]
    fn the_default_chambers_are_the_default_hammers() {
        let (h, s) = (HammerParams::default(), SensorModel::default());
        let c = estimator_config(&h, &s, &EstimatorParams::default(), 1e5, None).unwrap();
        let d = Config::default().chambers;
        let (got, want) = (c.chambers, d);
        assert_eq!(
            (got.rear_dead_m3, got.front_dead_m3),
            (want.rear_dead_m3, want.front_dead_m3)
        );
        assert_eq!(
            (got.rear_outlet_m, got.front_outlet_m),
            (want.rear_outlet_m, want.front_outlet_m)
        );
        assert_eq!(got.pressure_group_delay_s, want.pressure_group_delay_s);
        assert_eq!(c.geometry.travel_m, Config::default().geometry.travel_m);
        let mut other = h.clone();
        other.front_dead_volume_m3 = 25e-6;
        let c = estimator_config(&other, &s, &EstimatorParams::default(), 1e5, None).unwrap();
        assert_eq!(c.chambers.front_dead_m3, 25e-6);
    }

    /// Each refusal names the key of the config file it came from, never the
    /// estimator's internal field.
    #[test]
    fn estimator_refusals_name_the_config_keys() {
        let cases: [(fn(&mut EstimatorParams), &str); 6] = [
            (
                |p| p.pressure_gain_uncertainty = 0.9,
                "estimator.pressure_gain_uncertainty = 0.9",
            ),
            (
                |p| p.accel_offset_uncertainty_mps2 = -1.0,
                "estimator.accel_offset_uncertainty_mps2 = -1",
            ),
            (|p| p.wear_budget_j = 0.0, "estimator.wear_budget_j = 0"),
            (|p| p.baseline_cycles = 1, "estimator.baseline_cycles = 1"),
            (|p| p.coverage_factor = 9.0, "estimator.coverage_factor = 9"),
            (|p| p.max_period_s = 5.0, "estimator.max_period_s: 5 s is longer than"),
        ];
        let (h, s) = (HammerParams::default(), SensorModel::default());
        for (set, want) in cases {
            let mut p = EstimatorParams::default();
            set(&mut p);
            let e = estimator_config(&h, &s, &p, 1e5, None).unwrap_err().to_string();
            assert!(e.starts_with(want), "{e}");
        }
        let e = estimator_config(&h, &s, &EstimatorParams::default(), 500.0, None)
            .unwrap_err()
            .to_string();
        assert!(
            e.starts_with("sample rate: 500 Hz") && e.ends_with("1000 ..= 1000000 Hz"),
            "{e}"
        );
        let e = estimator_config(&h, &s, &EstimatorParams::default(), 1e5, Some(-0.5))
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("supply pressure: -0.5 bar (--supply-bar"), "{e}");
    }
}
