//! Board layer for the hammer monitor on the Nucleo-G474RE (STM32G474RE).
//!
//! This binary stays thin: it owns what is specific to this board — clock
//! tree, pins, the sampling chain's timer/ADC/DMA, the link's USART, flash
//! layout, watchdog and interrupt priorities — and runs the
//! hardware-independent app (`hammer-app`) on top of it. Pin map, real-time
//! budget and design notes: docs/firmware.md.
//!
//! Two executors, so telemetry can never starve the DSP:
//! - an interrupt executor on the otherwise unused UART4 vector, priority 6,
//!   runs the app's `sampling` task (estimator, commands, reports);
//! - the thread executor runs the link tasks, the watchdog and the LED.
//!
//! Hardware interrupt handlers (DMA, USART2, the time base) stay at priority
//! 0 and only wake tasks, so they preempt the DSP only briefly.

#![no_std]
#![no_main]

mod clock;
mod link;
mod panic;
mod persist;
mod reset;
mod sampler;
mod stack;
mod supply;

use defmt::{error, info, unwrap, warn};
use defmt_rtt as _;
use embassy_executor::{InterruptExecutor, Spawner};
use embassy_stm32::gpio::{Level, Output, Speed};
use embassy_stm32::interrupt;
use embassy_stm32::interrupt::{InterruptExt, Priority};
use embassy_stm32::peripherals::{self, IWDG};
use embassy_stm32::wdg::IndependentWatchdog;
use embassy_stm32::{bind_interrupts, dma, pac, usart, Config};
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
use embassy_sync::zerocopy_channel;
use embassy_time::{Duration, Instant, Ticker, Timer};
use hammer_app::chambers::{Block, READER_BLOCKS};
use hammer_app::{persisted, ChamberReader, Monitor, ReaderRoom, Shared};
use hammer_estimator::wear::WEAR_STATE_BYTES;
use hammer_estimator::ConfigError;
use hammer_wire::{DeviceMsg, HostMsg, WearBlob};
use static_cell::{ConstStaticCell, StaticCell};

use crate::clock::BoardClock;
use crate::sampler::Sampler;

/// Reported to the host in `Hello`.
const BOARD_NAME: &str = "nucleo-g474re";
/// Per-channel sample rate; `sampler` accepts 20 000 to 200 000.
const SAMPLE_RATE_HZ: u32 = 100_000;
const _: () = assert!(SAMPLE_RATE_HZ >= sampler::MIN_RATE_HZ && SAMPLE_RATE_HZ <= sampler::MAX_RATE_HZ);

/// IWDG timeout. Long enough for a page erase (~22 ms) and boot, short
/// enough that a hung board is back within about a second.
const WATCHDOG_TIMEOUT_US: u32 = 1_000_000;
/// How often the watchdog task checks liveness and pets.
const WATCHDOG_CHECK: Duration = Duration::from_millis(250);
/// No new sample block, or one link write, for this long counts as hung.
const STALL_LIMIT: Duration = Duration::from_millis(500);

/// Blink half-period; one full on/off cycle per second is easy to tell apart
/// from a hung board (LED stuck) or a wrong clock (visibly fast or slow).
const HEARTBEAT_HALF_PERIOD: Duration = Duration::from_millis(500);

bind_interrupts!(struct Irqs {
    DMA1_CHANNEL1 => dma::InterruptHandler<peripherals::DMA1_CH1>;
    DMA1_CHANNEL2 => dma::InterruptHandler<peripherals::DMA1_CH2>;
    DMA1_CHANNEL3 => dma::InterruptHandler<peripherals::DMA1_CH3>;
    USART2 => usart::InterruptHandler<peripherals::USART2>;
});

static SHARED: Shared<CriticalSectionRawMutex> = Shared::new();
/// ~40 KB with its capture buffer: far too big for a task's stack frame.
static MONITOR: StaticCell<Monitor> = StaticCell::new();
/// The chambers' reader's ring of kept codes, track and room (~36 KB,
/// `hammer_app::chambers`), built at link time: never on a stack.
static READER_ROOM: ConstStaticCell<ReaderRoom> = ConstStaticCell::new(ReaderRoom::new());
static READER: StaticCell<ChamberReader<&'static mut ReaderRoom>> = StaticCell::new();
/// The blocks the sampling task reads the ADC's samples into and the
/// reader takes them from (~7.7 KB, `hammer_app::chambers::READER_BLOCKS`).
static BLOCKS: ConstStaticCell<[Block; READER_BLOCKS]> = ConstStaticCell::new([Block::EMPTY; READER_BLOCKS]);
static BLOCK_CHANNEL: StaticCell<zerocopy_channel::Channel<'static, CriticalSectionRawMutex, Block>> =
    StaticCell::new();
