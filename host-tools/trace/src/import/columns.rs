//! The binary formats' common ground: named channels of numbers (a TDMS
//! channel, a MAT variable, a WAV channel, a Parquet column), picked by the
//! map, converted to SI and handed to the time-base layer row by row.

use crate::import::mapping::{ColumnRef, ImportMap, Resolved};
use crate::rows::{Row, RowSource};
use crate::trace::TraceError;

/// One channel of a file.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Channel {
    /// Its name (`group/channel` for TDMS, also found by the channel name alone).
    pub name: String,
    pub values: Vec<f64>,
    /// Time of the first value and between values, s, when the file gives
    /// the time that way (TDMS `wf_start_offset`/`wf_increment`).
    pub start_s: Option<f64>,
    pub increment_s: Option<f64>,
    /// The values were stored as 32-bit floats: each is good to 2^-24 of its
    /// magnitude, which in a time column can be coarser than the tolerance
    /// on the sample interval.
    pub float32: bool,
}

impl Channel {
    pub fn new(name: impl Into<String>, values: Vec<f64>) -> Self {
        Self {
            name: name.into(),
            values,
            start_s: None,
            increment_s: None,
            float32: false,
        }
    }

    fn matches(&self, name: &str) -> bool {
        self.name == name || self.name.rsplit_once('/').is_some_and(|(_, c)| c == name)
    }
}

/// How the time of each sample is found.
#[derive(Debug, Clone, PartialEq)]
pub enum TimeBase {
    /// A channel of time stamps (index into the file's channels).
    Column(usize, Resolved),
    /// A start and an increment, s.
    Rate {
        start_s: f64,
        increment_s: f64,
        from: String,
    },
}

/// Channels chosen and converted, as rows.
pub struct Columns {
    label: String,
    channels: Vec<Channel>,
    time: TimeBase,
    signals: [(usize, Resolved); 3],
    atmosphere_pa: f64,
    next: usize,
    len: usize,
    /// A rate stated besides the time column (the map's, the format's), checked against it.
    stated: Option<(f64, String)>,
}

/// Finds signal `key`'s channel by the map's reference: its full name, or a
/// TDMS channel's name within its group. A name that several channels
/// answer to (the same channel name in two groups, a name written twice) is
/// refused, never settled by file order.
pub fn find(channels: &[Channel], r: &ColumnRef, key: &str) -> Result<Option<usize>, String> {
    match r {
        ColumnRef::Index(i) => Ok((*i >= 1 && *i <= channels.len()).then(|| i - 1)),
        ColumnRef::Name(n) => {
            let exact: Vec<usize> = (0..channels.len()).filter(|&i| channels[i].name == *n).collect();
            let hits = if exact.is_empty() {
                (0..channels.len()).filter(|&i| channels[i].matches(n)).collect()
            } else {
                exact
            };
            match hits[..] {
                [] => Ok(None),
                [i] => Ok(Some(i)),
                _ if hits.iter().all(|&i| channels[i].name == *n) => Err(format!(
                    "{key}: {} channels are named `{n}`: rename them apart, or map the one meant by its position ([import.{key}] column = {})",
                    hits.len(),
                    hits[0] + 1
                )),
                _ => {
                    let groups: Vec<String> = hits
                        .iter()
                        .filter_map(|&i| channels[i].name.rsplit_once('/').map(|(g, _)| format!("`{g}`")))
                        .collect();
                    Err(format!(
                        "{key}: a channel `{n}` is in the groups {}: choose one with `group = \"{}\"` under [import] (import.group), or name it whole (`group/{n}`)",
                        groups.join(", "),
                        channels[hits[0]].name.rsplit_once('/').map_or("", |(g, _)| g)
                    ))
                }
            }
        }
    }
}

/// The resolution of a float32 time column, s: one step of f32 at its
/// largest magnitude (each stamp rounded by half of it, an interval by up to one).
fn float32_resolution_s(c: &Channel, factor: f64) -> f64 {
    let max = c.values.iter().fold(0f64, |m, v| m.max(v.abs())) as f32;
    if !max.is_finite() {
        return f64::INFINITY;
    }
    (f32::from_bits(max.to_bits() + 1) - max) as f64 * factor
}

