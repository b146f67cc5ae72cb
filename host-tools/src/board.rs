//! The firmware's app running natively on the host, for machines without
//! QEMU: the same `hammer-app` tasks, each on its own thread, talking over a
//! local socket pair exactly as the emulated board talks over its UART.

use std::io::{Read, Write};
use std::os::unix::net::UnixStream;
use std::time::Instant;

use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
use hammer_app::{Clock, LinkRx, LinkSamples, LinkTx, Monitor, Overrun, SampleSource, Shared};
use hammer_estimator::RawSample;

struct HostClock(Instant);

impl Clock for HostClock {
    fn now_us(&self) -> u64 {
        self.0.elapsed().as_micros() as u64
    }
}

/// The link's samples, held by the host while the chambers' reader catches
/// up. The reader's thread may wait its turn on a busy machine for longer
/// than its blocks last; a real board's budget is measured on the emulated
/// one, so here the host's scheduling costs no chamber reading.
struct HostSamples<'a>(LinkSamples<'a, CriticalSectionRawMutex>);

impl SampleSource for HostSamples<'_> {
    async fn read(&mut self, buf: &mut [RawSample]) -> Result<usize, Overrun> {
        self.0.read(buf).await
    }

    fn holds_samples(&self) -> bool {
        true
    }
}

struct SocketRx(UnixStream);
struct SocketTx(UnixStream);

impl LinkRx for SocketRx {
    async fn read(&mut self, buf: &mut [u8]) -> usize {
        // A dedicated thread: blocking here blocks nothing else. A closed
        // host end parks the task for good, like an unplugged UART.
        loop {
            match self.0.read(buf) {
                Ok(0) | Err(_) => std::thread::park(),
                Ok(n) => return n,
            }
        }
    }
}

impl LinkTx for SocketTx {
    async fn write_all(&mut self, bytes: &[u8]) {
        // Nobody listening: the bytes are lost, as on a UART with no host.
        let _ = self.0.write_all(bytes);
    }
}

/// Starts the app on background threads and returns the host end of its link.
/// The board lives until the process ends.
pub fn start_native_board(cfg: hammer_estimator::Config) -> std::io::Result<UnixStream> {
    let (host, device) = UnixStream::pair()?;
    let shared: &'static Shared<CriticalSectionRawMutex> = Box::leak(Box::new(Shared::new()));
    let monitor = Monitor::new(cfg, "native-host")
        .map_err(|e| std::io::Error::new(std::io::ErrorKind::InvalidInput, format!("{e}")))?;
    let mut rx = SocketRx(device.try_clone()?);
    let mut tx = SocketTx(device);
    let mut monitor = Box::new(monitor);
    let mut reader = hammer_app::ChamberReader::new(&cfg, Box::<hammer_app::ReaderRoom>::default());
    let blocks: &'static mut [hammer_app::chambers::Block] =
        Box::leak(vec![hammer_app::chambers::Block::EMPTY; hammer_app::chambers::READER_BLOCKS].into_boxed_slice());
    let channel = Box::leak(Box::new(embassy_sync::zerocopy_channel::Channel::<
        CriticalSectionRawMutex,
        _,
    >::new(blocks)));
    let (mut blocks_tx, mut blocks_rx) = channel.split();
    std::thread::Builder::new()
        .name("board-sampling".into())
        .spawn(move || {
            let clock = HostClock(Instant::now());
            let mut source = HostSamples(LinkSamples::new(shared));
            futures::executor::block_on(hammer_app::sampling(
                &mut source,
                &mut monitor,
                shared,
                &clock,
                &mut blocks_tx,
            ))
        })?;
    std::thread::Builder::new()
        .name("board-chambers".into())
        .spawn(move || futures::executor::block_on(hammer_app::reading(&mut reader, shared, &mut blocks_rx)))?;
    std::thread::Builder::new()
        .name("board-link-rx".into())
        .spawn(move || futures::executor::block_on(hammer_app::link_rx(&mut rx, shared)))?;
    std::thread::Builder::new()
        .name("board-link-tx".into())
        .spawn(move || futures::executor::block_on(hammer_app::link_tx(&mut tx, shared)))?;
    Ok(host)
}
