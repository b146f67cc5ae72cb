//! Sample-sets a timer-paced ADC has produced in an elapsed time: what a
//! board writes off after its DMA ring was lapped or restarted.

/// ⌊`us` · `timer_hz` / (10⁶ · `period_clocks`)⌋, exactly, in 64-bit
/// integers: the `u128` product this is would cost the reference board
/// ~800 B of flash for a 128-bit division. Exact for `us` below 10¹⁷
/// (3000 years) and any timer and period a board can have; 0 for a period
/// of 0.
pub fn sets_in(us: u64, timer_hz: u32, period_clocks: u32) -> u64 {
    if period_clocks == 0 {
        return 0;
    }
    let (t, p) = (u64::from(timer_hz), u64::from(period_clocks));
    // Timer clocks in the whole seconds (`a`) and in the rest, in millionths
    // of a clock (`b` < 10⁶ · 2³²).
    let (secs, rest_us) = (us / 1_000_000, us % 1_000_000);
    let a = secs.saturating_mul(t);
    let b = rest_us * t;
    // ⌊(a·10⁶ + b) / (10⁶·p)⌋ = ⌊a/p⌋ + ⌊((a mod p)·10⁶ + b) / (10⁶·p)⌋.
    (a / p).saturating_add(((a % p) * 1_000_000 + b) / (1_000_000 * p))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn matches_the_128_bit_product() {
        let exact = |us: u64, t: u32, p: u32| (u128::from(us) * u128::from(t) / (1_000_000 * u128::from(p))) as u64;
        let mut x = 0x9E37_79B9_7F4A_7C15u64;
        for _ in 0..100_000 {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            let us = x % 100_000_000_000_000; // up to 3 years
            let t = (x >> 20) as u32 | 1;
            let p = ((x >> 40) as u32 % 100_000).max(1);
            assert_eq!(sets_in(us, t, p), exact(us, t, p), "{us} µs, {t} Hz, {p} clocks");
        }
        // The reference board: 170 MHz, 1700 clocks a set = 100 kS/s.
        assert_eq!(sets_in(1_000_000, 170_000_000, 1700), 100_000);
        assert_eq!(sets_in(9, 170_000_000, 1700), 0);
        assert_eq!(sets_in(10, 170_000_000, 1700), 1);
        assert_eq!(sets_in(86_400_000_000 * 365, 170_000_000, 1700), 100_000 * 86_400 * 365);
        assert_eq!(sets_in(5, 1, 0), 0);
    }
}
