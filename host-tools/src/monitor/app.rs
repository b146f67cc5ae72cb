//! The dashboard's state: everything [`super::ui::ui`] draws, updated from
//! events. Pausing freezes a copy for the screen while this goes on.

use std::collections::VecDeque;

use hammer_estimator::Flags;
use hammer_wire::{AlarmKind, CycleReport, DeviceConfig, DeviceInfo, DeviceMsg, Status};

use super::event::{describe, flag_list, now_us, Event, LinkStats, Severity, Stamped};

/// Points kept for the charts whatever `--history-s` says (a hammer at
/// 25 Hz fills 300 s with 7500).
pub const HISTORY_CAP: usize = 20_000;
/// Lines kept in the event panel.
pub const EVENTS_CAP: usize = 200;

/// One valid cycle in the charts.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Point {
    pub t_us: u64,
    pub friction_n: f32,
    pub energy_j: f32,
    pub energy_frictionless_j: f32,
    pub frequency_hz: f32,
}

/// The charts' data: the last `span_us` of valid cycles, never more than [`HISTORY_CAP`].
#[derive(Debug, Clone, Default)]
pub struct History {
    pub points: VecDeque<Point>,
}

impl History {
    pub fn push(&mut self, p: Point) {
        while self.points.len() >= HISTORY_CAP {
            self.points.pop_front();
        }
        self.points.push_back(p);
    }

    pub fn trim(&mut self, now_us: u64, span_us: u64) {
        let oldest = now_us.saturating_sub(span_us);
        while self.points.front().is_some_and(|p| p.t_us < oldest) {
            self.points.pop_front();
        }
    }
}

#[derive(Debug, Clone, PartialEq)]
pub struct Banner {
    pub t_us: u64,
    pub text: String,
}

#[derive(Debug, Clone)]
pub struct EventLine {
    pub t_us: u64,
    pub severity: Severity,
    pub text: String,
}

/// What is on screen.
#[derive(Debug, Clone, Default)]
pub struct View {
    pub stats: LinkStats,
    pub port: Option<String>,
    pub connected: bool,
    /// The device answered the handshake on the current connection.
    pub handshaken: bool,
    pub ever_connected: bool,
    /// Why the port does not open (while it does not).
    pub connect_error: Option<String>,
    pub lost_at_us: Option<u64>,
    /// The last device that answered (kept across a reconnect, for reference).
    pub device: Option<DeviceInfo>,
    pub mismatch: Option<u16>,
    pub config: Option<DeviceConfig>,
    pub status: Option<(u64, Status)>,
    /// The latest report and when it arrived.
    pub last: Option<(u64, CycleReport)>,
    pub history: History,
    /// Drift alarm or sensor fault, until cleared with `c`.
    pub alarm: Option<Banner>,
    pub events: VecDeque<EventLine>,
    pub captures: u64,
    /// The latest drift since commissioning (`--reference`), when read.
    pub drift: Option<(u64, crate::drift::Drift)>,
}

pub struct App {
    /// What the data comes from: the port, or the replayed file.
    pub source: String,
    pub live: bool,
    pub history_s: f64,
    /// The dashboard's clock: the wall clock live, the recording's in a replay.
    pub now_us: u64,
    pub view: View,
    /// The copy on screen while paused.
    pub frozen: Option<Box<View>>,
    pub reports_since_pause: u64,
    pub show_help: bool,
    pub quit: bool,
    /// Reports seen since start (for `--exit-after-reports`).
    pub reports: u64,
    pub ended: bool,
}

impl App {
    pub fn new(source: String, live: bool, history_s: f64) -> Self {
        Self {
            source,
            live,
            history_s,
            now_us: if live { now_us() } else { 0 },
            view: View::default(),
            frozen: None,
            reports_since_pause: 0,
            show_help: false,
            quit: false,
            reports: 0,
            ended: false,
        }
    }

    /// The view to draw: frozen while paused.
    pub fn shown(&self) -> &View {
        self.frozen.as_deref().unwrap_or(&self.view)
    }

    pub fn paused(&self) -> bool {
        self.frozen.is_some()
    }

    pub fn toggle_pause(&mut self) {
        if self.frozen.take().is_none() {
            self.frozen = Some(Box::new(self.view.clone()));
            self.reports_since_pause = 0;
        }
    }

