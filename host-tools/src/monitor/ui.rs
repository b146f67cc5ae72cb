//! The terminal dashboard: [`run`] is the event loop (keys, a redraw tick,
//! events from the reader), [`ui`] draws one frame from the [`App`].

use std::sync::mpsc::{Receiver, TryRecvError};
use std::time::{Duration, Instant};

use anyhow::Result;
use hammer_estimator::Flags;
use hammer_wire::{config_hash, PROTOCOL_VERSION};
use ratatui::crossterm::event::{self, Event as TermEvent, KeyCode, KeyEventKind, KeyModifiers};
use ratatui::layout::{Alignment, Constraint, Layout, Rect};
use ratatui::style::{Color, Modifier, Style, Stylize};
use ratatui::symbols::Marker;
use ratatui::text::{Line, Span};
use ratatui::widgets::{Axis, Block, Chart, Clear, Dataset, GraphType, Paragraph, Wrap};
use ratatui::Frame;

use super::app::{App, View};
use super::event::{board_name, clock, firmware_version, flag_list, Event, Severity, Stamped};
use super::UiOptions;
use crate::numfmt::{ago, bytes, coarse, duration, num, si_count};
use crate::records::{shown, unit};

/// Redraw at least this often (clocks, "ago" times, scrolling charts).
const TICK: Duration = Duration::from_millis(250);
/// ... and at most this often while data pours in.
const MIN_FRAME: Duration = Duration::from_millis(50);
/// Events taken from the queue between two looks at the keyboard.
const DRAIN_MAX: usize = 5_000;

/// Puts the terminal in raw mode on the alternate screen (restored on exit,
/// on error and, through ratatui's panic hook, on panic) and runs until `q`.
pub fn run(app: &mut App, rx: &Receiver<Stamped>, opts: UiOptions) -> Result<()> {
    struct Restore;
    impl Drop for Restore {
        fn drop(&mut self) {
            ratatui::restore();
        }
    }
    let mut terminal = ratatui::try_init()?;
    let _restore = Restore;
    let mut last_draw: Option<Instant> = None;
    let mut dirty = true;
    let mut source_gone = false;
    loop {
        for _ in 0..DRAIN_MAX {
            match rx.try_recv() {
                Ok(ev) => {
                    app.on_event(&ev);
                    dirty = true;
                    if opts.exit_after_reports.is_some_and(|n| app.reports >= n) {
                        app.quit = true;
                        break;
                    }
                }
                Err(TryRecvError::Empty) => break,
                Err(TryRecvError::Disconnected) => {
                    if !source_gone && opts.live {
                        app.on_event(&Stamped::now(Event::Note(
                            "the reader thread stopped unexpectedly; restart the monitor".into(),
                        )));
                    }
                    source_gone = true;
                    break;
                }
            }
        }
        let due = last_draw.is_none_or(|t| t.elapsed() >= TICK || (dirty && t.elapsed() >= MIN_FRAME));
        if due || app.quit {
            app.tick();
            terminal.draw(|f| ui(f, app))?;
            last_draw = Some(Instant::now());
            dirty = false;
        }
        if app.quit {
            return Ok(());
        }
        if event::poll(Duration::from_millis(20))? {
            match event::read()? {
                TermEvent::Key(k) if k.kind != KeyEventKind::Release => {
                    dirty = true;
                    match k.code {
                        KeyCode::Char('c') if k.modifiers.contains(KeyModifiers::CONTROL) => app.quit = true,
                        KeyCode::Char('q') | KeyCode::Char('Q') => app.quit = true,
                        KeyCode::Esc if app.show_help => app.show_help = false,
                        KeyCode::Esc => app.quit = true,
                        KeyCode::Char('p') | KeyCode::Char(' ') => app.toggle_pause(),
                        KeyCode::Char('c') => app.clear_alarm(),
                        KeyCode::Char('?') | KeyCode::Char('h') | KeyCode::F(1) => app.show_help = !app.show_help,
                        _ => {}
                    }
                }
                TermEvent::Resize(..) => dirty = true,
                _ => {}
            }
        }
    }
}

/// Draws the whole dashboard.
pub fn ui(f: &mut Frame, app: &App) {
    ui_in(f, f.area(), app)
}

