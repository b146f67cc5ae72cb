//! The emulated board's ADC + DMA: sample-sets the host writes into the
//! board's PSRAM (`hammer_wire::stimulus`), released half a DMA ring at a
//! time at the reference board's rate and block size.
//!
//! What is modelled, and why it is enough: the reference board's DMA fills a
//! two-half ring and interrupts at each half; the firmware must read a half
//! before the DMA comes back to it, i.e. before the *next* half completes, or
//! the samples are gone (an overrun). Here the DMA's position is a function
//! of guest time, as a real DMA's is: half k completes 2.56 ms × (k + 1)
//! after the start, whatever the CPU was doing, interrupts masked or not.
//! TIMER0 (CMSDK APB timer at 0x4000_0000, IRQ 8) interrupts when a half is
//! due, to publish it and wake the sampling task. [`StimulusAdc::read`] applies the
//! reference board's rule: only the last completed half may be read, checked
//! again after the copy. The halves are read where the host wrote them, so
//! the "DMA" costs no guest instructions, as a real DMA costs no CPU.
//!
//! The one departure: if the host has not written a half when it is due,
//! the DMA's clock slips by a half (counted as late stimulus): the samples
//! are delayed, never lost, and the firmware's figures stay its own.

use core::cell::Cell;
use core::future::poll_fn;
use core::ptr::{read_volatile, write_volatile};
use core::sync::atomic::Ordering;
use core::task::Poll;

use cortex_m::peripheral::NVIC;
use critical_section::Mutex;
use embassy_sync::waitqueue::AtomicWaker;
use hammer_app::{Overrun, SampleSource};
use hammer_estimator::RawSample;
use hammer_wire::stimulus::{self, Header, BLOCK_SETS, CAPACITY_SETS, MAGIC, RATE_HZ, VERSION};

use crate::clock::{self, SYSCLK_HZ};
use crate::vectors::Interrupt;

/// TIMER0's registers (CMSDK APB timer; ARM DDI0479C, hw/timer/cmsdk-apb-timer.c).
const TIMER0: usize = 0x4000_0000;
const CTRL: usize = 0x00;
const VALUE: usize = 0x04;
const RELOAD: usize = 0x08;
/// INTSTATUS on read, INTCLEAR on write.
const INTCLEAR: usize = 0x0c;
const CTRL_ENABLE: u32 = 1 << 0;
const CTRL_IRQ_ENABLE: u32 = 1 << 3;

/// Core (and timer) clocks per half: 64 000, 2.56 ms.
const CLOCKS_PER_BLOCK: u32 = (SYSCLK_HZ as u64 * BLOCK_SETS as u64 / RATE_HZ as u64) as u32;
const _: () = assert!(CLOCKS_PER_BLOCK as u64 * RATE_HZ as u64 == SYSCLK_HZ as u64 * BLOCK_SETS as u64);

/// The DMA's clock.
#[derive(Clone, Copy)]
struct Dma {
    /// When the first half of this run started, in core cycles; moved on by
    /// a half each time the host's stimulus was late.
    epoch: u64,
    /// Halves completed since `epoch`.
    completed: u64,
    /// When each of the last four halves completed (core cycles, low 32
    /// bits), by half number modulo 4, for the latency of its processing.
    done_at: [u32; 4],
}

static DMA: Mutex<Cell<Dma>> = Mutex::new(Cell::new(Dma {
    epoch: 0,
    completed: 0,
    done_at: [0; 4],
}));
static WAKER: AtomicWaker = AtomicWaker::new();

fn header() -> &'static Header {
    // SAFETY: the PSRAM is always mapped on this board (zeros without the
    // host's backing file), aligned, and Header is only atomics, valid for any bits.
    unsafe { &*((stimulus::PSRAM_BASE + stimulus::HEADER_OFFSET) as *const Header) }
}

fn timer_write(offset: usize, value: u32) {
    // SAFETY: TIMER0's registers, written only here and in the handler.
    unsafe { write_volatile((TIMER0 + offset) as *mut u32, value) }
}

/// Completes every half due by now (if the host has written it) and returns
/// the DMA's position in sample-sets and the core cycles to the next half.
fn advance(h: &Header) -> (u32, u64) {
    critical_section::with(|cs| {
        let cell = DMA.borrow(cs);
        let mut dma = cell.get();
        let now = clock::cycles();
        let period = u64::from(CLOCKS_PER_BLOCK);
        let mut pos = h.dma_sets.load(Ordering::Relaxed);
        while dma.completed < now.saturating_sub(dma.epoch) / period {
            let ahead = h.written_sets.load(Ordering::Acquire).wrapping_sub(pos);
            if (BLOCK_SETS..=CAPACITY_SETS).contains(&ahead) {
                dma.completed += 1;
                let due = dma.epoch + dma.completed * period;
                dma.done_at[(pos / BLOCK_SETS) as usize % 4] = due as u32;
                pos = pos.wrapping_add(BLOCK_SETS);
                h.dma_sets.store(pos, Ordering::Release);
            } else {
                if h.end_of_stream.load(Ordering::Acquire) == 0 {
                    h.starved_blocks.fetch_add(1, Ordering::Relaxed);
                }
                dma.epoch += period;
            }
        }
        cell.set(dma);
        (pos, (dma.epoch + (dma.completed + 1) * period).saturating_sub(now))
    })
}