    pub fn clear_alarm(&mut self) {
        self.view.alarm = None;
        if let Some(f) = &mut self.frozen {
            f.alarm = None;
        }
    }

    fn span_us(&self) -> u64 {
        (self.history_s * 1e6).min(u64::MAX as f64) as u64
    }

    /// Live: the clock moves on with no data too, and the charts scroll.
    pub fn tick(&mut self) {
        if self.live {
            self.now_us = self.now_us.max(now_us());
        }
        let span = self.span_us();
        self.view.history.trim(self.now_us, span);
    }

    pub fn on_event(&mut self, ev: &Stamped) {
        self.now_us = self.now_us.max(ev.t_us);
        if matches!(ev.event, Event::Msg(DeviceMsg::Report(_))) {
            self.reports += 1;
            if self.paused() {
                self.reports_since_pause += 1;
            }
        }
        if ev.event == Event::End {
            self.ended = true;
        }
        self.view.apply(ev);
        let span = self.span_us();
        self.view.history.trim(self.now_us, span);
    }
}

impl View {
    fn log(&mut self, t_us: u64, severity: Severity, text: String) {
        if self.events.len() >= EVENTS_CAP {
            self.events.pop_front();
        }
        self.events.push_back(EventLine { t_us, severity, text });
    }

    fn raise(&mut self, t_us: u64, text: String) {
        self.alarm = Some(Banner { t_us, text });
    }

    pub fn apply(&mut self, ev: &Stamped) {
        let t = ev.t_us;
        if let Some((sev, text)) = describe(&ev.event) {
            // Frame errors have their counters; list only the first few in a row.
            let repeat = matches!(ev.event, Event::FrameError { .. })
                && self.events.back().is_some_and(|e| e.text.starts_with("frame error"))
                && self
                    .events
                    .iter()
                    .rev()
                    .take(5)
                    .all(|e| e.text.starts_with("frame error"));
            if !repeat {
                self.log(t, sev, text);
            }
        }
        match &ev.event {
            Event::Stats(s) => self.stats = *s,
            Event::Connected { port, .. } => {
                self.port = Some(port.clone());
                self.connected = true;
                self.handshaken = false;
                self.ever_connected = true;
                self.connect_error = None;
                self.lost_at_us = None;
                self.mismatch = None;
            }
            Event::Disconnected { port, .. } => {
                self.port = Some(port.clone());
                self.connected = false;
                self.handshaken = false;
                self.lost_at_us = Some(t);
            }
            Event::ConnectFailed { port, error } => {
                self.port = Some(port.clone());
                self.connected = false;
                self.connect_error = Some(error.clone());
                self.lost_at_us.get_or_insert(t);
            }
            Event::Device(info) => {
                self.device = Some(info.clone());
                self.handshaken = true;
                self.mismatch = None;
            }
            Event::VersionMismatch { device } => self.mismatch = Some(*device),
            Event::Msg(m) => self.message(t, m),
            Event::Drift(d) => {
                if d.alarm() {
                    let named: Vec<&str> = d
                        .characteristics
                        .iter()
                        .filter(|c| c.alarm)
                        .map(|c| c.name.as_str())
                        .collect();
                    self.raise(
                        t,
                        format!(
                            "CHANGE SINCE COMMISSIONING: {} beyond its uncertainty",
                            named.join(", ")
                        ),
                    );
                } else if self.alarm.as_ref().is_some_and(|b| b.text.starts_with("CHANGE")) {
                    self.alarm = None;
                }
                self.drift = Some((t, (**d).clone()));
            }
            _ => {}
        }
    }

