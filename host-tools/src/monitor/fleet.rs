//! Several devices in one monitor (`--port A --port B …`, `hammer demo
//! --devices N`): one reader thread per device, each reconnecting on its
//! own and logging into its own `--log DIR/<device>/`; the exports are
//! shared (one Parquet dataset, one line-protocol destination). The screen
//! is a summary row per device above the current device's dashboard (Tab or
//! the arrow keys switch); headless, every line starts with `[device]`.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{self, Receiver, TryRecvError};
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use hammer_wire::DeviceMsg;
use ratatui::crossterm::event::{self, Event as TermEvent, KeyCode, KeyEventKind, KeyModifiers};
use ratatui::layout::{Constraint, Layout};
use ratatui::style::{Color, Style};
use ratatui::text::{Line, Span};
use ratatui::widgets::{Block, Paragraph};
use ratatui::Frame;

use super::app::App;
use super::event::{describe, rfc3339, Event, Stamped};
use super::export::{DeviceExport, Exports};
use super::headless::{report_line, Stall};
use super::{log, reader, Connector, MonitorArgs, EVENT_QUEUE};

/// One watched device.
pub struct Member {
    pub name: String,
    pub app: App,
    rx: Receiver<Stamped>,
    stall: Stall,
    gone: bool,
}

/// Starts a reader per device and shows them until quit (or, headless,
/// until every device has sent `--exit-after-reports` reports).
pub fn run(devices: Vec<(String, Box<dyn Connector>)>, args: &MonitorArgs, headless: bool) -> Result<()> {
    let mut names: Vec<&str> = devices.iter().map(|(n, _)| n.as_str()).collect();
    names.sort_unstable();
    if let Some(w) = names.windows(2).find(|w| w[0] == w[1]) {
        bail!("two devices are named {:?}: name them (--port NAME=PORT)", w[0]);
    }
    let max_bytes = (args.log_max_mb * 1e6) as u64;
    let exports = Exports::open(&args.export)?;
    let stop = Arc::new(AtomicBool::new(false));
    let reference = super::commissioned(&args.drift)?;
    let mut members = vec![];
    let mut readers = vec![];
    for (name, connector) in devices {
        let logger = match &args.log {
            Some(dir) => {
                let dir = dir.join(&name);
                Some(log::Logger::open(&dir, max_bytes).with_context(|| format!("cannot log to {}", dir.display()))?)
            }
            None => None,
        };
        let export = exports.clone().map(|x| DeviceExport::new(&name, x));
        let (tx, rx) = mpsc::sync_channel(EVENT_QUEUE);
        let title = connector.describe();
        // Each member at its own point: `--point-bar`, else what its link knows.
        let watch = reference
            .clone()
            .map(|c| super::drift::Watch::new(c, &args.drift, connector.supply_bar()));
        readers.push(reader::spawn(connector, logger, export, watch, tx, stop.clone())?);
        members.push(Member {
            name,
            app: App::new(title, true, args.history_s),
            rx,
            stall: Stall::new(Instant::now()),
            gone: false,
        });
    }
    let result = if headless {
        run_headless(&mut members, args.exit_after_reports)
    } else {
        run_ui(&mut members, args.exit_after_reports)
    };
    stop.store(true, Ordering::Relaxed);
    drop(members);
    for r in readers {
        if r.join().is_err() {
            eprintln!("a reader thread panicked; its logs may be incomplete");
        }
    }
    let closed = super::close_exports(exports);
    result.and(closed)
}

/// Takes what each device has sent; `line` gets each one's printable lines.
fn drain(members: &mut [Member], mut line: impl FnMut(&str, &str)) {
    for m in members.iter_mut() {
        for _ in 0..5_000 {
            match m.rx.try_recv() {
                Ok(ev) => {
                    m.app.on_event(&ev);
                    if let Some(text) = m.stall.event(Instant::now(), &ev.event) {
                        line(&m.name, &text);
                    }
                    match &ev.event {
                        Event::Msg(DeviceMsg::Report(r)) => line(&m.name, &report_line(r)),
                        Event::Stats(_) | Event::Msg(_) => {}
                        e => {
                            if let Some((_, text)) = describe(e) {
                                line(&m.name, &format!("{}  {text}", rfc3339(ev.t_us)));
                            }
                        }
                    }
                }
                Err(TryRecvError::Empty) => break,
                Err(TryRecvError::Disconnected) => {
                    if !m.gone {
                        m.gone = true;
                        line(&m.name, "the reader stopped");
                    }
                    break;
                }
            }
        }
        if let Some(text) = m.stall.check(Instant::now()) {
            line(&m.name, &text);
        }
    }
}

fn done(members: &[Member], exit_after: Option<u64>) -> bool {
    exit_after.is_some_and(|n| members.iter().all(|m| m.app.reports >= n || m.gone))
}