/// Draws the dashboard of one device into `area` (the fleet view's lower part).
pub fn ui_in(f: &mut Frame, area: Rect, app: &App) {
    let v = app.shown();
    let banners = banners(app, v);
    let events_h = if area.height >= 40 { 8 } else { 5 };
    let [header, banner_area, main, events, footer] = Layout::vertical([
        Constraint::Length(1),
        Constraint::Length(banners.len() as u16),
        Constraint::Min(10),
        Constraint::Length(events_h),
        Constraint::Length(1),
    ])
    .areas(area);
    f.render_widget(header_line(app, v), header);
    f.render_widget(Paragraph::new(banners), banner_area);

    let [left, right] = Layout::horizontal([Constraint::Length(50), Constraint::Min(30)]).areas(main);
    let [cycle, link, device] =
        Layout::vertical([Constraint::Length(14), Constraint::Length(11), Constraint::Min(4)]).areas(left);
    f.render_widget(cycle_panel(app, v), cycle);
    f.render_widget(link_panel(app, v), link);
    match &v.drift {
        Some((t, d)) => {
            let rows = d.characteristics.len() as u16 + 3;
            let [device, drift] = Layout::vertical([Constraint::Min(4), Constraint::Length(rows)]).areas(device);
            f.render_widget(device_panel(v), device);
            f.render_widget(super::drift_panel::drift_panel(app.now_us, *t, d), drift);
        }
        None => f.render_widget(device_panel(v), device),
    }
    // The latest report's chambers above the charts: one row per chamber.
    let [chambers, right] = Layout::vertical([Constraint::Length(5), Constraint::Min(6)]).areas(right);
    f.render_widget(
        super::chambers_panel::chambers_panel(v.last.as_ref().map(|(_, r)| r)),
        chambers,
    );
    charts(f, app, v, right);
    f.render_widget(events_panel(v, events.height.saturating_sub(2) as usize), events);
    f.render_widget(footer_line(app), footer);
    if app.show_help {
        help(f, area);
    }
}

fn header_line(app: &App, v: &View) -> Paragraph<'static> {
    let title = if app.live {
        " hammer monitor "
    } else {
        " hammer replay "
    };
    let state = if !app.live {
        if app.ended {
            Span::styled(" ■ end of recording ", Style::new().fg(Color::Cyan))
        } else {
            Span::styled(" ▶ replaying ", Style::new().fg(Color::Cyan))
        }
    } else if v.mismatch.is_some() {
        Span::styled(" ✖ protocol mismatch ", Style::new().fg(Color::Red).bold())
    } else if !v.connected {
        Span::styled(" ○ disconnected ", Style::new().fg(Color::Yellow).bold())
    } else if !v.handshaken {
        Span::styled(" ◌ handshaking ", Style::new().fg(Color::Yellow))
    } else {
        Span::styled(" ● connected ", Style::new().fg(Color::Green).bold())
    };
    let port = v.port.clone().unwrap_or_else(|| app.source.clone());
    let src = if app.live { port } else { app.source.clone() };
    Paragraph::new(Line::from(vec![
        Span::styled(title, Style::new().bg(Color::Blue).fg(Color::White).bold()),
        Span::raw(" "),
        Span::styled(src, Style::new().bold()),
        Span::raw(" "),
        state,
        Span::styled(format!(" {}Z", clock(app.now_us)), Style::new().dim()),
    ]))
}

