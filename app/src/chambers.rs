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
use hammer_wire::{DeviceMsg, BLOCK_SAMPLES};

use core::ops::DerefMut;

use hammer_estimator::{ConfigError, Estimator};

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
pub const WAITING: usize = 4;

/// The longest cycle the reader reads at `cfg`'s sample rate, s: the
/// longest whose window fits the track and whose span fits the room
/// ([`LONGEST_CYCLE_S`] at 100 kS/s). For a host to say why reports come
/// unread.
pub fn longest_cycle_s(cfg: &Config) -> f32 {
    let kept = at_kept_rate(cfg);
    let dt = kept.dt_s();
    let sets = (1..ROOM_FLOATS)
        .rev()
        .find(|&n| window_samples(n, dt) <= TRACK_FLOATS)
        .unwrap_or(0);
    sets as f32 * dt
}

/// Full-rate sample-sets the sampling task reads at a time (its block).
pub const READER_BLOCK: usize = 4 * BLOCK_SAMPLES;
/// Blocks the reference board keeps for its reader: the samples that
/// arrive while it reads a 50 ms cycle's window (about 1.6 M instructions,
/// 9.4 ms at 170 MHz: 940 sets, eight blocks), and margin. The sampling
/// task reads the ADC's samples straight into a free one (no copy: the
/// sampling loop pays nothing a set for the reader); with none free, into
/// its own, and the reader sees a gap. A slower core keeps more: the
/// emulated board, paced at 125 M instructions a second, keeps 20 (a
/// faulty hammer's 48.9 ms cycles filled 13 there).
pub const READER_BLOCKS: usize = 13;
/// Messages waiting for the reader: reports, alarms, a configuration.
pub const READER_MESSAGES: usize = 3;

/// Sample-sets from the full-rate index `first` on: `sets[..len]`.
#[derive(Clone, Copy)]
pub struct Block {
    pub first: u64,
    pub len: u32,
    pub sets: [RawSample; READER_BLOCK],
}

impl Block {
    pub const EMPTY: Block = Block {
        first: 0,
        len: 0,
        sets: [RawSample {
            rear: 0,
            front: 0,
            accel: 0,
        }; READER_BLOCK],
    };
}

/// What the sampling task hands the reader besides samples, in order.
pub enum ToReader {
    /// A report, or a message that leaves behind the reports before it.
    Msg(DeviceMsg),
    /// The estimator's new configuration (its indices start over).
    Config(Config),
}

impl<R: DerefMut<Target = ReaderRoom>> ChamberReader<R> {
    /// Takes one message from the sampling task.
    pub fn take(&mut self, m: ToReader, out: &mut impl FnMut(DeviceMsg)) {
        match m {
            ToReader::Msg(m) => self.push(m, out),
            ToReader::Config(c) => self.configure(&c, out),
        }
    }

    /// Takes one block of samples from the sampling task.
    pub fn take_block(&mut self, b: &Block, out: &mut impl FnMut(DeviceMsg)) {
        let n = (b.len as usize).min(READER_BLOCK);
        self.push_samples(b.first, &b.sets[..n], out);
    }
}

/// The sampling side of the message channel to the reader: it never waits
/// (the sampling task must not) and never reorders. While the channel is
/// full, messages wait in a small backlog; one that finds the backlog full
/// too goes straight out, unread.
#[derive(Default)]
pub struct Feed {
    backlog: heapless::Deque<ToReader, 4>,
    /// Messages that went out past the reader.
    pub bypassed: u32,
}

impl Feed {
    /// A message to the reader (a report, an alarm, a configuration).
    pub fn msg<M: embassy_sync::blocking_mutex::raw::RawMutex, const N: usize>(
        &mut self,
        ch: &embassy_sync::channel::Channel<M, ToReader, N>,
        m: ToReader,
        out: &mut impl FnMut(DeviceMsg),
    ) {
        self.drain(ch);
        let m = if self.backlog.is_empty() {
            match ch.try_send(m) {
                Ok(()) => return,
                Err(embassy_sync::channel::TrySendError::Full(m)) => m,
            }
        } else {
            m
        };
        if let Err(m) = self.backlog.push_back(m) {
            self.bypassed = self.bypassed.wrapping_add(1);
            if let ToReader::Msg(m) = m {
                out(m);
            }
        }
    }

    /// The backlog into the channel, as far as it has room.
    pub fn drain<M: embassy_sync::blocking_mutex::raw::RawMutex, const N: usize>(
        &mut self,
        ch: &embassy_sync::channel::Channel<M, ToReader, N>,
    ) {
        while let Some(m) = self.backlog.pop_front() {
            if let Err(embassy_sync::channel::TrySendError::Full(m)) = ch.try_send(m) {
                let _ = self.backlog.push_front(m);
                return;
            }
        }
    }
}

/// Full-rate sample-sets to kept ones: each pair averaged, from an even
/// index on; a gap (a block that does not follow the last) drops a half
/// pair and starts over at the next whole one.
#[derive(Default)]
pub struct Decimator {
    expected: u64,
    half: Option<RawSample>,
}

