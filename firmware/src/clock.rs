//! The app's time source: the embassy time base (TIM15, 1 MHz ticks), so the
//! app's timestamps and the board's timers can never disagree.

use embassy_time::Instant;
use hammer_app::Clock;

pub struct BoardClock;

impl Clock for BoardClock {
    fn now_us(&self) -> u64 {
        Instant::now().as_micros()
    }
}
