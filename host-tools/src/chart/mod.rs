//! The figures' chart model: what a panel shows (lines, uncertainty bands,
//! flagged crosses, shaded spans, markers, notes), apart from how it is
//! drawn ([`render`]). `hammer report`, `hammer figures` and the gap figures
//! of `hammer diagnose` describe their panels in these terms, so one
//! renderer (one font, one axis and legend style) draws every PNG.

pub mod render;

pub use plotters::chart::SeriesLabelPosition;
pub use plotters::style::RGBColor;

/// The nominal model, a truth or anything a second curve is compared with.
pub const NOMINAL: RGBColor = RGBColor(90, 90, 90);
/// An effect, a fitted model, a flag.
pub const EFFECT: RGBColor = RGBColor(214, 39, 40);
/// The measurement or the estimate.
pub const BLUE: RGBColor = RGBColor(31, 119, 180);
pub const ORANGE: RGBColor = RGBColor(255, 127, 14);
pub const GREEN: RGBColor = RGBColor(44, 160, 44);

/// A line; NaN breaks it.
pub struct Series<'a> {
    pub label: String,
    pub color: RGBColor,
    pub x: &'a [f64],
    pub y: Vec<f64>,
}

/// A shaded x interval (the blanked shock).
pub struct Span {
    pub x0: f64,
    pub x1: f64,
    pub color: RGBColor,
    pub label: Option<String>,
}

/// A dashed vertical marker (the turning point).
pub struct VLine {
    pub x: f64,
    pub color: RGBColor,
    pub label: Option<String>,
}

/// A shaded band around a line (an expanded uncertainty); its line's legend
/// entry names it.
pub struct Band<'a> {
    pub color: RGBColor,
    pub x: &'a [f64],
    pub lo: Vec<f64>,
    pub hi: Vec<f64>,
}

/// Crosses: values that are not estimates (flagged cycles), kept visible but
/// out of the lines and the autoscale.
pub struct Crosses<'a> {
    /// None: another set of crosses in the panel already names them.
    pub label: Option<String>,
    pub color: RGBColor,
    pub x: &'a [f64],
    pub y: Vec<f64>,
}

/// One panel of a figure; panels of a figure share the x axis.
pub struct Chart<'a> {
    pub y_label: String,
    pub series: Vec<Series<'a>>,
    /// Clamp the y range (impacts would otherwise flatten the flight phase).
    pub y_limits: Option<(f64, f64)>,
    pub bands: Vec<Band<'a>>,
    pub crosses: Vec<Crosses<'a>>,
    pub spans: Vec<Span>,
    pub vlines: Vec<VLine>,
    /// Text near the bottom of the panel, at an x position.
    pub notes: Vec<(f64, String)>,
    /// A thin line at y = 0 (where the velocity changes sign).
    pub zero_line: bool,
    /// A dot at each data point: per-cycle values are samples, not a curve.
    pub points: bool,
    pub legend: SeriesLabelPosition,
}

impl<'a> Chart<'a> {
    pub fn new(y_label: &str, series: Vec<Series<'a>>) -> Self {
        Chart {
            y_label: y_label.to_string(),
            series,
            y_limits: None,
            bands: Vec::new(),
            crosses: Vec::new(),
            spans: Vec::new(),
            vlines: Vec::new(),
            notes: Vec::new(),
            zero_line: false,
            points: false,
            legend: SeriesLabelPosition::UpperRight,
        }
    }
}
