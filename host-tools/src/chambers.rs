//! The chamber characteristics measured against their truth, on the
//! diagnosis' model and on the second model family: the accuracy figures
//! of `docs/estimator.md` ("Chamber characteristics"), the tests that hold
//! them, and `examples/chambers.rs`.
//!
//! A characteristic's truth is the same calculation on the true pressures
//! and the true position; the measured one reads the sensor chain's
//! pressures with the force balance's position track.

use hammer_estimator::chambers::{Characteristics, Feed};
use hammer_sim::characteristics::{
    characterise_cycles, mean_opening_after_impact_s, opening_times_s, CycleFeeds, Signals,
};
use hammer_sim::effects::Effects;
use hammer_sim::estimation;
use hammer_sim::SimConfig;
use hammer_trace::trace::Trace;
use hammer_variants::{generate, Structure, VariantParams};

/// The effects of `spec` (`"none"`, or a catalogue spec).
pub fn effects_of(spec: &str) -> Effects {
    let mut e = Effects::default();
    if spec != "none" {
        e.apply_spec(spec).expect("catalogue effect");
    }
    e
}

/// Which hammer made the trace.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Family {
    /// The diagnosis' own model (`hammer-sim`).
    Model,
    /// The second model family's base hammer (`hammer-variants`).
    Variant,
}

impl Family {
    pub fn name(self) -> &'static str {
        match self {
            Family::Model => "model",
            Family::Variant => "variant",
        }
    }
}

/// A run's measured and true characteristics, cycle by cycle, and when the
/// spool opened each port (the true crossings), from the trace's start.
pub struct Compared {
    /// The host's reading of the raw trace (two tracks, full rate).
    pub measured: Vec<CycleFeeds>,
    /// What the board reports: its reading at each cycle's close
    /// (`hammer_app::chambers`: one track, half rate), on the same codes.
    pub board: Vec<CycleFeeds>,
    pub truth: Vec<CycleFeeds>,
    /// Times the front and the rear supply port began to open.
    pub front_port_opens_s: Vec<f64>,
    pub rear_port_opens_s: Vec<f64>,
}

fn column<'a>(t: &'a Trace, name: &str) -> &'a [f64] {
    t.extra.get(name).map_or(&[], |v| v.as_slice())
}

