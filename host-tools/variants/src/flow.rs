//! Flow laws of this family: ISO 6358 (sonic conductance C, critical ratio
//! b) for valve and ports, where the simulator uses the isentropic nozzle;
//! laminar flow through annular gaps; the opening of outlet ports.

use std::f64::consts::PI;

/// Specific gas constant of air, J/(kg·K).
pub const R: f64 = 287.1;
pub const GAMMA: f64 = 1.4;
pub const CP: f64 = GAMMA * R / (GAMMA - 1.0);
pub const P_ATM: f64 = 101_325.0;
/// ISO 6358 reference state.
const RHO0: f64 = 1.185;
const T0: f64 = 293.15;
const MU: f64 = 1.81e-5;

/// Pressure ratio above which the flow is taken as linear in Δp: the ISO
/// ellipse has an infinite slope at ratio 1, which an explicit integrator
/// cannot follow when two volumes equalise.
const LINEAR_ABOVE: f64 = 0.999;

/// A temperature, K, with ISO 6358's factor √(T0/T) worked out once when
/// it is one of the run's constants (the supply's, the ambient): the flow
/// laws run four times per 1 µs step, and that division and root stood on
/// each evaluation's longest chain. The same operations on the same value,
/// so the same bits as working it out at each flow.
#[derive(Debug, Clone, Copy)]
pub struct Temp {
    pub k: f64,
    root: Option<f64>,
}

impl Temp {
    /// A temperature that stays over the run.
    pub fn fixed(k: f64) -> Self {
        Self {
            k,
            root: Some((T0 / k).sqrt()),
        }
    }

    /// A state's temperature (the chambers'), new at each evaluation.
    pub fn at(k: f64) -> Self {
        Self { k, root: None }
    }

    fn root(self) -> f64 {
        self.root.unwrap_or_else(|| (T0 / self.k).sqrt())
    }
}

/// Mass flow from a (p_a, t_a) to b (p_b, t_b) through conductance `c` with
/// critical ratio `b`; negative when it runs from b to a.
pub fn iso6358(c: f64, b: f64, p_a: f64, t_a: f64, p_b: f64, t_b: f64) -> f64 {
    iso6358_at(c, b, p_a, Temp::at(t_a), p_b, Temp::at(t_b))
}

/// [`iso6358`] with the temperatures as [`Temp`]s.
pub fn iso6358_at(c: f64, b: f64, p_a: f64, t_a: Temp, p_b: f64, t_b: Temp) -> f64 {
    if c <= 0.0 {
        return 0.0;
    }
    let (up, t_up, down, sign) = if p_a >= p_b {
        (p_a, t_a, p_b, 1.0)
    } else {
        (p_b, t_b, p_a, -1.0)
    };
    let r = down / up;
    let phi = |r: f64| {
        if r <= b {
            1.0
        } else {
            let z = (r - b) / (1.0 - b);
            (1.0 - z * z).max(0.0).sqrt()
        }
    };
    let f = if r < LINEAR_ABOVE {
        phi(r)
    } else {
        phi(LINEAR_ABOVE) * (1.0 - r) / (1.0 - LINEAR_ABOVE)
    };
    sign * c * RHO0 * up * t_up.root() * f
}

/// Laminar, isothermal flow through an annular gap (height `h`, diameter
/// `d`, length `l`, eccentricity `e`), compressible form.
pub fn annular_gap(d: f64, h: f64, l: f64, e: f64, p_a: f64, t_a: f64, p_b: f64, t_b: f64) -> f64 {
    let t = if p_a >= p_b { t_a } else { t_b };
    PI * d * h.powi(3) * (1.0 + 1.5 * e * e) * (p_a * p_a - p_b * p_b) / (24.0 * MU * R * t * l)
}

/// Open fraction of a round hole of diameter `d` uncovered by `u` metres
/// of a straight edge: the circular segment's area over the hole's.
pub fn circular_segment_fraction(d: f64, u: f64) -> f64 {
    if u <= 0.0 {
        return 0.0;
    }
    if u >= d {
        return 1.0;
    }
    let r = 0.5 * d;
    let a = r - u; // distance of the edge from the centre
    let theta = 2.0 * (a / r).clamp(-1.0, 1.0).acos();
    (theta - theta.sin()) / (2.0 * PI)
}

/// Open fraction of a chamfered port: a raised cosine over `ramp` metres.
pub fn smooth_ramp_fraction(ramp: f64, u: f64) -> f64 {
    let s = (u / ramp).clamp(0.0, 1.0);
    // Shut or fully open (most of a cycle): cos 0 = 1 and cos π = −1
    // exactly in f64, so the cosine is skipped with the same result.
    if s == 0.0 {
        return 0.0;
    }
    if s == 1.0 {
        return 1.0;
    }
    0.5 * (1.0 - (PI * s).cos())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn iso_flow_is_choked_below_b_continuous_and_antisymmetric() {
        let (c, b) = (1e-8, 0.3);
        let q = |pb: f64| iso6358(c, b, 6e5, 293.0, pb, 293.0);
        assert_eq!(q(1e5), q(1.5e5)); // both choked (ratio < 0.3)
        assert!(q(3e5) < q(1.7e5));
        assert!(q(6e5).abs() < 1e-15);
        let eps = 1e-3;
        for r in [b, LINEAR_ABOVE] {
            assert!((q(6e5 * (r - 1e-9)) - q(6e5 * (r + 1e-9))).abs() < eps * q(1e5));
        }
        assert_eq!(
            iso6358(c, b, 2e5, 293.0, 5e5, 293.0),
            -iso6358(c, b, 5e5, 293.0, 2e5, 293.0)
        );
    }

    /// The shortcuts at the ramp's ends are the cosine's own values.
    #[test]
    fn the_ramps_ends_are_the_cosines() {
        assert_eq!((PI * 0.0f64).cos(), 1.0);
        assert_eq!((PI * 1.0f64).cos(), -1.0);
        assert_eq!((0.5 * (1.0 - (PI * 0.0f64).cos())).to_bits(), 0.0f64.to_bits());
        assert_eq!((0.5 * (1.0 - (PI * 1.0f64).cos())).to_bits(), 1.0f64.to_bits());
        for t in [200.0, 293.15, 320.0] {
            let (a, b) = (
                iso6358(3e-9, 0.3, 6e5, t, 2e5, 300.0),
                iso6358_at(3e-9, 0.3, 6e5, Temp::fixed(t), 2e5, Temp::at(300.0)),
            );
            assert_eq!(a.to_bits(), b.to_bits());
        }
    }

    #[test]
    fn port_fractions_run_from_closed_to_open_monotonically() {
        let mut last = (0.0, 0.0);
        for i in 0..=120 {
            let u = i as f64 * 0.0001 - 0.001;
            let now = (circular_segment_fraction(0.005, u), smooth_ramp_fraction(0.006, u));
            assert!(now.0 >= last.0 && now.1 >= last.1);
            last = now;
        }
        assert_eq!(last, (1.0, 1.0));
        // Half the diameter uncovered: half the area.
        assert!((circular_segment_fraction(0.005, 0.0025) - 0.5).abs() < 1e-12);
    }
}
