//! UART0 of the mps2-an386, an Arm CMSDK APB UART, as the app's byte link.
//!
//! Register map and behaviour follow QEMU's model (hw/char/cmsdk-apb-uart.c),
//! which is what this board runs on:
//! - QEMU offers the guest a byte only while RXFULL is clear and holds the
//!   rest in the chardev, so nothing is lost as long as DATA gets read. The RX
//!   interrupt therefore drains DATA into a bounded pipe, and when the pipe is
//!   full it stops reading (and masks itself) instead of dropping bytes: the
//!   host then simply waits, which is the back-pressure the link needs.
//! - TXFULL stays set only while QEMU's chardev cannot take more (a host not
//!   reading its socket); a writer then sleeps on the TX interrupt.

use core::future::poll_fn;
use core::ptr::{read_volatile, write_volatile};
use core::sync::atomic::{AtomicBool, Ordering};
use core::task::Poll;

use cortex_m::peripheral::NVIC;
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
use embassy_sync::pipe::Pipe;
use embassy_sync::waitqueue::AtomicWaker;

use crate::clock::SYSCLK_HZ;
use crate::vectors::Interrupt;

/// UART0's base address (hw/arm/mps2.c, `uartbase[0]`); QEMU's serial port 0.
const BASE: usize = 0x4000_4000;

// Register offsets and bits (CMSDK APB UART; ARM DDI0479C).
const DATA: usize = 0x00;
const STATE: usize = 0x04;
const CTRL: usize = 0x08;
/// INTSTATUS on read, INTCLEAR (write one to clear) on write.
const INTSTATUS: usize = 0x0c;
const BAUDDIV: usize = 0x10;

const STATE_TXFULL: u32 = 1 << 0;
const STATE_RXFULL: u32 = 1 << 1;
const CTRL_TX_EN: u32 = 1 << 0;
const CTRL_RX_EN: u32 = 1 << 1;
const CTRL_TX_INTEN: u32 = 1 << 2;
const CTRL_RX_INTEN: u32 = 1 << 3;
const INT_TX: u32 = 1 << 0;
const INT_RX: u32 = 1 << 1;

/// QEMU ignores the rate, but it only accepts a divider of at least 16 and
/// logs a guest error when TX is enabled without one; 115200 Bd is the
/// conventional choice.
const BAUD: u32 = 115_200;

/// Received bytes waiting for `link_rx`: two maximum-size frames, so the
/// interrupt can keep draining while the app decodes one.
const RX_BUFFER: usize = 2 * hammer_wire::MAX_FRAME;

static RX_PIPE: Pipe<CriticalSectionRawMutex, RX_BUFFER> = Pipe::new();
/// Set by the RX interrupt when it left a byte in DATA for lack of room and
/// masked itself; the reader unmasks it once it has made room.
static RX_PAUSED: AtomicBool = AtomicBool::new(false);
static TX_WAKER: AtomicWaker = AtomicWaker::new();

fn read(offset: usize) -> u32 {
    // SAFETY: BASE + offset is one of UART0's 32-bit registers on this board;
    // reading it has no effect beyond the device's documented ones.
    unsafe { read_volatile((BASE + offset) as *const u32) }
}

fn write(offset: usize, value: u32) {
    // SAFETY: as in `read`; writes go only to the registers named above.
    unsafe { write_volatile((BASE + offset) as *mut u32, value) }
}

/// CTRL is changed by the tasks and by both interrupts; a critical section
/// keeps each read-modify-write whole.
fn modify_ctrl(f: impl FnOnce(u32) -> u32) {
    critical_section::with(|_| write(CTRL, f(read(CTRL))));
}

/// UART0's transmit side. Only one exists (see [`init`]).
pub struct UartTx {
    _private: (),
}

/// UART0's receive side. Only one exists (see [`init`]).
pub struct UartRx {
    _private: (),
}

