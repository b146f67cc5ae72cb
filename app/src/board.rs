//! What a board provides. The app is written against these small traits only,
//! so it runs unchanged on the Nucleo-G474RE (ADC + DMA, ST-LINK UART), on the
//! QEMU mps2-an386 board (samples over the UART) and in host tests.

use hammer_estimator::RawSample;

/// Samples were lost before they reached the app (ADC/DMA overrun, a gap in
/// the stream): `lost` sample-sets. The app flags the cycle and counts them.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Overrun {
    pub lost: u32,
}

/// The three-channel sample stream, in blocks (a DMA half-buffer, a frame).
pub trait SampleSource {
    /// Fills `buf` from the front with the next sample-sets and returns how
    /// many; `Err` reports lost samples (the stream continues after them).
    /// Must be cancel-safe: dropping the future loses no samples.
    async fn read(&mut self, buf: &mut [RawSample]) -> Result<usize, Overrun>;

    /// Whether the source holds its samples while the app is busy, so the
    /// sampling task waits for a free block of the chambers' reader rather
    /// than read on past it. An ADC cannot: its DMA runs on, and a board
    /// within its budget never needs to (the emulated board measures that
    /// budget, so it does not wait either). The native board's link can: its
    /// host waits, and the host's own scheduling then costs no reading.
    fn holds_samples(&self) -> bool {
        false
    }
}

/// The byte link's transmit side (UART, USB VCP, a pipe in tests).
pub trait LinkTx {
    async fn write_all(&mut self, bytes: &[u8]);
}

/// The byte link's receive side: returns at least one byte.
pub trait LinkRx {
    async fn read(&mut self, buf: &mut [u8]) -> usize;
}

/// Monotonic time since boot.
pub trait Clock {
    fn now_us(&self) -> u64;
}

/// What a [`Store`] keeps.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Record {
    Wear,
    Config,
}

/// Where a board keeps state across resets (flash, the emulated board's
/// PSRAM). The calls report their own failures (a log line, a counter):
/// persistence must never stop the monitor.
pub trait Store {
    fn store_wear(&mut self, blob: &hammer_wire::WearBlob);
    /// `record`: [`crate::persisted::config_record`]'s bytes.
    fn store_config(&mut self, record: &[u8; crate::persisted::CONFIG_RECORD]);
    /// A record that could not even be made.
    fn failed(&mut self, what: Record);
}