    fn message(&mut self, t: u64, m: &DeviceMsg) {
        match m {
            // Alarms are the device's: it raises them (`DeviceMsg::Alarm`)
            // from the flags, the host only shows them.
            DeviceMsg::Report(r) => {
                if r.is_valid() {
                    self.history.push(Point {
                        t_us: t,
                        friction_n: r.friction_n,
                        energy_j: r.impact_energy_j,
                        energy_frictionless_j: r.impact_energy_frictionless_j,
                        frequency_hz: r.frequency_hz,
                    });
                }
                self.last = Some((t, *r));
            }
            DeviceMsg::Status(s) => self.status = Some((t, *s)),
            DeviceMsg::Config(c) => self.config = Some(*c),
            DeviceMsg::Alarm(a) => match a.kind {
                AlarmKind::DriftOn => self.raise(
                    t,
                    format!(
                        "DRIFT ALARM since cycle {}: friction rising (drift score {:.2})",
                        a.cycle_seq, a.drift_score
                    ),
                ),
                AlarmKind::DriftOff => {
                    if self.alarm.as_ref().is_some_and(|b| b.text.starts_with("DRIFT")) {
                        self.alarm = None;
                    }
                }
                AlarmKind::SensorFault => {
                    let faults = Flags(a.flags.0 & Flags::SENSOR_FAULTS.0);
                    self.raise(
                        t,
                        format!("SENSOR FAULT at cycle {}: {}", a.cycle_seq, flag_list(faults)),
                    );
                }
            },
            DeviceMsg::Capture(_) => self.captures += 1,
            _ => {}
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use hammer_wire::Alarm;

    fn report(seq: u32, flags: u32) -> Stamped {
        Stamped {
            t_us: 1_000_000 + u64::from(seq) * 50_000,
            event: Event::Msg(DeviceMsg::Report(CycleReport {
                seq,
                friction_n: seq as f32,
                flags: Flags(flags),
                ..Default::default()
            })),
        }
    }

    /// What the device sends after a report that changes an alarm.
    fn alarm(kind: AlarmKind, seq: u32, flags: u32) -> Stamped {
        Stamped {
            t_us: 1_000_000 + u64::from(seq) * 50_000,
            event: Event::Msg(DeviceMsg::Alarm(Alarm {
                kind,
                cycle_seq: seq,
                flags: Flags(flags),
                drift_score: 11.5,
            })),
        }
    }

    #[test]
    fn history_is_bounded_by_time_and_count() {
        let mut app = App::new("x".into(), false, 1.0);
        for s in 0..100 {
            app.on_event(&report(s, 0));
        }
        // 1 s at 20 reports a second.
        assert_eq!(app.view.history.points.len(), 21);
        let mut h = History::default();
        for i in 0..(HISTORY_CAP as u64 + 10) {
            h.push(Point {
                t_us: i,
                friction_n: 0.0,
                energy_j: 0.0,
                energy_frictionless_j: 0.0,
                frequency_hz: 0.0,
            });
        }
        assert_eq!(h.points.len(), HISTORY_CAP);
    }

    #[test]
    fn pause_freezes_the_view_not_the_state_and_alarms_clear() {
        let mut app = App::new("x".into(), false, 300.0);
        app.on_event(&report(0, 0));
        app.toggle_pause();
        app.on_event(&report(1, Flags::DRIFT_ALARM.0));
        assert!(
            app.view.alarm.is_none(),
            "the host derives no alarm from a report's flags"
        );
        app.on_event(&alarm(AlarmKind::DriftOn, 1, Flags::DRIFT_ALARM.0));
        assert_eq!(app.shown().last.unwrap().1.seq, 0);
        assert_eq!(app.view.last.unwrap().1.seq, 1);
        assert_eq!(app.reports_since_pause, 1);
        assert!(app.view.alarm.as_ref().unwrap().text.contains("DRIFT ALARM"));
        app.clear_alarm();
        assert!(app.view.alarm.is_none());
        // Invalid cycles are not charted.
        app.on_event(&report(2, Flags::DISCONNECTED.0));
        assert_eq!(app.view.history.points.len(), 2);
        assert!(
            app.view.alarm.is_none(),
            "the device's alarm, not the report, raises the banner"
        );
        app.on_event(&alarm(AlarmKind::SensorFault, 2, Flags::DISCONNECTED.0));
        assert_eq!(
            app.view.alarm.as_ref().unwrap().text,
            "SENSOR FAULT at cycle 2: disconnected"
        );
        app.toggle_pause();
        assert_eq!(app.shown().last.unwrap().1.seq, 2);
        let off = Stamped {
            t_us: 9_000_000,
            event: Event::Msg(DeviceMsg::Alarm(Alarm {
                kind: AlarmKind::DriftOff,
                cycle_seq: 3,
                flags: Flags(0),
                drift_score: 0.0,
            })),
        };
        app.on_event(&off);
        assert!(app.view.alarm.is_some(), "a drift-off does not hide a sensor fault");
    }
}