type BlockSender = zerocopy_channel::Sender<'static, CriticalSectionRawMutex, Block>;
type BlockReceiver = zerocopy_channel::Receiver<'static, CriticalSectionRawMutex, Block>;
static ADC_RING: StaticCell<[u16; sampler::DMA_WORDS]> = StaticCell::new();
static UART_RX_RING: StaticCell<[u8; link::RX_RING]> = StaticCell::new();

static DSP_EXECUTOR: InterruptExecutor = InterruptExecutor::new();

#[interrupt]
unsafe fn UART4() {
    // SAFETY: this vector is used by nothing else, and the executor was
    // started before the interrupt was unmasked (`InterruptExecutor::start`).
    unsafe { DSP_EXECUTOR.on_interrupt() }
}

/// Clock tree for 170 MHz SYSCLK, the G474's maximum, from the internal HSI16.
///
/// HSI16 needs nothing fitted on the board, so the same bring-up works on the
/// Nucleo and on a custom carrier; its ~1 % accuracy is plenty until something
/// needs a precise clock (USB, CAN bit timing), at which point an HSE source
/// belongs here. The sample rate and the time base share this oscillator, so
/// its error scales both alike and sample timing stays self-consistent.
///
/// PLL: 16 MHz / 4 = 4 MHz input (inside the 2.66–16 MHz window),
/// x85 = 340 MHz VCO (inside 96–344 MHz), / 2 = 170 MHz on PLLR.
/// Above 150 MHz the core regulator must be in Range 1 boost mode, which
/// embassy only switches on when asked.
fn clock_config() -> Config {
    use embassy_stm32::rcc::{mux, AHBPrescaler, APBPrescaler, Pll, PllMul, PllPreDiv, PllRDiv, PllSource, Sysclk};

    let mut config = Config::default();
    config.rcc.hsi = true;
    config.rcc.pll = Some(Pll {
        source: PllSource::HSI,
        prediv: PllPreDiv::DIV4,
        mul: PllMul::MUL85,
        divp: None,
        divq: None,
        divr: Some(PllRDiv::DIV2),
    });
    config.rcc.sys = Sysclk::PLL1_R;
    config.rcc.boost = true;
    // Buses at full speed: the timers then also run at 170 MHz, which the
    // 1 MHz time base and the 100 kS/s sample clock both divide exactly.
    config.rcc.ahb_pre = AHBPrescaler::DIV1;
    config.rcc.apb1_pre = APBPrescaler::DIV1;
    config.rcc.apb2_pre = APBPrescaler::DIV1;
    // The ADC kernel clock is off after reset. SYSCLK / 4 (the prescaler the
    // driver picks to stay under 60 MHz) = 42.5 MHz.
    config.rcc.mux.adc12sel = mux::Adcsel::SYS;
    // ADC4 measures VREFINT (supply.rs).
    config.rcc.mux.adc345sel = mux::Adcsel::SYS;
    config
}

/// The app's sample → estimator → report loop, at interrupt priority.
#[embassy_executor::task]
async fn sampling(mut source: Sampler, monitor: &'static mut Monitor, mut blocks: BlockSender) {
    hammer_app::sampling(&mut source, monitor, &SHARED, &BoardClock, &mut blocks).await
}

/// The chambers' reading at each cycle's close, in thread mode: below the
/// sampling task, which preempts it from its interrupt executor.
#[embassy_executor::task]
async fn reading(reader: &'static mut ChamberReader<&'static mut ReaderRoom>, mut blocks: BlockReceiver) {
    hammer_app::reading(reader, &SHARED, &mut blocks).await
}

#[embassy_executor::task]
async fn link_rx(mut rx: link::Rx) {
    hammer_app::link_rx(&mut rx, &SHARED).await
}

#[embassy_executor::task]
async fn link_tx(mut tx: link::Tx) {
    hammer_app::link_tx(&mut tx, &SHARED).await
}

