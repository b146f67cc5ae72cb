//! The emulated board's ADC + DMA: sample-sets the host writes into the
//! board's PSRAM (`hammer_wire::stimulus`), released half a DMA ring at a
//! time by TIMER0 at the reference board's rate and block size.
//!
//! What is modelled, and why it is enough: the reference board's DMA fills a
//! two-half ring and interrupts at each half; the firmware must read a half
//! before the DMA comes back to it, i.e. before the *next* half completes, or
//! the samples are gone (an overrun). Here TIMER0 (CMSDK APB timer at
//! 0x4000_0000, IRQ 8, 25 MHz) completes one half per 256 sample-sets of guest
//! time, and [`StimulusAdc::read`] applies the same rule: only the last
//! completed half may be read, checked again after the copy. The halves are
//! read where the host wrote them, so the "DMA" costs no guest instructions,
//! as a real DMA costs no CPU. The timer does not wait for the firmware.

use core::future::poll_fn;
use core::ptr::{read_volatile, write_volatile};
use core::sync::atomic::{AtomicU32, Ordering};
use core::task::Poll;

use cortex_m::peripheral::NVIC;
use embassy_sync::waitqueue::AtomicWaker;
use hammer_app::{Overrun, SampleSource};
use hammer_estimator::RawSample;
use hammer_wire::stimulus::{self, Header, BLOCK_SETS, CAPACITY_SETS, MAGIC, RATE_HZ, VERSION};

use crate::clock::{self, SYSCLK_HZ};
use crate::vectors::Interrupt;

/// TIMER0's registers (CMSDK APB timer; ARM DDI0479C, hw/timer/cmsdk-apb-timer.c).
const TIMER0: usize = 0x4000_0000;
const CTRL: usize = 0x00;
const RELOAD: usize = 0x08;
/// INTSTATUS on read, INTCLEAR on write.
const INTCLEAR: usize = 0x0c;
const CTRL_ENABLE: u32 = 1 << 0;
const CTRL_IRQ_ENABLE: u32 = 1 << 3;

/// Timer clocks per half: 64 000, 2.56 ms.
const CLOCKS_PER_BLOCK: u32 = (SYSCLK_HZ as u64 * BLOCK_SETS as u64 / RATE_HZ as u64) as u32;
const _: () = assert!(CLOCKS_PER_BLOCK as u64 * RATE_HZ as u64 == SYSCLK_HZ as u64 * BLOCK_SETS as u64);

/// When each of the last four halves completed (SysTick cycles, low 32 bits),
/// indexed by half number modulo 4: the latency of a half is measured when
/// the app comes back for more after processing it.
static DONE_AT: [AtomicU32; 4] = [const { AtomicU32::new(0) }; 4];
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
}

impl StimulusAdc {
    /// Starts the timer if the host has prepared a stimulus; continues from
    /// wherever the "DMA" stands, so a reset board picks the stream up again.
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
        timer_write(CTRL, 0);
        timer_write(RELOAD, CLOCKS_PER_BLOCK - 1);
        timer_write(INTCLEAR, 1);
        // QEMU loads VALUE from RELOAD when the timer is enabled with VALUE 0.
        timer_write(CTRL, CTRL_ENABLE | CTRL_IRQ_ENABLE);
        // SAFETY: the handler only touches the header, DONE_AT and WAKER,
        // all interrupt-safe.
        unsafe { NVIC::unmask(Interrupt::Timer0) };
        Ok(Self { next, finished: None })
    }

    /// Publishes guest time and CPU use for the host's soak figures.
    fn publish_load(h: &Header) {
        let (uptime, busy) = clock::uptime_and_busy_us();
        h.uptime_us.store(uptime as u32, Ordering::Relaxed);
        h.busy_us.store(busy as u32, Ordering::Relaxed);
    }

    fn overrun(&mut self, h: &Header, oldest: u32) -> Overrun {
        let lost = oldest.wrapping_sub(self.next);
        self.next = oldest;
        self.finished = None;
        h.lost_sets.fetch_add(lost, Ordering::Relaxed);
        h.overruns.fetch_add(1, Ordering::Relaxed);
        Overrun { lost }
    }
}

/// `a` is after `b` in wrapping position order.
fn after(a: u32, b: u32) -> bool {
    (a.wrapping_sub(b) as i32) > 0
}

impl SampleSource for StimulusAdc {
    async fn read(&mut self, buf: &mut [RawSample]) -> Result<usize, Overrun> {
        let h = header();
        if let Some(half) = self.finished.take() {
            let done_at = DONE_AT[half as usize % 4].load(Ordering::Relaxed);
            let ticks = clock::cycles32().wrapping_sub(done_at);
            h.latency_max_us.fetch_max(ticks / (SYSCLK_HZ / 1_000_000), Ordering::Relaxed);
            Self::publish_load(h);
        }
        // Cancel-safe: nothing below the wait is interrupted by an await.
        let next = self.next;
        poll_fn(|cx| {
            WAKER.register(cx.waker());
            if after(h.dma_sets.load(Ordering::Acquire), next) {
                Poll::Ready(())
            } else {
                Poll::Pending
            }
        })
        .await;
        // Only the last completed half is intact: the DMA is filling the other.
        let oldest = h.dma_sets.load(Ordering::Acquire).wrapping_sub(BLOCK_SETS);
        if after(oldest, self.next) {
            return Err(self.overrun(h, oldest));
        }
        let half_end = (self.next - self.next % BLOCK_SETS).wrapping_add(BLOCK_SETS);
        let n = (half_end.wrapping_sub(self.next) as usize).min(buf.len());
        for (i, dst) in buf[..n].iter_mut().enumerate() {
            *dst = ring_set(self.next.wrapping_add(i as u32));
        }
        // A half that completed during the copy may have overwritten it.
        let oldest = h.dma_sets.load(Ordering::Acquire).wrapping_sub(BLOCK_SETS);
        if after(oldest, self.next) {
            return Err(self.overrun(h, oldest));
        }
        self.next = self.next.wrapping_add(n as u32);
        h.consumed_sets.fetch_add(n as u32, Ordering::Relaxed);
        if self.next == half_end {
            self.finished = Some(half_end / BLOCK_SETS - 1);
        }
        Ok(n)
    }
}

/// TIMER0 (IRQ 8): one DMA half complete, if the host has written it.
pub extern "C" fn on_timer_interrupt() {
    timer_write(INTCLEAR, 1);
    let h = header();
    let dma = h.dma_sets.load(Ordering::Relaxed);
    let written = h.written_sets.load(Ordering::Acquire);
    if written.wrapping_sub(dma) >= BLOCK_SETS && written.wrapping_sub(dma) <= CAPACITY_SETS {
        DONE_AT[(dma / BLOCK_SETS) as usize % 4].store(clock::cycles32(), Ordering::Relaxed);
        h.dma_sets.store(dma.wrapping_add(BLOCK_SETS), Ordering::Release);
        WAKER.wake();
    } else if h.end_of_stream.load(Ordering::Acquire) == 0 {
        h.starved_blocks.fetch_add(1, Ordering::Relaxed);
    }
}
