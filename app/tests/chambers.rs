//! The chambers' reading at each cycle's close (`hammer_app::chambers`),
//! on the host: against the reading of the same kept codes done by hand,
//! whatever the blocks, and what it does with cycles it cannot read.

use hammer_app::chambers::{
    longest_cycle_s, ChamberReader, Pipeline, ReaderCounters, ReaderRoom, DECIMATION, LONGEST_CYCLE_S,
};
use hammer_estimator::chambers::at_close::{characterise_cycle, fields, window_samples, Work};
use hammer_estimator::chambers::ChamberGeometry;
use hammer_estimator::{Config, CycleReport, Estimator, Flags, RawSample};
use hammer_sim::simulate::simulate;
use hammer_sim::SimConfig;
use hammer_wire::DeviceMsg;

/// A simulated hammer's codes and the configuration that reads them
/// (the supply pressure given, so the feed areas are read too).
fn hammer(bar: f64, seconds: f64) -> (Vec<RawSample>, Config) {
    let mut cfg = SimConfig::nominal(bar);
    cfg.solver.duration_s = seconds;
    cfg.effects.apply_spec("coulomb_friction").unwrap();
    let sim = simulate(&cfg).unwrap();
    (sim.measured.codes, cfg.estimator_config(Some(bar)).unwrap())
}

/// The estimator's reports through a reader (a host's [`Pipeline`], which
/// hands them over as a board's sampling task does), the samples given in
/// blocks of `block` sets.
fn through_reader(codes: &[RawSample], cfg: &Config, block: usize) -> (Vec<CycleReport>, ReaderCounters) {
    let mut p = Pipeline::new(*cfg, Box::new(ReaderRoom::new())).unwrap();
    let mut reports = vec![];
    for b in codes.chunks(block) {
        p.push_block(b, &mut |r| reports.push(r));
    }
    p.finish(&mut |r| reports.push(r));
    (reports, p.counters())
}

/// The mean of each pair, rounded half to even, written out again here.
fn kept(codes: &[RawSample]) -> Vec<RawSample> {
    let m = |a: u16, b: u16| ((f64::from(a) + f64::from(b)) / 2.0).round_ties_even() as u16;
    codes
        .chunks_exact(2)
        .map(|p| RawSample {
            rear: m(p[0].rear, p[1].rear),
            front: m(p[0].front, p[1].front),
            accel: m(p[0].accel, p[1].accel),
        })
        .collect()
}

