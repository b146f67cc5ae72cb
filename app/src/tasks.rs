//! The app's async tasks, generic over the board traits. A board spawns each
//! in an embassy task (the sampling one at a priority the link cannot starve)
//! and connects them through one [`Shared`].

use core::sync::atomic::{AtomicU32, Ordering};

use embassy_futures::select::{select, Either};
use embassy_sync::blocking_mutex::raw::RawMutex;
use embassy_sync::channel::Channel;
use embassy_sync::signal::Signal;
use hammer_estimator::RawSample;
use hammer_wire::{
    encode, DecodeError, Decoder, DeviceConfig, DeviceMsg, HostMsg, RejectReason, SampleBlock, WearBlob, BLOCK_SAMPLES,
    MAX_FRAME,
};

use crate::board::{Clock, LinkRx, LinkTx, Overrun, SampleSource, Store};
use crate::chambers::{Block, ChamberReader, Feed, ReaderRoom, ToReader, READER_BLOCK, READER_MESSAGES};
use crate::monitor::{LinkCounters, Monitor};
use crate::supervisor::{Duty, Supervisor};
use embassy_sync::zerocopy_channel;

/// How often the device sends a `Status` without being asked.
pub const STATUS_PERIOD_US: u64 = 1_000_000;
/// Outgoing messages waiting for the link.
pub const OUTGOING: usize = 12;
/// Valid cycles between two wear-state snapshots for non-volatile storage
/// (about 5 minutes at 20 Hz: a power cut loses at most that much wear).
pub const WEAR_SAVE_CYCLES: u32 = 6_000;

#[derive(Default)]
pub struct LinkAtomics {
    pub frames_sent: AtomicU32,
    pub frames_dropped: AtomicU32,
    pub rx_frames: AtomicU32,
    pub rx_crc_errors: AtomicU32,
    pub rx_cobs_errors: AtomicU32,
    pub rx_decode_errors: AtomicU32,
    pub rx_oversize: AtomicU32,
}

impl LinkAtomics {
    pub const fn new() -> Self {
        Self {
            frames_sent: AtomicU32::new(0),
            frames_dropped: AtomicU32::new(0),
            rx_frames: AtomicU32::new(0),
            rx_crc_errors: AtomicU32::new(0),
            rx_cobs_errors: AtomicU32::new(0),
            rx_decode_errors: AtomicU32::new(0),
            rx_oversize: AtomicU32::new(0),
        }
    }

    pub fn snapshot(&self) -> LinkCounters {
        let l = |a: &AtomicU32| a.load(Ordering::Relaxed);
        LinkCounters {
            frames_sent: l(&self.frames_sent),
            frames_dropped: l(&self.frames_dropped),
            rx_frames: l(&self.rx_frames),
            rx_crc_errors: l(&self.rx_crc_errors),
            rx_cobs_errors: l(&self.rx_cobs_errors),
            rx_decode_errors: l(&self.rx_decode_errors),
            rx_oversize: l(&self.rx_oversize),
        }
    }
}

