//! Board layer for the hammer monitor on the Nucleo-G474RE (STM32G474RE).
//!
//! This binary is meant to stay thin: it owns what is specific to this board
//! (clock tree, pin assignment, which timer backs the time base) and nothing
//! else. The monitoring application itself — impact detection, estimation,
//! alarm logic — is hardware-independent and will live in its own `no_std`
//! crate that this binary depends on, so it can be unit-tested on the host and
//! reused on another board by writing only a new board layer (future work).
//!
//! For now the board layer proves the bring-up: the core runs at full speed
//! and the executor, time driver and defmt logging over RTT all work.

#![no_std]
#![no_main]

use defmt::info;
use embassy_executor::Spawner;
use embassy_stm32::gpio::{Level, Output, Speed};
use embassy_stm32::Config;
use embassy_time::{Duration, Instant, Ticker};
use {defmt_rtt as _, panic_probe as _};

/// Blink half-period; one full on/off cycle per second is easy to tell apart
/// from a hung board (LED stuck) or a wrong clock (visibly fast or slow).
const HEARTBEAT_HALF_PERIOD: Duration = Duration::from_millis(500);

/// Clock tree for 170 MHz SYSCLK, the G474's maximum, from the internal HSI16.
///
/// HSI16 needs nothing fitted on the board, so the same bring-up works on the
/// Nucleo and on a custom carrier; its ~1 % accuracy is plenty until something
/// needs a precise clock (USB, CAN bit timing), at which point an HSE source
/// belongs here.
///
/// PLL: 16 MHz / 4 = 4 MHz input (inside the 2.66–16 MHz window),
/// x85 = 340 MHz VCO (inside 96–344 MHz), / 2 = 170 MHz on PLLR.
/// Above 150 MHz the core regulator must be in Range 1 boost mode, which
/// embassy only switches on when asked.
fn clock_config() -> Config {
    use embassy_stm32::rcc::{AHBPrescaler, APBPrescaler, Pll, PllMul, PllPreDiv, PllRDiv, PllSource, Sysclk};

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
    // 1 MHz time base divides exactly.
    config.rcc.ahb_pre = AHBPrescaler::DIV1;
    config.rcc.apb1_pre = APBPrescaler::DIV1;
    config.rcc.apb2_pre = APBPrescaler::DIV1;
    config
}

/// Visible and logged proof of life.
///
/// A `Ticker` rather than repeated `Timer::after` keeps the period from
/// drifting by however long the loop body takes, so the logged uptime stays on
/// whole seconds and a slipping count points at a starved executor.
#[embassy_executor::task]
async fn heartbeat(mut led: Output<'static>) {
    let mut ticker = Ticker::every(HEARTBEAT_HALF_PERIOD);
    loop {
        led.set_high();
        info!("heartbeat: uptime {} ms", Instant::now().as_millis());
        ticker.next().await;

        led.set_low();
        ticker.next().await;
    }
}

#[embassy_executor::main]
async fn main(spawner: Spawner) {
    let p = embassy_stm32::init(clock_config());
    info!("hammer-firmware {} up, SYSCLK 170 MHz", env!("CARGO_PKG_VERSION"));

    // LD2, the Nucleo's green user LED, is on PA5 (driven high = on).
    let led = Output::new(p.PA5, Level::Low, Speed::Low);
    spawner.spawn(defmt::unwrap!(heartbeat(led)));
}
