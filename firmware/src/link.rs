//! The telemetry link: USART2 on PA2 (TX) / PA3 (RX), which the Nucleo-64
//! routes to the ST-LINK's virtual COM port, so one USB cable carries power,
//! debug probe, defmt logs and telemetry.
//!
//! Both directions use DMA. Receive runs into a ring buffer that the DMA keeps
//! filling while the thread executor is busy (a flash erase, a burst of
//! frames to encode), so bytes are only lost if the ring itself overflows.

use core::sync::atomic::{AtomicU32, Ordering};

use defmt::warn;
use embassy_stm32::mode::Async;
use embassy_stm32::peripherals::{DMA1_CH2, DMA1_CH3, PA2, PA3, USART2};
use embassy_stm32::usart::{self, RingBufferedUartRx, Uart, UartTx};
use embassy_stm32::Peri;
use embassy_time::{Instant, Timer};
use hammer_app::{LinkRx, LinkTx};

use crate::Irqs;

/// The highest of the common PC rates. 170 MHz / 921 600 = 184.46, so the
/// USART's divider of 184 gives 923 913 Bd, 0.25 % fast: well inside what
/// a UART receiver tolerates (several percent at 16x oversampling).
pub const BAUD: u32 = 921_600;
/// Receive ring: 5.5 ms of back-to-back bytes at 921 600 Bd, more than the
/// largest frame (400 B); the host sends commands one at a time and waits
/// for the answer (this board takes no samples over the link), so this only
/// fills if the thread executor stalls, and a lost command is counted and
/// answered with a rejection.
pub const RX_RING: usize = 512;

/// Receive errors (framing, noise, overrun) since boot. The app counts the
/// frames these corrupt; this says why.
pub static RX_ERRORS: AtomicU32 = AtomicU32::new(0);
/// When the write in progress started (ms since boot, 0 = idle): a write
/// that never completes means a hung link, and the watchdog stops petting.
pub static TX_BUSY_SINCE_MS: AtomicU32 = AtomicU32::new(0);

pub struct Tx {
    uart: UartTx<'static, Async>,
}

pub struct Rx {
    uart: RingBufferedUartRx<'static>,
}

pub fn new(
    usart: Peri<'static, USART2>,
    tx_pin: Peri<'static, PA2>,
    rx_pin: Peri<'static, PA3>,
    tx_dma: Peri<'static, DMA1_CH2>,
    rx_dma: Peri<'static, DMA1_CH3>,
    rx_ring: &'static mut [u8; RX_RING],
) -> Result<(Tx, Rx), usart::ConfigError> {
    let mut config = usart::Config::default();
    config.baudrate = BAUD;
    let uart = Uart::new(usart, rx_pin, tx_pin, tx_dma, rx_dma, Irqs, config)?;
    let (tx, rx) = uart.split();
    Ok((
        Tx { uart: tx },
        Rx {
            uart: rx.into_ring_buffered(rx_ring),
        },
    ))
}

/// Milliseconds the current write has been under way, 0 when idle.
pub fn tx_busy_ms(now: Instant) -> u32 {
    match TX_BUSY_SINCE_MS.load(Ordering::Relaxed) {
        0 => 0,
        since => (now.as_millis() as u32).wrapping_sub(since),
    }
}

impl LinkTx for Tx {
    async fn write_all(&mut self, bytes: &[u8]) {
        TX_BUSY_SINCE_MS.store((Instant::now().as_millis() as u32).max(1), Ordering::Relaxed);
        if let Err(e) = self.uart.write(bytes).await {
            // A frame that did not go out whole is caught by the host's CRC.
            warn!("link: tx error {}", e);
        }
        TX_BUSY_SINCE_MS.store(0, Ordering::Relaxed);
    }
}

impl LinkRx for Rx {
    async fn read(&mut self, buf: &mut [u8]) -> usize {
        loop {
            match self.uart.read(buf).await {
                Ok(0) => {}
                Ok(n) => return n,
                Err(e) => {
                    // The driver has stopped reception; the next read restarts
                    // it. The bytes lost show up as a corrupt frame, which the
                    // app's decoder counts and resynchronises after.
                    RX_ERRORS.fetch_add(1, Ordering::Relaxed);
                    warn!("link: rx error {}", e);
                    // A line that produces nothing but errors (unplugged,
                    // wrong baud rate) must not keep the thread executor busy.
                    Timer::after_millis(1).await;
                }
            }
        }
    }
}
