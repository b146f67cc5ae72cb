//! Drift since commissioning: each chamber characteristic of the cycles a
//! board reports now, against the same characteristic of the hammer's own
//! reference record (`hammer commission`), with the uncertainty of the
//! difference and an alarm when it stays beyond it.
//!
//! - [`baseline`]: the record's points read as baselines, and a report's
//!   characteristics ([`report_reading`]).
//! - here: the options, the windows and their readings.
//!
//! The characteristics are the diagnosis' model-free ones (feed onsets,
//! closed-phase exponents, feed areas: `hammer_estimator::chambers`), which
//! the board reads into every report at a cycle's close (issue 47). The
//! record holds the board's reports of its cycles too, so both sides are
//! read by the same code and whatever it reads slightly wrong it reads wrong
//! on both sides; the model's form error never enters. The monitor asks the
//! board for nothing: every blow's report counts.
//!
//! A window of `k` reported cycles gives one reading per characteristic:
//! drift = window median − record median, with the expanded uncertainty
//! (k = 2) of that difference from the record's cycle-to-cycle spread,
//! U = 2·√((1.2533·σ)²·(1/m + 1/n) + u_b²) (m cycles in the window, n in
//! the record; 1.2533 = √(π/2), a median's standard error over a mean's;
//! u_b the baseline's systematic part, zero for a record of reports): under
//! no change the window's cycles scatter as the record's did. Medians, and σ
//! from the median absolute deviation (1.4826·MAD), because a cycle whose
//! feed was misread (one in a hundred reads its front feed a millisecond
//! late) would otherwise move a record's mean and widen every
//! window's U: an outlier is left out, not covered. One window beyond
//! its U happens by chance (about 1 in 20 per characteristic), so the alarm
//! needs `--drift-confirm` windows in a row beyond it (3 by default: about
//! 1 in 10 000 per characteristic and window by chance), the way a
//! condition monitor confirms a change before it calls someone.

use std::path::PathBuf;

use serde::Serialize;

use crate::diagnose::features::{feature_name, ESTIMATOR_CHARACTERISTICS};

pub mod baseline;
pub use baseline::{
    read_reports, readings_of, report_reading, steady_readings, steady_reports, write_reports, Baseline, Commissioned,
    Reading, Source, REPORTS_FILE,
};

/// Characteristics read, in [`ESTIMATOR_CHARACTERISTICS`] order.
pub const N_CHARACTERISTICS: usize = ESTIMATOR_CHARACTERISTICS.len();

/// A record's operating point within this of the board's configured supply
/// pressure is the one its reports are read against.
pub const POINT_MATCH_BAR: f64 = 0.05;

/// The monitor's options for the drift since commissioning.
#[derive(clap::Args, Debug, Clone)]
pub struct DriftArgs {
    /// The hammer's commissioning folder (`hammer commission --out DIR`):
    /// the monitor then reads each report's chamber characteristics (the
    /// board reads them at every cycle's close) and shows their drift from the
    /// record at the board's supply pressure, with an alarm when one stays
    /// beyond its uncertainty (docs/fleet.md, "Drift since commissioning").
    #[arg(long, value_name = "DIR")]
    pub reference: Option<PathBuf>,
    /// Reported cycles per drift reading.
    #[arg(long, value_name = "N", default_value_t = 10, requires = "reference",
          value_parser = clap::value_parser!(u32).range(2..=200))]
    pub drift_cycles: u32,
    /// Windows in a row beyond the uncertainty that raise the alarm (their
    /// cycles together must also stand 5 standard uncertainties off).
    #[arg(long, value_name = "N", default_value_t = 3, requires = "reference",
          value_parser = clap::value_parser!(u32).range(1..=100))]
    pub drift_confirm: u32,
    /// Read the drift against a record made with another calibration of
    /// the board (the drift then includes the recalibration's change).
    #[arg(long, requires = "reference")]
    pub allow_stale_reference: bool,
    /// The hammer's configuration (`hammer simulate --config`'s TOML): its
    /// chambers' geometry and transducers, to read the raw captures of a
    /// record made before the board read its chambers (version 1);
    /// default the paper's hammer.
    #[arg(long, value_name = "FILE", requires = "reference")]
    pub hammer_config: Option<PathBuf>,
    /// The record's operating point (gauge supply, bar) to read the
    /// reports against when the board's configuration holds no supply
    /// pressure (a record of one point needs none).
    #[arg(long, value_name = "BAR", requires = "reference", value_parser = crate::cli::supply_bar)]
    pub point_bar: Option<f64>,
}