/// A float32 time column is read when its resolution is finer than a
/// quarter of the sample interval (the rounding then cannot move a stamp
/// to another sample); coarser, it cannot tell the samples apart.
const FLOAT32_MAX_RESOLUTION: f64 = 0.25;

impl Columns {
    /// Picks the three signals and the time base from `channels`. The time
    /// is, in order: the map's time column; a channel named `t_s`; the map's
    /// sample rate; a start and increment the file gives (the pressure
    /// channel's, or `rate` from the format's header). A rate given besides
    /// a time column is checked against it ([`RowSource::stated_period_s`]).
    /// `skipped` names the file's variables not read (a MAT struct, a
    /// Parquet text column), for the error when a signal is not found.
    pub fn new(
        label: &str,
        channels: Vec<Channel>,
        map: &ImportMap,
        rate: Option<(f64, f64, String)>,
        skipped: &[String],
    ) -> Result<Self, TraceError> {
        let err = |message: String| TraceError::Import {
            path: label.to_string(),
            message,
        };
        map.validate().map_err(|e| err(e.to_string()))?;
        let names = || {
            let n: Vec<&str> = channels.iter().map(|c| c.name.as_str()).take(20).collect();
            let mut s = n.join(", ");
            if !skipped.is_empty() {
                s.push_str(&format!("; not read: {}", skipped.join(", ")));
            }
            s
        };
        let mut signals = Vec::new();
        for key in ["p_rear", "p_front", "accel"] {
            let r = map.resolve(key).map_err(|e| err(e.to_string()))?;
            let i = find(&channels, &r.column, key)
                .map_err(err)?
                .ok_or_else(|| {
                    err(format!(
                        "no channel {} for {key} (channels: {}); name it in the mapping ([import.{key}] column = ..., docs/trace-format.md)",
                        r.column,
                        names()
                    ))
                })?;
            signals.push((i, r));
        }
        let t = map.resolve("t").map_err(|e| err(e.to_string()))?;
        let map_rate = map
            .sample_rate_hz
            .map(|fs| (1.0 / fs, format!("import.sample_rate_hz = {fs}")));
        let column = if map.has_time_column() {
            let i = find(&channels, &t.column, "t")
                .map_err(err)?
                .ok_or_else(|| err(format!("no time channel {} (channels: {})", t.column, names())))?;
            Some(i)
        } else {
            find(&channels, &t.column, "t").map_err(err)?
        };
        // A float32 time column too coarse for the sample interval: the
        // map's rate in its place, or the cause said.
        let column = match column {
            Some(i) if channels[i].float32 => {
                let c = &channels[i];
                let res = float32_resolution_s(c, t.factor);
                let n = c.values.len();
                let dt = match (c.values.first(), c.values.last()) {
                    (Some(a), Some(b)) if n > 1 => (b - a) * t.factor / (n - 1) as f64,
                    _ => f64::INFINITY,
                };
                if res <= FLOAT32_MAX_RESOLUTION * dt.abs() {
                    Some(i)
                } else if map_rate.is_some() && !map.has_time_column() {
                    None
                } else {
                    return Err(err(format!(
                        "the time channel `{}` is float32: its resolution at its largest value is {res:.3e} s, too coarse for a sample interval of {dt:.3e} s; save the time as float64, or give the rate (import.sample_rate_hz) and no time column",
                        c.name
                    )));
                }
            }
            other => other,
        };
        let (time, stated) = if let Some(i) = column {
            let stated = map_rate.or_else(|| rate.map(|(_, inc, from)| (inc, from)));
            (TimeBase::Column(i, t), stated)
        } else if let Some((increment_s, from)) = map_rate {
            (
                TimeBase::Rate {
                    start_s: 0.0,
                    increment_s,
                    from,
                },
                None,
            )
        } else if let Some((start_s, increment_s, from)) = channels[signals[0].0]
            .increment_s
            .map(|inc| {
                (
                    channels[signals[0].0].start_s.unwrap_or(0.0),
                    inc,
                    "wf_increment".to_string(),
                )
            })
            .or(rate)
        {
            if !(increment_s > 0.0 && increment_s.is_finite() && start_s.is_finite()) {
                return Err(err(format!(
                    "{from}: the sample interval {increment_s} s is not a positive number"
                )));
            }
            (
                TimeBase::Rate {
                    start_s,
                    increment_s,
                    from,
                },
                None,
            )
        } else {
            return Err(err(format!(
                "no time: no channel `t_s` (channels: {}); give [import.t] column = ... or import.sample_rate_hz",
                names()
            )));
        };
        let len = channels[signals[0].0].values.len();
        let mut used: Vec<(&str, usize)> = signals.iter().map(|(i, r)| (r.signal, *i)).collect();
        if let TimeBase::Column(i, _) = &time {
            used.push(("t", *i));
        }
        for (sig, i) in &used {
            if channels[*i].values.len() != len {
                return Err(err(format!(
                    "channels of different lengths: `{}` ({sig}) has {} values, `{}` (p_rear) {len}",
                    channels[*i].name,
                    channels[*i].values.len(),
                    channels[signals[0].0].name
                )));
            }
        }
        let [a, b, c] =
            <[(usize, Resolved); 3]>::try_from(signals).map_err(|_| err("internal: three signals".into()))?;
        Ok(Self {
            label: label.to_string(),
            channels,
            time,
            signals: [a, b, c],
            atmosphere_pa: map.atmosphere_pa(),
            next: 0,
            len,
            stated,
        })
    }