fn run_headless(members: &mut [Member], exit_after: Option<u64>) -> Result<()> {
    use std::io::Write;
    let mut out = std::io::stdout().lock();
    let mut closed = false;
    loop {
        drain(members, |name, text| {
            closed |= writeln!(out, "[{name}] {text}").is_err();
        });
        if closed || done(members, exit_after) {
            return Ok(());
        }
        if members.iter().all(|m| m.gone) {
            bail!("every reader thread stopped");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// One summary row: name, link, the latest cycle's figures, wear, alarms.
fn summary_line(m: &Member, selected: bool) -> Line<'static> {
    let v = m.app.shown();
    let link = if v.connected && v.handshaken {
        Span::styled("up  ", Style::default().fg(Color::Green))
    } else if v.connected {
        Span::styled("open", Style::default().fg(Color::Yellow))
    } else {
        Span::styled("down", Style::default().fg(Color::Red))
    };
    let figures = match &v.last {
        Some((_, r)) if r.is_valid() => format!(
            "#{:<6} {:6.2} Hz  friction {:6.2} N  energy {:6.3} J  wear {:9.1} J",
            r.seq, r.frequency_hz, r.friction_n, r.impact_energy_j, r.wear_index_j
        ),
        Some((_, r)) => format!("#{:<6} not valid: {}", r.seq, crate::records::flag_list(r.flags)),
        None => "no report yet".into(),
    };
    let alarm = if v.alarm.is_some() {
        Span::styled(" ALARM", Style::default().fg(Color::Red).bold())
    } else {
        Span::raw("")
    };
    let name = format!("{}{:<14}", if selected { "> " } else { "  " }, m.name);
    let name = if selected {
        Span::styled(name, Style::default().bold())
    } else {
        Span::raw(name)
    };
    Line::from(vec![
        name,
        link,
        Span::raw(format!(
            "  {:>7} reports  {:>3} lost  ",
            v.stats.reports, v.stats.lost_reports
        )),
        Span::raw(figures),
        alarm,
    ])
}

fn draw(f: &mut Frame, members: &[Member], selected: usize) {
    let rows = members.len() as u16 + 2;
    let [top, rest] = Layout::vertical([Constraint::Length(rows), Constraint::Min(10)]).areas(f.area());
    let lines: Vec<Line> = members
        .iter()
        .enumerate()
        .map(|(i, m)| summary_line(m, i == selected))
        .collect();
    f.render_widget(
        Paragraph::new(lines).block(Block::bordered().title(format!(
            " fleet: {} devices (Tab/←/→ or 1-9: show a device) ",
            members.len()
        ))),
        top,
    );
    super::ui::ui_in(f, rest, &members[selected].app);
}

fn run_ui(members: &mut [Member], exit_after: Option<u64>) -> Result<()> {
    struct Restore;
    impl Drop for Restore {
        fn drop(&mut self) {
            ratatui::restore();
        }
    }
    let mut terminal = ratatui::try_init()?;
    let _restore = Restore;
    let mut sel = 0usize;
    let mut last_draw = Instant::now() - Duration::from_secs(1);
    loop {
        drain(members, |_, _| {});
        if last_draw.elapsed() >= Duration::from_millis(100) {
            for m in members.iter_mut() {
                m.app.tick();
            }
            terminal.draw(|f| draw(f, members, sel))?;
            last_draw = Instant::now();
        }
        if done(members, exit_after) || members[sel].app.quit {
            return Ok(());
        }
        if event::poll(Duration::from_millis(20))? {
            if let TermEvent::Key(k) = event::read()? {
                if k.kind == KeyEventKind::Release {
                    continue;
                }
                let n = members.len();
                let app = &mut members[sel].app;
                match k.code {
                    KeyCode::Char('c') if k.modifiers.contains(KeyModifiers::CONTROL) => return Ok(()),
                    KeyCode::Char('q') | KeyCode::Char('Q') => return Ok(()),
                    KeyCode::Esc if app.show_help => app.show_help = false,
                    KeyCode::Esc => return Ok(()),
                    KeyCode::Tab | KeyCode::Right => sel = (sel + 1) % n,
                    KeyCode::BackTab | KeyCode::Left => sel = (sel + n - 1) % n,
                    KeyCode::Char(d @ '1'..='9') if (d as usize - '1' as usize) < n => sel = d as usize - '1' as usize,
                    KeyCode::Char('p') | KeyCode::Char(' ') => app.toggle_pause(),
                    KeyCode::Char('c') => app.clear_alarm(),
                    KeyCode::Char('?') | KeyCode::Char('h') | KeyCode::F(1) => app.show_help = !app.show_help,
                    _ => {}
                }
                last_draw = Instant::now() - Duration::from_secs(1);
            }
        }
    }
}