/// Runs `family` at `bar` with `effects` for `seconds` (noise seed `seed`)
/// and reads its characteristics both ways.
pub fn run(family: Family, bar: f64, effects: &Effects, seconds: f64, seed: u64) -> Compared {
    let mut cfg = SimConfig::nominal(bar);
    cfg.seed = seed;
    let config = cfg.estimator_config(Some(bar)).expect("nominal estimator config");
    let (trace, chambers, front_open, rear_open): (Trace, _, Box<dyn Fn(f64) -> bool>, Box<dyn Fn(f64) -> bool>) =
        match family {
            Family::Model => {
                cfg.effects = effects.clone();
                cfg.solver.duration_s = seconds;
                let sim = hammer_sim::simulate(&cfg).expect("simulation");
                let (travel, opening) = (cfg.valve.travel_m, cfg.valve.opening_m);
                (
                    sim.trace(),
                    cfg.hammer.chambers(),
                    Box::new(move |xv| xv < opening),
                    Box::new(move |xv| xv > travel - opening),
                )
            }
            Family::Variant => {
                let p = VariantParams::default();
                let g = generate(&p, Structure::BASE, effects, bar, seconds, seed);
                (g.trace, p.chambers(), Box::new(|s| s < 0.5), Box::new(|s| s > 0.5))
            }
        };
    let spool = column(&trace, if family == Family::Model { "valve_m" } else { "spool" });
    let codes = estimation::to_codes(&trace, &config);
    let reports = estimation::run(&codes, config).expect("estimator");
    // The board as it is configured for this hammer: its chambers and the
    // pressures' delay, as the host's reading below takes them.
    let mut on_board = config;
    on_board.chambers = hammer_estimator::ChamberConfig {
        rear_dead_m3: chambers.rear_dead_m3 as f32,
        front_dead_m3: chambers.front_dead_m3 as f32,
        rear_outlet_m: chambers.rear_outlet_m as f32,
        front_outlet_m: chambers.front_outlet_m as f32,
        pressure_group_delay_s: cfg.sensors.front.group_delay_s(trace.dt_s) as f32,
    };
    on_board.geometry.travel_m = chambers.impact_position_m as f32;
    let board = board_feeds(&codes, on_board);
    let measured = Signals {
        dt_s: trace.dt_s,
        p_rear_pa: &trace.p_rear_pa,
        p_front_pa: &trace.p_front_pa,
        accel_mps2: &trace.accel_mps2,
        x_m: None,
        // The bench's configured transducers (the simulator's, 20 kHz);
        // the second family's front end (25 kHz, filtered every 1 µs)
        // lags 6.4 µs against these 4 µs.
        pressure_lag_s: cfg.sensors.front.group_delay_s(trace.dt_s),
    };
    let truth = Signals {
        dt_s: trace.dt_s,
        p_rear_pa: column(&trace, "p_rear_true_pa"),
        p_front_pa: column(&trace, "p_front_true_pa"),
        accel_mps2: &trace.accel_mps2,
        x_m: Some(column(&trace, "x_m")),
        pressure_lag_s: 0.0,
    };
    Compared {
        board,
        measured: characterise_cycles(&measured, &reports, &config, &chambers),
        truth: characterise_cycles(&truth, &reports, &config, &chambers),
        front_port_opens_s: opening_times_s(trace.dt_s, spool.len(), |i| front_open(spool[i])),
        rear_port_opens_s: opening_times_s(trace.dt_s, spool.len(), |i| rear_open(spool[i])),
    }
}

/// The board's reports over `codes`: each cycle's characteristics as its
/// report carries them (a chamber with a NaN onset is one not read).
pub fn board_feeds(codes: &[hammer_estimator::RawSample], config: hammer_estimator::Config) -> Vec<CycleFeeds> {
    use hammer_app::chambers::{Pipeline, ReaderRoom};
    let mut p = Pipeline::new(config, Box::<ReaderRoom>::default()).expect("the estimator's configuration");
    let mut out = Vec::new();
    let feed = |f: hammer_estimator::FeedFields| {
        f.feed_s.is_finite().then_some(Feed {
            onset_s: f.feed_s,
            onset_uncertainty_s: f.feed_uncertainty_s,
            x_m: f.feed_x_m,
            p_rear_pa: f.feed_p_rear_pa,
            p_front_pa: f.feed_p_front_pa,
            closed_exponent: f.closed_exponent,
            closed_exponent_uncertainty: f.closed_exponent_uncertainty,
            feed_area_m2: f.feed_area_m2,
            feed_area_uncertainty_m2: f.feed_area_uncertainty_m2,
            dead_volume_offset_m3: f32::NAN,
        })
    };
    let mut take = |r: hammer_estimator::CycleReport| {
        if !r.flags.contains(hammer_estimator::Flags::CHAMBERS_UNREAD) {
            out.push(CycleFeeds {
                seq: r.seq,
                t_impact_s: r.t_impact_s(),
                feeds: Characteristics {
                    front: feed(r.front_feed()),
                    rear: feed(r.rear_feed()),
                    charge: None,
                },
            });
        }
    };
    p.push_block(codes, &mut take);
    p.finish(&mut take);
    out
}

/// The aims for a characteristic's expanded uncertainty: a feed's
/// onset, a closed phase's exponent, a feed's area (relative).
pub const ONSET_AIM_S: f64 = 0.3e-3;
pub const EXPONENT_AIM: f64 = 0.02;
pub const AREA_AIM: f64 = 0.05;

