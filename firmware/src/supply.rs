//! VDDA, measured once a second on ADC4's internal reference channel
//! (VREFINT), against the factory calibration in system memory. ADC4 is
//! otherwise unused: the sampling chain keeps ADC1 to itself, so this never
//! delays or reorders a sample. The app turns the reading into volts
//! (`hammer_app::supply`) and `Status` carries it.

use embassy_stm32::adc::{Adc, AdcConfig, SampleTime, VrefInt};
use embassy_stm32::pac;
use embassy_stm32::peripherals::ADC4;
use embassy_stm32::Peri;
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
use embassy_time::{Duration, Ticker};
use hammer_app::Shared;

/// VREFINT needs at least 4 µs of sampling (DS12288, t_S_vrefint):
/// 247.5 ADC clocks at 42.5 MHz are 5.8 µs.
const SAMPLE_TIME: SampleTime = SampleTime::CYCLES247_5;
const PERIOD: Duration = Duration::from_secs(1);

pub struct Supply {
    adc: Adc<'static, ADC4>,
    vrefint: VrefInt,
    cal: u16,
}

impl Supply {
    pub fn new(adc4: Peri<'static, ADC4>) -> Self {
        let adc = Adc::new(adc4, AdcConfig::default());
        let vrefint = adc.enable_vrefint();
        let cal = pac::VREFINTCAL.data().read();
        Self { adc, vrefint, cal }
    }

    pub async fn run(mut self, shared: &Shared<CriticalSectionRawMutex>) -> ! {
        let mut ticker = Ticker::every(PERIOD);
        loop {
            let code = self.adc.blocking_read(&mut self.vrefint, SAMPLE_TIME);
            shared.set_vdda_v(hammer_app::supply::vdda_v(code, self.cal));
            ticker.next().await;
        }
    }
}
