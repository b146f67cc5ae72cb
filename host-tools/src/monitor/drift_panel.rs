//! The dashboard's panel of the drift since commissioning (`--reference`,
//! [`crate::drift`]): one row per chamber characteristic.

use ratatui::style::{Color, Style};
use ratatui::text::{Line, Span};
use ratatui::widgets::{Block, Paragraph};

use crate::numfmt::ago;

/// Each chamber characteristic's drift from the commissioning record
/// (`--reference`): drift ± its expanded uncertainty, red when it alarms.
pub fn drift_panel(now_us: u64, t: u64, d: &crate::drift::Drift) -> Paragraph<'static> {
    let block = Block::bordered().title(format!(" Since commissioning ({} bar) ", d.supply_bar));
    let mut lines = vec![Line::from(vec![
        Span::raw(format!("window {}, {} cycles  ", d.window, d.cycles)),
        Span::styled(ago(now_us, t), Style::new().dim()),
    ])];
    for c in &d.characteristics {
        let (scale, unit) = crate::drift::unit_of(&c.name);
        let (text, style) = if c.drift.is_finite() {
            let style = if c.alarm {
                Style::new().fg(Color::Red).bold()
            } else if c.beyond {
                Style::new().fg(Color::Yellow)
            } else {
                Style::new().fg(Color::Green)
            };
            let (d, u) = (c.drift * scale, c.uncertainty * scale);
            (format!("{d:+.3} ± {u:.3}{unit}"), style)
        } else {
            ("not read".to_string(), Style::new().dim())
        };
        lines.push(Line::from(vec![
            Span::raw(format!("{:<22}", c.name)),
            Span::styled(text, style),
        ]));
    }
    Paragraph::new(lines).block(block)
}