/// One characteristic's agreement with its truth over many cycles.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Agreement {
    pub cycles: usize,
    /// Cycles whose expanded uncertainty covers the difference to the truth.
    pub covered: usize,
    /// The largest expanded uncertainty, relative where `relative`.
    pub max_u: f64,
    /// Cycles whose expanded uncertainty is within the aim for the
    /// characteristic ([`ONSET_AIM_S`], [`EXPONENT_AIM`], [`AREA_AIM`]).
    pub within_aim: usize,
    pub sum_d: f64,
    pub sum_dd: f64,
}

impl Agreement {
    fn add(&mut self, measured: f64, truth: f64, u: f64, scale: f64, aim: f64) {
        if !(measured.is_finite() && truth.is_finite() && u.is_finite()) {
            return;
        }
        let d = (measured - truth) / scale;
        self.cycles += 1;
        self.covered += usize::from(d.abs() <= u / scale);
        self.within_aim += usize::from(u / scale <= aim);
        self.max_u = self.max_u.max(u / scale);
        self.sum_d += d;
        self.sum_dd += d * d;
    }

    fn merge(&mut self, o: &Agreement) {
        self.cycles += o.cycles;
        self.covered += o.covered;
        self.within_aim += o.within_aim;
        self.max_u = self.max_u.max(o.max_u);
        self.sum_d += o.sum_d;
        self.sum_dd += o.sum_dd;
    }

    pub fn coverage(&self) -> f64 {
        self.covered as f64 / self.cycles.max(1) as f64
    }

    /// The share of cycles whose uncertainty is within the aim.
    pub fn within_aim(&self) -> f64 {
        self.within_aim as f64 / self.cycles.max(1) as f64
    }

    pub fn mean(&self) -> f64 {
        self.sum_d / self.cycles.max(1) as f64
    }

    pub fn rms(&self) -> f64 {
        (self.sum_dd / self.cycles.max(1) as f64).sqrt()
    }
}

/// The six characteristics' agreements: onsets in seconds, exponents as
/// numbers, areas relative to the truth's.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Tally {
    pub front_onset: Agreement,
    pub rear_onset: Agreement,
    pub front_exponent: Agreement,
    pub rear_exponent: Agreement,
    pub front_area: Agreement,
    pub rear_area: Agreement,
    /// Cycles with a report pair, and those where a chamber gave no feed.
    pub cycles: usize,
    pub missing: usize,
}

impl Tally {
    pub fn of(c: &Compared) -> Tally {
        Self::of_reading(&c.measured, &c.truth)
    }

    /// The board's reading against the truth.
    pub fn of_board(c: &Compared) -> Tally {
        Self::of_reading(&c.board, &c.truth)
    }

    fn of_reading(measured: &[CycleFeeds], truth: &[CycleFeeds]) -> Tally {
        let mut t = Tally::default();
        for m in measured {
            let Some(tr) = truth.iter().find(|x| x.seq == m.seq) else {
                continue;
            };
            t.cycles += 1;
            t.add_chamber(m.feeds.front, tr.feeds.front, true);
            t.add_chamber(m.feeds.rear, tr.feeds.rear, false);
        }
        t
    }

    fn add_chamber(&mut self, m: Option<Feed>, tr: Option<Feed>, front: bool) {
        let (Some(m), Some(tr)) = (m, tr) else {
            self.missing += 1;
            return;
        };
        let (onset, exponent, area) = if front {
            (&mut self.front_onset, &mut self.front_exponent, &mut self.front_area)
        } else {
            (&mut self.rear_onset, &mut self.rear_exponent, &mut self.rear_area)
        };
        onset.add(
            m.onset_s as f64,
            tr.onset_s as f64,
            m.onset_uncertainty_s as f64,
            1.0,
            ONSET_AIM_S,
        );
        exponent.add(
            m.closed_exponent as f64,
            tr.closed_exponent as f64,
            m.closed_exponent_uncertainty as f64,
            1.0,
            EXPONENT_AIM,
        );
        area.add(
            m.feed_area_m2 as f64,
            tr.feed_area_m2 as f64,
            m.feed_area_uncertainty_m2 as f64,
            tr.feed_area_m2 as f64,
            AREA_AIM,
        );
    }

