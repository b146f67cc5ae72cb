//! Headless mode: one line per report and one per link event, for scripts,
//! pipes and CI logs. Report lines carry no host time, so a replay prints
//! the very lines the live run printed.
//!
//! A live run also says when reports stop coming ([`Stall`]): a silent
//! headless monitor cannot be told from a hung one otherwise. A replay does
//! not, as its pauses are the playback's, not the link's.

use std::io::Write;
use std::sync::mpsc::{Receiver, RecvTimeoutError};
use std::time::{Duration, Instant};

use anyhow::{bail, Result};
use hammer_wire::{DeviceMsg, PROTOCOL_VERSION};

use super::app::App;
use super::event::{describe, now_us, rfc3339, Event, Limiter, Stamped};
use super::log::Unlogged;
use super::UiOptions;

/// One line per report: the same line `hammer demo --headless` prints.
pub use crate::records::report_line;

/// The shortest silence called a stall: a hammer's cycle is far shorter,
/// but a device sends its status only every second.
pub const STALL_MIN: Duration = Duration::from_secs(1);
/// A stall is this many expected cycle periods without a report (or [`STALL_MIN`]).
pub const STALL_PERIODS: f64 = 2.0;

#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
enum Quiet {
    No,
    /// Frames (status, ...) still arrive, reports do not.
    NoCycles,
    /// Nothing arrives at all.
    Silent,
}

/// Watches a connected link for reports that stop coming; says so once when
/// a stall begins (again if frames stop too) and once when reports resume.
pub struct Stall {
    connected: bool,
    /// The last report, or the connect if none since.
    since: Instant,
    last_frame: Instant,
    frames: u64,
    period: Duration,
    quiet: Quiet,
}

impl Stall {
    pub fn new(now: Instant) -> Self {
        Self {
            connected: false,
            since: now,
            last_frame: now,
            frames: 0,
            period: Duration::ZERO,
            quiet: Quiet::No,
        }
    }

    fn limit(&self) -> Duration {
        self.period.mul_f64(STALL_PERIODS).max(STALL_MIN)
    }

    /// Takes in an event seen at `now`; returns a line to print, if any.
    pub fn event(&mut self, now: Instant, ev: &Event) -> Option<String> {
        match ev {
            Event::Connected { .. } => {
                self.connected = true;
                self.since = now;
                self.last_frame = now;
                self.quiet = Quiet::No;
            }
            Event::Disconnected { .. } => self.connected = false,
            Event::Stats(s) if s.frames != self.frames => {
                self.frames = s.frames;
                self.last_frame = now;
            }
            Event::Msg(DeviceMsg::Report(r)) => {
                let gap = now.duration_since(self.since);
                self.since = now;
                self.last_frame = now;
                if r.period_s.is_finite() && r.period_s > 0.0 {
                    self.period = Duration::from_secs_f64(r.period_s.min(3600.0) as f64);
                }
                if std::mem::replace(&mut self.quiet, Quiet::No) != Quiet::No {
                    return Some(format!("reports resumed after {:.1} s without any", gap.as_secs_f64()));
                }
            }
            _ => {}
        }
        None
    }

    /// Looks at the time; returns a line when a stall begins or deepens.
    pub fn check(&mut self, now: Instant) -> Option<String> {
        let quiet_for = now.duration_since(self.since);
        if !self.connected || quiet_for <= self.limit() {
            return None;
        }
        let silent_for = now.duration_since(self.last_frame);
        let quiet = if silent_for > self.limit() {
            Quiet::Silent
        } else {
            Quiet::NoCycles
        };
        if quiet <= self.quiet {
            return None;
        }
        self.quiet = quiet;
        Some(match quiet {
            Quiet::Silent => format!(
                "stall: no reports for {:.1} s and no frames at all for {:.1} s (link silent: device hung or cable?)",
                quiet_for.as_secs_f64(),
                silent_for.as_secs_f64()
            ),
            _ => format!(
                "stall: no reports for {:.1} s, but frames still arrive (link alive, no cycles: hammer stopped?)",
                quiet_for.as_secs_f64()
            ),
        })
    }
}

/// Prints what the log size cap has kept out, when it grew, at most every [`UNLOGGED_EVERY`].
pub const UNLOGGED_EVERY: Duration = Duration::from_secs(10);

fn unlogged_line(u: &Unlogged) -> String {
    format!(
        "not logged (log size cap reached): {} received bytes, {} reports, {} link.log lines so far",
        u.bytes, u.reports, u.lines
    )
}

/// A line of the headless monitor's own, stamped like the link events;
/// false once stdout is closed.
fn say(out: &mut impl Write, text: &str) -> bool {
    writeln!(out, "{}  {text}", rfc3339(now_us())).is_ok()
}

