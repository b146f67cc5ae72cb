//! Time since boot from SysTick, and the tick that wakes an idle app.
//!
//! SysTick runs from the core clock and its wraps are counted in the SysTick
//! exception, so time is exact to one core cycle and never runs backwards.
//! Under QEMU the counter follows the virtual clock: host time normally,
//! executed instructions with `-icount`.

use core::cell::Cell;
use core::future::poll_fn;
use core::sync::atomic::{AtomicU32, Ordering};
use core::task::Poll;

use cortex_m::peripheral::syst::SystClkSource;
use cortex_m::peripheral::{SCB, SYST};
use cortex_m_rt::exception;
use embassy_sync::waitqueue::AtomicWaker;

/// The mps2-an386's SYSCLK, which clocks the core, SysTick and the APB
/// peripherals (hw/arm/mps2.c: `SYSCLK_FRQ 25000000`); the host reads the
/// board's cycle counts in it, hence its place in `hammer_wire::stimulus`.
pub use hammer_wire::stimulus::SYSCLK_HZ;

/// Core cycles per SysTick period: 100 ms. Shorter than the 24-bit maximum
/// (0.67 s) because the wrap also serves as the idle tick ([`next_tick`]),
/// which bounds how late a periodic status can be.
const TICKS_PER_WRAP: u32 = SYSCLK_HZ / 10;
const RELOAD: u32 = TICKS_PER_WRAP - 1;
const _: () = assert!(RELOAD <= 0x00FF_FFFF, "SysTick's reload register has 24 bits");

/// Completed SysTick periods. 32 bits last 13 years at 100 ms a wrap.
static WRAPS: AtomicU32 = AtomicU32::new(0);
/// Core cycles spent asleep in WFI, for the CPU load the host reads.
static IDLE: critical_section::Mutex<Cell<u64>> = critical_section::Mutex::new(Cell::new(0));
/// The tasks waiting in [`next_tick`], one per [`Waiter`].
static TICK_WAKERS: [AtomicWaker; 2] = [const { AtomicWaker::new() }; 2];

/// Who waits for the tick: each may have one wait under way.
#[derive(Clone, Copy)]
pub enum Waiter {
    /// The sampling loop's idle tick (`pacing.rs`).
    Pacing = 0,
    /// The persistence task's check-in.
    Persistence = 1,
}

/// The app's [`hammer_app::Clock`]; owning SYST keeps anyone else from
/// reprogramming the counter underneath it.
pub struct SysTickClock {
    _syst: SYST,
}

impl SysTickClock {
    pub fn start(mut syst: SYST) -> Self {
        syst.set_clock_source(SystClkSource::Core);
        syst.set_reload(RELOAD);
        syst.clear_current();
        syst.enable_interrupt();
        syst.enable_counter();
        Self { _syst: syst }
    }
}

impl hammer_app::Clock for SysTickClock {
    fn now_us(&self) -> u64 {
        cycles() / u64::from(SYSCLK_HZ / 1_000_000)
    }
}

/// Core cycles since [`SysTickClock::start`].
pub fn cycles() -> u64 {
    critical_section::with(|_| {
        // The exception cannot run in here, so a wrap since it last ran shows
        // only as its pending bit. The counter pends it on reaching 0 and
        // reloads one cycle later, so a pending wrap with the counter still
        // at 0 has not happened yet.
        let mut wraps = WRAPS.load(Ordering::Relaxed);
        let mut val = SYST::get_current();
        if SCB::is_pendst_pending() {
            val = SYST::get_current();
            if val != 0 {
                wraps = wraps.wrapping_add(1);
            }
        }
        u64::from(wraps) * u64::from(TICKS_PER_WRAP) + u64::from(RELOAD - val.min(RELOAD))
    })
}

/// The low 32 bits of [`cycles`]: enough for differences under 171 s.
pub fn cycles32() -> u32 {
    cycles() as u32
}

/// Counts `n` cycles the core slept (the executor's WFI).
pub fn add_idle(n: u64) {
    critical_section::with(|cs| {
        let idle = IDLE.borrow(cs);
        idle.set(idle.get() + n);
    });
}

/// Time since start and the part of it the core was awake, µs.
pub fn uptime_and_busy_us() -> (u64, u64) {
    let now = cycles();
    let idle = critical_section::with(|cs| IDLE.borrow(cs).get());
    let per_us = u64::from(SYSCLK_HZ / 1_000_000);
    (now / per_us, now.saturating_sub(idle) / per_us)
}

/// Completes at the next SysTick wrap. One wait per [`Waiter`] at a time
/// (a second would take over its waker).
pub async fn next_tick(waiter: Waiter) {
    let start = WRAPS.load(Ordering::Acquire);
    poll_fn(|cx| {
        TICK_WAKERS[waiter as usize].register(cx.waker());
        if WRAPS.load(Ordering::Acquire) != start {
            Poll::Ready(())
        } else {
            Poll::Pending
        }
    })
    .await
}

#[exception]
fn SysTick() {
    WRAPS.fetch_add(1, Ordering::Release);
    // 1024 words a tick (≈ 25 µs of guest time): a pass over 70 KB of paint
    // in under 2 s.
    crate::stack::scan_step(1024);
    crate::adc::measure_vdda();
    for w in &TICK_WAKERS {
        w.wake();
    }
    crate::watchdog::on_tick();
}
