//! Headless mode: one line per report and one per link event, for scripts,
//! pipes and CI logs. Report lines carry no host time, so a replay prints
//! the very lines the live run printed.

use std::io::Write;
use std::sync::mpsc::{Receiver, RecvTimeoutError};
use std::time::Duration;

use anyhow::{bail, Result};
use hammer_wire::{DeviceMsg, Report, PROTOCOL_VERSION};

use super::app::App;
use super::event::{describe, flag_list, rfc3339, Event, Limiter, Stamped};
use super::ui::{num, pm};
use super::UiOptions;

/// `cycle 12  t 1.234567 s  friction 12.34 ± 1.12 N  energy 4.616 ± 0.166 J  (w/o friction 5.299 ± 0.180 J)  21.79 Hz  flags -`
pub fn report_line(r: &Report) -> String {
    format!(
        "cycle {:>6}  t {} s  friction {} N  energy {} J  (w/o friction {} J)  {} Hz  flags {}{}",
        r.seq,
        num(r.t_impact_s, 6),
        pm(r.friction_n, r.friction_uncertainty_n, 2),
        pm(r.impact_energy_j, r.impact_energy_uncertainty_j, 3),
        pm(
            r.impact_energy_frictionless_j,
            r.impact_energy_frictionless_uncertainty_j,
            3
        ),
        num(r.frequency_hz as f64, 2),
        flag_list(r.flags),
        if r.is_valid() { "" } else { "  INVALID" }
    )
}

pub fn run(app: &mut App, rx: &Receiver<Stamped>, opts: UiOptions) -> Result<()> {
    let mut out = std::io::stdout().lock();
    let mut errors = Limiter::new(10);
    loop {
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
            Event::FrameError { .. } => match errors.allow(ev.t_us) {
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
        if let Event::VersionMismatch { device } = ev.event {
            if opts.live {
                bail!("protocol mismatch: the device speaks protocol {device}, this host {PROTOCOL_VERSION}");
            }
        }
        if ev.event == Event::End {
            return Ok(());
        }
        if opts.exit_after_reports.is_some_and(|n| app.reports >= n) {
            return Ok(());
        }
    }
}
