//! How much of its stack the board has used: the stack region is painted at
//! boot (cortex-m-rt's `paint-stack`), and the lowest word no longer painted
//! marks the deepest the stack has been. The scan runs from the region's
//! bottom up, so a frame's unwritten padding cannot hide deeper use.
//!
//! The scan goes in steps of a bounded number of words, so a caller in an
//! interrupt (the emulated board's SysTick) never holds the sampling task up
//! for long: a whole pass over 70 KB of paint at once took 0.6 ms there and
//! doubled the worst latency of a DMA half. The deepest use only ever grows,
//! so a pass that takes a few seconds reports a figure at most that old.
//!
//! Both boards' (the emulated one includes this file by path): each has
//! its `SHARED` at the crate root and links cortex-m-rt with `paint-stack`.

use core::sync::atomic::{AtomicUsize, Ordering};

use cortex_m_rt::STACK_PAINT_VALUE;

extern "C" {
    /// The top of the stack (initial SP), from cortex-m-rt's link.x.
    static _stack_start: u32;
    /// The bottom of the painted region (flip-link puts it at the start of RAM).
    static _stack_end: u32;
}

/// Where the pass under way has got to (0: start a new one).
static SCAN_AT: AtomicUsize = AtomicUsize::new(0);

/// Scans up to `max_words` more words of the pass under way; when the pass
/// reaches the deepest used word, publishes the figures for `Status`
/// (`Shared::stack_*`) and starts the next pass. Call from one context only.
pub fn scan_step(max_words: usize) {
    // Only the symbols' addresses are taken, never their (meaningless) values.
    let top = core::ptr::addr_of!(_stack_start) as usize;
    let bottom = core::ptr::addr_of!(_stack_end) as usize;
    let mut p = match SCAN_AT.load(Ordering::Relaxed) {
        0 => bottom,
        at => at,
    };
    for _ in 0..max_words {
        // SAFETY: bottom <= p < top: the stack region, RAM, word-aligned
        // (link.x asserts both); reading it races only with the stack's own
        // use, which moves the boundary, never the memory's validity.
        if p >= top || unsafe { core::ptr::read_volatile(p as *const u32) } != STACK_PAINT_VALUE {
            let shared = &crate::SHARED;
            shared.stack_used_bytes.store((top - p) as u32, Ordering::Relaxed);
            shared
                .stack_reserved_bytes
                .store((top - bottom) as u32, Ordering::Relaxed);
            SCAN_AT.store(0, Ordering::Relaxed);
            return;
        }
        p += 4;
    }
    SCAN_AT.store(p, Ordering::Relaxed);
}
