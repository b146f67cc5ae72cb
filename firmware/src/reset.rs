//! The reset cause across a reset: `hammer_app::reset`'s record in RAM the
//! startup code leaves alone (`.uninit`), cross-checked at boot with the
//! reset flags in RCC_CSR, which say which reset it was but not why.

use core::mem::MaybeUninit;
use core::ptr::{addr_of, addr_of_mut, read_volatile, write_volatile};

use embassy_stm32::pac;
use hammer_app::reset;
use hammer_wire::ResetCause;

#[link_section = ".uninit.hammer_reset_cause"]
static mut RECORD: MaybeUninit<[u32; reset::WORDS]> = MaybeUninit::uninit();

/// Records `cause` for the next boot.
pub fn record(cause: ResetCause) {
    let words = reset::encode(cause);
    cortex_m::interrupt::free(|_| {
        // Plain RAM, only accessed inside critical sections or by the fault
        // handler, which never returns.
        let p = addr_of_mut!(RECORD) as *mut u32;
        for (i, w) in words.into_iter().enumerate() {
            // SAFETY: i < WORDS, inside RECORD.
            unsafe { write_volatile(p.add(i), w) };
        }
    });
}

/// Why this boot happened, from the record and the reset flags; clears both.
/// A record the flags do not confirm (a watchdog record without the IWDG
/// flag: the duty recovered, then the power went) counts as a power-on.
pub fn take_cause() -> ResetCause {
    let mut words = [0u32; reset::WORDS];
    cortex_m::interrupt::free(|_| {
        let p = addr_of!(RECORD) as *const u32;
        for (i, w) in words.iter_mut().enumerate() {
            // SAFETY: i < WORDS, inside RECORD; any bits are valid u32s.
            *w = unsafe { read_volatile(p.add(i)) };
        }
    });
    record(ResetCause::PowerOn);
    let csr = pac::RCC.csr().read();
    pac::RCC.csr().modify(|w| w.set_rmvf(true));
    match reset::decode(words) {
        ResetCause::Watchdog { .. } if !csr.iwdgrstf() => ResetCause::PowerOn,
        ResetCause::Fault { .. } if !csr.sftrstf() => ResetCause::PowerOn,
        cause => cause,
    }
}

/// For the log: defmt then needs no `Debug` (and no core formatting).
pub fn name(cause: ResetCause) -> &'static str {
    use hammer_wire::Duty;
    match cause {
        ResetCause::PowerOn => "power-on",
        ResetCause::Watchdog {
            overdue: Duty::Sampling,
        } => "watchdog: sampling",
        ResetCause::Watchdog { overdue: Duty::Link } => "watchdog: link",
        ResetCause::Watchdog {
            overdue: Duty::Persistence,
        } => "watchdog: persistence",
        ResetCause::Fault { .. } => "fault",
    }
}
