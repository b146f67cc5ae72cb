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
}

impl Channel {
    pub fn new(name: impl Into<String>, values: Vec<f64>) -> Self {
        Self {
            name: name.into(),
            values,
            start_s: None,
            increment_s: None,
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
}

/// Finds a channel by the map's reference.
pub fn find(channels: &[Channel], r: &ColumnRef) -> Option<usize> {
    match r {
        ColumnRef::Index(i) => (*i >= 1 && *i <= channels.len()).then(|| i - 1),
        ColumnRef::Name(n) => channels
            .iter()
            .position(|c| c.name == *n)
            .or_else(|| channels.iter().position(|c| c.matches(n))),
    }
}

impl Columns {
    /// Picks the three signals and the time base from `channels`. The time
    /// is, in order: the map's time column; the map's sample rate; a
    /// channel named `t_s`; a start and increment the file gives (the
    /// pressure channel's, or `rate` from the format's header).
    pub fn new(
        label: &str,
        channels: Vec<Channel>,
        map: &ImportMap,
        rate: Option<(f64, f64, String)>,
    ) -> Result<Self, TraceError> {
        let err = |message: String| TraceError::Import {
            path: label.to_string(),
            message,
        };
        map.validate().map_err(|e| err(e.to_string()))?;
        let names = || {
            let n: Vec<&str> = channels.iter().map(|c| c.name.as_str()).take(20).collect();
            n.join(", ")
        };
        let mut signals = Vec::new();
        for key in ["p_rear", "p_front", "accel"] {
            let r = map.resolve(key).map_err(|e| err(e.to_string()))?;
            let i = find(&channels, &r.column).ok_or_else(|| {
                err(format!(
                    "no channel {} for {key} (channels: {}); name it in the mapping ([import.{key}] column = ..., docs/trace-format.md)",
                    r.column,
                    names()
                ))
            })?;
            signals.push((i, r));
        }
        let t = map.resolve("t").map_err(|e| err(e.to_string()))?;
        let time = if map.has_time_column() {
            let i = find(&channels, &t.column)
                .ok_or_else(|| err(format!("no time channel {} (channels: {})", t.column, names())))?;
            TimeBase::Column(i, t)
        } else if let Some(fs) = map.sample_rate_hz {
            TimeBase::Rate {
                start_s: 0.0,
                increment_s: 1.0 / fs,
                from: "import.sample_rate_hz".into(),
            }
        } else if let Some(i) = find(&channels, &t.column) {
            TimeBase::Column(i, t)
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
            TimeBase::Rate {
                start_s,
                increment_s,
                from,
            }
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
}
