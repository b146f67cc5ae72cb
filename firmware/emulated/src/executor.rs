//! A thread-mode executor that sleeps with WFI (or spins, see [`Idle`]).
//!
//! embassy's cortex-m thread executor idles on WFE, which QEMU implements as
//! a mere yield: an idle guest then keeps a host core busy (measured: ~80 %
//! while doing nothing). WFI really halts QEMU's vCPU until an interrupt, so
//! an idle board costs the host nothing, which matters when tests run
//! several emulators side by side. Hence `raw::Executor` with this pender in
//! place of embassy's `executor-thread`.

use core::sync::atomic::{AtomicBool, AtomicPtr, AtomicU32, Ordering};

use cortex_m::peripheral::NVIC;
use embassy_executor::raw;
use static_cell::StaticCell;

use crate::vectors::Interrupt;

/// Set whenever a thread-mode task is woken, from a task or an interrupt handler.
static WORK: AtomicBool = AtomicBool::new(false);

/// The executor of the sampling task, polled in an interrupt handler
/// ([`Interrupt::Dsp`], software-pended) so that it preempts the thread
/// mode's tasks, the chambers' reading among them, as the reference
/// board's interrupt executor does. Its pender context tells it apart.
static SAMPLING: StaticCell<raw::Executor> = StaticCell::new();
static SAMPLING_EXECUTOR: AtomicPtr<raw::Executor> = AtomicPtr::new(core::ptr::null_mut());
const SAMPLING_CONTEXT: *mut () = 1 as *mut ();
/// Core cycles spent polling the sampling executor: the thread mode's idle
/// spans exclude them.
static SAMPLING_CYCLES: AtomicU32 = AtomicU32::new(0);

#[export_name = "__pender"]
fn pender(context: *mut ()) {
    if context == SAMPLING_CONTEXT {
        NVIC::pend(Interrupt::Dsp);
    } else {
        WORK.store(true, Ordering::Release);
    }
}

/// Starts the sampling executor at a priority above thread mode and below
/// the ADC's and the UART's interrupts (which only wake tasks); returns its
/// spawner.
pub fn start_sampling(nvic: &mut NVIC) -> embassy_executor::Spawner {
    let executor: &'static raw::Executor = SAMPLING.init(raw::Executor::new(SAMPLING_CONTEXT));
    SAMPLING_EXECUTOR.store(
        executor as *const raw::Executor as *mut raw::Executor,
        Ordering::Release,
    );
    // SAFETY: setting a priority and unmasking an interrupt whose handler
    // (below) only polls the executor stored above.
    unsafe {
        nvic.set_priority(Interrupt::Dsp, 0x80);
        NVIC::unmask(Interrupt::Dsp);
    }
    executor.spawner()
}

/// The sampling executor's interrupt: polls it, and counts the cycles.
pub unsafe extern "C" fn on_dsp_interrupt() {
    let executor = SAMPLING_EXECUTOR.load(Ordering::Acquire);
    if executor.is_null() {
        return;
    }
    let t0 = crate::clock::cycles32();
    // SAFETY: the executor is 'static; this handler is its only poller and
    // does not nest (one priority level).
    unsafe { (*executor).poll() };
    SAMPLING_CYCLES.fetch_add(crate::clock::cycles32().wrapping_sub(t0), Ordering::Relaxed);
}

/// The thread mode's idle from `from` (cycles) to now, less the sampling
/// executor's work that interrupted it since `sampling_at`.
fn idle_since(from: u64, sampling_at: u32) -> u64 {
    let busy = SAMPLING_CYCLES.load(Ordering::Relaxed).wrapping_sub(sampling_at);
    (crate::clock::cycles() - from).saturating_sub(u64::from(busy))
}

/// What the core does while no task is woken.
#[derive(Clone, Copy, PartialEq, Eq)]
pub enum Idle {
    /// WFI: an idle board costs the host nothing.
    Sleep,
    /// Spin on the wake flag. For the full-rate ADC under `-icount`: a core
    /// that never halts keeps guest time a pure count of instructions. With a
    /// halted core QEMU 7.2 either lets guest time follow the host's clock
    /// (`sleep=on`: a host stall then looks like a slow firmware) or jumps it
    /// to the next deadline (`sleep=off`: measured, TIMER0's interrupt then
    /// comes every second period by SysTick, halving the sample rate).
    Spin,
}

/// Polls woken tasks forever, idling as `idle` says while none is.
pub fn run(executor: &'static raw::Executor, idle: Idle) -> ! {
    loop {
        // Cleared before polling, so a wake during the poll is not lost.
        WORK.store(false, Ordering::Relaxed);
        // SAFETY: `poll` is never re-entered: this is the only caller and the
        // pender only sets a flag.
        unsafe { executor.poll() };
        match idle {
            Idle::Sleep => cortex_m::interrupt::free(|_| {
                // With interrupts masked no wake can slip in between this
                // check and the WFI, and an interrupt becoming pending still
                // ends the WFI; its handler runs as the critical section
                // ends, before the next poll.
                if !WORK.load(Ordering::Acquire) {
                    let (asleep, at) = (crate::clock::cycles(), SAMPLING_CYCLES.load(Ordering::Relaxed));
                    cortex_m::asm::wfi();
                    crate::clock::add_idle(idle_since(asleep, at));
                }
            }),
            Idle::Spin => {
                if !WORK.load(Ordering::Acquire) {
                    let (idle_from, at) = (crate::clock::cycles(), SAMPLING_CYCLES.load(Ordering::Relaxed));
                    spin_until_woken();
                    crate::clock::add_idle(idle_since(idle_from, at));
                }
            }
        }
    }
}

/// The idle spin, out of line so that an instruction profile
/// (`cargo xtask bench-firmware`) can tell idle from work by its name.
#[inline(never)]
fn spin_until_woken() {
    // Interrupts stay enabled: their handlers set WORK.
    while !WORK.load(Ordering::Acquire) {}
}
