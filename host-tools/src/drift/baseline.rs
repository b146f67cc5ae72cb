//! What the drift is read against: each operating point of the hammer's
//! commissioning record as a [`Baseline`], and the one reading of a cycle
//! both sides share, the board's ([`report_reading`]).
//!
//! A record of version 2 holds the board's own reports of the point's
//! cycles (`reports.csv`), so the record and the live windows are read by
//! the same code on the same board: whatever that reading gets slightly
//! wrong, it gets wrong on both sides. A version-1 record holds raw captures
//! alone; those are read by the diagnosis' extractor, which stands a little
//! off the board's reading ([`CAPTURE_OFFSET_BOUND`]), and that offset is
//! carried in every drift's uncertainty rather than corrected: it was
//! measured on the model, not on this hammer.

use std::path::{Path, PathBuf};

use anyhow::{anyhow, bail, Context, Result};
use hammer_estimator::{CycleReport, Flags};
use hammer_sim::SimConfig;
use hammer_trace::trace::Trace;

use super::{median, robust_sd, N_CHARACTERISTICS, POINT_MATCH_BAR};
use crate::diagnose::engine::extractor_for;
use crate::diagnose::features::{
    feature_name, steady_from, CycleFeatures, Extractor, Signals, ESTIMATOR_CHARACTERISTICS,
};
use crate::diagnose::record::{Folder, Point, Record};

/// The chamber characteristics of one cycle, NaN where not read.
pub type Reading = [f64; N_CHARACTERISTICS];

/// Where a baseline's cycles were read.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Source {
    /// The board's reports (a version-2 record): the live windows' reading.
    Reports,
    /// The host's extractor on raw captures (a version-1 record).
    Captures,
}

/// How far the host's reading of a raw capture stands from the board's
/// reading of the same cycles at most, per characteristic in the drift's
/// order: 1.5 times the largest offset (report − capture) measured on the
/// paper's hammer at 4 and 7 bar, sound and with a 1.5 ms valve delay
/// (`cargo run --release -p hammer-host --example report_vs_capture -- 20 4 7`:
/// front feed +0.039 ms, rear feed −0.025 ms, exponents 0.00042, feed
/// areas +1.66 % and +0.66 %). The feed areas' bound is relative to the
/// record's median. A baseline read from captures carries it as a
/// rectangular standard uncertainty, bound/√3.
pub const CAPTURE_OFFSET_BOUND: Reading = [6e-5, 4e-5, 7e-4, 7e-4, 0.025, 0.01];

/// Characteristics whose [`CAPTURE_OFFSET_BOUND`] is relative (the feed areas).
const RELATIVE_BOUND: [bool; N_CHARACTERISTICS] = [false, false, false, false, true, true];

/// One operating point of the record: each characteristic's median, its
/// cycle-to-cycle spread (1.4826·MAD: a standard deviation where the
/// cycles scatter normally, untouched by a misread one), how many
/// cycles gave it, and a standard uncertainty common to every window read
/// against it (zero when read as the board reads).
#[derive(Debug, Clone, PartialEq)]
pub struct Baseline {
    pub supply_bar: f64,
    pub median: Reading,
    pub spread: Reading,
    pub cycles: [usize; N_CHARACTERISTICS],
    pub source: Source,
    pub systematic: Reading,
}

impl Baseline {
    /// The baseline of a record's cycles (`readings`) at `supply_bar`, read
    /// as the board reads them.
    pub fn of(supply_bar: f64, readings: &[Reading]) -> Self {
        let values: [Vec<f64>; N_CHARACTERISTICS] =
            std::array::from_fn(|i| readings.iter().map(|r| r[i]).filter(|x| x.is_finite()).collect());
        Baseline {
            supply_bar,
            median: values.each_ref().map(|v| median(v)),
            spread: values.each_ref().map(|v| robust_sd(v)),
            cycles: values.each_ref().map(Vec::len),
            source: Source::Reports,
            systematic: [0.0; N_CHARACTERISTICS],
        }
    }