impl Decimator {
    /// The kept sets of `block` (full-rate index `first` on) through `out`,
    /// in order and without a gap between them; returns the kept index of
    /// the first.
    pub fn keep(&mut self, mut first: u64, mut block: &[RawSample], mut out: impl FnMut(RawSample)) -> u64 {
        if first != self.expected {
            self.half = None;
            let start = first.div_ceil(DECIMATION) * DECIMATION;
            let skip = ((start - first) as usize).min(block.len());
            block = &block[skip..];
            first += skip as u64;
        }
        let at = (first - u64::from(self.half.is_some())) / DECIMATION;
        for &s in block {
            match self.half.take() {
                None => self.half = Some(s),
                Some(a) => out(mean(a, s)),
            }
        }
        self.expected = first + block.len() as u64;
        at
    }
}

/// A report and where its cycle lies in the kept sets, if it is to be read.
struct Waiting {
    msg: DeviceMsg,
    /// The kept sets of the cycle's opening and closing impacts, and the
    /// end of its window (computed once: it is checked at every kept set).
    window: Option<(u64, u64, u64)>,
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

/// The reader's large buffers (~36 KB): the ring of kept codes, the track
/// and its room. `const`-constructible, so a board keeps them in a
/// `ConstStaticCell` built at link time, never on a stack.
pub struct ReaderRoom {
    ring: Packed<RING_SETS, RING_BYTES>,
    x_m: [f32; TRACK_FLOATS],
    room: [f32; ROOM_FLOATS],
}

impl ReaderRoom {
    pub const fn new() -> Self {
        Self {
            ring: Packed::new(),
            x_m: [0.0; TRACK_FLOATS],
            room: [0.0; ROOM_FLOATS],
        }
    }
}

impl Default for ReaderRoom {
    fn default() -> Self {
        Self::new()
    }
}

/// Generic over where its [`ReaderRoom`] lives: a board's
/// `&'static mut` in a `ConstStaticCell`, a host's `Box`.
pub struct ChamberReader<R: DerefMut<Target = ReaderRoom>> {
    /// The reading's configuration: the board's at the kept rate.
    cfg: Config,
    geo: ChamberGeometry,
    /// The reports' sample clock, whole Hz.
    rate_hz: u64,
    /// The ring (slot = kept index modulo [`RING_SETS`]), track and room.
    buf: R,
    decimator: Decimator,
    /// The kept index of the next set into the ring, and its slot.
    next: u64,
    slot: usize,
    /// The ring holds every set from this kept index on (a gap restarts it).
    continuous_from: u64,
    waiting: heapless::Deque<Waiting, WAITING>,
    last: Option<Last>,
    pub counters: ReaderCounters,
}

impl<R: DerefMut<Target = ReaderRoom>> ChamberReader<R> {
    pub fn new(cfg: &Config, buf: R) -> Self {
        Self {
            cfg: at_kept_rate(cfg),
            geo: ChamberGeometry::of(cfg),
            rate_hz: cfg.sample_hz(),
            buf,
            decimator: Decimator::default(),
            next: 0,
            slot: 0,
            continuous_from: 0,
            waiting: heapless::Deque::new(),
            last: None,
            counters: ReaderCounters::default(),
        }
    }

    /// The reports' sample clock, whole Hz.
    pub fn rate_hz(&self) -> u64 {
        self.rate_hz
    }

    /// A new configuration: the estimator starts its indices over, so the
    /// reader does too; what waits is released first, unread.
    pub fn configure(&mut self, cfg: &Config, out: &mut impl FnMut(DeviceMsg)) {
        self.flush(out);
        self.reset(cfg);
    }

    fn reset(&mut self, cfg: &Config) {
        self.cfg = at_kept_rate(cfg);
        self.geo = ChamberGeometry::of(cfg);
        self.rate_hz = cfg.sample_hz();
        self.last = None;
        self.decimator = Decimator::default();
        self.next = 0;
        self.slot = 0;
        self.continuous_from = 0;
    }

    /// Sample-sets from the full-rate index `first` on (the estimator's
    /// [`hammer_estimator::Estimator::next_index`] before it took them),
    /// kept in pairs ([`Decimator`]).
    pub fn push_samples(&mut self, first: u64, block: &[RawSample], out: &mut impl FnMut(DeviceMsg)) {
        let mut kept = heapless::Vec::<RawSample, { READER_BLOCK / 2 + 1 }>::new();
        for (n, part) in block.chunks(READER_BLOCK).enumerate() {
            kept.clear();
            let at = self.decimator.keep(first + (n * READER_BLOCK) as u64, part, |set| {
                let _ = kept.push(set);
            });
            for (i, &set) in kept.iter().enumerate() {
                self.push_kept(at + i as u64, set, out);
            }
        }
    }