/// Every report leaves, in order, as the estimator made it but for its
/// characteristics; a cycle between two valid reports is read, and its
/// values are `at_close`'s on the kept codes, bit for bit; the blocks'
/// sizes change nothing.
#[test]
fn each_cycle_is_read_into_its_report_as_at_close_reads_the_kept_codes() {
    for bar in [4.0, 7.0] {
        let (codes, cfg) = hammer(bar, 0.6);
        let mut est = Estimator::new(cfg).unwrap();
        let mut expected = vec![];
        est.push_block(&codes, |r| expected.push(r));
        let (reports, reader) = through_reader(&codes, &cfg, 128);
        assert_eq!(reports.len(), expected.len());
        for (r, e) in reports.iter().zip(&expected) {
            let mut bare = *r;
            bare.mark_chambers_unread();
            assert_eq!(
                bare, *e,
                "{bar} bar, cycle {}: the estimator's report but for the chambers",
                e.seq
            );
        }
        // The blocks of a board's DMA, or one sample at a time: the same bytes.
        for block in [37, 256] {
            assert_eq!(
                through_reader(&codes, &cfg, block).0,
                reports,
                "{bar} bar, blocks of {block}"
            );
        }
        // By hand: the kept codes, the configuration at the kept rate.
        let half = kept(&codes);
        let mut slow = cfg;
        slow.sample_rate_hz /= DECIMATION as f32;
        let geo = ChamberGeometry::of(&cfg);
        let (mut x, mut room) = (vec![0.0f32; 4_000], vec![0.0f32; 4_000]);
        let at = |r: &CycleReport| (r.t_impact_us * 100_000 + 1_000_000) / 1_000_000 / DECIMATION;
        let mut read = 0;
        for pair in expected.windows(2) {
            let (prev, cur) = (&pair[0], &pair[1]);
            let got = reports.iter().find(|r| r.seq == cur.seq).unwrap();
            let (open, close) = (at(prev) as usize, at(cur) as usize);
            let end = open + window_samples(close - open, slow.dt_s());
            let c = (prev.is_valid() && cur.is_valid() && end <= half.len())
                .then(|| {
                    let mut work = Work {
                        x_m: &mut x,
                        room: &mut room,
                    };
                    characterise_cycle(&slow, &geo, &half[open..end], close - open, cur, false, &mut work)
                })
                .flatten();
            let Some(c) = c else {
                assert!(got.flags.contains(Flags::CHAMBERS_UNREAD), "cycle {}", cur.seq);
                assert!(got.front_feed_s.is_nan() && got.rear_closed_exponent.is_nan());
                continue;
            };
            read += 1;
            assert!(!got.flags.contains(Flags::CHAMBERS_UNREAD), "cycle {}", cur.seq);
            let (f, r) = (fields(c.front), fields(c.rear));
            assert_eq!(format!("{:?}", got.front_feed()), format!("{f:?}"), "cycle {}", cur.seq);
            assert_eq!(format!("{:?}", got.rear_feed()), format!("{r:?}"), "cycle {}", cur.seq);
        }
        assert_eq!(reader.read, read);
        // Every cycle but the first (no opening report) and the last (its
        // 8 ms after it not in the trace) is read, and both chambers in it.
        assert!(
            read as usize + 2 >= expected.len(),
            "{bar} bar: {read} of {}",
            expected.len()
        );
        let both = reports
            .iter()
            .filter(|r| r.front_feed_s.is_finite() && r.rear_feed_s.is_finite() && r.front_feed_area_m2 > 0.0)
            .count();
        assert_eq!(both, read as usize, "{bar} bar: a read cycle without both feeds");
        println!("{bar} bar: {read} of {} cycles read", expected.len());
    }
}

/// Samples lost inside a cycle's window leave it unread (never a reading
/// of stale codes); a report waits for the 8 ms after its impact, and a
/// stream that ends lets what waits go, unread.
#[test]
fn a_gap_in_the_window_leaves_the_cycle_unread_and_a_report_waits_for_its_tail() {
    let (codes, cfg) = hammer(5.0, 0.5);
    let mut est = Estimator::new(cfg).unwrap();
    let mut reports = vec![];
    est.push_block(&codes, |r| reports.push(r));
    let valid: Vec<&CycleReport> = reports.iter().filter(|r| r.is_valid()).collect();
    let (a, b) = (valid[2], valid[3]);
    assert_eq!(a.seq + 1, b.seq);
    let index = |r: &CycleReport| ((r.t_impact_us * 100_000 + 1_000_000) / 1_000_000) as usize;
    // Feed up to b's impact, then lose 100 sets in the 8 ms after it.
    let mut p = Pipeline::new(cfg, Box::new(ReaderRoom::new())).unwrap();
    let mut out = vec![];
    let lost_at = index(b) + 200;
    let mut pushed_b = false;
    for (k, chunk) in codes[..index(b) + 2_000].chunks(100).enumerate() {
        if (lost_at..lost_at + 100).contains(&(k * 100)) {
            p.push_gap(chunk.len() as u32);
            continue;
        }
        p.push_block(chunk, &mut |r| out.push(DeviceMsg::Report(r)));
        if !pushed_b && p.estimator().counters().cycles > b.seq {
            // b closed in this block; its 8 ms have not arrived: it waits.
            pushed_b = true;
            assert!(!out.iter().any(|m| matches!(m, DeviceMsg::Report(x) if x.seq == b.seq)));
        }
    }
    assert!(pushed_b);
    let got = |seq: u32, out: &[DeviceMsg]| {
        out.iter()
            .find_map(|m| match m {
                DeviceMsg::Report(r) if r.seq == seq => Some(*r),
                _ => None,
            })
            .expect("the report left")
    };
    assert!(
        !got(a.seq, &out).flags.contains(Flags::CHAMBERS_UNREAD),
        "a's window is whole"
    );
    let lost = got(b.seq, &out);
    assert!(lost.flags.contains(Flags::CHAMBERS_UNREAD) && lost.front_feed_s.is_nan());
    assert!(p.counters().overtaken >= 1);
    // The end of the stream: what waits leaves, unread, in order.
    let before = out.len();
    p.finish(&mut |r| out.push(DeviceMsg::Report(r)));
    let seqs: Vec<u32> = out
        .iter()
        .filter_map(|m| match m {
            DeviceMsg::Report(r) => Some(r.seq),
            _ => None,
        })
        .collect();
    assert!(seqs.windows(2).all(|w| w[1] == w[0] + 1), "{seqs:?}");
    assert!(out[before..]
        .iter()
        .all(|m| matches!(m, DeviceMsg::Report(r) if r.flags.contains(Flags::CHAMBERS_UNREAD))));
}