/// One sample-set from the ring, read volatile: the host writes the ring
/// while the guest runs (never the half being read, unless the guest is late,
/// which the check after the copy catches).
fn ring_set(pos: u32) -> RawSample {
    let addr = stimulus::PSRAM_BASE + stimulus::RING_OFFSET + stimulus::slot(pos) * stimulus::SET_BYTES;
    // SAFETY: slot() < CAPACITY_SETS, so the three u16 lie inside the ring,
    // which lies inside the PSRAM (checked in hammer_wire::stimulus); aligned to 2.
    unsafe {
        RawSample {
            rear: read_volatile(addr as *const u16),
            front: read_volatile((addr + 2) as *const u16),
            accel: read_volatile((addr + 4) as *const u16),
        }
    }
}

/// Why the host's stimulus cannot be used.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NoStimulus {
    /// No backing file: the board was started for samples over the UART.
    Absent,
    /// A header of another layout or rate than this firmware's.
    Mismatch,
}

pub struct StimulusAdc {
    /// Position of the next sample-set to hand out.
    next: u32,
    /// The half whose processing ends when the app next asks for samples.
    finished: Option<u32>,
    /// When the last block was handed over (core cycles, low 32 bits), until
    /// the app next asks: its processing time goes to `Header::loop_cycles`.
    handed_at: Option<u32>,
}

/// `a` is after `b` in wrapping position order.
fn after(a: u32, b: u32) -> bool {
    (a.wrapping_sub(b) as i32) > 0
}

impl StimulusAdc {
    /// Starts the DMA's clock if the host has prepared a stimulus; continues
    /// from wherever the DMA stands, so a reset board picks the stream up again.
    pub fn start() -> Result<Self, NoStimulus> {
        let h = header();
        if h.magic.load(Ordering::Acquire) != MAGIC {
            return Err(NoStimulus::Absent);
        }
        let expected = [VERSION, CAPACITY_SETS, BLOCK_SETS, RATE_HZ];
        let found = [&h.version, &h.capacity_sets, &h.block_sets, &h.rate_hz].map(|a| a.load(Ordering::Relaxed));
        if found != expected {
            return Err(NoStimulus::Mismatch);
        }
        let next = h.dma_sets.load(Ordering::Acquire);
        critical_section::with(|cs| {
            DMA.borrow(cs).set(Dma {
                epoch: clock::cycles(),
                completed: 0,
                done_at: [0; 4],
            })
        });
        timer_write(CTRL, 0);
        timer_write(RELOAD, CLOCKS_PER_BLOCK - 1);
        timer_write(INTCLEAR, 1);
        timer_write(CTRL, CTRL_ENABLE | CTRL_IRQ_ENABLE);
        // SAFETY: the handler only touches the header, DMA and WAKER, all
        // interrupt-safe.
        unsafe { NVIC::unmask(Interrupt::Timer0) };
        Ok(Self {
            next,
            finished: None,
            handed_at: None,
        })
    }

    fn overrun(&mut self, h: &Header, oldest: u32) -> Overrun {
        let lost = oldest.wrapping_sub(self.next);
        let n = h.overruns.load(Ordering::Relaxed);
        let [from_at, lost_at] = &h.lost_log[n as usize % stimulus::LOST_LOG];
        from_at.store(self.next, Ordering::Relaxed);
        lost_at.store(lost, Ordering::Relaxed);
        self.next = oldest;
        self.finished = None;
        h.lost_sets.fetch_add(lost, Ordering::Relaxed);
        h.overruns.store(n.wrapping_add(1), Ordering::Release);
        Overrun { lost }
    }

    /// The end of a half's processing: its latency, and the load figures.
    fn processed(&mut self, h: &Header, half: u32) {
        let done_at = critical_section::with(|cs| DMA.borrow(cs).get().done_at[half as usize % 4]);
        let ticks = clock::cycles32().wrapping_sub(done_at);
        h.latency_max_us
            .fetch_max(ticks / (SYSCLK_HZ / 1_000_000), Ordering::Relaxed);
        let (uptime, busy) = clock::uptime_and_busy_us();
        // The stack's figures, as the SysTick measures them (stack.rs).
        let shared = &crate::SHARED;
        h.stack_used_bytes
            .store(shared.stack_used_bytes.load(Ordering::Relaxed), Ordering::Relaxed);
        h.stack_reserved_bytes
            .store(shared.stack_reserved_bytes.load(Ordering::Relaxed), Ordering::Relaxed);
        for (to, from) in [
            (&h.chambers_read, &shared.chambers_read),
            (&h.chambers_unread, &shared.chambers_unread),
            (&h.reader_blocks_peak, &shared.reader_blocks_peak),
            (&h.reader_blocks_dropped, &shared.reader_blocks_dropped),
            (&h.report_latency_max_sets, &shared.report_latency_max_sets),
        ] {
            to.store(from.load(Ordering::Relaxed), Ordering::Relaxed);
        }
        h.reader_blocks.store(crate::READER_BLOCKS as u32, Ordering::Relaxed);
        h.uptime_us.store(uptime as u32, Ordering::Relaxed);
        h.busy_us.store(busy as u32, Ordering::Relaxed);
    }

