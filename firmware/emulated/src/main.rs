//! Board layer for the hammer monitor on QEMU's mps2-an386 (Cortex-M4F).
//!
//! Samples arrive the way the reference board's ADC + DMA deliver them: a
//! ring the host fills in the board's PSRAM, released half by half by a timer
//! at 100 kS/s of guest time (`adc.rs`, layout in `hammer_wire::stimulus`).
//! Started without that shared memory, the board takes `Samples` frames over
//! UART0 instead, which the tests use to inject gaps and corrupt frames.
//! UART0 carries commands and the device's reports either way. Everything
//! else is the hardware-independent `hammer_app`, unchanged: this lets the
//! complete firmware, executor and all, be tested without a board.
//!
//! Run it with `cargo run --release` from this directory (UART0 is then
//! QEMU's stdin/stdout, binary-clean) or, for a test harness, with UART0 on a
//! socket:
//! `qemu-system-arm -M mps2-an386 -nographic -monitor none -semihosting-config enable=on,target=native
//!  -serial tcp:127.0.0.1:PORT,server=on,wait=on -kernel hammer-firmware-emu`,
//! plus, for the full-rate samples, `-object memory-backend-file,id=stim,size=16M,mem-path=FILE,share=on
//! -machine memory-backend=stim` (`hammer demo` does all this).
//! A panic or fault exits QEMU with a failure status instead of hanging.
//!
//! QEMU hands this UART one byte per main-loop turn, which caps host-to-board
//! traffic at roughly 40 KB/s (about 7 kS/s of samples): the UART path runs
//! slower than real time, and nothing is lost.

#![no_std]
#![no_main]

mod adc;
mod clock;
mod executor;
mod nvm;
mod pacing;
#[path = "../../src/stack.rs"]
mod stack;
mod uart;
mod vectors;
mod watchdog;

use core::fmt::Write as _;

use cortex_m_rt::{entry, exception, ExceptionFrame};
use cortex_m_semihosting::debug;
use embassy_executor::raw;
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
use embassy_sync::zerocopy_channel;
use hammer_app::chambers::Block;
use hammer_app::{persisted, ChamberReader, LinkSamples, Monitor, Overrun, ReaderRoom, Record, SampleSource, Shared};
use hammer_estimator::RawSample;
use hammer_wire::{HostMsg, WearBlob};
use static_cell::{ConstStaticCell, StaticCell};

use crate::adc::{NoStimulus, StimulusAdc};
use crate::clock::SysTickClock;
use crate::pacing::Paced;
use crate::uart::{PanicWriter, UartRx, UartTx};

/// Reported in `Hello`, so a host can tell the emulator from real hardware.
const BOARD_NAME: &str = "qemu-mps2-an386";

type Mutex = CriticalSectionRawMutex;

/// `pub(crate)`: the watchdog's feeder reads the duties' check-ins.
pub(crate) static SHARED: Shared<Mutex> = Shared::new();
/// The monitor holds a ~40 KB capture buffer: a static, not a task's stack.
static MONITOR: StaticCell<Monitor> = StaticCell::new();
/// The chambers' reader's ring of kept codes, track and room (~36 KB),
/// built at link time: never on a stack.
static READER_ROOM: ConstStaticCell<ReaderRoom> = ConstStaticCell::new(ReaderRoom::new());
static READER: StaticCell<ChamberReader<&'static mut ReaderRoom>> = StaticCell::new();
/// The blocks the sampling task reads its samples into and the reader
/// takes them from: more than the reference board's 13
/// (`hammer_app::chambers::READER_BLOCKS`), because this core is paced at
/// 125 M instructions a second (the host's `Icount::m4_at_125_mips`), 1.36
/// times slower than the G474's 170 MHz, so the samples that arrive while
/// a cycle is read fill 1.36 times as many. Measured: a 4-bar hammer with a
/// 1.5 ms valve delay (48.9 ms cycles) filled all 13 and lost 28 blocks in
/// half a minute; with 20, at most 13 waited (`hammer soak --effect
/// valve_delay:tau_s=0.0015 --supply-bar 4`, docs/firmware.md).
pub(crate) const READER_BLOCKS: usize = 20;
static BLOCKS: ConstStaticCell<[Block; READER_BLOCKS]> = ConstStaticCell::new([Block::EMPTY; READER_BLOCKS]);
static BLOCK_CHANNEL: StaticCell<zerocopy_channel::Channel<'static, Mutex, Block>> = StaticCell::new();
type BlockSender = zerocopy_channel::Sender<'static, Mutex, Block>;
type BlockReceiver = zerocopy_channel::Receiver<'static, Mutex, Block>;
static CLOCK: StaticCell<SysTickClock> = StaticCell::new();
static EXECUTOR: StaticCell<raw::Executor> = StaticCell::new();