fn banners(app: &App, v: &View) -> Vec<Line<'static>> {
    let mut out = vec![];
    if let Some(device) = v.mismatch {
        out.push(
            Line::from(format!(
                " ✖ PROTOCOL MISMATCH: the device speaks protocol {device}, this host {PROTOCOL_VERSION}. \
             Its data is not interpreted: update the firmware or the host tools."
            ))
            .style(Style::new().bg(Color::Red).fg(Color::White).bold()),
        );
    }
    if let Some(a) = &v.alarm {
        out.push(
            Line::from(format!(" ⚠ {}  ({} UTC; c clears)", a.text, clock(a.t_us)))
                .style(Style::new().bg(Color::Red).fg(Color::White).bold()),
        );
    }
    if app.live && !v.connected && !v.ever_connected {
        if let Some(since) = v.lost_at_us {
            let why = v.connect_error.as_deref().unwrap_or("not there");
            out.push(
                Line::from(format!(
                    " NO DEVICE YET ({:.0} s): {why}; trying every 0.5 s",
                    app.now_us.saturating_sub(since) as f64 * 1e-6
                ))
                .style(Style::new().bg(Color::Yellow).fg(Color::Black).bold()),
            );
        }
    } else if app.live && !v.connected {
        if let Some(lost) = v.lost_at_us {
            out.push(
                Line::from(format!(
                    " LINK DOWN since {}Z ({:.1} s): retrying every 0.5 s; reconnects so far {}",
                    clock(lost),
                    app.now_us.saturating_sub(lost) as f64 * 1e-6,
                    v.stats.reconnects
                ))
                .style(Style::new().bg(Color::Yellow).fg(Color::Black).bold()),
            );
        }
    }
    out
}

fn label(s: &str) -> Span<'static> {
    Span::styled(format!("{s:<16}"), Style::new().fg(Color::Gray))
}

fn row(l: &str, value: String, unit: &str) -> Line<'static> {
    Line::from(vec![
        label(l),
        Span::styled(value, Style::new().bold()),
        Span::raw(format!(" {unit}")),
    ])
}

/// The cycle panel's rows with an uncertainty: (label, field, decimals).
const PANEL: [(&str, &str, usize); 5] = [
    ("Friction", "friction_n", 2),
    ("  stroke", "friction_stroke_n", 2),
    ("  backhaul", "friction_backhaul_n", 2),
    ("Impact energy", "impact_energy_j", 3),
    ("  w/o friction", "impact_energy_frictionless_j", 3),
];

fn cycle_panel(app: &App, v: &View) -> Paragraph<'static> {
    let block = Block::bordered().title(" Current cycle ");
    let Some((t, r)) = v.last else {
        let msg = if v.mismatch.is_some() {
            "not interpreting: protocol mismatch"
        } else {
            "waiting for the first report…"
        };
        return Paragraph::new(Line::from(msg).dim()).block(block);
    };
    let valid = r.is_valid();
    let value_style = if valid { Style::new().bold() } else { Style::new().dim() };
    let mut lines = vec![Line::from(vec![
        Span::styled(format!("Cycle {}", r.seq), Style::new().bold().fg(Color::Cyan)),
        Span::raw(format!("  t {} s  ", num(r.t_impact_s(), 4))),
        Span::styled(ago(app.now_us, t), Style::new().dim()),
    ])];
    if !valid {
        lines.push(
            Line::from(" INVALID: these numbers are not estimates ")
                .style(Style::new().bg(Color::Red).fg(Color::White)),
        );
    }
    let mut add = |l: &str, value: String, unit: &str| {
        lines.push(Line::from(vec![
            label(l),
            Span::styled(value, value_style),
            Span::raw(format!(" {unit}")),
        ]));
    };
    // Value, uncertainty and unit from the one table of report fields.
    for (l, name, decimals) in PANEL {
        add(l, shown(&r, name, decimals), unit(name));
    }
    add(
        "Frequency",
        shown(&r, "frequency_hz", 2),
        &format!(
            "{}  (period {} ms)",
            unit("frequency_hz"),
            num(r.period_s as f64 * 1e3, 2)
        ),
    );
    add(
        "Wear index",
        shown(&r, "wear_index_j", 1),
        &format!(
            "{}  ({} % left)",
            unit("wear_index_j"),
            num(r.wear_remaining_fraction as f64 * 100.0, 1)
        ),
    );
    let life_s = r.remaining_life_cycles as f64 / r.frequency_hz as f64;
    let life = if life_s.is_finite() && life_s >= 0.0 {
        format!("{}  (≈ {})", unit("remaining_life_cycles"), coarse(life_s))
    } else {
        unit("remaining_life_cycles").into()
    };
    add(
        "Remaining life",
        si_count(r.remaining_life_cycles as f64).trim_end().to_string(),
        &life,
    );
    add("Drift score", shown(&r, "drift_score", 2), unit("drift_score"));
    let flags = r.flags;
    let flag_style = if !valid || flags.intersects(Flags::SENSOR_FAULTS) {
        Style::new().fg(Color::Red).bold()
    } else if flags.is_empty() {
        Style::new().fg(Color::Green)
    } else {
        Style::new().fg(Color::Yellow)
    };
    lines.push(Line::from(vec![
        label("Flags"),
        Span::styled(flag_list(r.flags), flag_style),
    ]));
    Paragraph::new(lines).block(block).wrap(Wrap { trim: false })
}

