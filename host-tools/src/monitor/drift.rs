//! The reader's side of the drift since commissioning ([`crate::drift`]):
//! it asks the board for one raw cycle at a time, puts the chunks together,
//! reads the cycle's chamber characteristics and emits an
//! [`Event::Drift`] when a window of them is full. The reader owns the
//! port, so the requests go out from its loop ([`Watch::due`]); the
//! chunks, the configuration and the refusals come back as the events it
//! already emits ([`Watch::see`]).

use std::sync::Arc;
use std::time::{Duration, Instant};

use hammer_estimator::Config;
use hammer_wire::{CaptureChunk, CommandKind, DeviceMsg};

use super::event::{Event, Stamped};
use crate::drift::{Commissioned, DriftArgs, Window};

/// Pause between one capture's end and the next request: the captures
/// stream beside the reports, and the board needs no more than a cycle
/// every so often to read the drift.
pub const CAPTURE_PAUSE: Duration = Duration::from_millis(500);
/// A capture that has not finished by then is given up (the board lost a
/// chunk, or the hammer stopped) and asked for again.
pub const CAPTURE_TIMEOUT: Duration = Duration::from_secs(30);
/// After the board refused a capture (busy with another), wait this long.
const REFUSED_PAUSE: Duration = Duration::from_secs(5);

pub struct Watch {
    reference: Arc<Commissioned>,
    allow_stale: bool,
    k: usize,
    confirm: usize,
    point_bar: Option<f64>,
    config: Option<Config>,
    window: Option<Window>,
    /// The last reason no drift is read, said once.
    refused: Option<String>,
    chunks: Vec<CaptureChunk>,
    asked_at: Option<Instant>,
    next_at: Instant,
}

impl Watch {
    /// `link_bar`: the hammer's supply pressure where the link knows it
    /// ([`super::Connector::supply_bar`]), the point read when `--point-bar`
    /// does not say.
    pub fn new(reference: Arc<Commissioned>, args: &DriftArgs, link_bar: Option<f64>) -> Self {
        Self {
            reference,
            allow_stale: args.allow_stale_reference,
            k: args.drift_cycles as usize,
            confirm: args.drift_confirm as usize,
            point_bar: args.point_bar.or(link_bar),
            config: None,
            window: None,
            refused: None,
            chunks: Vec::new(),
            asked_at: None,
            next_at: Instant::now(),
        }
    }

    /// Whether to ask for a capture now; a capture that never finished is
    /// given up first (and said so).
    pub fn due(&mut self, now: Instant) -> (bool, Option<Event>) {
        if let Some(t) = self.asked_at {
            if now.duration_since(t) < CAPTURE_TIMEOUT {
                return (false, None);
            }
            self.asked_at = None;
            self.chunks.clear();
            let note = Event::Note(format!(
                "drift: a capture did not finish within {} s; asking again",
                CAPTURE_TIMEOUT.as_secs()
            ));
            return (self.window.is_some(), Some(note));
        }
        (self.window.is_some() && now >= self.next_at, None)
    }

    pub fn asked(&mut self, now: Instant) {
        self.asked_at = Some(now);
        self.chunks.clear();
    }

    /// A new connection: a capture in flight is lost with the old one, and
    /// the configuration is asked for again.
    pub fn reconnected(&mut self) {
        self.asked_at = None;
        self.chunks.clear();
        self.config = None;
    }

    /// Sees an event the reader emits; returns the events that follow from
    /// it (a drift reading, notes).
    pub fn see(&mut self, ev: &Stamped) -> Vec<Event> {
        match &ev.event {
            Event::Msg(DeviceMsg::Config(c)) => self.configured(Config::default().with_device(c)),
            Event::Msg(DeviceMsg::Rejected {
                command: CommandKind::StartCapture,
                ..
            }) => {
                self.asked_at = None;
                self.next_at = Instant::now() + REFUSED_PAUSE;
                vec![]
            }
            Event::Msg(DeviceMsg::Capture(c)) if self.asked_at.is_some() => self.chunk(c),
            _ => vec![],
        }
    }

    fn configured(&mut self, cfg: Config) -> Vec<Event> {
        let mut out = vec![];
        let supply_bar = f64::from(cfg.supply_pressure_pa) / 1e5;
        let checked = self
            .reference
            .check_calibration(cfg.calibration_hash(), self.allow_stale)
            .and_then(|warning| {
                self.reference
                    .point_for(supply_bar, self.point_bar)
                    .map(|b| (warning, b.clone()))
            });
        self.config = Some(cfg);
        match checked {
            Err(why) => {
                self.window = None;
                if self.refused.as_ref() != Some(&why) {
                    out.push(Event::Note(why.clone()));
                    self.refused = Some(why);
                }
            }
            Ok((warning, baseline)) => {
                self.refused = None;
                if self.window.as_ref().is_none_or(|w| w.baseline() != &baseline) {
                    out.extend(warning.map(Event::Note));
                    out.push(Event::Note(format!(
                        "drift: reading raw captures against {} at {} bar ({} cycles a reading)",
                        self.reference.dir.display(),
                        baseline.supply_bar,
                        self.k
                    )));
                    self.window = Some(Window::new(baseline, self.k, self.confirm));
                }
            }
        }
        out
    }

    fn chunk(&mut self, c: &CaptureChunk) -> Vec<Event> {
        let done = c.offset as usize + c.samples.len() >= c.total as usize;
        self.chunks.push(c.clone());
        if !done {
            return vec![];
        }
        self.asked_at = None;
        self.next_at = Instant::now() + CAPTURE_PAUSE;
        let chunks = std::mem::take(&mut self.chunks);
        let (Some(cfg), Some(window)) = (self.config.as_ref(), self.window.as_mut()) else {
            return vec![];
        };
        let codes = match crate::capture::assemble(&chunks) {
            Ok(c) => c,
            Err(e) => return vec![Event::Note(format!("drift: {e}; the capture is not read"))],
        };
        let (trace, _) = crate::capture::to_trace(&codes, cfg, None);
        let readings = self.reference.readings(&trace, window.baseline().supply_bar);
        if readings.is_empty() {
            return vec![Event::Note(
                "drift: a capture held no whole cycle (is the hammer running steadily?)".into(),
            )];
        }
        readings
            .into_iter()
            .filter_map(|r| window.push(r))
            .map(|d| Event::Drift(Box::new(d)))
            .collect()
    }
}
