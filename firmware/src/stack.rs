//! How much of its stack the board has used: the stack region is painted at
//! boot (cortex-m-rt's `paint-stack`), and the lowest word no longer painted
//! marks the deepest the stack has been. The scan runs from the region's
//! bottom up, so a frame's unwritten padding cannot hide deeper use.
//!
//! Both boards' (the emulated one includes this file by path): each has
//! its `SHARED` at the crate root and links cortex-m-rt with `paint-stack`.

use cortex_m_rt::STACK_PAINT_VALUE;

extern "C" {
    /// The top of the stack (initial SP), from cortex-m-rt's link.x.
    static _stack_start: u32;
    /// The bottom of the painted region: the end of the statics (link.x), or
    /// a board's memory.x.
    static _stack_end: u32;
}

/// (bytes used at the deepest so far, bytes reserved).
pub fn high_water() -> (u32, u32) {
    // Only the symbols' addresses are taken, never their (meaningless) values.
    let top = core::ptr::addr_of!(_stack_start) as usize;
    let bottom = core::ptr::addr_of!(_stack_end) as usize;
    let mut p = bottom;
    // SAFETY: [bottom, top) is the stack region, RAM, word-aligned (link.x
    // asserts both); reading it races only with the stack's own use, which
    // moves the boundary, never the memory's validity.
    while p < top && unsafe { core::ptr::read_volatile(p as *const u32) } == STACK_PAINT_VALUE {
        p += 4;
    }
    ((top - p) as u32, (top - bottom) as u32)
}

/// Measures and publishes the figures for `Status` (`Shared::stack_*`), about
/// once a second: the scan reads the painted words below the deepest use.
pub fn publish() {
    let (used, reserved) = high_water();
    crate::SHARED
        .stack_used_bytes
        .store(used, core::sync::atomic::Ordering::Relaxed);
    crate::SHARED
        .stack_reserved_bytes
        .store(reserved, core::sync::atomic::Ordering::Relaxed);
}