/// Pets the IWDG only while the board is demonstrably working: this task
/// runs (the thread executor is not starved by a runaway DSP or a spinning
/// link task), sample blocks keep arriving (the sampling chain has not
/// stalled beyond its own recovery), no link write is stuck, and every
/// supervised duty (sampling loop, link, persistence) has checked in within
/// its period (`hammer_app::Watch`). A board that fails any of these records
/// which duty failed (`reset`) and resets within STALL_LIMIT + WATCHDOG_TIMEOUT.
#[embassy_executor::task]
async fn watchdog(mut wdg: IndependentWatchdog<'static, IWDG>, persisting: bool) {
    let mut last_blocks = sampler::BLOCKS.load(core::sync::atomic::Ordering::Relaxed);
    let mut last_progress = Instant::now();
    // In WATCHDOG_CHECK periods (250 ms): sampling 0.5 s, link and persistence 3 s.
    let mut watch = hammer_app::Watch::new([Some(2), Some(12), persisting.then_some(12)]);
    let mut reported = false;
    let mut checks = 0u32;
    loop {
        Timer::after(WATCHDOG_CHECK).await;
        // The stack's high-water mark for `Status`: a whole pass once a
        // second (thread mode: the sampling executor preempts it).
        if checks % 4 == 0 {
            stack::scan_step(usize::MAX);
        }
        checks = checks.wrapping_add(1);
        let now = Instant::now();
        let blocks = sampler::BLOCKS.load(core::sync::atomic::Ordering::Relaxed);
        if blocks != last_blocks {
            last_blocks = blocks;
            last_progress = now;
        }
        let dsp_ok = now - last_progress < STALL_LIMIT;
        let link_ok = (link::tx_busy_ms(now) as u64) < STALL_LIMIT.as_millis();
        let duties = watch.tick(&SHARED.supervisor);
        let overdue = match (dsp_ok, link_ok, duties) {
            (true, true, Ok(())) => None,
            (false, _, _) => Some(hammer_app::Duty::Sampling),
            (_, false, _) => Some(hammer_app::Duty::Link),
            (_, _, Err(duty)) => Some(duty),
        };
        match overdue {
            None => {
                wdg.pet();
                if reported {
                    reset::record(hammer_wire::ResetCause::PowerOn);
                }
                reported = false;
            }
            Some(duty) if !reported => {
                reset::record(hammer_wire::ResetCause::Watchdog { overdue: duty });
                error!(
                    "watchdog: {=str} stopped checking in: letting the IWDG reset the board",
                    reset::name(hammer_wire::ResetCause::Watchdog { overdue: duty })
                );
                reported = true;
            }
            Some(_) => {}
        }
    }
}

/// A fault is recorded for the next boot's status, then the board resets.
#[cortex_m_rt::exception]
unsafe fn HardFault(frame: &cortex_m_rt::ExceptionFrame) -> ! {
    // SAFETY: CFSR (0xE000_ED28) is readable at any time.
    let cfsr = unsafe { core::ptr::read_volatile(0xE000_ED28 as *const u32) };
    reset::record(hammer_wire::ResetCause::Fault { pc: frame.pc(), cfsr });
    cortex_m::peripheral::SCB::sys_reset()
}

/// VDDA for `Status`, once a second (supply.rs).
#[embassy_executor::task]
async fn measure_supply(supply: supply::Supply) {
    supply.run(&SHARED).await
}

/// Visible proof of life, independent of the link.
#[embassy_executor::task]
async fn heartbeat(mut led: Output<'static>) {
    let mut ticker = Ticker::every(HEARTBEAT_HALF_PERIOD);
    loop {
        led.toggle();
        ticker.next().await;
    }
}

/// Hands the wear state saved before the last reset to the monitor, through
/// the same command the host would use, so it is validated the same way.
/// Returns the store for the task that keeps saving it.
fn restore_wear(monitor: &mut Monitor, store: Option<persist::Persist>) -> Option<persist::Persist> {
    let mut store = store?;
    match store.load::<WEAR_STATE_BYTES>(&persist::WEAR) {
        None => info!("persist: no stored wear state"),
        Some(bytes) => {
            if let Ok(bytes) = heapless::Vec::from_slice(&bytes) {
                monitor.on_command(HostMsg::RestoreWear(WearBlob { bytes }), 0, &mut |reply| match reply {
                    DeviceMsg::Ack(_) => info!("persist: wear state restored"),
                    _ => warn!("persist: stored wear state rejected by the monitor"),
                });
            }
        }
    }
    Some(store)
}

/// The configuration saved before the last reset (calibration, tare, thresholds),
/// if there is one the estimator accepts. The sample rate stays the board's:
/// TIM6 is set at build time.
fn stored_config(store: &mut persist::Persist, rate_hz: f32) -> Option<hammer_estimator::Config> {
    let rec = store.load::<{ persisted::CONFIG_RECORD }>(&persist::CONFIG)?;
    let cfg = persisted::config_from_record(&rec, Some(rate_hz));
    if cfg.is_none() {
        warn!("persist: stored configuration rejected, using defaults");
    }
    cfg
}

/// The flash store as the app's `Store`, logging over defmt.
struct FlashStore(persist::Persist);

impl hammer_app::Store for FlashStore {
    fn store_wear(&mut self, blob: &WearBlob) {
        match self.0.store(&persist::WEAR, &blob.bytes) {
            Ok(()) => info!("persist: wear state saved"),
            Err(_) => warn!("persist: saving the wear state failed"),
        }
    }