    /// Whether some characteristic was read in two cycles or more.
    pub fn is_read(&self) -> bool {
        self.cycles.iter().any(|&n| n >= 2)
    }

    /// [`Baseline::of`] for cycles read from raw captures: the offset to
    /// the board's reading carried as a systematic uncertainty.
    pub fn of_captures(supply_bar: f64, readings: &[Reading]) -> Self {
        let mut b = Self::of(supply_bar, readings);
        b.source = Source::Captures;
        b.systematic = std::array::from_fn(|i| {
            let bound = CAPTURE_OFFSET_BOUND[i] * if RELATIVE_BOUND[i] { b.median[i].abs() } else { 1.0 };
            bound / 3f64.sqrt()
        });
        b
    }
}

/// The characteristics a board read into its report, in the drift's order
/// (NaN for a chamber that showed none); `None` for a report whose
/// chambers were left unread (`chambers_unread`) or that is invalid.
pub fn report_reading(r: &CycleReport) -> Option<Reading> {
    if !r.is_valid() || r.flags.contains(Flags::CHAMBERS_UNREAD) {
        return None;
    }
    let (f, b) = (r.front_feed(), r.rear_feed());
    Some(
        [
            f.feed_s,
            b.feed_s,
            f.closed_exponent,
            b.closed_exponent,
            f.feed_area_m2,
            b.feed_area_m2,
        ]
        .map(f64::from),
    )
}

/// The valid reports from the first steady cycle on: leading cycles whose
/// energy or period stands more than 1 % off the later ones' are the
/// hammer's start-up, which the record must not hold (the rule the
/// diagnosis applies to a record's captures, `steady_start`). Invalid
/// reports are left out first, so their NaNs move no median.
pub fn steady_reports(reports: &[CycleReport]) -> Vec<CycleReport> {
    let valid: Vec<CycleReport> = reports.iter().filter(|r| r.is_valid()).copied().collect();
    let ep: Vec<(f64, f64)> = valid
        .iter()
        .map(|r| (f64::from(r.impact_energy_j), f64::from(r.period_s)))
        .collect();
    let from = crate::diagnose::steady::steady_start(&ep);
    valid[from..].to_vec()
}

/// The characteristics of a run's reports as a record keeps them: the
/// steady ones ([`steady_reports`]) that carry a reading.
pub fn steady_readings(reports: &[CycleReport]) -> Vec<Reading> {
    steady_reports(reports).iter().filter_map(report_reading).collect()
}

/// The largest reports file read, bytes: a record's holds about 1.2 KB a
/// report, so this is some 50 000 reports; a larger file is refused, not
/// read into memory.
const REPORTS_FILE_MAX_BYTES: u64 = 64 << 20;

/// The file a point's reports are written to, in its folder.
pub const REPORTS_FILE: &str = "reports.csv";

/// Writes `reports` as `hammer estimate --format csv` does (every field at
/// full precision, `valid`, `flags`).
pub fn write_reports(path: &Path, reports: &[CycleReport]) -> Result<()> {
    let mut text = crate::records::csv_header();
    text.push('\n');
    for r in reports {
        text.push_str(&crate::records::csv_record(r));
        text.push('\n');
    }
    std::fs::write(path, text).with_context(|| format!("writing {}", path.display()))
}