    /// Fault injection (see `Header::fault`): an undefined instruction,
    /// which escalates to a HardFault (UsageFault is not enabled). Cleared
    /// first, so the board that restarts runs on.
    fn fault_if_asked(h: &Header) {
        if h.fault.swap(0, Ordering::AcqRel) != 0 {
            cortex_m::asm::udf();
        }
    }

    /// The bench's end (see `Header::exit_when_drained`): QEMU exits once the
    /// loop asks for more after the stream's last sample-set, `next`.
    fn exit_if_drained(h: &Header, next: u32) {
        if h.exit_when_drained.load(Ordering::Acquire) != 0
            && h.end_of_stream.load(Ordering::Acquire) != 0
            && next == h.written_sets.load(Ordering::Acquire)
        {
            crate::exit_qemu(cortex_m_semihosting::debug::EXIT_SUCCESS);
        }
    }

    /// Fault injection (see `Header::stall_us`): a late firmware.
    fn stall_if_asked(h: &Header) {
        let us = h.stall_us.swap(0, Ordering::AcqRel);
        if us > 0 {
            let until = clock::cycles() + u64::from(us) * u64::from(SYSCLK_HZ / 1_000_000);
            while clock::cycles() < until {}
        }
    }
}

impl SampleSource for StimulusAdc {
    async fn read(&mut self, buf: &mut [RawSample]) -> Result<usize, Overrun> {
        let h = header();
        if let Some(at) = self.handed_at.take() {
            h.loop_cycles
                .fetch_add(clock::cycles32().wrapping_sub(at), Ordering::Relaxed);
        }
        if let Some(half) = self.finished.take() {
            self.processed(h, half);
        }
        Self::exit_if_drained(h, self.next);
        Self::stall_if_asked(h);
        Self::fault_if_asked(h);
        // Cancel-safe: nothing below the wait is interrupted by an await.
        let next = self.next;
        poll_fn(|cx| {
            WAKER.register(cx.waker());
            if after(advance(h).0, next) {
                Poll::Ready(())
            } else {
                Poll::Pending
            }
        })
        .await;
        // Only the last completed half is intact: the DMA is filling the other.
        let oldest = advance(h).0.wrapping_sub(BLOCK_SETS);
        if after(oldest, self.next) {
            return Err(self.overrun(h, oldest));
        }
        let half_end = (self.next - self.next % BLOCK_SETS).wrapping_add(BLOCK_SETS);
        let n = (half_end.wrapping_sub(self.next) as usize).min(buf.len());
        for (i, dst) in buf[..n].iter_mut().enumerate() {
            *dst = ring_set(self.next.wrapping_add(i as u32));
        }
        // A half that completed during the copy may have overwritten it.
        let oldest = advance(h).0.wrapping_sub(BLOCK_SETS);
        if after(oldest, self.next) {
            return Err(self.overrun(h, oldest));
        }
        self.next = self.next.wrapping_add(n as u32);
        h.consumed_sets.fetch_add(n as u32, Ordering::Relaxed);
        if self.next == half_end {
            self.finished = Some((half_end / BLOCK_SETS).wrapping_sub(1));
        }
        if n > 0 {
            self.handed_at = Some(clock::cycles32());
        }
        Ok(n)
    }
}

/// The internal reference's reading, as the host's model of the analog
/// supply sets it: VDDA for `Status`. The reference board reads its
/// VREFINT channel once a second; this runs on every SysTick (100 ms).
pub fn measure_vdda() {
    let h = header();
    if h.magic.load(Ordering::Acquire) != MAGIC {
        return;
    }
    let code = h.vrefint_code.load(Ordering::Relaxed).min(u32::from(u16::MAX)) as u16;
    crate::SHARED.set_vdda_v(hammer_app::supply::vdda_v(code, stimulus::VREFINT_CAL));
}

/// TIMER0 (IRQ 8): a DMA half is due. Completes it, wakes the sampling task
/// and sets the timer to the next half's due time, so the timer cannot
/// drift from the DMA's clock.
pub extern "C" fn on_timer_interrupt() {
    timer_write(INTCLEAR, 1);
    let (_, to_next) = advance(header());
    timer_write(VALUE, (to_next as u32).clamp(1, CLOCKS_PER_BLOCK));
    WAKER.wake();
}