    /// Samples in the file.
    pub fn len(&self) -> usize {
        self.len
    }

    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    pub fn time(&self) -> &TimeBase {
        &self.time
    }

    /// The resolved signals with the channel each comes from.
    pub fn signals(&self) -> impl Iterator<Item = (&Resolved, &str)> {
        self.signals.iter().map(|(i, r)| (r, self.channels[*i].name.as_str()))
    }
}

impl RowSource for Columns {
    fn next_row(&mut self) -> Result<Option<Row>, TraceError> {
        let i = self.next;
        if i >= self.len {
            return Ok(None);
        }
        self.next += 1;
        let t_s = match &self.time {
            TimeBase::Column(c, r) => r.si(self.channels[*c].values[i], 0.0),
            TimeBase::Rate {
                start_s, increment_s, ..
            } => start_s + i as f64 * increment_s,
        };
        for (c, r) in &self.signals {
            let raw = self.channels[*c].values[i];
            if r.below_vacuum(raw) {
                return Err(TraceError::Import {
                    path: self.label.clone(),
                    message: format!("sample {}: {}", i + 1, r.vacuum_message(&self.channels[*c].name, raw)),
                });
            }
        }
        let v = |k: usize| {
            let (c, r) = &self.signals[k];
            r.si(self.channels[*c].values[i], self.atmosphere_pa)
        };
        let row = Row {
            t_s,
            p_rear_pa: v(0),
            p_front_pa: v(1),
            accel_mps2: v(2),
        };
        for (k, (x, name)) in [
            (row.p_rear_pa, "p_rear"),
            (row.p_front_pa, "p_front"),
            (row.accel_mps2, "accel"),
        ]
        .into_iter()
        .enumerate()
        {
            if !x.is_finite() {
                return Err(TraceError::BadNumber {
                    path: self.label.clone(),
                    line: i + 1,
                    column: format!("{name} ({})", self.channels[self.signals[k].0].name),
                    text: x.to_string(),
                });
            }
        }
        if !t_s.is_finite() {
            return Err(TraceError::BadNumber {
                path: self.label.clone(),
                line: i + 1,
                column: "t".into(),
                text: t_s.to_string(),
            });
        }
        Ok(Some(row))
    }

    fn label(&self) -> &str {
        &self.label
    }

    /// The sample number (from 1): a binary file has no lines.
    fn line(&self) -> usize {
        self.next
    }

    /// A float32 time column's step at its largest value (exact otherwise).
    fn time_resolution_s(&self) -> f64 {
        match &self.time {
            TimeBase::Column(c, r) if self.channels[*c].float32 => float32_resolution_s(&self.channels[*c], r.factor),
            _ => 0.0,
        }
    }

    fn stated_period_s(&self) -> Option<(f64, String)> {
        let TimeBase::Column(c, _) = &self.time else {
            return None;
        };
        self.stated
            .as_ref()
            .map(|(p, from)| (*p, format!("the time channel `{}` and {from}", self.channels[*c].name)))
    }
}