impl Default for DriftArgs {
    fn default() -> Self {
        Self {
            reference: None,
            drift_cycles: 10,
            drift_confirm: 3,
            allow_stale_reference: false,
            hammer_config: None,
            point_bar: None,
        }
    }
}

/// The median of `xs` (NaN when empty).
pub fn median(xs: &[f64]) -> f64 {
    let mut v = xs.to_vec();
    v.sort_by(f64::total_cmp);
    match v.len() {
        0 => f64::NAN,
        n if n % 2 == 1 => v[n / 2],
        n => 0.5 * (v[n / 2 - 1] + v[n / 2]),
    }
}

/// 1.4826·MAD: the standard deviation of normally scattered values, robust
/// to a few that are not; the plain one where the MAD is zero (values
/// quantised to a few levels).
pub fn robust_sd(xs: &[f64]) -> f64 {
    let m = median(xs);
    let dev: Vec<f64> = xs.iter().map(|x| (x - m).abs()).collect();
    let r = 1.4826 * median(&dev);
    if r > 0.0 || xs.len() < 2 {
        return r;
    }
    let mean = xs.iter().sum::<f64>() / xs.len() as f64;
    (xs.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (xs.len() - 1) as f64).sqrt()
}

/// A median's standard error over a mean's, for normal scatter: √(π/2).
const MEDIAN_EFFICIENCY: f64 = 1.2533;

/// One characteristic's drift in one window.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Characteristic {
    /// The diagnosis' feature name, with its unit (`front_feed_s`, …).
    pub name: String,
    /// Window median; NaN where the window read it in no cycle.
    pub measured: f64,
    /// The record's median at this operating point.
    pub reference: f64,
    /// measured − reference.
    pub drift: f64,
    /// Expanded uncertainty (k = 2) of the drift.
    pub uncertainty: f64,
    /// Cycles of the window that read it.
    pub cycles: usize,
    /// |drift| > uncertainty in this window.
    pub beyond: bool,
    /// Beyond in this window and the ones before it, as many as confirm,
    /// and those windows' cycles together beyond [`ALARM_Z`] standard
    /// uncertainties.
    pub alarm: bool,
}

/// One window's drift readings.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Drift {
    pub supply_bar: f64,
    /// Cycles reported in the window.
    pub cycles: usize,
    /// Windows read so far (this one included).
    pub window: u64,
    pub characteristics: Vec<Characteristic>,
}

impl Drift {
    pub fn alarm(&self) -> bool {
        self.characteristics.iter().any(|c| c.alarm)
    }

    /// The characteristic named `name`.
    pub fn get(&self, name: &str) -> Option<&Characteristic> {
        self.characteristics.iter().find(|c| c.name == name)
    }

    /// The characteristics whose alarm is on.
    pub fn alarms(&self) -> Vec<&str> {
        self.characteristics
            .iter()
            .filter(|c| c.alarm)
            .map(|c| c.name.as_str())
            .collect()
    }