/// The readings of a record's `reports.csv`: the cycles the board read,
/// valid and with their chambers read. A file without the columns, or a
/// row that does not hold as many values as the header or a value that is
/// not a number, is refused with the file and line named (never quoted).
pub fn read_reports(path: &Path) -> Result<Vec<Reading>> {
    let size = std::fs::metadata(path)
        .with_context(|| format!("reading {}", path.display()))?
        .len();
    if size > REPORTS_FILE_MAX_BYTES {
        bail!(
            "{}: {size} bytes, more than the {} MB a record's reports take: refused, not read",
            path.display(),
            REPORTS_FILE_MAX_BYTES >> 20
        );
    }
    let text = std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap_or("").split(',').map(str::trim).collect();
    let at = |name: &str| header.iter().position(|h| *h == name);
    let (Some(valid), Some(flags)) = (at("valid"), at("flags")) else {
        bail!(
            "{}: not a board's reports (its header has no `valid` and `flags` columns)",
            path.display()
        );
    };
    // A report's field for each characteristic has the feature's name.
    let names = ESTIMATOR_CHARACTERISTICS.map(feature_name);
    let columns = names
        .iter()
        .map(|c| at(c).ok_or(c.as_str()))
        .collect::<Result<Vec<usize>, &str>>()
        .map_err(|c| {
            anyhow!(
                "{}: no `{c}` column: reports from before the board read its chambers (protocol 6) cannot give a baseline",
                path.display()
            )
        })?;
    let mut out = Vec::new();
    for (n, line) in lines.enumerate() {
        let row = n + 2;
        if line.trim().is_empty() {
            continue;
        }
        let cells: Vec<&str> = line.split(',').collect();
        if cells.len() != header.len() {
            bail!(
                "{}: line {row} has {} values for {} columns",
                path.display(),
                cells.len(),
                header.len()
            );
        }
        let is_valid = match cells[valid].trim() {
            "true" => true,
            "false" => false,
            _ => bail!("{}: line {row}: `valid` is neither true nor false", path.display()),
        };
        if !is_valid || cells[flags].split('|').any(|f| f.trim() == "chambers_unread") {
            continue;
        }
        let mut r = [f64::NAN; N_CHARACTERISTICS];
        for (slot, &c) in r.iter_mut().zip(&columns) {
            // The board's fields are f32, written as the shortest text that
            // reads back to the same f32.
            *slot = cells[c]
                .trim()
                .parse::<f32>()
                .map(f64::from)
                .map_err(|_| anyhow!("{}: line {row}: `{}` is not a number", path.display(), header[c]))?;
        }
        out.push(r);
    }
    Ok(out)
}

/// A commissioning record read for drift: its baselines, one per point.
#[derive(Debug, Clone)]
pub struct Commissioned {
    pub dir: PathBuf,
    pub record: Record,
    pub baselines: Vec<Baseline>,
}

impl Commissioned {
    /// Reads the record in `dir`: each point's reports, or for a point
    /// that has none (a version-1 record) its captures, read with the
    /// hammer `config` describes (its chambers, its transducers' ranges).
    pub fn load(dir: &Path, config: &SimConfig) -> Result<Self> {
        let Folder { record, points, .. } = Folder::open(dir)?;
        let mut extractor = None;
        let mut baselines = Vec::new();
        for point in &points {
            // A point's reports, unless they hold no characteristic twice
            // (every cycle longer than the board reads, say): then its
            // captures, as a version-1 record's.
            let from_reports = match &point.reports {
                Some(path) => Some(Baseline::of(point.supply_bar, &read_reports(path)?)).filter(Baseline::is_read),
                None => None,
            };
            let b = match from_reports {
                Some(b) => b,
                None => {
                    let ex = extractor.get_or_insert_with(|| extractor_for(config));
                    Baseline::of_captures(point.supply_bar, &captured(ex, point)?)
                }
            };
            if !b.is_read() {
                bail!(
                    "{}: the record's cycles at {} bar give no chamber characteristic twice: nothing to read a drift against",
                    dir.display(),
                    point.supply_bar
                );
            }
            baselines.push(b);
        }
        if baselines.is_empty() {
            bail!("{}: the record holds no operating point", dir.display());
        }
        Ok(Self {
            dir: dir.to_path_buf(),
            record,
            baselines,
        })
    }

