//! The sampling chain: TIM6 update → ADC1 regular scan of three channels →
//! DMA1 channel 1 into a circular buffer, read a half at a time.
//!
//! The timer, not software, paces the conversions, so the sample instants are
//! as regular as the 170 MHz clock and do not move with interrupt load; the
//! DSP only has to keep up on average, with half the ring as slack.
//!
//! embassy-stm32 0.6.0 provides exactly this on the G4
//! (`Adc::into_ring_buffered` with a `RegularTrigger` and `Exten`, see
//! `src/adc/mod.rs` and `src/adc/ringbuffered.rs` there); the board adds the
//! timer, the lost-sample accounting and the recovery from an ADC overrun,
//! which the driver leaves to the user.

use core::sync::atomic::{AtomicU32, Ordering};

use defmt::{info, warn};
use embassy_stm32::adc::{Adc, AdcChannel, AdcConfig, AnyAdcChannel, Exten, Resolution, RingBufferedAdc, SampleTime};
use embassy_stm32::pac;
use embassy_stm32::pac::adc::vals::{Adstp, Dmaen};
use embassy_stm32::peripherals::{ADC1, DMA1_CH1, PA0, PA1, PB0, TIM6};
use embassy_stm32::timer::low_level::{MasterMode, RoundTo, Timer};
use embassy_stm32::triggers::TIM6_TRGO;
use embassy_stm32::Peri;
use embassy_time::{with_timeout, Duration, Instant};
use hammer_app::{Overrun, SampleSource};
use hammer_estimator::RawSample;

use crate::Irqs;

/// Rear pressure, front pressure, acceleration: the order of `RawSample`.
pub const CHANNELS: usize = 3;
/// ADC1 input numbers of PA0, PA1 and PB0, in `RawSample` order. Needed
/// again after an overrun, when the scan order is rotated (see `recover`).
const ADC1_INPUTS: [u8; CHANNELS] = [1, 2, 15];

/// Sample-sets per DMA half-buffer: 2.56 ms at 100 kS/s, which is how late
/// the DSP may fall behind before samples are lost.
pub const SETS_PER_HALF: usize = 256;
/// The whole circular DMA buffer, in 16-bit words.
pub const DMA_WORDS: usize = 2 * SETS_PER_HALF * CHANNELS;

/// Rates the chain is specified for: below 20 kS/s the impact transient is
/// undersampled for the estimator's blanking; above 200 kS/s the three
/// conversions no longer fit in one period (see `SAMPLE_TIME`).
pub const MIN_RATE_HZ: u32 = 20_000;
pub const MAX_RATE_HZ: u32 = 200_000;

/// 47.5 + 12.5 = 60 ADC clocks = 1.41 µs per conversion at 42.5 MHz, so a
/// three-channel scan takes 4.24 µs and fits the 5 µs period at 200 kS/s.
/// One value for all rates keeps the channel-to-channel skew at 1.41 µs
/// whatever the rate, so it can be accounted for once.
const SAMPLE_TIME: SampleTime = SampleTime::CYCLES47_5;

/// Half-buffers delivered (or skipped over by an overrun) since boot: the
/// watchdog task pets the IWDG only while this advances.
pub static BLOCKS: AtomicU32 = AtomicU32::new(0);

pub struct Pins {
    /// Arduino A0.
    pub rear: Peri<'static, PA0>,
    /// Arduino A1.
    pub front: Peri<'static, PA1>,
    /// Arduino A3.
    pub accel: Peri<'static, PB0>,
}

pub struct Sampler {
    adc: RingBufferedAdc<'static, ADC1>,
    /// Kept only so it is not dropped: dropping a `Timer` gates its clock.
    _timer: Timer<'static, TIM6>,
    /// One half-buffer, copied out of the ring; served to the app in
    /// whatever block size it asks for.
    half: [u16; SETS_PER_HALF * CHANNELS],
    served: usize,
    filled: usize,
    timer_hz: u32,
    period_clocks: u32,
    started: Option<Instant>,
    /// Sample-sets taken out of the ring or written off as lost, for
    /// estimating how many an overrun cost.
    accounted: u64,
}

impl Sampler {
    /// Configures TIM6, ADC1 and the DMA ring; conversions start at the first read.
    pub fn new(
        adc: Peri<'static, ADC1>,
        tim: Peri<'static, TIM6>,
        dma: Peri<'static, DMA1_CH1>,
        pins: Pins,
        dma_buf: &'static mut [u16; DMA_WORDS],
        rate_hz: u32,
    ) -> Self {
        let rate_hz = rate_hz.clamp(MIN_RATE_HZ, MAX_RATE_HZ);

        // TIM6 is a basic timer: nothing to do but count and pulse TRGO on
        // every update, which is all the ADC needs. 170 MHz / 100 kHz = 1700
        // clocks fits the 16-bit counter without prescaling, so the period is
        // exact whenever the rate divides 170 MHz.
        let timer = Timer::new(tim);
        let timer_hz = timer.get_clock_frequency().0;
        let period_clocks = ((timer_hz + rate_hz / 2) / rate_hz).max(2);
        timer.set_period_clocks(period_clocks as u64, RoundTo::Slower);
        timer.regs_basic().cr2().modify(|w| w.set_mms(MasterMode::UPDATE));
        timer.generate_update_event();

        let adc = Adc::new(
            adc,
            AdcConfig {
                resolution: Some(Resolution::BITS12),
                ..Default::default()
            },
        );
        let rear: AnyAdcChannel<'static, ADC1> = pins.rear.degrade_adc();
        let front: AnyAdcChannel<'static, ADC1> = pins.front.degrade_adc();
        let accel: AnyAdcChannel<'static, ADC1> = pins.accel.degrade_adc();
        let adc = adc.into_ring_buffered(
            dma,
            &mut dma_buf[..],
            Irqs,
            [(rear, SAMPLE_TIME), (front, SAMPLE_TIME), (accel, SAMPLE_TIME)].into_iter(),
            TIM6_TRGO,
            Exten::RISING_EDGE,
        );
        // Triggers before ADSTART are ignored, so the timer may run from now on.
        timer.start();

        let s = Self {
            adc,
            _timer: timer,
            half: [0; SETS_PER_HALF * CHANNELS],
            served: 0,
            filled: 0,
            timer_hz,
            period_clocks,
            started: None,
            accounted: 0,
        };
        info!(
            "sampler: {} S/s per channel ({} timer clocks)",
            s.rate_hz(),
            period_clocks
        );
        s
    }