/// A cycle longer than the window is reported unread, never read in part.
#[test]
fn a_cycle_longer_than_the_window_is_unread() {
    let (codes, cfg) = hammer(5.0, 0.4);
    let mut est = Estimator::new(cfg).unwrap();
    let mut reports = vec![];
    est.push_block(&codes, |r| reports.push(r));
    let (prev, mut cur) = (reports[2], reports[3]);
    assert!(prev.is_valid() && cur.is_valid());
    // The same cycle, its closing impact moved past the longest read.
    cur.t_impact_us = prev.t_impact_us + (LONGEST_CYCLE_S as f64 * 1.1e6) as u64;
    let mut reader = ChamberReader::new(&cfg, Box::new(ReaderRoom::new()));
    let mut out = vec![];
    reader.push(DeviceMsg::Report(prev), &mut |m| out.push(m));
    reader.push(DeviceMsg::Report(cur), &mut |m| out.push(m));
    // It leaves at once (nothing to wait for), unread.
    assert_eq!(out.len(), 2, "{out:?}");
    assert!(matches!(out[1], DeviceMsg::Report(r) if r.flags.contains(Flags::CHAMBERS_UNREAD)));
    // The longest cycle read at this rate is the one the constant states,
    // to a kept set; at twice the rate the 8 ms after the impact take twice
    // the kept sets, so the longest cycle is shorter.
    let longest = longest_cycle_s(&cfg);
    let kept_dt = DECIMATION as f32 / cfg.sample_rate_hz;
    assert!((longest - LONGEST_CYCLE_S).abs() <= 1.5 * kept_dt, "{longest}");
    let fast = Config {
        sample_rate_hz: 2.0 * cfg.sample_rate_hz,
        ..cfg
    };
    assert!(longest_cycle_s(&fast) < 0.5 * longest, "{}", longest_cycle_s(&fast));
}

/// An estimator renewed in place (`Estimator::renew`, what a board's
/// `SetConfig` and tare do) is a new one: after a run under another
/// configuration it reports the same bytes, and counts the same, as one
/// built for the new configuration.
#[test]
fn an_estimator_renewed_in_place_is_a_new_one() {
    let (codes, cfg) = hammer(5.0, 0.4);
    let other = Config {
        blank_after_s: 1.5 * cfg.blank_after_s,
        supply_pressure_pa: 0.8 * cfg.supply_pressure_pa,
        ..cfg
    };
    let mut renewed = Estimator::new(other).unwrap();
    let mut before = 0;
    renewed.push_block(&codes, |_| before += 1);
    assert!(before > 3, "the run before the renewal closed {before} cycles");
    renewed.renew(cfg).unwrap();
    let mut fresh = Estimator::new(cfg).unwrap();
    let (mut a, mut b) = (vec![], vec![]);
    fresh.push_block(&codes, |r| a.push(r));
    renewed.push_block(&codes, |r| b.push(r));
    assert!(a.len() > 3);
    assert_eq!(a, b);
    assert_eq!(fresh.counters(), renewed.counters());
    assert_eq!(fresh.next_index(), renewed.next_index());
    assert_eq!(fresh.wear_state(), renewed.wear_state());
}
