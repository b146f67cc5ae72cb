//! The chambers' characteristics of every cycle, read at its close and
//! carried in its report: how the valve switched each chamber's feed, the
//! fill, and how the closed chambers held their air (issue 47).
//!
//! - **What is read.** `hammer_estimator::chambers::at_close`, one track
//!   (the accelerometer's), from the cycle's codes and the 8 ms after its
//!   closing impact, where the front feed may start. Only the host's
//!   reading of a raw capture adds the second track, whose spread widens
//!   the uncertainties.
//! - **At half rate.** The codes are kept as the mean of each pair of
//!   sample-sets (rounded half to even: no bias), so the reading runs at
//!   50 kS/s on a 100 kS/s board. That halves the RAM and the work, and is
//!   what fits the window of a 50 ms cycle beside the raw capture in the
//!   board's 96 KiB aim (`docs/firmware.md`, "Chamber characteristics on
//!   the board"). What it costs in accuracy is measured against the truth
//!   (`docs/chambers-accuracy.txt`).
//! - **A report waits for its cycle's reading.** It leaves once the 8 ms
//!   after its impact have arrived and its cycle is read; messages behind it
//!   (its alarms, the next reports) wait in order. A cycle that cannot be
//!   read leaves at once, its characteristics NaN and flagged
//!   `chambers_unread`: not a valid cycle or not following one, longer
//!   than the window [`LONGEST_CYCLE_S`], samples lost in it, or the
//!   reader overtaken by the samples.
//! - **One reader, the same bytes.** A board feeds it from its sampling task
//!   through a channel and runs it in a task below sampling
//!   ([`crate::tasks::reading`]); a host feeds it the same codes and reports
//!   directly. The reports are the same, bit for bit, however the samples
//!   were split into blocks.

use hammer_estimator::chambers::at_close::{characterise_cycle, fields, window_samples, Codes, Work};
use hammer_estimator::chambers::ChamberGeometry;
use hammer_estimator::clock::index_at_edge_us;
use hammer_estimator::{Config, CycleReport, RawSample};
use hammer_wire::DeviceMsg;

use crate::packed::{self, Packed};

/// Sample-sets averaged into one kept set.
pub const DECIMATION: u64 = 2;
/// The longest cycle read at 100 kS/s: 50 ms (the paper's hammer runs at
/// 47 ms at 4 bar); a longer one is reported unread. At another rate the
/// window holds the same number of kept sets.
pub const LONGEST_CYCLE_S: f32 = 0.05;
/// Kept sets the ring holds: the longest window and the block that
/// completes it, with margin.
pub const RING_SETS: usize = 3_072;
const RING_BYTES: usize = packed::bytes_for(RING_SETS);
/// The track's floats: the longest window at the kept rate (2 500 sets of
/// the cycle, its closing impact, 400 of the look-after and 64 more).
pub const TRACK_FLOATS: usize = 2_965;
/// The room: the track's source over the longest cycle and its closing
/// impact, then the closed fits' logarithms (two floats a sample of a
/// closed phase; a longer phase's are computed as read, the same figures).
pub const ROOM_FLOATS: usize = 2_501;
/// Messages waiting behind a report that waits for its reading.
pub const WAITING: usize = 8;

/// A report and where its cycle lies in the kept sets, if it is to be read.
struct Waiting {
    msg: DeviceMsg,
    /// The kept sets of the cycle's opening and closing impacts.
    window: Option<(u64, u64)>,
}

/// The last report seen: the next cycle opens at its closing impact.
#[derive(Clone, Copy)]
struct Last {
    seq: u32,
    valid: bool,
    close: u64,
}

/// Counts of what the reader did, for a board's status and the tests.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ReaderCounters {
    pub read: u32,
    pub unread: u32,
    /// Unread because samples were lost in the window or the ring was
    /// overtaken (never in a board within its budget).
    pub overtaken: u32,
}

pub struct ChamberReader {
    /// The reading's configuration: the board's at the kept rate.
    cfg: Config,
    geo: ChamberGeometry,
    /// The reports' sample clock, whole Hz.
    rate_hz: u64,
    ring: Packed<RING_SETS, RING_BYTES>,
    /// The kept index of the next set into the ring.
    next: u64,
    /// The ring holds every set from this kept index on (a gap restarts it).
    continuous_from: u64,
    /// The full-rate index of the next sample-set expected.
    expected: u64,
    /// The first of a pair, waiting for its second.
    half: Option<RawSample>,
    x_m: [f32; TRACK_FLOATS],
    room: [f32; ROOM_FLOATS],
    waiting: heapless::Deque<Waiting, WAITING>,
    last: Option<Last>,
    pub counters: ReaderCounters,
}

impl ChamberReader {
    pub fn new(cfg: &Config) -> Self {
        let mut r = Self {
            cfg: *cfg,
            geo: ChamberGeometry::of(cfg),
            rate_hz: 1,
            ring: Packed::new(),
            next: 0,
            continuous_from: 0,
            expected: 0,
            half: None,
            x_m: [0.0; TRACK_FLOATS],
            room: [0.0; ROOM_FLOATS],
            waiting: heapless::Deque::new(),
            last: None,
            counters: ReaderCounters::default(),
        };
        r.reset(cfg);
        r
    }

    /// A new configuration: the estimator starts its indices over, so the
    /// reader does too; what waits is released first, unread.
    pub fn configure(&mut self, cfg: &Config, out: &mut impl FnMut(DeviceMsg)) {
        self.flush(out);
        self.reset(cfg);
    }

    fn reset(&mut self, cfg: &Config) {
        self.cfg = *cfg;
        self.cfg.sample_rate_hz = cfg.sample_rate_hz / DECIMATION as f32;
        self.geo = ChamberGeometry::of(cfg);
        self.rate_hz = cfg.sample_hz();
        self.last = None;
        self.half = None;
        self.expected = 0;
        self.next = 0;
        self.continuous_from = 0;
    }