    /// The rate actually achieved, for the estimator's configuration.
    pub fn rate_hz(&self) -> f32 {
        self.timer_hz as f32 / self.period_clocks as f32
    }

    fn half_period(&self) -> Duration {
        let ticks = SETS_PER_HALF as u64 * self.period_clocks as u64 * embassy_time::TICK_HZ / self.timer_hz as u64;
        Duration::from_ticks(ticks)
    }

    /// Sample-sets the ADC has produced since it was started, from the
    /// clock: the timer and the time base share one oscillator, so this is
    /// exact but for the few sets in flight.
    fn produced(&self, now: Instant) -> u64 {
        let Some(start) = self.started else { return 0 };
        let us = now.saturating_duration_since(start).as_micros();
        hammer_app::sample_clock::sets_in(us, self.timer_hz, self.period_clocks)
    }

    /// Writes off everything produced but not taken, after the ring was reset.
    fn write_off(&mut self) -> u32 {
        let produced = self.produced(Instant::now());
        let lost = produced.saturating_sub(self.accounted).max(1);
        self.accounted += lost;
        lost.min(u32::MAX as u64) as u32
    }

    async fn fill(&mut self) -> Result<(), Overrun> {
        if self.started.is_none() {
            self.adc.start();
            self.started = Some(Instant::now());
        }
        // A healthy chain completes a half every `half_period`; four of them
        // without one means the DMA is no longer being fed (ADC overrun).
        let stall = self.half_period() * 4 + Duration::from_millis(2);
        match with_timeout(stall, self.adc.read(&mut self.half)).await {
            Ok(Ok(_)) => {
                self.accounted += SETS_PER_HALF as u64;
                self.served = 0;
                self.filled = SETS_PER_HALF;
                BLOCKS.fetch_add(1, Ordering::Relaxed);
                Ok(())
            }
            Ok(Err(_)) => {
                // The DMA lapped the reader: the DSP fell more than half a
                // ring behind. The driver has already moved the read index
                // to the DMA's position (keeping whole sample-sets), so
                // sampling simply continues from there.
                let lost = self.write_off();
                BLOCKS.fetch_add(1, Ordering::Relaxed);
                warn!("sampler: DSP overrun, ~{} sample-sets lost", lost);
                Err(Overrun { lost })
            }
            Err(_) => {
                let ovr = self.recover();
                let lost = self.write_off();
                warn!(
                    "sampler: stream stalled (ADC OVR {}), restarted, ~{} sample-sets lost",
                    ovr, lost
                );
                Err(Overrun { lost })
            }
        }
    }

    /// Restarts a stalled stream. With OVRMOD = 0 (the reset value, which the
    /// driver keeps) an ADC overrun blocks further DMA requests until OVR is
    /// cleared (RM0440, "ADC overrun"), so the DMA stops mid-buffer, possibly
    /// mid-sample-set. Restarting the scan would then put rank 1 where the
    /// ring expects rank 2 or 3 and silently swap channels; instead the scan
    /// order is rotated so the next conversion is the channel that belongs at
    /// the DMA's position. Returns whether the ADC had flagged an overrun.
    fn recover(&mut self) -> bool {
        let adc = pac::ADC1;
        let ovr = adc.isr().read().ovr();

        // ADSTP aborts the sequence, so the next start begins at rank 1.
        if adc.cr().read().adstart() {
            adc.cr().modify(|w| w.set_adstp(Adstp::STOP));
            // Bounded: ADSTART drops within a conversion time (< 2 µs).
            for _ in 0..10_000 {
                if !adc.cr().read().adstart() {
                    break;
                }
            }
        }
        adc.cfgr().modify(|w| w.set_dmaen(Dmaen::DISABLE));
        let _ = adc.dr().read(); // the word the DMA never took
        adc.isr().write(|w| {
            w.set_ovr(true);
            w.set_eoc(true);
            w.set_eos(true);
        });

        let written = DMA_WORDS - pac::DMA1.ch(0).ndtr().read().ndt() as usize;
        let rank1 = written % CHANNELS;
        adc.sqr1().modify(|w| {
            for rank in 0..CHANNELS {
                w.set_sq(rank, ADC1_INPUTS[(rank1 + rank) % CHANNELS]);
            }
        });

        self.adc.clear();
        adc.cfgr().modify(|w| w.set_dmaen(Dmaen::ENABLE));
        adc.cr().modify(|w| w.set_adstart(true));
        ovr
    }
}

impl SampleSource for Sampler {
    async fn read(&mut self, buf: &mut [RawSample]) -> Result<usize, Overrun> {
        if self.served == self.filled {
            self.fill().await?;
        }
        let n = (self.filled - self.served).min(buf.len());
        let words = &self.half[self.served * CHANNELS..(self.served + n) * CHANNELS];
        for (dst, set) in buf.iter_mut().zip(words.chunks_exact(CHANNELS)) {
            *dst = RawSample {
                rear: set[0],
                front: set[1],
                accel: set[2],
            };
        }
        self.served += n;
        Ok(n)
    }
}
