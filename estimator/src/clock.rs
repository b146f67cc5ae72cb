//! The sample clock: a sample's index as a time.

/// The time of sample `index`'s leading edge (half a sample before its
/// centre), µs from the first sample, at `rate_hz` samples a second: integer
/// arithmetic, exact to the µs (rounded) for years, and no double precision
/// on a board whose FPU has none.
pub fn edge_us(index: u64, rate_hz: u64) -> u64 {
    // (index − ½) / rate = (2·index − 1) · 500 000 / rate µs, split so that
    // no product overflows.
    let rate = rate_hz.max(1);
    let half_samples = (2 * index).saturating_sub(1);
    let (whole, part) = (half_samples / rate, half_samples % rate);
    whole.saturating_mul(500_000) + (part * 500_000 + rate / 2) / rate
}

/// The sample whose leading edge [`edge_us`] puts at `t_us`: a report's
/// impact as an index (a reader of the codes that keeps them by index).
/// Exact where a sample lasts at least 2 µs (up to 500 kS/s); faster, two
/// neighbours' edges can round to one µs.
pub fn index_at_edge_us(t_us: u64, rate_hz: u64) -> u64 {
    // index = round(t·rate/10⁶ + ½), split so that no product overflows.
    let rate = rate_hz.max(1);
    let (whole, rem) = (t_us / 1_000_000, t_us % 1_000_000);
    whole.saturating_mul(rate) + (rem * rate + 1_000_000) / 1_000_000
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_edge_reads_back_as_its_sample() {
        for rate in [100_000u64, 30_000, 44_100, 200_000, 500_000] {
            for index in [
                1u64,
                2,
                7,
                99_999,
                100_000,
                100_001,
                29_999,
                123_456_789,
                100_000 * 86_400 * 365,
            ] {
                assert_eq!(
                    index_at_edge_us(edge_us(index, rate), rate),
                    index,
                    "{index} at {rate} Hz"
                );
            }
        }
    }

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