/// Queues between the tasks; `const`-constructible so a board keeps it in a `static`.
pub struct Shared<M: RawMutex> {
    pub commands: Channel<M, HostMsg, 4>,
    pub outgoing: Channel<M, DeviceMsg, OUTGOING>,
    /// Sample blocks that arrive over the link (boards without an ADC). Two:
    /// the link task waits while both are taken, which holds the host back.
    pub samples: Channel<M, SampleBlock, 2>,
    /// The sampling task's reports, alarms and configurations to the
    /// chambers' reader ([`reading`]), which sends the reports on once read
    /// (the samples go through a board's blocks, [`sampling`]).
    pub to_reader: Channel<M, ToReader, READER_MESSAGES>,
    pub link: LinkAtomics,
    /// The latest wear state to persist. A board with flash stores it from a
    /// low-priority task (a page erase must never stall sampling); a board
    /// without simply never waits on it.
    pub wear_snapshot: Signal<M, WearBlob>,
    /// The configuration after a change (set by the host, or by a tare), to persist likewise.
    pub config_snapshot: Signal<M, DeviceConfig>,
    /// The duties' check-ins (the sampling loop and the link here, a board's
    /// persistence task there), for the board's watchdog.
    pub supervisor: Supervisor,
    /// The stack's high-water mark and region, bytes, as the board last
    /// measured them (painted stack); reported in every `Status`.
    pub stack_used_bytes: AtomicU32,
    pub stack_reserved_bytes: AtomicU32,
    /// VDDA as the board last measured it ([`crate::supply::vdda_v`]),
    /// an `f32`'s bits; 0 where not measured.
    pub vdda_v_bits: AtomicU32,
    /// The chambers' reader's figures ([`reading`], [`sampling`]): cycles
    /// read and reports sent unread, the most blocks ever waiting for it,
    /// and the blocks it never got.
    pub chambers_read: AtomicU32,
    pub chambers_unread: AtomicU32,
    pub reader_blocks_peak: AtomicU32,
    pub reader_blocks_dropped: AtomicU32,
    /// The sampling task's position, sample-sets (the estimator's next
    /// index, low 32 bits), and the longest a report waited from its
    /// impact to leaving the reader, sample-sets.
    pub sample_index: AtomicU32,
    pub report_latency_max_sets: AtomicU32,
}

impl<M: RawMutex> Shared<M> {
    pub const fn new() -> Self {
        Self {
            commands: Channel::new(),
            outgoing: Channel::new(),
            samples: Channel::new(),
            to_reader: Channel::new(),
            link: LinkAtomics::new(),
            wear_snapshot: Signal::new(),
            config_snapshot: Signal::new(),
            supervisor: Supervisor::new(),
            stack_used_bytes: AtomicU32::new(0),
            stack_reserved_bytes: AtomicU32::new(0),
            vdda_v_bits: AtomicU32::new(0),
            chambers_read: AtomicU32::new(0),
            chambers_unread: AtomicU32::new(0),
            reader_blocks_peak: AtomicU32::new(0),
            reader_blocks_dropped: AtomicU32::new(0),
            sample_index: AtomicU32::new(0),
            report_latency_max_sets: AtomicU32::new(0),
        }
    }

    /// `status` with the figures the board measures itself (stack, VDDA).
    pub fn with_board_figures(&self, status: hammer_wire::Status) -> hammer_wire::Status {
        hammer_wire::Status {
            stack_used_bytes: self.stack_used_bytes.load(Ordering::Relaxed),
            stack_reserved_bytes: self.stack_reserved_bytes.load(Ordering::Relaxed),
            vdda_v: f32::from_bits(self.vdda_v_bits.load(Ordering::Relaxed)),
            ..status
        }
    }

    /// Publishes a VDDA measurement for `Status`.
    pub fn set_vdda_v(&self, v: f32) {
        self.vdda_v_bits.store(v.to_bits(), Ordering::Relaxed);
    }

    /// Queues a message; a full queue drops it and counts the drop.
    pub fn send(&self, m: DeviceMsg) {
        if self.outgoing.try_send(m).is_err() {
            self.link.frames_dropped.fetch_add(1, Ordering::Relaxed);
        }
    }
}

impl<M: RawMutex> Default for Shared<M> {
    fn default() -> Self {
        Self::new()
    }
}