    pub fn add(&mut self, o: &Tally) {
        for (a, b) in self.all_mut().into_iter().zip(o.all()) {
            a.merge(&b);
        }
        self.cycles += o.cycles;
        self.missing += o.missing;
    }

    pub fn all(&self) -> [Agreement; 6] {
        [
            self.front_onset,
            self.rear_onset,
            self.front_exponent,
            self.rear_exponent,
            self.front_area,
            self.rear_area,
        ]
    }

    fn all_mut(&mut self) -> [&mut Agreement; 6] {
        [
            &mut self.front_onset,
            &mut self.rear_onset,
            &mut self.front_exponent,
            &mut self.rear_exponent,
            &mut self.front_area,
            &mut self.rear_area,
        ]
    }

    /// One line: per characteristic, coverage, largest U, the share of
    /// cycles whose U is within the aim, mean and RMS difference.
    pub fn line(&self) -> String {
        let a = self.all();
        let ms = |x: f64| x * 1e3;
        let aim = |x: &Agreement| 100.0 * x.within_aim();
        format!(
            "cycles {:3} missing {:2} | front onset cov {:3.0}% U≤{:.3} ms aim {:3.0}% d {:+.3}±{:.3} | rear onset cov {:3.0}% U≤{:.3} ms aim {:3.0}% d {:+.3}±{:.3} | n_f cov {:3.0}% U≤{:.3} aim {:3.0}% d {:+.3}±{:.3} | n_r cov {:3.0}% U≤{:.3} aim {:3.0}% d {:+.3}±{:.3} | A_f cov {:3.0}% U≤{:.1}% aim {:3.0}% d {:+.1}±{:.1}% | A_r cov {:3.0}% U≤{:.1}% aim {:3.0}% d {:+.1}±{:.1}%",
            self.cycles,
            self.missing,
            100.0 * a[0].coverage(), ms(a[0].max_u), aim(&a[0]), ms(a[0].mean()), ms(a[0].rms()),
            100.0 * a[1].coverage(), ms(a[1].max_u), aim(&a[1]), ms(a[1].mean()), ms(a[1].rms()),
            100.0 * a[2].coverage(), a[2].max_u, aim(&a[2]), a[2].mean(), a[2].rms(),
            100.0 * a[3].coverage(), a[3].max_u, aim(&a[3]), a[3].mean(), a[3].rms(),
            100.0 * a[4].coverage(), 100.0 * a[4].max_u, aim(&a[4]), 100.0 * a[4].mean(), 100.0 * a[4].rms(),
            100.0 * a[5].coverage(), 100.0 * a[5].max_u, aim(&a[5]), 100.0 * a[5].mean(), 100.0 * a[5].rms(),
        )
    }
}

/// [`run`], then [`Tally::of`] and [`Tally::of_board`].
pub fn compare(family: Family, bar: f64, effects: &Effects, seconds: f64, seed: u64) -> (Tally, Tally) {
    let c = run(family, bar, effects, seconds, seed);
    (Tally::of(&c), Tally::of_board(&c))
}

/// Mean onset of a chamber over the cycles that have one.
pub fn mean_onset_s(cycles: &[CycleFeeds], front: bool) -> Option<f64> {
    let pick = |c: &Characteristics| if front { c.front } else { c.rear };
    let v: Vec<f64> = cycles
        .iter()
        .filter_map(|c| pick(&c.feeds))
        .map(|f| f.onset_s as f64)
        .collect();
    (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64)
}

/// Mean time from each cycle's closing impact to the nearest opening of
/// the front port (the spool's true crossing), over the cycles measured.
pub fn mean_front_port_opening_s(c: &Compared) -> Option<f64> {
    let impacts: Vec<f64> = c.measured.iter().map(|m| m.t_impact_s).collect();
    mean_opening_after_impact_s(&impacts, &c.front_port_opens_s)
}