fn count(l: &str, n: u64, bad: bool) -> Vec<Span<'static>> {
    let style = if bad && n > 0 {
        Style::new().fg(Color::Red).bold()
    } else {
        Style::new().bold()
    };
    vec![
        Span::styled(format!("{l:<14}"), Style::new().fg(Color::Gray)),
        Span::styled(format!("{n:>8}"), style),
        Span::raw("   "),
    ]
}

fn pair(a: Vec<Span<'static>>, b: Vec<Span<'static>>) -> Line<'static> {
    Line::from([a, b].concat())
}

fn link_panel(app: &App, v: &View) -> Paragraph<'static> {
    let s = &v.stats;
    let last = s.last_frame_us.map_or("never".into(), |t| ago(app.now_us, t));
    let mut lines = vec![
        pair(
            count("Frames", s.frames, false),
            vec![
                Span::styled("Bytes ", Style::new().fg(Color::Gray)),
                Span::styled(bytes(s.bytes), Style::new().bold()),
            ],
        ),
        pair(
            count("CRC errors", s.crc_errors, true),
            count("COBS errors", s.cobs_errors, true),
        ),
        pair(
            count("Decode errors", s.decode_errors, true),
            count("Oversize", s.oversize, true),
        ),
        pair(
            count("Seq gaps", s.seq_gaps, true),
            count("Lost reports", s.lost_reports, true),
        ),
        pair(
            count("Reconnects", s.reconnects as u64, true),
            vec![
                Span::styled("Last frame ", Style::new().fg(Color::Gray)),
                Span::raw(last),
            ],
        ),
    ];
    let u = &s.unlogged;
    if *u != Default::default() {
        lines.push(Line::from(Span::styled(
            format!(
                "Log cap reached: not logged {} received, {} reports, {} lines",
                bytes(u.bytes),
                u.reports,
                u.lines
            ),
            Style::new().fg(Color::Red).bold(),
        )));
    }
    match v.status {
        Some((t, st)) => {
            let load = st.cpu_load_permille as f64 / 10.0;
            let load_style = if load > 80.0 {
                Style::new().fg(Color::Red).bold()
            } else {
                Style::new().bold()
            };
            lines.push(Line::from(vec![Span::styled(
                format!("Device status ({})", ago(app.now_us, t)),
                Style::new().fg(Color::Cyan),
            )]));
            lines.push(Line::from(vec![
                Span::styled(format!("{:<14}", "CPU load"), Style::new().fg(Color::Gray)),
                Span::styled(format!("{load:>6.1} %"), load_style),
                Span::raw("   "),
                count("Dropped samp.", st.dropped_samples, true)[0].clone(),
                count("Dropped samp.", st.dropped_samples, true)[1].clone(),
            ]));
            lines.push(pair(
                count("ADC overruns", st.adc_overruns as u64, true),
                count("TX dropped", st.frames_dropped as u64, true),
            ));
            let rx_err =
                st.rx_crc_errors as u64 + st.rx_cobs_errors as u64 + st.rx_decode_errors as u64 + st.rx_oversize as u64;
            lines.push(pair(
                count("Device RX err", rx_err, true),
                count("Rejected cmds", st.rejected_commands as u64, false),
            ));
        }
        None => lines.push(Line::from("no device status yet").dim()),
    }
    Paragraph::new(lines).block(Block::bordered().title(" Link health "))
}