/// Sampling → estimator → outgoing queue; applies commands between blocks
/// (the source's `read` must be cancel-safe: a command may interrupt it),
/// streams capture chunks when the queue has room, sends a periodic status.
/// Reads each block straight into a free one of the chambers' reader's
/// (`blocks`, [`reading`]), and hands it over after the estimator took it;
/// with none free, a source that holds its samples
/// ([`SampleSource::holds_samples`]) waits for one, and any other's block is
/// read into the task's own buffer and never reaches the reader.
pub async fn sampling<S: SampleSource, M: RawMutex, C: Clock>(
    source: &mut S,
    monitor: &mut Monitor,
    shared: &Shared<M>,
    clock: &C,
    blocks: &mut zerocopy_channel::Sender<'_, M, Block>,
) -> ! {
    // Where a block goes when the reader has none free.
    let mut own = [RawSample::default(); READER_BLOCK];
    let mut window_start = clock.now_us();
    let mut busy_us = 0u64;
    let mut busy_total_us = 0u64;
    let mut load_permille = 0u16;
    let mut next_status = window_start + STATUS_PERIOD_US;
    let mut saved_at_cycle = 0u32;
    let mut config_hash = monitor.config_hash();
    let mut feed = Feed::default();
    loop {
        let at = monitor.estimator().next_index();
        // Commands are answered even when no samples flow, and while a
        // source that holds its samples waits for the reader.
        let (mut slot, command) = if source.holds_samples() {
            match select(blocks.send(), shared.commands.receive()).await {
                Either::First(b) => (Some(b), None),
                Either::Second(cmd) => (None, Some(cmd)),
            }
        } else {
            (blocks.try_send(), None)
        };
        let first = match command {
            Some(cmd) => Either::Second(cmd),
            None => {
                let buf = match slot.as_deref_mut() {
                    Some(b) => &mut b.sets[..],
                    None => &mut own[..],
                };
                select(source.read(buf), shared.commands.receive()).await
            }
        };
        shared.supervisor.beat(Duty::Sampling);
        let t0 = clock.now_us();
        // Reports and their alarms go out through the chambers' reader,
        // which holds each report until its cycle is read.
        let mut emit = |m: DeviceMsg| match m {
            DeviceMsg::Report(_) | DeviceMsg::Alarm(_) => {
                feed.msg(&shared.to_reader, ToReader::Msg(m), &mut |m| shared.send(m))
            }
            m => shared.send(m),
        };
        let (mut handed, got_samples) = (false, matches!(first, Either::First(Ok(_))));
        let mut pending = None;
        match first {
            Either::First(Ok(n)) => {
                let n = n.min(READER_BLOCK);
                let block = match slot.as_deref_mut() {
                    Some(b) => {
                        (b.first, b.len, handed) = (at, n as u32, true);
                        &b.sets[..n]
                    }
                    None => &own[..n],
                };
                monitor.on_samples(block, &mut emit)
            }
            Either::First(Err(Overrun { lost })) => monitor.on_overrun(lost),
            Either::Second(cmd) => pending = Some(cmd),
        }
        while let Some(cmd) = pending.take().or_else(|| shared.commands.try_receive().ok()) {
            if cmd == HostMsg::GetStatus {
                emit(DeviceMsg::Status(shared.with_board_figures(monitor.status(
                    t0,
                    load_permille,
                    busy_total_us,
                    shared.link.snapshot(),
                ))));
            } else {
                monitor.on_command(cmd, t0, &mut emit);
            }
        }
        // Capture chunks never crowd out reports: only into spare room.
        while shared.outgoing.free_capacity() > 4 {
            match monitor.next_capture_chunk() {
                Some(m) => emit(m),
                None => break,
            }
        }
        drop(slot);
        shared
            .sample_index
            .store(monitor.estimator().next_index() as u32, Ordering::Relaxed);
        if handed {
            blocks.send_done();
        } else if got_samples {
            shared.reader_blocks_dropped.fetch_add(1, Ordering::Relaxed);
        }
        if monitor.config_hash() != config_hash {
            config_hash = monitor.config_hash();
            shared.config_snapshot.signal(DeviceConfig::from(monitor.config()));
            // The reader follows: the new estimator counts its samples from 0.
            feed.msg(&shared.to_reader, ToReader::Config(*monitor.config()), &mut |m| {
                shared.send(m)
            });
        }
        let cycles = monitor.estimator().wear_state().cycles;
        if cycles.wrapping_sub(saved_at_cycle) >= WEAR_SAVE_CYCLES {
            saved_at_cycle = cycles;
            shared.wear_snapshot.signal(monitor.wear_blob());
        }
        let t1 = clock.now_us();
        busy_us += t1.saturating_sub(t0);
        busy_total_us += t1.saturating_sub(t0);
        if t1 >= next_status {
            let window = t1.saturating_sub(window_start).max(1);
            load_permille = (busy_us * 1000 / window).min(1000) as u16;
            window_start = t1;
            busy_us = 0;
            next_status = t1 + STATUS_PERIOD_US;
            shared.send(DeviceMsg::Status(shared.with_board_figures(monitor.status(
                t1,
                load_permille,
                busy_total_us,
                shared.link.snapshot(),
            ))));
        }
    }
}

