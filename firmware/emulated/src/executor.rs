//! A thread-mode executor that sleeps with WFI (or spins, see [`Idle`]).
//!
//! embassy's cortex-m thread executor idles on WFE, which QEMU implements as
//! a mere yield: an idle guest then keeps a host core busy (measured: ~80 %
//! while doing nothing). WFI really halts QEMU's vCPU until an interrupt, so
//! an idle board costs the host nothing, which matters when tests run
//! several emulators side by side. Hence `raw::Executor` with this pender in
//! place of embassy's `executor-thread`.

use core::sync::atomic::{AtomicBool, Ordering};

use embassy_executor::raw;

/// Set whenever a task is woken, from a task or an interrupt handler.
static WORK: AtomicBool = AtomicBool::new(false);

#[export_name = "__pender"]
fn pender(_context: *mut ()) {
    WORK.store(true, Ordering::Release);
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
                    let asleep = crate::clock::cycles();
                    cortex_m::asm::wfi();
                    crate::clock::add_idle(crate::clock::cycles() - asleep);
                }
            }),
            Idle::Spin => {
                if !WORK.load(Ordering::Acquire) {
                    let idle_from = crate::clock::cycles();
                    spin_until_woken();
                    crate::clock::add_idle(crate::clock::cycles() - idle_from);
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