fn device_panel(v: &View) -> Paragraph<'static> {
    let mut lines = vec![];
    match &v.device {
        Some(d) => {
            lines.push(row("Board", board_name(d), ""));
            lines.push(row(
                "Firmware",
                firmware_version(d.firmware_version),
                &format!(" protocol {}", d.protocol_version),
            ));
            let cfg = match &v.config {
                Some(c) if config_hash(c) == d.config_hash => format!(" {:.0} S/s", c.sample_rate_hz),
                Some(c) => format!(" now {:08x}", config_hash(c)),
                None => String::new(),
            };
            lines.push(row("Config", format!("{:08x}", d.config_hash), &cfg));
            if !v.handshaken {
                lines.push(Line::from("(as last seen; no handshake on this link yet)").dim());
            }
        }
        None => lines.push(
            Line::from(if v.connected {
                "waiting for the device's Hello…"
            } else {
                "no device"
            })
            .dim(),
        ),
    }
    if let Some((_, st)) = v.status {
        lines.push(row(
            "Uptime",
            duration(st.uptime_us as f64 * 1e-6),
            &format!(" {} samples", si_count(st.samples as f64).trim_end()),
        ));
        lines.push(row(
            "Cycles",
            st.cycles.to_string(),
            &format!(" ({} invalid)", st.invalid_cycles),
        ));
        lines.push(row("Last reset", crate::numfmt::reset_cause(&st.reset_cause), ""));
        if st.stack_reserved_bytes > 0 {
            lines.push(row(
                "Stack",
                format!("{:.1} KiB", f64::from(st.stack_used_bytes) / 1024.0),
                &format!(
                    " of {:.1} KiB at the deepest",
                    f64::from(st.stack_reserved_bytes) / 1024.0
                ),
            ));
        }
        if st.vdda_v > 0.0 {
            let nominal = hammer_app::supply::NOMINAL_VDDA_V;
            lines.push(row(
                "VDDA",
                format!("{:.3} V", st.vdda_v),
                &format!(" {:+.1} % of {nominal:.1} V", (st.vdda_v / nominal - 1.0) * 100.0),
            ));
        }
    }
    if v.captures > 0 {
        lines.push(row("Capture chunks", v.captures.to_string(), ""));
    }
    Paragraph::new(lines).block(Block::bordered().title(" Device "))
}

/// (min, max) of the values, padded so a flat line sits mid-chart.
fn bounds(values: impl Iterator<Item = f64>) -> [f64; 2] {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for x in values.filter(|x| x.is_finite()) {
        lo = lo.min(x);
        hi = hi.max(x);
    }
    if lo > hi {
        return [0.0, 1.0];
    }
    let pad = ((hi - lo) * 0.1).max(hi.abs().max(lo.abs()) * 0.01).max(1e-3);
    [lo - pad, hi + pad]
}

/// The charts' time span: `--history-s` once there is that much history,
/// before that the next round span that holds it, so a fresh run is not a
/// sliver at the right edge.
fn chart_span(app: &App, v: &View) -> f64 {
    let have = v
        .history
        .points
        .front()
        .map_or(0.0, |p| app.now_us.saturating_sub(p.t_us) as f64 * 1e-6);
    [10.0, 30.0, 60.0, 120.0, 300.0, 600.0, 1800.0, 3600.0]
        .into_iter()
        .find(|&s| s >= have * 1.05)
        .unwrap_or(f64::INFINITY)
        .min(app.history_s)
}

fn charts(f: &mut Frame, app: &App, v: &View, area: Rect) {
    let [a, b, c] = Layout::vertical([Constraint::Ratio(1, 3); 3]).areas(area);
    let now = app.now_us;
    let x = |t: u64| -(now.saturating_sub(t) as f64) * 1e-6;
    let pts = &v.history.points;
    let series = |g: fn(&super::app::Point) -> f32| -> Vec<(f64, f64)> {
        pts.iter()
            .map(|p| (x(p.t_us), g(p) as f64))
            .filter(|(_, y)| y.is_finite())
            .collect()
    };
    let friction = series(|p| p.friction_n);
    let energy = series(|p| p.energy_j);
    let energy_nf = series(|p| p.energy_frictionless_j);
    let freq = series(|p| p.frequency_hz);
    let span = chart_span(app, v);
    chart(f, a, "Friction (N)", span, 2, vec![("", Color::Cyan, &friction)]);
    chart(
        f,
        b,
        "Impact energy (J)",
        span,
        3,
        vec![
            ("with friction", Color::Yellow, &energy),
            ("without friction", Color::Magenta, &energy_nf),
        ],
    );
    chart(f, c, "Frequency (Hz)", span, 2, vec![("", Color::Green, &freq)]);
}