    /// The point a board is read at: its configured supply pressure, else
    /// `point_bar`, else the record's only point.
    pub fn point_for(&self, configured_bar: f64, point_bar: Option<f64>) -> Result<&Baseline, String> {
        if configured_bar.is_finite() {
            return self.point(configured_bar);
        }
        match (point_bar, self.baselines.as_slice()) {
            (Some(bar), _) => self.point(bar),
            (None, [only]) => Ok(only),
            (None, _) => Err(format!(
                "drift: the board's configuration holds no supply pressure and {} has several operating points: give --point-bar BAR",
                self.dir.display()
            )),
        }
    }

    /// The record's point at `supply_bar`, or why there is none.
    pub fn point(&self, supply_bar: f64) -> Result<&Baseline, String> {
        self.baselines
            .iter()
            .find(|b| (b.supply_bar - supply_bar).abs() <= POINT_MATCH_BAR)
            .ok_or_else(|| {
                let have: Vec<String> = self.baselines.iter().map(|b| format!("{} bar", b.supply_bar)).collect();
                format!(
                    "{} has no operating point at {supply_bar:.2} bar (it has {}): commission this point to read its drift",
                    self.dir.display(),
                    have.join(", ")
                )
            })
    }

    /// Whether a board with calibration `hash` may be read against the
    /// record: an error when it was recalibrated since and `allow_stale`
    /// is not given, else `Some(warning)` for a stale record.
    pub fn check_calibration(&self, hash: u32, allow_stale: bool) -> Result<Option<String>, String> {
        if hash == self.record.calibration_hash {
            return Ok(None);
        }
        let what = format!(
            "{} was commissioned with calibration {:08x}; the board now has {hash:08x}: it was recalibrated since, so the record is stale",
            self.dir.display(),
            self.record.calibration_hash
        );
        if allow_stale {
            Ok(Some(format!(
                "{what}; its drift includes the recalibration's change (--allow-stale-reference)"
            )))
        } else {
            Err(format!(
                "{what}: no drift is read. Commission again, or pass --allow-stale-reference"
            ))
        }
    }
}

/// The readings of a point's captures, each trace's steady cycles.
pub fn captured(extractor: &Extractor, point: &Point) -> Result<Vec<Reading>> {
    let mut out = Vec::new();
    for path in &point.traces {
        let (trace, _, _) =
            hammer_trace::import::read_trace(path, None).with_context(|| format!("reading {}", path.display()))?;
        out.extend(readings_of(extractor, &trace, point.supply_bar));
    }
    Ok(out)
}

fn reading(c: &CycleFeatures) -> Reading {
    ESTIMATOR_CHARACTERISTICS.map(|j| c.values[j])
}