/// The chambers' reader: takes the sampling task's blocks and messages,
/// reads each cycle once the 8 ms after it have arrived, and sends the
/// reports on. A board runs it below the sampling task's priority (a
/// reading takes about 1.6 M instructions, 10 ms at 170 MHz); samples keep
/// arriving meanwhile, in the blocks ([`crate::chambers::READER_BLOCKS`]).
/// Messages first: a report or a configuration reaches the reader before
/// the samples read after it.
pub async fn reading<M: RawMutex, R: core::ops::DerefMut<Target = ReaderRoom>>(
    reader: &mut ChamberReader<R>,
    shared: &Shared<M>,
    blocks: &mut zerocopy_channel::Receiver<'_, M, Block>,
) -> ! {
    loop {
        let rate_hz = reader.rate_hz();
        let mut out = |m: DeviceMsg| {
            if let DeviceMsg::Report(r) = &m {
                // How long it waited since its impact, as the samples count it.
                let at = hammer_estimator::clock::index_at_edge_us(r.t_impact_us, rate_hz) as u32;
                let waited = shared.sample_index.load(Ordering::Relaxed).wrapping_sub(at);
                if waited < u32::MAX / 2 {
                    shared.report_latency_max_sets.fetch_max(waited, Ordering::Relaxed);
                }
            }
            shared.send(m)
        };
        if let Ok(m) = shared.to_reader.try_receive() {
            reader.take(m, &mut out);
            continue;
        }
        let took_block = match select(shared.to_reader.receive(), blocks.receive()).await {
            Either::First(m) => {
                reader.take(m, &mut out);
                false
            }
            Either::Second(b) => {
                reader.take_block(b, &mut out);
                true
            }
        };
        if took_block {
            blocks.receive_done();
            // Waiting now, and the one just read.
            shared
                .reader_blocks_peak
                .fetch_max(blocks.len() as u32 + 1, Ordering::Relaxed);
        }
        shared.chambers_read.store(reader.counters.read, Ordering::Relaxed);
        shared.chambers_unread.store(reader.counters.unread, Ordering::Relaxed);
    }
}

/// Persistence: stores the wear state and the configuration as the sampling
/// task hands them over, at low priority (a flash erase stalls only this).
/// Checks in with the supervisor at every `tick` (a board's periodic timer,
/// at most a second) and after every store, so a store that never returns
/// stops the watchdog's feeding.
pub async fn persisting<S: Store, M: RawMutex, F: core::future::Future<Output = ()>>(
    store: &mut S,
    shared: &Shared<M>,
    mut tick: impl FnMut() -> F,
) -> ! {
    use embassy_futures::select::{select3, Either3};
    loop {
        shared.supervisor.beat(Duty::Persistence);
        match select3(shared.wear_snapshot.wait(), shared.config_snapshot.wait(), tick()).await {
            Either3::First(blob) => store.store_wear(&blob),
            Either3::Second(cfg) => match crate::persisted::config_record(&cfg) {
                Some(rec) => store.store_config(&rec),
                None => store.failed(crate::board::Record::Config),
            },
            Either3::Third(()) => {}
        }
    }
}