pub fn run(app: &mut App, rx: &Receiver<Stamped>, opts: UiOptions) -> Result<()> {
    let mut out = std::io::stdout().lock();
    let mut errors = Limiter::new(10);
    // A stream whose sequence runs backwards "restarts" at every report.
    let mut seq_events = Limiter::new(10);
    let mut stall = Stall::new(Instant::now());
    let mut unlogged = (Unlogged::default(), Unlogged::default(), None::<Instant>);
    loop {
        if opts.live {
            if let Some(text) = stall.check(Instant::now()) {
                if !say(&mut out, &text) {
                    return Ok(());
                }
            }
        }
        let ev = match rx.recv_timeout(Duration::from_millis(200)) {
            Ok(ev) => ev,
            Err(RecvTimeoutError::Timeout) => {
                app.tick();
                continue;
            }
            Err(RecvTimeoutError::Disconnected) => {
                if opts.live {
                    bail!("the reader thread stopped unexpectedly");
                }
                return Ok(());
            }
        };
        app.on_event(&ev);
        let line = match &ev.event {
            Event::Msg(DeviceMsg::Report(r)) => Some(report_line(r)),
            Event::FrameError { .. } | Event::SeqGap { .. } => match match &ev.event {
                Event::SeqGap { .. } => seq_events.allow(ev.t_us),
                _ => errors.allow(ev.t_us),
            } {
                Some(held) => describe(&ev.event).map(|(_, t)| {
                    let more = if held > 0 {
                        format!(" [{held} more not listed]")
                    } else {
                        String::new()
                    };
                    format!("{}  {t}{more}", rfc3339(ev.t_us))
                }),
                None => None,
            },
            e => describe(e).map(|(_, t)| format!("{}  {t}", rfc3339(ev.t_us))),
        };
        if let Some(line) = line {
            if writeln!(out, "{line}").is_err() {
                return Ok(()); // stdout closed (`| head`): nothing more to say
            }
        }
        if opts.live {
            if let Some(text) = stall.event(Instant::now(), &ev.event) {
                if !say(&mut out, &text) {
                    return Ok(());
                }
            }
        }
        if let Event::Stats(s) = &ev.event {
            let (latest, shown, at) = &mut unlogged;
            *latest = s.unlogged;
            if *latest != *shown && at.is_none_or(|t| t.elapsed() >= UNLOGGED_EVERY) {
                *shown = *latest;
                *at = Some(Instant::now());
                if !say(&mut out, &unlogged_line(latest)) {
                    return Ok(());
                }
            }
        }
        if let Event::VersionMismatch { device } = ev.event {
            if opts.live {
                bail!("protocol mismatch: the device speaks protocol {device}, this host {PROTOCOL_VERSION}");
            }
        }
        if ev.event == Event::End || opts.exit_after_reports.is_some_and(|n| app.reports >= n) {
            // The final count, if the last line did not say it.
            let (latest, shown, _) = &unlogged;
            if latest != shown {
                say(&mut out, &unlogged_line(latest));
            }
            return Ok(());
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::monitor::event::LinkStats;
    use hammer_wire::CycleReport;

    fn report(period_s: f32) -> Event {
        Event::Msg(DeviceMsg::Report(CycleReport {
            period_s,
            ..Default::default()
        }))
    }

    #[test]
    fn a_stall_is_said_once_when_it_begins_once_when_it_deepens_and_once_when_it_ends() {
        let t0 = Instant::now();
        let at = |ms: u64| t0 + Duration::from_millis(ms);
        let mut s = Stall::new(t0);
        assert_eq!(s.check(at(5_000)), None, "not connected: the disconnect said it");
        s.event(
            at(5_000),
            &Event::Connected {
                port: "p".into(),
                reconnects: 0,
                lost_at_us: None,
                outage_us: None,
            },
        );
        assert_eq!(s.event(at(5_100), &report(0.05)), None);
        assert_eq!(s.check(at(6_000)), None, "1 s is the least stall");
        // A status frame at 6.0 s: the link is alive.
        let stats = |frames| {
            Event::Stats(LinkStats {
                frames,
                ..Default::default()
            })
        };
        s.event(at(6_000), &stats(5));
        let line = s.check(at(6_200)).expect("a stall");
        assert!(
            line.contains("no reports for 1.1 s") && line.contains("link alive"),
            "{line}"
        );
        assert_eq!(s.check(at(6_400)), None, "once per stall");
        s.event(at(6_500), &stats(5));
        let line = s.check(at(7_100)).expect("the link went silent too");
        assert!(line.contains("no frames at all for 1.1 s"), "{line}");
        assert_eq!(s.check(at(9_000)), None);
        let line = s.event(at(9_100), &report(0.05)).expect("resumed");
        assert!(line.contains("resumed after 4.0 s"), "{line}");
        // A slow hammer (2 s cycles) is no stall at 3 s, but is at 4.1 s.
        assert_eq!(s.event(at(10_000), &report(2.0)), None);
        assert_eq!(s.check(at(13_000)), None);
        assert!(s.check(at(14_100)).is_some());
    }
}