/// The characteristics of each steady cycle of `trace` at `supply_bar`,
/// read by `extractor` as a version-1 record's captures are.
pub fn readings_of(extractor: &Extractor, trace: &Trace, supply_bar: f64) -> Vec<Reading> {
    let all = extractor.cycles(&Signals::of_trace(trace, supply_bar));
    let from = steady_from(&all);
    all[from..].iter().map(reading).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use hammer_estimator::FeedFields;

    fn report(seq: u32, front_feed_s: f32) -> CycleReport {
        let mut r = CycleReport {
            seq,
            ..CycleReport::default()
        };
        let feed = |feed_s| FeedFields {
            feed_s,
            closed_exponent: 1.4,
            ..FeedFields::NAN
        };
        r.set_chambers_read(feed(front_feed_s), feed(0.021));
        r
    }

    /// A report's reading is its fields in the drift's order; an unread or
    /// invalid report gives none.
    #[test]
    fn a_report_gives_its_chambers_unless_unread_or_invalid() {
        let r = report(1, 1.5e-3);
        let x = report_reading(&r).expect("read");
        // Each characteristic is the report's field of the feature's name.
        for (i, j) in ESTIMATOR_CHARACTERISTICS.into_iter().enumerate() {
            let f = hammer_estimator::fields::field(&feature_name(j)).expect("a report field");
            assert_eq!(f.f64(&r).to_bits(), x[i].to_bits(), "{}", f.name);
        }
        assert_eq!(x[0], f64::from(1.5e-3f32));
        assert_eq!(x[1], f64::from(0.021f32));
        assert_eq!(x[2], f64::from(1.4f32));
        assert!(x[4].is_nan() && x[5].is_nan());
        let mut unread = r;
        unread.mark_chambers_unread();
        assert!(report_reading(&unread).is_none());
        let mut invalid = r;
        invalid.flags.insert(Flags::NO_IMPACT);
        assert!(report_reading(&invalid).is_none());
    }

    fn tmp(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("hammer-baseline-{}-{name}", std::process::id()));
        std::fs::create_dir_all(&d).unwrap();
        d.join(REPORTS_FILE)
    }

    /// What `write_reports` writes reads back to the same readings, the
    /// unread and invalid rows left out.
    #[test]
    fn reports_read_back_as_written() {
        let path = tmp("roundtrip");
        let mut unread = report(3, 2e-3);
        unread.mark_chambers_unread();
        let mut invalid = report(4, 2e-3);
        invalid.flags.insert(Flags::NO_IMPACT);
        let reports = [report(1, 1.5e-3), report(2, -2.5e-5), unread, invalid];
        write_reports(&path, &reports).unwrap();
        let back = read_reports(&path).unwrap();
        let expected: Vec<Reading> = reports.iter().filter_map(report_reading).collect();
        assert_eq!(back.len(), 2);
        for (a, b) in back.iter().zip(&expected) {
            for (x, y) in a.iter().zip(b) {
                assert!(x.to_bits() == y.to_bits(), "{x} vs {y}");
            }
        }
        let _ = std::fs::remove_dir_all(path.parent().unwrap());
    }

    /// A file that is not a board's reports, or a row cut short or not a
    /// number, is refused with the file and the line named, its text never
    /// quoted.
    #[test]
    fn a_file_that_is_not_reports_is_refused_by_name() {
        let path = tmp("bad");
        let header = crate::records::csv_header();
        let row = crate::records::csv_record(&report(1, 1e-3));
        let cases = [
            ("secret,words\n1,2\n".to_string(), "no `valid` and `flags`"),
            (
                header.replace("front_feed_s,", "other,") + "\n",
                "no `front_feed_s` column",
            ),
            (format!("{header}\n{row}\n1,2\n"), "line 3 has 2 values"),
            (
                format!("{header}\n{}\n", row.replacen("1.4", "x-secret", 1)),
                "line 2: `front_closed_exponent` is not a number",
            ),
        ];
        for (text, says) in cases {
            std::fs::write(&path, &text).unwrap();
            let e = format!("{:#}", read_reports(&path).unwrap_err());
            assert!(e.contains(says) && e.contains(REPORTS_FILE), "{e}");
            assert!(!e.contains("secret"), "{e}");
        }
        let _ = std::fs::remove_dir_all(path.parent().unwrap());
    }

    /// A baseline read from captures carries the offset to the board's
    /// reading as a rectangular standard uncertainty, the areas' relative
    /// to their median; one read from reports carries none.
    #[test]
    fn a_capture_baseline_carries_the_offset_bound() {
        let readings = vec![[1e-3, 2e-2, 1.4, 1.4, 1.6e-6, 1.8e-6]; 5];
        let b = Baseline::of(4.0, &readings);
        assert_eq!((b.source, b.systematic), (Source::Reports, [0.0; N_CHARACTERISTICS]));
        let c = Baseline::of_captures(4.0, &readings);
        assert_eq!(c.source, Source::Captures);
        assert!((c.systematic[0] - 6e-5 / 3f64.sqrt()).abs() < 1e-15);
        assert!((c.systematic[4] - 0.025 * 1.6e-6 / 3f64.sqrt()).abs() < 1e-15);
        assert_eq!(c.median, b.median);
    }
}