/// Link receive: frames → commands and sample blocks. Garbage is counted,
/// answered with a rejection, and the decoder resynchronises at the next frame.
pub async fn link_rx<R: LinkRx, M: RawMutex>(rx: &mut R, shared: &Shared<M>) -> ! {
    let mut dec = Decoder::<MAX_FRAME>::new();
    let mut buf = [0u8; 64];
    loop {
        let n = rx.read(&mut buf).await;
        for &b in &buf[..n.min(buf.len())] {
            let Some(res) = dec.push::<HostMsg>(b) else { continue };
            let link = &shared.link;
            match res {
                Ok(HostMsg::Samples(block)) => {
                    link.rx_frames.fetch_add(1, Ordering::Relaxed);
                    shared.samples.send(block).await;
                }
                Ok(cmd) => {
                    link.rx_frames.fetch_add(1, Ordering::Relaxed);
                    shared.commands.send(cmd).await;
                }
                Err(e) => {
                    let (counter, reason) = match e {
                        DecodeError::Cobs => (&link.rx_cobs_errors, RejectReason::CorruptFrame),
                        DecodeError::Crc => (&link.rx_crc_errors, RejectReason::CorruptFrame),
                        DecodeError::Message => (&link.rx_decode_errors, RejectReason::CorruptFrame),
                        DecodeError::Oversize => (&link.rx_oversize, RejectReason::Oversize),
                    };
                    counter.fetch_add(1, Ordering::Relaxed);
                    shared.send(DeviceMsg::Rejected {
                        command: hammer_wire::CommandKind::Unknown,
                        reason,
                    });
                }
            }
        }
    }
}

/// Link transmit: outgoing messages → frames.
pub async fn link_tx<T: LinkTx, M: RawMutex>(tx: &mut T, shared: &Shared<M>) -> ! {
    let mut buf = [0u8; MAX_FRAME];
    loop {
        let m = shared.outgoing.receive().await;
        match encode(&m, &mut buf) {
            Ok(n) => {
                tx.write_all(&buf[..n]).await;
                shared.link.frames_sent.fetch_add(1, Ordering::Relaxed);
                shared.supervisor.beat(Duty::Link);
            }
            Err(_) => {
                shared.link.frames_dropped.fetch_add(1, Ordering::Relaxed);
            }
        }
    }
}

/// The sample source of a board that receives its samples over the link.
/// Block sequence numbers reveal lost blocks, which become an overrun.
pub struct LinkSamples<'a, M: RawMutex> {
    shared: &'a Shared<M>,
    pending: Option<SampleBlock>,
    expected_seq: Option<u32>,
}

impl<'a, M: RawMutex> LinkSamples<'a, M> {
    pub fn new(shared: &'a Shared<M>) -> Self {
        Self {
            shared,
            pending: None,
            expected_seq: None,
        }
    }
}

impl<M: RawMutex> SampleSource for LinkSamples<'_, M> {
    async fn read(&mut self, buf: &mut [RawSample]) -> Result<usize, Overrun> {
        let block = match self.pending.take() {
            Some(b) => b,
            None => {
                let b = self.shared.samples.receive().await;
                if let Some(exp) = self.expected_seq {
                    if b.seq != exp {
                        // A block went missing (or the host restarted its count).
                        let lost = b.seq.wrapping_sub(exp).min(1 << 20) * BLOCK_SAMPLES as u32;
                        self.expected_seq = Some(b.seq.wrapping_add(1));
                        self.pending = Some(b);
                        return Err(Overrun { lost });
                    }
                }
                b
            }
        };
        self.expected_seq = Some(block.seq.wrapping_add(1));
        let n = block.samples.len().min(buf.len());
        for (dst, c) in buf.iter_mut().zip(block.samples.iter()) {
            *dst = RawSample::from(*c);
        }
        Ok(n)
    }
}
