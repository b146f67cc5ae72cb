//! The reader's side of the drift since commissioning ([`crate::drift`]):
//! it reads each report's chamber characteristics (the board read them at
//! the cycle's close) and emits an [`Event::Drift`] when a window of them
//! is full. It asks the board for nothing: it sees the events the reader
//! already emits ([`Watch::see`]), the configuration and the reports.

use std::sync::Arc;

use hammer_app::chambers::longest_cycle_s;
use hammer_estimator::{Config, CycleReport};
use hammer_wire::DeviceMsg;

use super::event::{Event, Stamped};
use crate::drift::baseline::CAPTURE_OFFSET_BOUND;
use crate::drift::{report_reading, Commissioned, DriftArgs, Source, Window};

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
    /// The periods of the reports in a row whose chambers the board left
    /// unread (NaN for an invalid one): a window's worth is said once.
    unread_periods: Vec<f64>,
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
            unread_periods: Vec::new(),
        }
    }

    /// A new connection: the configuration is asked for again, and the
    /// window goes on (a report's reading does not depend on the link).
    pub fn reconnected(&mut self) {
        self.config = None;
    }

    /// Sees an event the reader emits; returns the events that follow from
    /// it (a drift reading, notes).
    pub fn see(&mut self, ev: &Stamped) -> Vec<Event> {
        match &ev.event {
            Event::Msg(DeviceMsg::Config(c)) => self.configured(Config::default().with_device(c)),
            Event::Msg(DeviceMsg::Report(r)) if self.config.is_some() => self.report(r),
            _ => vec![],
        }
    }

    /// A report: its reading into the window, or, unread, counted; a
    /// window's worth unread in a row is said, with their period.
    fn report(&mut self, r: &CycleReport) -> Vec<Event> {
        let Some(window) = self.window.as_mut() else {
            return vec![];
        };
        if let Some(reading) = report_reading(r) {
            self.unread_periods.clear();
            return window
                .push(reading)
                .map(|d| Event::Drift(Box::new(d)))
                .into_iter()
                .collect();
        }
        // A window's worth is kept and said once; the run may go on.
        if self.unread_periods.len() == self.k {
            return vec![];
        }
        self.unread_periods
            .push(if r.is_valid() { f64::from(r.period_s) } else { f64::NAN });
        if self.unread_periods.len() < self.k {
            return vec![];
        }
        let periods: Vec<f64> = self.unread_periods.iter().copied().filter(|p| p.is_finite()).collect();
        let period_s = crate::drift::median(&periods);
        let longest_s = self.config.as_ref().map_or(f64::NAN, |c| f64::from(longest_cycle_s(c)));
        let why = if period_s > longest_s {
            format!(
                "their cycles last {:.1} ms, longer than the {:.1} ms the board reads: the hammer's period itself has changed since commissioning (at {} bar)",
                period_s * 1e3,
                longest_s * 1e3,
                window.baseline().supply_bar
            )
        } else if periods.is_empty() {
            "none of them is valid (their flags say why)".into()
        } else {
            format!(
                "their cycles last {:.1} ms; see their flags and the board's status (samples lost?)",
                period_s * 1e3
            )
        };
        vec![Event::Note(format!(
            "drift: the last {} reports carry no chamber reading (chambers_unread), so no drift is read: {why}",
            self.k
        ))]
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
                // The same point keeps its window (compared by pressure: a median
                // may be NaN, which equals nothing).
                if self
                    .window
                    .as_ref()
                    .is_none_or(|w| w.baseline().supply_bar != baseline.supply_bar)
                {
                    out.extend(warning.map(Event::Note));
                    out.push(Event::Note(format!(
                        "drift: reading every report against {} at {} bar ({} cycles a reading)",
                        self.reference.dir.display(),
                        baseline.supply_bar,
                        self.k
                    )));
                    if baseline.source == Source::Captures {
                        out.push(Event::Note(format!(
                            "drift: {} at {} bar is read from its raw captures (the record predates the board's reading of its chambers, or its reports carry none): read by the host, they stand up to {:.3} ms off the board's reading of the front feed, which every drift's uncertainty includes; commission again to read without it",
                            self.reference.dir.display(),
                            baseline.supply_bar,
                            CAPTURE_OFFSET_BOUND[0] * 1e3
                        )));
                    }
                    self.window = Some(Window::new(baseline, self.k, self.confirm));
                }
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::diagnose::record::Record;
    use crate::drift::{Baseline, N_CHARACTERISTICS};
    use hammer_estimator::FeedFields;
    use hammer_wire::DeviceConfig;

    fn watch(k: u32) -> Watch {
        let cfg = Config::default();
        let median = [1e-3, 2e-2, 1.4, 1.4, f64::NAN, f64::NAN];
        let reference = Commissioned {
            dir: "ref".into(),
            record: Record {
                format: "hammer-commission".into(),
                version: 2,
                firmware_version: "0.1.0".into(),
                board: "b".into(),
                calibration_hash: cfg.calibration_hash(),
                points: vec![],
            },
            baselines: vec![Baseline {
                spread: [1e-4, 1e-4, 0.01, 0.01, f64::NAN, f64::NAN],
                cycles: [100; N_CHARACTERISTICS],
                ..Baseline::of(4.0, &[median])
            }],
        };
        let args = DriftArgs {
            drift_cycles: k,
            ..DriftArgs::default()
        };
        Watch::new(Arc::new(reference), &args, Some(4.0))
    }

    fn stamped(m: DeviceMsg) -> Stamped {
        Stamped {
            t_us: 0,
            event: Event::Msg(m),
        }
    }

    fn report(seq: u32, front_feed_s: f32, period_s: f32) -> DeviceMsg {
        let mut r = CycleReport {
            seq,
            period_s,
            ..CycleReport::default()
        };
        let feed = |feed_s| FeedFields {
            feed_s,
            closed_exponent: 1.4,
            ..FeedFields::NAN
        };
        r.set_chambers_read(feed(front_feed_s), feed(0.02));
        DeviceMsg::Report(r)
    }

    /// Every report counts and nothing is asked of the board: k read
    /// reports give a reading; k unread in a row are said once, with the
    /// reason their period gives.
    #[test]
    fn every_report_counts_and_a_run_of_unread_ones_is_said() {
        let mut w = watch(4);
        // Before the configuration nothing is read.
        assert!(w.see(&stamped(report(0, 2.5e-3, 0.047))).is_empty());
        let notes = w.see(&stamped(DeviceMsg::Config(DeviceConfig::from(&Config::default()))));
        assert!(
            notes
                .iter()
                .any(|n| matches!(n, Event::Note(s) if s.contains("reading every report"))),
            "{notes:?}"
        );
        let mut out = vec![];
        for seq in 1..=4 {
            out.extend(w.see(&stamped(report(seq, 2.5e-3, 0.047))));
        }
        let [Event::Drift(d)] = out.as_slice() else {
            panic!("{out:?}")
        };
        let f = d.get("front_feed_s").unwrap();
        assert!((f.drift - 1.5e-3).abs() < 1e-9 && f.beyond, "{f:?}");
        let mut out = vec![];
        for seq in 5..=12 {
            let DeviceMsg::Report(mut r) = report(seq, 2.5e-3, 0.0507) else {
                unreachable!()
            };
            r.mark_chambers_unread();
            out.extend(w.see(&stamped(DeviceMsg::Report(r))));
        }
        let [Event::Note(n)] = out.as_slice() else {
            panic!("{out:?}")
        };
        assert!(
            n.contains("last 4 reports") && n.contains("50.7 ms, longer than the 50.0 ms"),
            "{n}"
        );
        // The run goes on, said once, and a reconfiguration keeps the window.
        for seq in 13..=30 {
            let DeviceMsg::Report(mut r) = report(seq, 2.5e-3, 0.0507) else {
                unreachable!()
            };
            r.mark_chambers_unread();
            assert!(w.see(&stamped(DeviceMsg::Report(r))).is_empty());
        }
        assert_eq!(w.unread_periods.len(), 4);
        // A reconfiguration (a reconnect, a tare) keeps the same point's
        // window, though its areas' medians are NaN.
        let again = w.see(&stamped(DeviceMsg::Config(DeviceConfig::from(&Config::default()))));
        assert!(again.is_empty(), "{again:?}");
    }
}
