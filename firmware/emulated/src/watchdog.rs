//! The supervised watchdog, and the reset cause kept across a reset.
//!
//! The mps2-an386's CMSDK APB watchdog (0x4000_8000, clocked by SYSCLK; QEMU
//! wires its interrupt to the NMI): the counter runs down from LOAD; at zero
//! it raises its interrupt and reloads; at zero again with the interrupt
//! still raised it resets the board. The SysTick exception (every 100 ms)
//! feeds it, clearing the interrupt, which also reloads the counter, only
//! while every supervised duty has checked in (`hammer_app::Watch`). A duty
//! that goes quiet is recorded as the cause first, in RAM the startup code
//! leaves alone, so the board can say after the reset why it happened.
//!
//! The timeouts are generous (1 s to the interrupt, 1 s more to the reset):
//! without `-icount`, guest time is the host's, and a loaded host can stall
//! QEMU for a moment; a watchdog must not mistake that for a hung board.

use core::cell::RefCell;
use core::mem::MaybeUninit;
use core::ptr::{addr_of, addr_of_mut, read_volatile, write_volatile};
use core::sync::atomic::{AtomicBool, Ordering};

use critical_section::Mutex;
use hammer_app::{reset, Watch};
use hammer_wire::ResetCause;

use crate::clock::SYSCLK_HZ;

const BASE: usize = 0x4000_8000;
const LOAD: usize = 0x000;
const CONTROL: usize = 0x008;
/// Writing clears the interrupt and reloads the counter.
const INTCLR: usize = 0x00c;
const LOCK: usize = 0xc00;
const UNLOCK: u32 = 0x1ACC_E551;
const CONTROL_INTEN: u32 = 1 << 0;
const CONTROL_RESEN: u32 = 1 << 1;
/// One second of SYSCLK to the interrupt (and one more to the reset).
const TIMEOUT_CLOCKS: u32 = SYSCLK_HZ;

/// In SysTick periods (100 ms): the sampling loop turns at least every
/// 100 ms (its idle tick) and must have within 0.5 s; the link sends a
/// status every second and must have within 3 s; persistence checks in at
/// every tick and must have within 3 s.
static WATCH: Mutex<RefCell<Watch>> = Mutex::new(RefCell::new(Watch::new([Some(5), Some(30), Some(30)])));

/// A quiet duty has been recorded and the watchdog is no longer fed.
static STARVING: AtomicBool = AtomicBool::new(false);

/// The reset cause, in `.uninit`: neither zeroed nor initialised at boot.
#[link_section = ".uninit.hammer_reset_cause"]
static mut RECORD: MaybeUninit<[u32; reset::WORDS]> = MaybeUninit::uninit();

fn write(offset: usize, value: u32) {
    // SAFETY: the watchdog's registers on this board; written only here.
    unsafe { write_volatile((BASE + offset) as *mut u32, value) }
}

/// Writes the registers behind the lock, then locks them again.
fn unlocked(f: impl FnOnce()) {
    write(LOCK, UNLOCK);
    f();
    write(LOCK, 0);
}

/// Faults since QEMU started, in `.uninit` beside a magic word (QEMU starts
/// with RAM zeroed, and a reset leaves it alone).
#[link_section = ".uninit.hammer_faults"]
static mut FAULTS: MaybeUninit<[u32; 2]> = MaybeUninit::uninit();
const FAULTS_MAGIC: u32 = 0xFA17_C0DE;

/// Counts a fault and returns how many there have been since QEMU started.
pub fn count_fault() -> u32 {
    critical_section::with(|_| {
        // Plain RAM, only accessed here, with interrupts masked.
        let p = addr_of_mut!(FAULTS) as *mut u32;
        // SAFETY: both words inside FAULTS; any bits are valid u32s.
        unsafe {
            let n = if read_volatile(p) == FAULTS_MAGIC {
                read_volatile(p.add(1)).saturating_add(1)
            } else {
                1
            };
            write_volatile(p, FAULTS_MAGIC);
            write_volatile(p.add(1), n);
            n
        }
    })
}

/// Records `cause` for the next boot.
pub fn record(cause: ResetCause) {
    let words = reset::encode(cause);
    critical_section::with(|_| {
        // RECORD is plain RAM, accessed only inside critical sections (this,
        // `take_reset_cause`) and by the fault handler, which never returns.
        let p = addr_of_mut!(RECORD) as *mut u32;
        for (i, w) in words.into_iter().enumerate() {
            // SAFETY: i < WORDS, inside RECORD.
            unsafe { write_volatile(p.add(i), w) };
        }
    });
}

/// The cause the last run recorded (a power-on if none), and forgets it.
pub fn take_reset_cause() -> ResetCause {
    let mut words = [0u32; reset::WORDS];
    critical_section::with(|_| {
        // As in `record`; any bits are valid u32s.
        let p = addr_of!(RECORD) as *const u32;
        for (i, w) in words.iter_mut().enumerate() {
            // SAFETY: i < WORDS, inside RECORD.
            *w = unsafe { read_volatile(p.add(i)) };
        }
    });
    record(ResetCause::PowerOn);
    reset::decode(words)
}

/// Starts the watchdog. From here on the board resets unless fed.
pub fn start() {
    unlocked(|| {
        write(LOAD, TIMEOUT_CLOCKS);
        write(INTCLR, 1);
        write(CONTROL, CONTROL_INTEN | CONTROL_RESEN);
    });
}

/// From the SysTick exception: feeds the watchdog while every duty is alive;
/// otherwise records the quiet duty as the reason for the coming reset.
pub fn on_tick() {
    let verdict = critical_section::with(|cs| WATCH.borrow(cs).borrow_mut().tick(&crate::SHARED.supervisor));
    match verdict {
        Ok(()) => {
            unlocked(|| write(INTCLR, 1));
            if STARVING.swap(false, Ordering::Relaxed) {
                // The duty came back before the watchdog struck.
                record(ResetCause::PowerOn);
            }
        }
        Err(overdue) => {
            if !STARVING.swap(true, Ordering::Relaxed) {
                record(ResetCause::Watchdog { overdue });
            }
        }
    }
}

/// The watchdog's first strike (its interrupt is the NMI): the cause is
/// already recorded, and its second strike resets the board.
///
/// SAFETY (cortex-m-rt's requirement for an NMI handler): it touches nothing.
#[cortex_m_rt::exception]
unsafe fn NonMaskableInt() {}
