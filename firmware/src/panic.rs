//! The panic handler: where, over defmt, then the fault path.
//!
//! Only the location is logged. A panic's message needs `core::fmt` on the
//! target (panic-probe's `print-defmt` formats it); the file and line say
//! which check failed, and the code there says why, for 700 B less flash.
//! `defmt::panic!` sites log their own message before they get here.
//! `udf` raises the HardFault that records the cause for the next boot's
//! status and resets the board (main.rs), as a fault in any other place.

use core::panic::PanicInfo;
use core::sync::atomic::{AtomicBool, Ordering};

#[panic_handler]
fn panic(info: &PanicInfo) -> ! {
    static PANICKED: AtomicBool = AtomicBool::new(false);
    cortex_m::interrupt::disable();
    // A panic inside the logger (or in this handler) must not recurse.
    if !PANICKED.swap(true, Ordering::Relaxed) {
        match info.location() {
            Some(l) => defmt::error!("panicked at {=str}:{=u32}", l.file(), l.line()),
            None => defmt::error!("panicked"),
        }
    }
    cortex_m::asm::udf()
}
