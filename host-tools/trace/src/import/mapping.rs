//! What a recorder's file means: the `[import]` table (in a config, or a
//! `--map FILE.toml` of its own). Each signal names its column (by name or
//! by its 1-based position), its unit, gauge or absolute, and a sign; the
//! table gives the text layout (delimiter, decimal comma, preamble) and,
//! for a file without a time column, the sample rate. Everything is
//! optional: a file whose columns carry the project's names in SI needs none.

use serde::{Deserialize, Serialize};

use crate::config::{check_range, ConfigError};

/// Standard atmosphere: what an absolute pressure reads at a vented chamber.
pub const STANDARD_ATMOSPHERE_PA: f64 = 101_325.0;
/// Standard gravity, m/s² per g.
pub const STANDARD_GRAVITY_MPS2: f64 = 9.806_65;

/// The `[import]` table.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ImportMap {
    /// Field separator of a text file: one character (`";"`, `"\t"`); found
    /// among `, ; TAB |` when absent.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub delimiter: Option<String>,
    /// `","` for a decimal comma (`1,25`), `"."` for a point; when absent,
    /// found from the first rows (commas in the numbers and no point: a comma).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub decimal: Option<String>,
    /// Lines before the header row (a recorder's preamble). When absent the
    /// header is the first of the first lines that holds every named column.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub skip_lines: Option<usize>,
    /// False when the text has no header row (columns then go by position).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub header: Option<bool>,
    /// Samples per second, for a file without a time column (WAV gives its
    /// own); with a time column, checked against it, never in its place.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub sample_rate_hz: Option<f64>,
    /// TDMS: the group that holds the channels (when absent, any group; a
    /// channel name found in two groups is then refused).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub group: Option<String>,
    /// What an absolute pressure reads at atmosphere, Pa (standard atmosphere by default).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub atmosphere_pa: Option<f64>,
    /// The operating point of the recording, gauge bar (for its sidecar).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub supply_pressure_bar: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub t: Option<Signal>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub p_rear: Option<Signal>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub p_front: Option<Signal>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub accel: Option<Signal>,
}

/// One signal's source.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Signal {
    /// Column, channel or variable: its name, or its position counted from 1.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub column: Option<ColumnRef>,
    /// `Pa kPa bar mbar MPa psi` | `m/s2 g` | `s ms us` (the SI unit by default).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub unit: Option<String>,
    /// The pressure is absolute: atmosphere is subtracted to make it gauge.
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    pub absolute: bool,
    /// −1 for a channel wired or mounted the other way round.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub sign: Option<f64>,
    /// WAV: the value (in `unit`) of a full-scale sample.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub scale: Option<f64>,
}

/// A column by name, or by position counted from 1.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum ColumnRef {
    Index(usize),
    Name(String),
}

impl std::fmt::Display for ColumnRef {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            ColumnRef::Index(i) => write!(f, "#{i}"),
            ColumnRef::Name(n) => write!(f, "`{n}`"),
        }
    }
}

/// The four signals the estimator reads.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Quantity {
    Time,
    Pressure,
    Acceleration,
}

/// (signal key, the project's column name, quantity).
pub const SIGNALS: [(&str, &str, Quantity); 4] = [
    ("t", "t_s", Quantity::Time),
    ("p_rear", "p_rear_pa", Quantity::Pressure),
    ("p_front", "p_front_pa", Quantity::Pressure),
    ("accel", "accel_mps2", Quantity::Acceleration),
];

/// Units a signal may be given in: (names, quantity, factor to SI).
const UNITS: [(&[&str], Quantity, f64); 13] = [
    (&["pa"], Quantity::Pressure, 1.0),
    (&["hpa", "mbar"], Quantity::Pressure, 100.0),
    (&["kpa"], Quantity::Pressure, 1e3),
    (&["bar"], Quantity::Pressure, 1e5),
    (&["mpa"], Quantity::Pressure, 1e6),
    (&["psi"], Quantity::Pressure, 6_894.757_293_168_361),
    (&["m/s2", "m/s^2", "m/s²", "mps2", "m s-2"], Quantity::Acceleration, 1.0),
    (&["g", "gn"], Quantity::Acceleration, STANDARD_GRAVITY_MPS2),
    (&["s"], Quantity::Time, 1.0),
    (&["ms"], Quantity::Time, 1e-3),
    (&["us", "µs", "μs"], Quantity::Time, 1e-6),
    (&["ns"], Quantity::Time, 1e-9),
    (&["min"], Quantity::Time, 60.0),
];