/// Where this run's samples come from, chosen once at boot.
enum Samples {
    Adc(StimulusAdc),
    Link(LinkSamples<'static, Mutex>),
}

impl SampleSource for Samples {
    async fn read(&mut self, buf: &mut [RawSample]) -> Result<usize, Overrun> {
        match self {
            Samples::Adc(adc) => adc.read(buf).await,
            Samples::Link(link) => link.read(buf).await,
        }
    }
}

#[embassy_executor::task]
async fn sampling(
    monitor: &'static mut Monitor,
    clock: &'static SysTickClock,
    samples: Samples,
    mut blocks: BlockSender,
) -> ! {
    let mut source = Paced::new(samples, &SHARED);
    hammer_app::sampling(&mut source, monitor, &SHARED, clock, &mut blocks).await
}

/// The chambers' reading at each cycle's close, in thread mode: below the
/// sampling task's interrupt-priority executor, which preempts it.
#[embassy_executor::task]
async fn reading(reader: &'static mut ChamberReader<&'static mut ReaderRoom>, mut blocks: BlockReceiver) -> ! {
    hammer_app::reading(reader, &SHARED, &mut blocks).await
}

#[embassy_executor::task]
async fn link_rx(mut rx: UartRx) -> ! {
    hammer_app::link_rx(&mut rx, &SHARED).await
}

#[embassy_executor::task]
async fn link_tx(mut tx: UartTx) -> ! {
    hammer_app::link_tx(&mut tx, &SHARED).await
}

#[embassy_executor::task]
async fn persistence() -> ! {
    hammer_app::persisting(&mut nvm::Nvm, &SHARED, || clock::next_tick(clock::Waiter::Persistence)).await
}

#[entry]
fn main() -> ! {
    let Some(core) = cortex_m::Peripherals::take() else {
        panic!("core peripherals taken twice");
    };
    let clock: &'static SysTickClock = CLOCK.init(SysTickClock::start(core.SYST));
    let (tx, rx) = uart::init();

    // The configuration stored before the last reset, if any and valid.
    let stored = nvm::load(Record::Config).and_then(|(rec, len)| persisted::config_from_record(&rec[..len], None));
    // `init_with` lets the compiler build the monitor in place: no stack
    // frame of its size (measured: the painted stack, src/stack.rs; a
    // fallback chain of `Result<Monitor, _>` here once took 33 KB of stack).
    // A stored configuration has passed the estimator's validation, and the
    // default one is valid, so the error arm is a programming error.
    let cfg = stored.unwrap_or_default();
    let monitor = MONITOR.init_with(|| match Monitor::new(cfg, BOARD_NAME) {
        Ok(m) => m,
        Err(_) => panic!("estimator configuration rejected after validation"),
    });
    // The wear state, through the command the host would use: validated alike.
    if let Some((bytes, len)) = nvm::load(Record::Wear) {
        if let Ok(bytes) = heapless::Vec::from_slice(&bytes[..len]) {
            monitor.on_command(HostMsg::RestoreWear(WearBlob { bytes }), 0, &mut |_| {});
        }
    }
    monitor.set_reset_cause(watchdog::take_reset_cause());
    watchdog::start();

    let (samples, idle) = match StimulusAdc::start() {
        Ok(adc) => (Samples::Adc(adc), executor::Idle::Spin),
        Err(NoStimulus::Absent) => (Samples::Link(LinkSamples::new(&SHARED)), executor::Idle::Sleep),
        Err(NoStimulus::Mismatch) => panic!("the host's sample stimulus has another layout than this firmware's"),
    };

    // Thread mode: everything but sampling (its pender context is null).
    let executor: &'static raw::Executor = EXECUTOR.init(raw::Executor::new(core::ptr::null_mut()));
    let spawner = executor.spawner();
    // Each task has a pool of one and is spawned once, so spawning cannot fail.
    // Sampling preempts thread mode, as on the reference board.
    let mut nvic = core.NVIC;
    let sampling_spawner = executor::start_sampling(&mut nvic);
    let (blocks_tx, blocks_rx) = BLOCK_CHANNEL
        .init(zerocopy_channel::Channel::new(BLOCKS.take()))
        .split();
    sampling_spawner.spawn(sampling(monitor, clock, samples, blocks_tx).expect("sampling task spawned once"));
    let reader = READER.init(ChamberReader::new(&cfg, READER_ROOM.take()));
    spawner.spawn(reading(reader, blocks_rx).expect("reading task spawned once"));
    spawner.spawn(link_rx(rx).expect("link_rx task spawned once"));
    spawner.spawn(link_tx(tx).expect("link_tx task spawned once"));
    spawner.spawn(persistence().expect("persistence task spawned once"));
    executor::run(executor, idle)
}

/// Reports on UART0 (after a frame delimiter, so a host's decoder drops any
/// half-sent frame and sees the text as one bad frame) and on semihosting
/// stderr, then ends QEMU with a failure status: a test sees a panic as an
/// exit code, never as a hang.
#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    cortex_m::interrupt::disable();
    let _ = write!(PanicWriter, "\0panic: {info}\r\n\0");
    cortex_m_semihosting::heprintln!("panic: {}", info);
    exit_failure()
}

/// Faults (a bad pointer, an undefined instruction) are recorded for the
/// next boot's status and reset the board, as on the reference board. The
/// third since QEMU started ends QEMU like a panic instead, so a fault at
/// boot cannot loop forever under a test.
#[exception]
unsafe fn HardFault(frame: &ExceptionFrame) -> ! {
    let _ = write!(PanicWriter, "\0hard fault at pc {:#010x}\r\n\0", frame.pc());
    cortex_m_semihosting::heprintln!("hard fault at pc {:#010x}", frame.pc());
    // SAFETY: CFSR (0xE000_ED28) is readable at any time.
    let cfsr = unsafe { core::ptr::read_volatile(0xE000_ED28 as *const u32) };
    watchdog::record(hammer_wire::ResetCause::Fault { pc: frame.pc(), cfsr });
    if watchdog::count_fault() >= 3 {
        exit_failure()
    }
    cortex_m::peripheral::SCB::sys_reset()
}

fn exit_failure() -> ! {
    exit_qemu(debug::EXIT_FAILURE)
}

/// Ends QEMU with `status` through semihosting.
pub(crate) fn exit_qemu(status: debug::ExitStatus) -> ! {
    debug::exit(status);
    // Returns only if a debugger took the semihosting request and let the
    // core run on; then stop here.
    loop {
        cortex_m::asm::wfi();
    }
}