/// Configures UART0 (8N1 is fixed in this UART) and unmasks its interrupts,
/// at their reset priority: nothing on this board needs to preempt them.
///
/// Call once, at boot: the halves it returns share the statics above.
pub fn init() -> (UartTx, UartRx) {
    write(BAUDDIV, SYSCLK_HZ / BAUD);
    write(INTSTATUS, INT_TX | INT_RX);
    write(CTRL, CTRL_TX_EN | CTRL_RX_EN | CTRL_RX_INTEN);
    // SAFETY: the handlers and their shared state (RX_PIPE, RX_PAUSED,
    // TX_WAKER) are interrupt-safe, and nothing here relies on a critical
    // section being free of these interrupts.
    unsafe {
        NVIC::unmask(Interrupt::Uart0Rx);
        NVIC::unmask(Interrupt::Uart0Tx);
    }
    (UartTx { _private: () }, UartRx { _private: () })
}

impl hammer_app::LinkRx for UartRx {
    async fn read(&mut self, buf: &mut [u8]) -> usize {
        if buf.is_empty() {
            return 0;
        }
        let n = RX_PIPE.read(buf).await;
        if RX_PAUSED.swap(false, Ordering::AcqRel) {
            // There is room now. Re-enabling RX_INTEN alone would not raise
            // the interrupt for the byte already waiting in DATA (QEMU sets
            // the RX status only when a byte arrives), so pend it by hand.
            modify_ctrl(|c| c | CTRL_RX_INTEN);
            NVIC::pend(Interrupt::Uart0Rx);
        }
        n
    }
}

impl hammer_app::LinkTx for UartTx {
    async fn write_all(&mut self, bytes: &[u8]) {
        for &b in bytes {
            poll_fn(|cx| {
                if read(STATE) & STATE_TXFULL == 0 {
                    write(DATA, u32::from(b));
                    return Poll::Ready(());
                }
                TX_WAKER.register(cx.waker());
                // The interrupt fires on TXFULL going clear, so it must be
                // enabled before looking again, or that edge could be missed.
                modify_ctrl(|c| c | CTRL_TX_INTEN);
                if read(STATE) & STATE_TXFULL == 0 {
                    write(DATA, u32::from(b));
                    return Poll::Ready(());
                }
                Poll::Pending
            })
            .await;
        }
    }
}

/// UART0 RX interrupt (IRQ 0): moves received bytes into [`RX_PIPE`].
pub extern "C" fn on_rx_interrupt() {
    // Clear first, then drain: a byte arriving after the clear raises the
    // status again, whereas clearing after the drain could swallow the
    // status of a byte that arrived in between and leave it stuck in DATA.
    write(INTSTATUS, INT_RX);
    while read(STATE) & STATE_RXFULL != 0 {
        if RX_PIPE.is_full() {
            modify_ctrl(|c| c & !CTRL_RX_INTEN);
            RX_PAUSED.store(true, Ordering::Release);
            return;
        }
        let b = read(DATA) as u8;
        // Cannot fail: the pipe had room and only this handler writes it.
        let _ = RX_PIPE.try_write(&[b]);
    }
}

/// UART0 TX interrupt (IRQ 1): the transmitter has room again.
pub extern "C" fn on_tx_interrupt() {
    modify_ctrl(|c| c & !CTRL_TX_INTEN);
    write(INTSTATUS, INT_TX);
    TX_WAKER.wake();
}

/// Writes straight to the UART, for the panic and fault handlers only: it
/// polls instead of awaiting, and gives up on a byte after a bounded wait so
/// that a wedged link cannot keep the caller from exiting QEMU.
pub struct PanicWriter;

impl core::fmt::Write for PanicWriter {
    fn write_str(&mut self, s: &str) -> core::fmt::Result {
        modify_ctrl(|c| c | CTRL_TX_EN);
        for &b in s.as_bytes() {
            let mut spins = 0u32;
            while read(STATE) & STATE_TXFULL != 0 && spins < 100_000 {
                spins += 1;
            }
            write(DATA, u32::from(b));
        }
        Ok(())
    }
}