    /// The kept set of kept index `k` (full-rate sets `2k` and `2k + 1`,
    /// [`Decimator`]); a `k` that does not follow the last starts the ring
    /// over (samples were lost). Messages waiting for it leave through
    /// `out`. A report must arrive before the sets run 400 past its impact
    /// (a board hands them over [`READER_BLOCK`] at a time): the ring then
    /// holds its window, however the sets were split.
    pub fn push_kept(&mut self, k: u64, set: RawSample, out: &mut impl FnMut(DeviceMsg)) {
        if k != self.next {
            self.next = k;
            self.slot = (k % RING_SETS as u64) as usize;
            self.continuous_from = k;
        }
        self.buf.ring.set(self.slot, set);
        self.next += 1;
        self.slot = if self.slot + 1 == RING_SETS { 0 } else { self.slot + 1 };
        self.release(out);
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
    fn window_of(&mut self, r: &CycleReport) -> Option<(u64, u64, u64)> {
        let close = index_at_edge_us(r.t_impact_us, self.rate_hz) / DECIMATION;
        let prev = self.last.replace(Last {
            seq: r.seq,
            valid: r.is_valid(),
            close,
        });
        let p = prev?;
        let follows = p.valid && r.is_valid() && p.seq.wrapping_add(1) == r.seq && p.close < close;
        let window = window_samples((close - p.close) as usize, self.cfg.dt_s());
        let fits = window <= TRACK_FLOATS && ((close - p.close) as usize) < ROOM_FLOATS;
        (follows && fits).then_some((p.close, close, p.close + window as u64))
    }

    /// Reads and sends what is ready at the head of the queue.
    fn release(&mut self, out: &mut impl FnMut(DeviceMsg)) {
        while let Some(window) = self.waiting.front().map(|w| w.window) {
            let Some((open, close, end)) = window else {
                self.leave_unread(out);
                continue;
            };
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
                let ReaderRoom { ring, x_m, room } = &mut *self.buf;
                let codes = Window {
                    ring,
                    start: (open % RING_SETS as u64) as usize,
                    len: (end - open) as usize,
                };
                let mut work = Work { x_m, room };
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

/// `cfg` at the rate of the kept sets.
fn at_kept_rate(cfg: &Config) -> Config {
    Config {
        sample_rate_hz: cfg.sample_rate_hz / DECIMATION as f32,
        ..*cfg
    }
}

/// The mean of two sample-sets, each code rounded half to even.
fn mean(a: RawSample, b: RawSample) -> RawSample {
    let m = |x: u16, y: u16| {
        let s = u32::from(x) + u32::from(y);
        let h = s >> 1;
        // An odd sum's half goes to the even neighbour (up where the half
        // is odd), so the means carry no bias.
        (h + (s & h & 1)) as u16
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
    #[inline(always)]
    fn code(&self, i: usize, ch: usize) -> u16 {
        let j = self.start + i;
        self.ring.code(if j >= RING_SETS { j - RING_SETS } else { j }, ch)
    }
}

/// A host's copy of a board's pipeline over the same codes: the estimator,
/// then the chambers' reader. The reports are the board's, bit for bit
/// (the parity that the soak and the emulated board's tests check), and
/// what `hammer estimate` reports.
pub struct Pipeline<R: DerefMut<Target = ReaderRoom>> {
    est: Estimator,
    reader: ChamberReader<R>,
}

impl<R: DerefMut<Target = ReaderRoom>> Pipeline<R> {
    pub fn new(cfg: Config, room: R) -> Result<Self, ConfigError> {
        Ok(Self {
            est: Estimator::new(cfg)?,
            reader: ChamberReader::new(&cfg, room),
        })
    }

    /// Sample-sets in order; `out` gets each report once it is read. Taken
    /// [`READER_BLOCK`] at a time, each block then the reports it closed, as
    /// a board's sampling task hands them to its reader: a report reaches
    /// the reader before the samples run past its window.
    pub fn push_block(&mut self, block: &[RawSample], out: &mut impl FnMut(CycleReport)) {
        let mut emit = |m: DeviceMsg| {
            if let DeviceMsg::Report(r) = m {
                out(r)
            }
        };
        for part in block.chunks(READER_BLOCK) {
            let Self { est, reader } = self;
            reader.push_samples(est.next_index(), part, &mut emit);
            est.push_block(part, |r| reader.push(DeviceMsg::Report(r), &mut emit));
        }
    }

    /// Samples lost (a gap, as the board's `push_gap`).
    pub fn push_gap(&mut self, missing: u32) {
        self.est.push_gap(missing);
    }

    /// The end of the stream: the reports still waiting for the samples
    /// after their impact, unread.
    pub fn finish(&mut self, out: &mut impl FnMut(CycleReport)) {
        self.reader.flush(&mut |m| {
            if let DeviceMsg::Report(r) = m {
                out(r)
            }
        });
    }

    pub fn estimator(&self) -> &Estimator {
        &self.est
    }

    pub fn counters(&self) -> ReaderCounters {
        self.reader.counters
    }
}