    /// The reading as named numbers for the fleet (MQTT, line protocol):
    /// per characteristic `<name>` (window median) and, its unit kept last,
    /// `<stem>_reference<unit>`, `<stem>_drift<unit>`,
    /// `<stem>_drift_uncertainty<unit>` (`front_feed_s`,
    /// `front_feed_drift_s`, …); then `cycles` and `window`.
    pub fn fields(&self) -> Vec<(String, f64)> {
        let mut out = Vec::new();
        for c in &self.characteristics {
            let (stem, unit) = split_unit(&c.name);
            out.push((c.name.clone(), c.measured));
            out.push((format!("{stem}_reference{unit}"), c.reference));
            out.push((format!("{stem}_drift{unit}"), c.drift));
            out.push((format!("{stem}_drift_uncertainty{unit}"), c.uncertainty));
        }
        out.push(("cycles".into(), self.cycles as f64));
        out.push(("window".into(), self.window as f64));
        out
    }

    /// One line for people: every characteristic read, drift ± U, in
    /// milliseconds for times, alarms named.
    pub fn line(&self) -> String {
        let parts: Vec<String> = self
            .characteristics
            .iter()
            .filter(|c| c.drift.is_finite())
            .map(|c| {
                let (scale, unit) = unit_of(&c.name);
                format!(
                    "{} {:+.3}±{:.3}{unit}{}",
                    c.name,
                    c.drift * scale,
                    c.uncertainty * scale,
                    if c.alarm {
                        " ALARM"
                    } else if c.beyond {
                        " (beyond)"
                    } else {
                        ""
                    }
                )
            })
            .collect();
        format!(
            "drift since commissioning at {} bar ({} cycles, window {}): {}",
            self.supply_bar,
            self.cycles,
            self.window,
            if parts.is_empty() {
                "no characteristic read".into()
            } else {
                parts.join(", ")
            }
        )
    }
}

/// A name's stem and its unit suffix (`front_feed_s` → `front_feed`, `_s`).
fn split_unit(name: &str) -> (&str, &str) {
    ["_s", "_m2"]
        .iter()
        .find_map(|u| name.strip_suffix(u).map(|stem| (stem, *u)))
        .unwrap_or((name, ""))
}

/// A characteristic's display scale and unit from its name's suffix.
pub fn unit_of(name: &str) -> (f64, &'static str) {
    if name.ends_with("_s") {
        (1e3, " ms")
    } else if name.ends_with("_m2") {
        (1e6, " mm²")
    } else {
        (1.0, "")
    }
}

/// The windows of reported cycles at one operating point.
#[derive(Debug, Clone)]
pub struct Window {
    baseline: Baseline,
    k: usize,
    confirm: usize,
    readings: Vec<Reading>,
    /// The last `confirm` windows' cycles, oldest first.
    recent: std::collections::VecDeque<Vec<Reading>>,
    windows: u64,
    /// Windows in a row each characteristic has been beyond.
    beyond_run: [usize; N_CHARACTERISTICS],
}

/// The alarm's threshold: the last `confirm` windows' cycles together must
/// stand this many standard uncertainties from the record. Each window
/// beyond its U alone is not enough: the record's own median error is
/// common to every window read against it, so a record a little off makes
/// every window a little off, and three in a row came 2–13 times as often
/// as (1/20)³ (`examples/drift_false_alarms.rs`: 40 records of 30 cycles,
/// 5000 windows each, 39 records raised an alarm on the sound hammer).
/// Five standard uncertainties is about one chance in 1.7·10⁶ per
/// characteristic and window for normal scatter.
pub const ALARM_Z: f64 = 5.0;

impl Window {
    /// Windows of `k` cycles; `confirm` windows in a row beyond raise the alarm.
    pub fn new(baseline: Baseline, k: usize, confirm: usize) -> Self {
        Self {
            baseline,
            k: k.max(1),
            confirm: confirm.max(1),
            readings: Vec::new(),
            recent: std::collections::VecDeque::new(),
            windows: 0,
            beyond_run: [0; N_CHARACTERISTICS],
        }
    }

    pub fn baseline(&self) -> &Baseline {
        &self.baseline
    }

