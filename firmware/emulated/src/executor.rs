//! A thread-mode executor that sleeps with WFI.
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

/// Polls woken tasks forever, sleeping while none is.
pub fn run(executor: &'static raw::Executor) -> ! {
    loop {
        // Cleared before polling, so a wake during the poll is not lost.
        WORK.store(false, Ordering::Relaxed);
        // SAFETY: `poll` is never re-entered: this is the only caller and the
        // pender only sets a flag.
        unsafe { executor.poll() };
        cortex_m::interrupt::free(|_| {
            // With interrupts masked no wake can slip in between this check
            // and the WFI, and an interrupt becoming pending still ends the
            // WFI; its handler runs as the critical section ends, before the
            // next poll.
            if !WORK.load(Ordering::Acquire) {
                cortex_m::asm::wfi();
            }
        });
    }
}