/// A signal resolved: where it comes from and how to make SI of it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Resolved {
    pub signal: &'static str,
    /// The column as the map names it (the project's name when unmapped).
    pub column: ColumnRef,
    pub unit: String,
    pub factor: f64,
    pub absolute: bool,
    pub sign: f64,
    pub scale: Option<f64>,
}

impl Resolved {
    /// The value in SI (gauge for pressure) of `raw` in the file's unit.
    #[inline]
    pub fn si(&self, raw: f64, atmosphere_pa: f64) -> f64 {
        let v = raw * self.factor;
        let v = if self.absolute { v - atmosphere_pa } else { v };
        self.sign * v
    }

    /// An absolute pressure at or below 0 Pa absolute: impossible in a
    /// chamber, so the column holds gauge pressure mapped as absolute.
    #[inline]
    pub fn below_vacuum(&self, raw: f64) -> bool {
        self.absolute && raw * self.factor <= 0.0
    }

    /// What [`Resolved::below_vacuum`] means, for `column`'s `raw` value.
    pub fn vacuum_message(&self, column: &str, raw: f64) -> String {
        format!(
            "`{column}` ({}) reads {raw} {} absolute, at or below vacuum: the column holds gauge pressure; remove `absolute = true` under [import.{}]",
            self.signal, self.unit, self.signal
        )
    }
}

impl ImportMap {
    /// The text layout and every signal checked: units known and of the
    /// right kind, signs ±1, positive rates and scales.
    pub fn validate(&self) -> Result<(), ConfigError> {
        if let Some(d) = &self.delimiter {
            if unescape(d).is_none() {
                return Err(invalid("import.delimiter", "must be one character (\"\\t\" for a tab)"));
            }
        }
        if let Some(d) = &self.decimal {
            if d != "." && d != "," {
                return Err(invalid("import.decimal", "must be \".\" or \",\""));
            }
        }
        if self.decimal.as_deref() == Some(",") && self.delimiter().ok().flatten() == Some(',') {
            return Err(invalid(
                "import.decimal",
                "a decimal comma needs another delimiter (\";\" or \"\\t\")",
            ));
        }
        if let Some(r) = self.sample_rate_hz {
            check_range("import.sample_rate_hz", r, 1.0, 1e9)?;
        }
        if let Some(a) = self.atmosphere_pa {
            check_range("import.atmosphere_pa", a, 50e3, 120e3)?;
        }
        if let Some(b) = self.supply_pressure_bar {
            check_range("import.supply_pressure_bar", b, 0.0, 1000.0)?;
        }
        for (key, _, _) in SIGNALS {
            self.resolve(key)?;
        }
        Ok(())
    }

    pub fn delimiter(&self) -> Result<Option<char>, ConfigError> {
        match &self.delimiter {
            None => Ok(None),
            Some(d) => unescape(d)
                .map(Some)
                .ok_or_else(|| invalid("import.delimiter", "must be one character (\"\\t\" for a tab)")),
        }
    }

    pub fn decimal_comma(&self) -> bool {
        self.decimal.as_deref() == Some(",")
    }

    pub fn atmosphere_pa(&self) -> f64 {
        self.atmosphere_pa.unwrap_or(STANDARD_ATMOSPHERE_PA)
    }

    pub fn signal(&self, key: &str) -> Option<&Signal> {
        match key {
            "t" => self.t.as_ref(),
            "p_rear" => self.p_rear.as_ref(),
            "p_front" => self.p_front.as_ref(),
            "accel" => self.accel.as_ref(),
            _ => None,
        }
    }