    /// Takes one reported cycle; a full window gives its drift.
    pub fn push(&mut self, r: Reading) -> Option<Drift> {
        self.readings.push(r);
        if self.readings.len() < self.k {
            return None;
        }
        let readings = std::mem::take(&mut self.readings);
        self.windows += 1;
        self.recent.push_back(readings.clone());
        if self.recent.len() > self.confirm {
            self.recent.pop_front();
        }
        let b = &self.baseline;
        let u_of = |i: usize, m: usize| {
            let n = b.cycles[i];
            if m > 0 && n > 1 {
                let scatter = MEDIAN_EFFICIENCY * b.spread[i] * (1.0 / m as f64 + 1.0 / n as f64).sqrt();
                scatter.hypot(b.systematic[i])
            } else {
                f64::NAN
            }
        };
        let characteristics = (0..N_CHARACTERISTICS)
            .map(|i| {
                let read = |rs: &[Reading]| -> Vec<f64> { rs.iter().map(|r| r[i]).filter(|x| x.is_finite()).collect() };
                let xs = read(&readings);
                let m = xs.len();
                let measured = median(&xs);
                let drift = measured - b.median[i];
                let uncertainty = 2.0 * u_of(i, m);
                let beyond = drift.is_finite() && uncertainty.is_finite() && drift.abs() > uncertainty;
                self.beyond_run[i] = if beyond { self.beyond_run[i] + 1 } else { 0 };
                let alarm = self.beyond_run[i] >= self.confirm && {
                    let pooled: Vec<f64> = self.recent.iter().flat_map(|w| read(w)).collect();
                    (median(&pooled) - b.median[i]).abs() > ALARM_Z * u_of(i, pooled.len())
                };
                Characteristic {
                    name: feature_name(ESTIMATOR_CHARACTERISTICS[i]),
                    measured,
                    reference: b.median[i],
                    drift,
                    uncertainty,
                    cycles: m,
                    beyond,
                    alarm,
                }
            })
            .collect();
        Some(Drift {
            supply_bar: b.supply_bar,
            cycles: readings.len(),
            window: self.windows,
            characteristics,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::diagnose::record::Record;

    /// One misread cycle in a hundred moves neither the median nor the
    /// spread; normal scatter gives its standard deviation back.
    #[test]
    fn an_outlier_moves_neither_the_median_nor_the_spread() {
        let mut rng = hammer_sim::rng::Rng::new(7);
        let normal: Vec<f64> = (0..4000).map(|_| rng.normal()).collect();
        let sd = robust_sd(&normal);
        // 1.4826·MAD over 4 000 normal values: within 0.05 of 1 (its own
        // standard error is about 0.02).
        assert!((sd - 1.0).abs() < 0.05, "{sd}");
        let mut with = normal[..99].to_vec();
        let (sd99, m99) = (robust_sd(&with), median(&with));
        with.push(1e3);
        assert!((robust_sd(&with) - sd99).abs() < 0.05 * sd99 && (median(&with) - m99).abs() < 0.05);
        assert_eq!(median(&[3.0, 1.0]), 2.0);
        assert!(median(&[]).is_nan());
        // Quantised to one level but one: the plain standard deviation.
        assert!((robust_sd(&[1.0, 1.0, 1.0, 2.0]) - 0.5).abs() < 1e-12);
    }

    fn baseline() -> Baseline {
        Baseline {
            supply_bar: 4.0,
            median: [1e-3, 2e-3, 1.3, 1.35, 5e-6, 6e-6],
            spread: [1e-4, 1e-4, 0.02, 0.02, 2e-7, 2e-7],
            cycles: [30; N_CHARACTERISTICS],
            source: Source::Reports,
            systematic: [0.0; N_CHARACTERISTICS],
        }
    }

    /// A window at the record's median reads no drift; one moved by ten
    /// record spreads is beyond at once and alarms on the second window;
    /// the uncertainty is 2·1.2533·σ·√(1/m + 1/n).
    #[test]
    fn a_move_beyond_the_uncertainty_alarms_on_the_second_window() {
        let b = baseline();
        let mut w = Window::new(b.clone(), 4, 2);
        for _ in 0..3 {
            assert!(w.push(b.median).is_none());
        }
        let d = w.push(b.median).expect("a full window");
        assert!(!d.alarm());
        let u = 2.0 * 1.2533 * 1e-4 * (1.0 / 4.0 + 1.0 / 30.0f64).sqrt();
        let f = d.get("front_feed_s").unwrap();
        assert!((f.uncertainty - u).abs() < 1e-12 && f.drift.abs() < 1e-15);
        let mut moved = b.median;
        moved[0] += 10.0 * b.spread[0];
        let first = (0..4).filter_map(|_| w.push(moved)).last().unwrap();
        let f = first.get("front_feed_s").unwrap();
        assert!(f.beyond && !f.alarm, "{f:?}");
        let second = (0..4).filter_map(|_| w.push(moved)).last().unwrap();
        assert!(second.get("front_feed_s").unwrap().alarm);
        assert!(!second.get("rear_feed_s").unwrap().beyond);
        assert!(second.line().contains("front_feed_s +1.000±"), "{}", second.line());
        assert_eq!(second.alarms(), ["front_feed_s"]);
        let fields = second.fields();
        let get = |n: &str| fields.iter().find(|(k, _)| k == n).map(|(_, v)| *v);
        assert_eq!(get("front_feed_drift_s"), Some(10.0 * b.spread[0]));
        assert!(get("front_closed_exponent_drift_uncertainty").is_some());
        assert!(get("rear_feed_area_reference_m2").is_some());
    }

    /// A characteristic no cycle of the window read is NaN, never beyond.
    fn record(points: &[f64]) -> Commissioned {
        Commissioned {
            dir: PathBuf::from("ref"),
            record: Record {
                format: "hammer-commission".into(),
                version: 1,
                firmware_version: "0.1.0".into(),
                board: "b".into(),
                calibration_hash: 0x1234,
                points: vec![],
            },
            baselines: points
                .iter()
                .map(|&supply_bar| Baseline {
                    supply_bar,
                    ..baseline()
                })
                .collect(),
        }
    }

    /// A recalibrated board reads no drift unless told, and then with a
    /// warning; the point is the board's supply, else the one given, else
    /// the record's only one, and a pressure the record lacks is named.
    #[test]
    fn a_stale_record_is_refused_and_the_point_is_chosen_by_pressure() {
        let c = record(&[4.0, 7.0]);
        assert_eq!(c.check_calibration(0x1234, false), Ok(None));
        let e = c.check_calibration(0x9999, false).unwrap_err();
        assert!(e.contains("stale") && e.contains("--allow-stale-reference"), "{e}");
        assert!(c
            .check_calibration(0x9999, true)
            .unwrap()
            .unwrap()
            .contains("recalibration"));
        assert_eq!(c.point_for(4.02, None).unwrap().supply_bar, 4.0);
        assert_eq!(c.point_for(f64::NAN, Some(7.0)).unwrap().supply_bar, 7.0);
        assert!(c.point_for(f64::NAN, None).unwrap_err().contains("--point-bar"));
        let e = c.point_for(5.5, None).unwrap_err();
        assert!(e.contains("5.50 bar") && e.contains("4 bar, 7 bar"), "{e}");
        assert_eq!(record(&[4.0]).point_for(f64::NAN, None).unwrap().supply_bar, 4.0);
    }

    #[test]
    fn an_unread_characteristic_is_not_a_drift() {
        let b = baseline();
        let mut w = Window::new(b.clone(), 2, 2);
        let mut r = b.median;
        r[4] = f64::NAN;
        w.push(r);
        let d = w.push(r).unwrap();
        let a = d.get("front_feed_area_m2").unwrap();
        assert!(a.measured.is_nan() && !a.beyond && a.cycles == 0);
    }
}
