//! The sample clock: a sample's index as a time.

/// The time of sample `index`'s leading edge (half a sample before its
/// centre), µs from the first sample, at `rate_hz` samples a second: integer
/// arithmetic, exact to the µs (rounded) for years, and no double precision
/// on a board whose FPU has none.
pub(crate) fn edge_us(index: u64, rate_hz: u64) -> u64 {
    // (index − ½) / rate = (2·index − 1) · 500 000 / rate µs, split so that
    // no product overflows.
    let rate = rate_hz.max(1);
    let half_samples = (2 * index).saturating_sub(1);
    let (whole, part) = (half_samples / rate, half_samples % rate);
    whole.saturating_mul(500_000) + (part * 500_000 + rate / 2) / rate
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_edge_of_a_sample_is_half_a_period_before_it() {
        assert_eq!(edge_us(1, 100_000), 5);
        assert_eq!(edge_us(100_000, 100_000), 999_995);
        assert_eq!(edge_us(0, 100_000), 0);
        // A year at 100 kS/s, and a rate that does not divide a second.
        let year = 100_000 * 86_400 * 365;
        assert_eq!(edge_us(year, 100_000), 86_400 * 365 * 1_000_000 - 5);
        for index in [1u64, 7, 29_999, 30_001, 123_456_789] {
            let exact = (index as f64 - 0.5) / 30_000.0 * 1e6;
            assert!((edge_us(index, 30_000) as f64 - exact).abs() <= 0.5, "{index}");
        }
    }
}