/// A line chart over the last `span` seconds; named series are keyed in the title.
fn chart(
    f: &mut Frame,
    area: Rect,
    title: &str,
    span: f64,
    decimals: usize,
    sets: Vec<(&str, Color, &Vec<(f64, f64)>)>,
) {
    let y = bounds(sets.iter().flat_map(|(_, _, d)| d.iter().map(|p| p.1)));
    let mut head = vec![Span::raw(format!(" {title}"))];
    for (name, color, _) in &sets {
        if !name.is_empty() {
            head.push(Span::styled(format!("  ━ {name}"), Style::new().fg(*color)));
        }
    }
    let empty = sets.iter().all(|(_, _, d)| d.is_empty());
    head.push(Span::raw(if empty {
        format!(", last {span:.0} s: no valid cycle yet ")
    } else {
        format!(", last {span:.0} s ")
    }));
    let datasets: Vec<Dataset> = sets
        .into_iter()
        .map(|(_, color, data)| {
            Dataset::default()
                .marker(Marker::Braille)
                .graph_type(GraphType::Line)
                .style(Style::new().fg(color))
                .data(data)
        })
        .collect();
    let ylabels = [y[0], (y[0] + y[1]) / 2.0, y[1]].map(|v| Span::raw(format!("{v:.decimals$}")));
    let chart = Chart::new(datasets)
        .block(Block::bordered().title(Line::from(head)))
        .legend_position(None)
        .x_axis(
            Axis::default()
                .bounds([-span, 0.0])
                .labels([format!("-{span:.0} s"), format!("-{:.0} s", span / 2.0), "now".into()])
                .style(Style::new().fg(Color::Gray)),
        )
        .y_axis(
            Axis::default()
                .bounds(y)
                .labels(ylabels)
                .style(Style::new().fg(Color::Gray)),
        );
    f.render_widget(chart, area);
}

fn events_panel(v: &View, rows: usize) -> Paragraph<'static> {
    let skip = v.events.len().saturating_sub(rows);
    let lines: Vec<Line> = v
        .events
        .iter()
        .skip(skip)
        .map(|e| {
            let style = match e.severity {
                Severity::Info => Style::new(),
                Severity::Warn => Style::new().fg(Color::Yellow),
                Severity::Error => Style::new().fg(Color::Red).bold(),
            };
            Line::from(vec![
                Span::styled(format!("{} ", clock(e.t_us)), Style::new().dim()),
                Span::styled(e.text.clone(), style),
            ])
        })
        .collect();
    Paragraph::new(lines).block(Block::bordered().title(" Link events (UTC) "))
}

fn footer_line(app: &App) -> Paragraph<'static> {
    let key = |k: &str| {
        Span::styled(
            format!(" {k} "),
            Style::new().bg(Color::DarkGray).fg(Color::White).bold(),
        )
    };
    let mut spans = vec![
        key("q"),
        Span::raw(" quit "),
        key("p"),
        Span::raw(" pause "),
        key("c"),
        Span::raw(" clear alarm "),
        key("?"),
        Span::raw(" help "),
    ];
    if app.paused() {
        spans.push(Span::raw("  "));
        spans.push(Span::styled(
            format!(" PAUSED ({} new reports; logging goes on) ", app.reports_since_pause),
            Style::new()
                .bg(Color::Yellow)
                .fg(Color::Black)
                .add_modifier(Modifier::BOLD),
        ));
    }
    if app.ended {
        spans.push(Span::raw("  "));
        spans.push(Span::styled(
            " END OF RECORDING ",
            Style::new().bg(Color::Cyan).fg(Color::Black).bold(),
        ));
    }
    spans.push(Span::styled(format!("  {} reports", app.reports), Style::new().dim()));
    Paragraph::new(Line::from(spans))
}