    fn store_config(&mut self, record: &[u8; persisted::CONFIG_RECORD]) {
        match self.0.store(&persist::CONFIG, record) {
            Ok(()) => info!("persist: configuration saved"),
            Err(_) => warn!("persist: saving the configuration failed"),
        }
    }

    fn failed(&mut self, _: hammer_app::Record) {
        warn!("persist: configuration does not fit a record");
    }
}

/// Saves what the app hands over: the wear state every few thousand cycles
/// (`hammer_app::tasks::WEAR_SAVE_CYCLES`) and the configuration when it
/// changes. Thread mode: a page erase stalls only this task, the sampling
/// executor preempts it, and bank 2 is written while the code runs from bank 1.
#[embassy_executor::task]
async fn persist_state(store: persist::Persist) {
    let mut store = FlashStore(store);
    hammer_app::persisting(&mut store, &SHARED, || Timer::after(Duration::from_secs(1))).await
}

#[embassy_executor::main]
async fn main(spawner: Spawner) {
    let p = embassy_stm32::init(clock_config());
    info!("hammer-firmware {} up, SYSCLK 170 MHz", env!("CARGO_PKG_VERSION"));

    // First, so a hang anywhere below is caught too. Frozen while a debugger
    // halts the core; without a debugger the freeze bit has no effect.
    pac::DBGMCU.apb1lfzr().modify(|w| w.set_iwdg(true));
    let mut wdg = IndependentWatchdog::new(p.IWDG, WATCHDOG_TIMEOUT_US);
    wdg.unleash();

    let pins = sampler::Pins {
        rear: p.PA0,
        front: p.PA1,
        accel: p.PB0,
    };
    let source = Sampler::new(
        p.ADC1,
        p.TIM6,
        p.DMA1_CH1,
        pins,
        ADC_RING.init([0; sampler::DMA_WORDS]),
        SAMPLE_RATE_HZ,
    );

    let mut store = persist::Persist::new(p.FLASH);
    let cfg = store
        .as_mut()
        .and_then(|s| stored_config(s, source.rate_hz()))
        .unwrap_or(hammer_estimator::Config {
            sample_rate_hz: source.rate_hz(),
            ..Default::default()
        });
    let monitor = MONITOR.init_with(|| match Monitor::new(cfg, BOARD_NAME) {
        Ok(m) => m,
        // The configuration is a constant of this build, not data: a
        // rejection is a programming error, caught on the first boot.
        // Its fields go to defmt as they are (formatted on the host): core's
        // float formatting, ~10 KB of flash, stays out of the image.
        Err(ConfigError::OutOfRange { field, value, min, max }) => defmt::panic!(
            "estimator rejects the board's default configuration: {=str} = {} is outside {} ..= {}",
            field,
            value,
            min,
            max
        ),
        Err(ConfigError::PeriodTooLongForMemory { max_period_s, limit_s }) => defmt::panic!(
            "estimator rejects the board's default configuration: max_period_s = {} over the checkpoint memory's {} s",
            max_period_s,
            limit_s
        ),
    });
    let store = restore_wear(monitor, store);
    let cause = reset::take_cause();
    info!("reset cause: {=str}", reset::name(cause));
    monitor.set_reset_cause(cause);

    let (tx, rx) = unwrap!(link::new(
        p.USART2,
        p.PA2,
        p.PA3,
        p.DMA1_CH2,
        p.DMA1_CH3,
        UART_RX_RING.init([0; link::RX_RING])
    ));
    info!("link: USART2 {} Bd on the ST-LINK VCP", link::BAUD);

    // The priority must be set before `start`, which unmasks the interrupt.
    interrupt::UART4.set_priority(Priority::P6);
    let dsp = DSP_EXECUTOR.start(interrupt::UART4);
    let (blocks_tx, blocks_rx) = BLOCK_CHANNEL
        .init(zerocopy_channel::Channel::new(BLOCKS.take()))
        .split();
    dsp.spawn(unwrap!(sampling(source, monitor, blocks_tx)));

    let reader = READER.init(ChamberReader::new(&cfg, READER_ROOM.take()));
    spawner.spawn(unwrap!(reading(reader, blocks_rx)));
    spawner.spawn(unwrap!(link_rx(rx)));
    spawner.spawn(unwrap!(link_tx(tx)));
    spawner.spawn(unwrap!(watchdog(wdg, store.is_some())));
    if let Some(store) = store {
        spawner.spawn(unwrap!(persist_state(store)));
    }
    spawner.spawn(unwrap!(measure_supply(supply::Supply::new(p.ADC4))));
    // LD2, the Nucleo's green user LED, is on PA5 (driven high = on).
    spawner.spawn(unwrap!(heartbeat(Output::new(p.PA5, Level::Low, Speed::Low))));
}