    /// Sample-sets from the full-rate index `first` on (the estimator's
    /// [`hammer_estimator::Estimator::next_index`] before it took them).
    /// Messages waiting for these samples leave through `out`.
    pub fn push_samples(&mut self, mut first: u64, mut block: &[RawSample], out: &mut impl FnMut(DeviceMsg)) {
        if block.is_empty() {
            return;
        }
        if first != self.expected {
            // Samples lost (or a new count): the kept sets start over at
            // the next whole pair.
            self.half = None;
            let start = first.div_ceil(DECIMATION) * DECIMATION;
            let skip = ((start - first) as usize).min(block.len());
            block = &block[skip..];
            first += skip as u64;
            self.next = start / DECIMATION;
            self.continuous_from = self.next;
        }
        let mut slot = (self.next % RING_SETS as u64) as usize;
        for &s in block {
            match self.half.take() {
                None => self.half = Some(s),
                Some(a) => {
                    self.ring.set(slot, mean(a, s));
                    self.next += 1;
                    slot = if slot + 1 == RING_SETS { 0 } else { slot + 1 };
                    self.release(out);
                }
            }
        }
        self.expected = first + block.len() as u64;
    }

    /// A message from the monitor: a report waits for its cycle's reading;
    /// anything else waits only behind the reports before it.
    pub fn push(&mut self, msg: DeviceMsg, out: &mut impl FnMut(DeviceMsg)) {
        let window = match &msg {
            DeviceMsg::Report(r) => self.window_of(r),
            _ => None,
        };
        if self.waiting.is_full() {
            // Never in a board within its budget: the oldest leaves unread.
            self.leave_unread(out);
        }
        let _ = self.waiting.push_back(Waiting { msg, window });
        self.release(out);
    }

    /// Everything still waiting, unread: the end of a stream of samples.
    pub fn flush(&mut self, out: &mut impl FnMut(DeviceMsg)) {
        while !self.waiting.is_empty() {
            self.leave_unread(out);
        }
    }

    /// Where the cycle `r` closes lies in the kept sets, if it is to be read.
    fn window_of(&mut self, r: &CycleReport) -> Option<(u64, u64)> {
        let close = index_at_edge_us(r.t_impact_us, self.rate_hz) / DECIMATION;
        let prev = self.last.replace(Last {
            seq: r.seq,
            valid: r.is_valid(),
            close,
        });
        let p = prev?;
        let follows = p.valid && r.is_valid() && p.seq.wrapping_add(1) == r.seq && p.close < close;
        let fits = window_samples((close - p.close) as usize, self.cfg.dt_s()) <= TRACK_FLOATS
            && ((close - p.close) as usize) < ROOM_FLOATS;
        (follows && fits).then_some((p.close, close))
    }

    /// Reads and sends what is ready at the head of the queue.
    fn release(&mut self, out: &mut impl FnMut(DeviceMsg)) {
        while let Some(window) = self.waiting.front().map(|w| w.window) {
            let Some((open, close)) = window else {
                self.leave_unread(out);
                continue;
            };
            let end = open + window_samples((close - open) as usize, self.cfg.dt_s()) as u64;
            if self.next < end {
                return;
            }
            let Some(Waiting {
                msg: DeviceMsg::Report(mut r),
                ..
            }) = self.waiting.pop_front()
            else {
                continue;
            };
            let kept = open >= self.continuous_from && self.next - open <= RING_SETS as u64;
            let c = if kept {
                let codes = Window {
                    ring: &self.ring,
                    start: (open % RING_SETS as u64) as usize,
                    len: (end - open) as usize,
                };
                let mut work = Work {
                    x_m: &mut self.x_m,
                    room: &mut self.room,
                };
                characterise_cycle(
                    &self.cfg,
                    &self.geo,
                    &codes,
                    (close - open) as usize,
                    &r,
                    false,
                    &mut work,
                )
            } else {
                self.counters.overtaken += 1;
                None
            };
            match c {
                Some(c) => {
                    r.set_chambers_read(fields(c.front), fields(c.rear));
                    self.counters.read += 1;
                }
                None => self.counters.unread += 1,
            }
            out(DeviceMsg::Report(r));
        }
    }

    /// The head leaves as it came: a report unread (the estimator marked it so).
    fn leave_unread(&mut self, out: &mut impl FnMut(DeviceMsg)) {
        if let Some(w) = self.waiting.pop_front() {
            if matches!(w.msg, DeviceMsg::Report(_)) {
                self.counters.unread += 1;
            }
            out(w.msg);
        }
    }
}

/// The mean of two sample-sets, each code rounded half to even.
fn mean(a: RawSample, b: RawSample) -> RawSample {
    let m = |x: u16, y: u16| {
        let s = u32::from(x) + u32::from(y);
        let h = s / 2;
        // An odd sum's half: to the even neighbour, so no bias.
        (if s % 2 == 1 && h % 2 == 1 { h + 1 } else { h }) as u16
    };
    RawSample {
        rear: m(a.rear, b.rear),
        front: m(a.front, b.front),
        accel: m(a.accel, b.accel),
    }
}

/// A cycle's kept sets in the ring, from its opening impact.
struct Window<'a> {
    ring: &'a Packed<RING_SETS, RING_BYTES>,
    start: usize,
    len: usize,
}

impl Codes for Window<'_> {
    fn len(&self) -> usize {
        self.len
    }
    #[inline(always)]
    fn get(&self, i: usize) -> RawSample {
        let j = self.start + i;
        self.ring.get(if j >= RING_SETS { j - RING_SETS } else { j })
    }
}