    /// Signal `key` (`t`, `p_rear`, `p_front`, `accel`) with its defaults:
    /// the project's column name and SI unit.
    pub fn resolve(&self, key: &str) -> Result<Resolved, ConfigError> {
        let (signal, name, quantity) = SIGNALS
            .iter()
            .copied()
            .find(|(k, _, _)| *k == key)
            .ok_or_else(|| invalid("import", &format!("no signal `{key}`")))?;
        let s = self.signal(key).cloned().unwrap_or_default();
        let field = |f: &str| format!("import.{key}.{f}");
        let (unit, factor) = match &s.unit {
            None => (si_unit(quantity).to_string(), 1.0),
            Some(u) => {
                let low = u.trim().to_lowercase();
                let (_, q, factor) = UNITS
                    .iter()
                    .find(|(names, _, _)| names.contains(&low.as_str()))
                    .ok_or_else(|| invalid(&field("unit"), &format!("unknown unit `{u}` ({})", unit_list(quantity))))?;
                if *q != quantity {
                    return Err(invalid(
                        &field("unit"),
                        &format!(
                            "`{u}` is not a unit of {} ({})",
                            quantity_name(quantity),
                            unit_list(quantity)
                        ),
                    ));
                }
                (u.trim().to_string(), *factor)
            }
        };
        if s.absolute && quantity != Quantity::Pressure {
            return Err(invalid(&field("absolute"), "only a pressure is absolute or gauge"));
        }
        let sign = s.sign.unwrap_or(1.0);
        if sign != 1.0 && sign != -1.0 {
            return Err(invalid(&field("sign"), "must be 1 or -1"));
        }
        if let Some(sc) = s.scale {
            if !(sc.is_finite() && sc > 0.0) {
                return Err(invalid(
                    &field("scale"),
                    "must be a positive value (the full-scale reading)",
                ));
            }
        }
        if let Some(ColumnRef::Index(0)) = s.column {
            return Err(invalid(&field("column"), "positions count from 1"));
        }
        Ok(Resolved {
            signal,
            column: s.column.clone().unwrap_or(ColumnRef::Name(name.to_string())),
            unit,
            factor,
            absolute: s.absolute,
            sign,
            scale: s.scale,
        })
    }

    /// Whether the map says anything about the signals or the text layout
    /// (beyond the operating point): then it applies even to a file in the
    /// project's own format.
    pub fn maps_signals(&self) -> bool {
        self.t.is_some()
            || self.p_rear.is_some()
            || self.p_front.is_some()
            || self.accel.is_some()
            || self.delimiter.is_some()
            || self.decimal.is_some()
            || self.skip_lines.is_some()
            || self.header.is_some()
            || self.sample_rate_hz.is_some()
    }

    /// Whether the map names a time column (else the time comes from a rate).
    pub fn has_time_column(&self) -> bool {
        self.t.as_ref().is_some_and(|t| t.column.is_some())
    }
}

fn invalid(field: &str, message: &str) -> ConfigError {
    ConfigError::Invalid {
        field: field.to_string(),
        message: message.to_string(),
    }
}

fn unescape(d: &str) -> Option<char> {
    match d {
        "\\t" | "tab" => Some('\t'),
        _ => {
            let mut c = d.chars();
            match (c.next(), c.next()) {
                (Some(ch), None) if ch != '\n' && ch != '\r' && ch != '"' => Some(ch),
                _ => None,
            }
        }
    }
}

fn si_unit(q: Quantity) -> &'static str {
    match q {
        Quantity::Time => "s",
        Quantity::Pressure => "Pa",
        Quantity::Acceleration => "m/s2",
    }
}

fn quantity_name(q: Quantity) -> &'static str {
    match q {
        Quantity::Time => "time",
        Quantity::Pressure => "pressure",
        Quantity::Acceleration => "acceleration",
    }
}

fn unit_list(q: Quantity) -> String {
    let names: Vec<&str> = UNITS.iter().filter(|(_, k, _)| *k == q).map(|(n, _, _)| n[0]).collect();
    format!("{}: {}", quantity_name(q), names.join(", "))
}
