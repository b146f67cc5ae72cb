//! The simulator's random numbers: xoshiro256++ for uniform bits, and
//! standard normal deviates by the ziggurat method, both the same bits on
//! every machine for a seed.
//!
//! Why the ziggurat: the sensor chain draws a normal deviate per channel
//! per sample, 300 000 a second of hammer time; Box–Muller (a `ln`, a
//! `sqrt` and a `sin_cos` per pair, the trace format's version 1) cost
//! about a third of the chain. The ziggurat (Marsaglia & Tsang 2000, in
//! Doornik's 2005 "ZIGNOR" form, 128 layers) returns on ~98.8 % of draws
//! after one random number, a table look-up, a compare and a multiply; the
//! rest go through `exp` or the tail's `log`. It is exact: the deviates are
//! N(0, 1), not an approximation. Tables and slow path use `libm`, so no
//! platform's own maths library can change a trace.

use std::sync::OnceLock;

/// Deterministic xoshiro256++ so a seed reproduces a trace on every machine.
pub struct Rng {
    s: [u64; 4],
    zig: &'static Ziggurat,
}

impl Rng {
    pub fn new(seed: u64) -> Self {
        let mut z = seed;
        let mut next = || {
            z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
            let mut x = z;
            x = (x ^ (x >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            x = (x ^ (x >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
            x ^ (x >> 31)
        };
        Rng {
            s: [next(), next(), next(), next()],
            zig: Ziggurat::get(),
        }
    }

    #[inline]
    pub fn next_u64(&mut self) -> u64 {
        let s = &mut self.s;
        let r = (s[0].wrapping_add(s[3])).rotate_left(23).wrapping_add(s[0]);
        let t = s[1] << 17;
        s[2] ^= s[0];
        s[3] ^= s[1];
        s[1] ^= s[2];
        s[0] ^= s[3];
        s[2] ^= t;
        s[3] = s[3].rotate_left(45);
        r
    }

    /// Uniform in [0, 1).
    #[inline]
    pub fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }

    /// Standard normal (ziggurat). One `u64` gives both the layer (its low
    /// 7 bits) and the abscissa (its top 53 bits, uniform in (−1, 1)).
    #[inline]
    pub fn normal(&mut self) -> f64 {
        let z = self.zig;
        loop {
            let bits = self.next_u64();
            let i = (bits & (LAYERS as u64 - 1)) as usize;
            let u = (bits >> 11) as f64 * (2.0 / (1u64 << 53) as f64) - 1.0;
            if u.abs() < z.ratio[i] {
                return u * z.x[i];
            }
            if let Some(x) = self.normal_slow(i, u) {
                return x;
            }
        }
    }

    /// The ziggurat's edge of layer `i` (and the tail under the base
    /// layer): accepted under the density, or `None` to draw again.
    #[cold]
    fn normal_slow(&mut self, i: usize, u: f64) -> Option<f64> {
        let z = self.zig;
        if i == 0 {
            // Marsaglia's tail beyond R: exact, by rejection.
            loop {
                let x = libm::log(1.0 - self.uniform()) / R;
                let y = libm::log(1.0 - self.uniform());
                if -2.0 * y >= x * x {
                    return Some(if u < 0.0 { x - R } else { R - x });
                }
            }
        }
        let x = u * z.x[i];
        let f0 = libm::exp(-0.5 * (z.x[i] * z.x[i] - x * x));
        let f1 = libm::exp(-0.5 * (z.x[i + 1] * z.x[i + 1] - x * x));
        (f1 + self.uniform() * (f0 - f1) < 1.0).then_some(x)
    }
}

/// Layers of the ziggurat (a power of two: the layer is a deviate's low bits).
const LAYERS: usize = 128;
/// Where the base layer's tail starts, and each layer's area (Doornik's
/// ZIGNOR constants for 128 layers).
const R: f64 = 3.442619855899;
const V: f64 = 9.91256303526217e-3;

/// Layer `i` spans [0, x[i]] above x[i + 1]'s height; `ratio[i]` =
/// x[i + 1] / x[i], under which a point is inside the density for sure.
struct Ziggurat {
    x: [f64; LAYERS + 1],
    ratio: [f64; LAYERS],
}

impl Ziggurat {
    fn get() -> &'static Self {
        static TABLES: OnceLock<Ziggurat> = OnceLock::new();
        TABLES.get_or_init(|| {
            let f = |x: f64| libm::exp(-0.5 * x * x);
            let mut x = [0.0; LAYERS + 1];
            x[0] = V / f(R);
            x[1] = R;
            for i in 2..LAYERS {
                x[i] = libm::sqrt(-2.0 * libm::log(V / x[i - 1] + f(x[i - 1])));
            }
            x[LAYERS] = 0.0;
            let mut ratio = [0.0; LAYERS];
            for i in 0..LAYERS {
                ratio[i] = x[i + 1] / x[i];
            }
            Ziggurat { x, ratio }
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn draws(seed: u64, n: usize) -> Vec<f64> {
        let mut r = Rng::new(seed);
        (0..n).map(|_| r.normal()).collect()
    }

    #[test]
    fn normal_deviates_have_the_moments_of_a_standard_normal() {
        let n = 400_000;
        let xs = draws(7, n);
        let mean = xs.iter().sum::<f64>() / n as f64;
        let m = |k: i32| xs.iter().map(|x| (x - mean).powi(k)).sum::<f64>() / n as f64;
        let (var, skew, kurt) = (m(2), m(3) / m(2).powf(1.5), m(4) / (m(2) * m(2)));
        // Standard errors at n = 4e5: mean 0.0016, variance 0.0022, skewness 0.004, kurtosis 0.008.
        assert!(mean.abs() < 0.008, "mean {mean}");
        assert!((var - 1.0).abs() < 0.011, "variance {var}");
        assert!(skew.abs() < 0.02, "skewness {skew}");
        assert!((kurt - 3.0).abs() < 0.04, "kurtosis {kurt}");
    }

    /// The whole distribution, tails included (the tail and the layers'
    /// edges are the ziggurat's slow paths): the empirical CDF stays within
    /// Kolmogorov–Smirnov's 0.1 % bound of Φ, and the share beyond 3 σ and
    /// beyond R (the base layer's tail) is Φ's.
    #[test]
    fn normal_deviates_follow_the_normal_distribution_into_the_tails() {
        let n = 400_000;
        let mut xs = draws(11, n);
        xs.sort_by(f64::total_cmp);
        let phi = |x: f64| 0.5 * (1.0 + libm::erf(x / std::f64::consts::SQRT_2));
        let d = xs
            .iter()
            .enumerate()
            .map(|(k, &x)| {
                let p = phi(x);
                (p - k as f64 / n as f64)
                    .abs()
                    .max(((k + 1) as f64 / n as f64 - p).abs())
            })
            .fold(0.0, f64::max);
        assert!(d < 1.95 / (n as f64).sqrt(), "KS distance {d}");
        for (beyond, sigmas) in [(3.0, 6.0), (R, 6.0)] {
            let expected = 2.0 * (1.0 - phi(beyond)) * n as f64;
            let got = xs.iter().filter(|x| x.abs() > beyond).count() as f64;
            assert!(
                (got - expected).abs() < sigmas * expected.sqrt(),
                "beyond {beyond}: {got} vs {expected}"
            );
        }
    }

    #[test]
    fn a_seed_gives_the_same_deviates_and_another_seed_others() {
        assert_eq!(draws(3, 1000), draws(3, 1000));
        assert_ne!(draws(3, 1000), draws(4, 1000));
    }
}
