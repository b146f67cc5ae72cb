//! The ADC's reference voltage, as the board measures it through the chip's
//! internal reference. Every channel's code is its voltage over VDDA, so a
//! VDDA 2 % low reads every pressure 2 % high: the self-test checks it, and
//! `Status` carries it so a drifting supply shows up next to the reports.

/// VDDA the sensors' scales assume (the Nucleo's and the emulated board's 3.3 V).
pub const NOMINAL_VDDA_V: f32 = 3.3;
/// VDDA at which the factory measured `VREFINT_CAL` (STM32G4: 3.0 V, RM0440 "VREFINT").
pub const VREFINT_CAL_VDDA_V: f32 = 3.0;

/// VDDA from a 12-bit reading of the internal reference and its factory
/// calibration: `VDDA = 3.0 V · VREFINT_CAL / VREFINT_DATA`. A zero reading
/// (no reference, a shorted input) gives 0: not measured, never infinity.
pub fn vdda_v(vrefint_code: u16, vrefint_cal: u16) -> f32 {
    if vrefint_code == 0 {
        return 0.0;
    }
    VREFINT_CAL_VDDA_V * f32::from(vrefint_cal) / f32::from(vrefint_code)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_calibration_point_reads_three_volts_and_a_sagging_supply_raises_the_code() {
        // A typical G474 VREFINT_CAL (1.212 V of 3.0 V at 12 bits).
        let cal = 1655;
        assert_eq!(vdda_v(cal, cal), 3.0);
        // At 3.3 V the reference reads 3.0/3.3 of its calibration code.
        let at_3v3 = (f32::from(cal) * 3.0 / 3.3).round() as u16;
        assert!(
            (vdda_v(at_3v3, cal) - 3.3).abs() < 3.3 / 1504.0,
            "{}",
            vdda_v(at_3v3, cal)
        );
        assert!(vdda_v(at_3v3 + 50, cal) < 3.2);
        assert_eq!(vdda_v(0, cal), 0.0);
    }
}