fn help(f: &mut Frame, area: Rect) {
    let w = area.width.min(72);
    let h = area.height.min(18);
    let popup = Rect::new(area.x + (area.width - w) / 2, area.y + (area.height - h) / 2, w, h);
    let text = vec![
        Line::from("Keys").bold(),
        Line::from("  q, Esc, Ctrl-C   quit (the terminal is restored)"),
        Line::from("  p, space         pause the view; reading and logging go on"),
        Line::from("  c                clear the alarm banner (a new alarm shows again)"),
        Line::from("  ?, h, F1         this help"),
        Line::from(""),
        Line::from("Numbers").bold(),
        Line::from("  ± is the expanded uncertainty the device states for the cycle."),
        Line::from("  Charts show valid cycles only; INVALID cycles keep their flags."),
        Line::from("  Seq gaps: reports lost on the way (numbers not consecutive)."),
        Line::from("  CRC/COBS errors: corrupted or cut frames, counted, never shown."),
        Line::from("  The link is reopened every 0.5 s after it drops."),
        Line::from(""),
        Line::from(format!(
            "  Flags: {}",
            Flags::NAMES.iter().map(|(_, n)| *n).collect::<Vec<_>>().join(" ")
        )),
    ];
    f.render_widget(Clear, popup);
    f.render_widget(
        Paragraph::new(text)
            .wrap(Wrap { trim: false })
            .alignment(Alignment::Left)
            .block(
                Block::bordered()
                    .title(" Help (? closes) ")
                    .style(Style::new().bg(Color::Black)),
            ),
        popup,
    );
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::monitor::event::LinkStats;
    use hammer_wire::{CycleReport, DeviceMsg};
    use ratatui::backend::TestBackend;
    use ratatui::Terminal;

    fn screen(app: &App, w: u16, h: u16) -> String {
        let mut t = Terminal::new(TestBackend::new(w, h)).unwrap();
        t.draw(|f| ui(f, app)).unwrap();
        let buf = t.backend().buffer().clone();
        let mut s = String::new();
        for y in 0..h {
            for x in 0..w {
                s.push_str(buf[(x, y)].symbol());
            }
            s.push('\n');
        }
        s
    }

    #[test]
    fn draws_numbers_counters_and_survives_tiny_terminals() {
        let mut app = App::new("tcp:127.0.0.1:1".into(), true, 300.0);
        let t = app.now_us;
        for seq in 0..5 {
            app.on_event(&Stamped {
                t_us: t + seq * 40_000,
                event: Event::Msg(DeviceMsg::Report(CycleReport {
                    seq: seq as u32,
                    friction_n: 12.345,
                    friction_uncertainty_n: 1.118,
                    impact_energy_j: 4.6161,
                    impact_energy_uncertainty_j: 0.1661,
                    frequency_hz: 21.79,
                    remaining_life_cycles: 1.5e6,
                    ..Default::default()
                })),
            });
        }
        app.on_event(&Stamped {
            t_us: t,
            event: Event::Stats(LinkStats {
                reconnects: 3,
                crc_errors: 2,
                ..Default::default()
            }),
        });
        app.toggle_pause();
        app.show_help = true;
        let s = screen(&app, 160, 50);
        assert!(s.contains("12.35 ± 1.12"), "{s}");
        assert!(s.contains("4.616 ± 0.166"), "{s}");
        assert!(s.contains("PAUSED"), "{s}");
        assert!(s.contains("Help"), "{s}");
        let reconnects = s.lines().find(|l| l.contains("Reconnects")).unwrap();
        assert!(
            reconnects
                .split("Reconnects")
                .nth(1)
                .unwrap()
                .trim_start()
                .starts_with('3'),
            "{reconnects}"
        );
        for (w, h) in [(80, 24), (40, 10), (10, 5), (1, 1)] {
            screen(&app, w, h);
        }
        // The latest report's chambers (zeros here).
        assert!(s.contains("Chambers, cycle 4"), "{s}");
        let front = s.lines().find(|l| l.contains("│front ")).unwrap();
        assert!(front.contains("0.000 ± 0.000 ms"), "{s}");
        // A drift reading gets its panel, and an alarm its banner.
        app.toggle_pause();
        let mut w = crate::drift::Window::new(
            crate::drift::Baseline {
                supply_bar: 4.0,
                median: [1e-3, 2e-3, 1.3, 1.3, 5e-6, 5e-6],
                spread: [1e-4, 1e-4, 0.02, 0.02, 2e-7, 2e-7],
                cycles: [30; 6],
                source: crate::drift::Source::Reports,
                systematic: [0.0; 6],
            },
            1,
            2,
        );
        let moved = [1.5e-3, 2e-3, 1.3, 1.3, 5e-6, 5e-6];
        for _ in 0..2 {
            let d = w.push(moved).unwrap();
            app.on_event(&Stamped {
                t_us: t,
                event: Event::Drift(Box::new(d)),
            });
        }
        app.show_help = false;
        let s = screen(&app, 160, 50);
        assert!(s.contains("Since commissioning (4 bar)"), "{s}");
        assert!(s.contains("front_feed_s") && s.contains("+0.500 ± 0.255 ms"), "{s}");
        assert!(s.contains("CHANGE SINCE COMMISSIONING: front_feed_s"), "{s}");
        // A full history draws in well under a frame's time.
        let mut app = App::new("x".into(), false, 1e9);
        for seq in 0..crate::monitor::app::HISTORY_CAP as u64 {
            app.on_event(&Stamped {
                t_us: seq * 40_000,
                event: Event::Msg(DeviceMsg::Report(CycleReport {
                    seq: seq as u32,
                    friction_n: (seq % 17) as f32,
                    impact_energy_j: 4.0,
                    ..Default::default()
                })),
            });
        }
        let t = std::time::Instant::now();
        let s = screen(&app, 160, 50);
        let took = t.elapsed();
        assert!(s.contains("last 1800 s"), "{s}");
        assert!(
            took < Duration::from_millis(200),
            "a frame with a full history took {took:?}"
        );
    }

    /// The chambers' panel shows the latest report's characteristics, each
    /// ± its U in the drift panel's units, `n/a (unread)` where not read.
    #[test]
    fn the_chambers_of_the_latest_report_are_shown() {
        let mut app = App::new("x".into(), false, 300.0);
        let mut report = |r: CycleReport| {
            app.on_event(&Stamped {
                t_us: app.now_us,
                event: Event::Msg(DeviceMsg::Report(r)),
            });
            screen(&app, 160, 50)
        };
        let mut unread = CycleReport {
            seq: 7,
            ..Default::default()
        };
        unread.mark_chambers_unread();
        let s = report(unread);
        let row = |s: &str, chamber: &str| {
            s.lines()
                .find(|l| l.contains(&format!("│{chamber} ")))
                .unwrap()
                .to_string()
        };
        assert!(s.contains("Chambers, cycle 7") && s.contains("feed onset"), "{s}");
        for chamber in ["front", "rear"] {
            assert_eq!(row(&s, chamber).matches("n/a (unread)").count(), 3, "{s}");
        }
        let read = CycleReport {
            seq: 8,
            front_feed_s: 1.57e-3,
            front_feed_uncertainty_s: 3.6e-5,
            front_closed_exponent: 1.32,
            front_closed_exponent_uncertainty: 0.021,
            front_feed_area_m2: 1.23e-5,
            front_feed_area_uncertainty_m2: 5.6e-7,
            rear_feed_s: -2.5e-4,
            rear_feed_uncertainty_s: 4e-5,
            rear_closed_exponent: f32::NAN,
            rear_closed_exponent_uncertainty: f32::NAN,
            rear_feed_area_m2: f32::NAN,
            rear_feed_area_uncertainty_m2: f32::NAN,
            ..Default::default()
        };
        let s = report(read);
        let front = row(&s, "front");
        assert!(
            front.contains("1.570 ± 0.036 ms") && front.contains("1.320 ± 0.021") && front.contains("12.30 ± 0.56 mm²"),
            "{s}"
        );
        let rear = row(&s, "rear");
        assert!(
            rear.contains("-0.250 ± 0.040 ms") && rear.matches("n/a").count() == 2,
            "{s}"
        );
        assert!(!rear.contains("unread"), "{s}");
    }
}
