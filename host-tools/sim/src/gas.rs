//! Compressible gas relations: orifice mass flow and annular-gap leakage.
//!
//! Air as a perfect gas. Every flow function returns a signed mass flow
//! (positive from `a` to `b`) so callers never have to decide the direction.

/// Specific gas constant of air, J/(kg·K).
pub const R_AIR: f64 = 287.05;
/// Ratio of specific heats of air.
pub const GAMMA: f64 = 1.4;
/// Standard atmosphere, Pa (absolute). Gauge pressures are relative to it.
pub const P_ATM_PA: f64 = 101_325.0;
/// Dynamic viscosity of air at 20 °C, Pa·s (pressure-independent below 20 MPa, paper assumption 1).
pub const MU_AIR_PA_S: f64 = 1.81e-5;

/// Critical pressure ratio (2/(γ+1))^(γ/(γ−1)) for γ = 1.4.
pub const CRITICAL_RATIO: f64 = 0.528_281_787_717_174_2;

/// Pressure ratio above which the subsonic branch is replaced by a straight
/// line to zero flow at ratio 1. Both orifice forms have infinite slope at a
/// ratio of 1, which makes an integrator chatter when two volumes equalise.
pub const LAMINAR_RATIO: f64 = 0.995;

/// Isentropic orifice flow with discharge coefficient `cd` through area `area_m2`.
///
/// Choked below the critical ratio, subsonic above it, linear (laminar) above
/// [`LAMINAR_RATIO`]. Temperatures are those of the upstream volume.
pub fn orifice_mass_flow(cd: f64, area_m2: f64, p_a_abs: f64, t_a_k: f64, p_b_abs: f64, t_b_k: f64) -> f64 {
    if area_m2 <= 0.0 {
        return 0.0;
    }
    if p_a_abs >= p_b_abs {
        cd * area_m2 * unit_flow(p_a_abs, t_a_k, p_b_abs)
    } else {
        -cd * area_m2 * unit_flow(p_b_abs, t_b_k, p_a_abs)
    }
}

/// Mass flux per unit effective area from `p_up` to `p_down` (p_up ≥ p_down).
fn unit_flow(p_up: f64, t_up: f64, p_down: f64) -> f64 {
    let ratio = p_down / p_up;
    let scale = p_up / (R_AIR * t_up).sqrt();
    if ratio <= CRITICAL_RATIO {
        scale * choked_psi()
    } else if ratio < LAMINAR_RATIO {
        scale * subsonic_psi(ratio)
    } else {
        scale * laminar_psi() * (1.0 - ratio) / (1.0 - LAMINAR_RATIO)
    }
}

/// ψ at [`LAMINAR_RATIO`], computed once (the laminar branch took a `powf`
/// per call for this constant).
fn laminar_psi() -> f64 {
    static PSI: std::sync::LazyLock<f64> = std::sync::LazyLock::new(|| subsonic_psi(LAMINAR_RATIO));
    *PSI
}

/// ψ(r) = sqrt(2γ/(γ−1)·(r^(2/γ) − r^((γ+1)/γ))), one `powf` per call.
fn subsonic_psi(ratio: f64) -> f64 {
    let q = ratio.powf(1.0 / GAMMA);
    let inner = 2.0 * GAMMA / (GAMMA - 1.0) * (q * q - ratio * q);
    inner.max(0.0).sqrt()
}

fn choked_psi() -> f64 {
    // sqrt(γ)·(2/(γ+1))^((γ+1)/(2(γ−1))) for γ = 1.4.
    0.684_731_456_377_270_4
}

/// Laminar isothermal leakage through an annular gap of radial height `gap_m`,
/// mean diameter `diameter_m` and length `length_m`, with eccentricity ratio
/// `eccentricity` (0 centred, 1 touching the wall).
///
/// ṁ = π·D·h³·(pa² − pb²)·(1 + 1.5ε²) / (24·μ·R·T·L); the divisor is 24 for a
/// compressible gas (12 for a liquid with Δp alone).
pub fn annular_leak_mass_flow(
    diameter_m: f64,
    gap_m: f64,
    length_m: f64,
    eccentricity: f64,
    p_a_abs: f64,
    t_a_k: f64,
    p_b_abs: f64,
    t_b_k: f64,
) -> f64 {
    let t_up = if p_a_abs >= p_b_abs { t_a_k } else { t_b_k };
    let k = std::f64::consts::PI * diameter_m * gap_m.powi(3) * (1.0 + 1.5 * eccentricity * eccentricity)
        / (24.0 * MU_AIR_PA_S * R_AIR * t_up * length_m);
    k * (p_a_abs * p_a_abs - p_b_abs * p_b_abs)
}

/// Area of a circular hole of diameter `d_m` uncovered by a straight edge over
/// a width `u_m` measured from the hole's rim.
pub fn circular_port_area_m2(d_m: f64, u_m: f64) -> f64 {
    // Covered (most of a stroke): the formula's 0, without its `acos`.
    if u_m <= 0.0 {
        return 0.0;
    }
    let r = 0.5 * d_m;
    let u = u_m.clamp(0.0, d_m);
    let c = r - u;
    r * r * (c / r).clamp(-1.0, 1.0).acos() - c * (2.0 * r * u - u * u).max(0.0).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn choked_constant_matches_its_formula() {
        let g = GAMMA;
        let expect = g.sqrt() * (2.0 / (g + 1.0)).powf((g + 1.0) / (2.0 * (g - 1.0)));
        assert!((choked_psi() - expect).abs() < 1e-12);
        let crit = (2.0 / (g + 1.0)).powf(g / (g - 1.0));
        assert!((CRITICAL_RATIO - crit).abs() < 1e-12);
        // Subsonic branch meets the choked branch at the critical ratio.
        assert!((subsonic_psi(CRITICAL_RATIO) - choked_psi()).abs() < 1e-9);
    }

    #[test]
    fn orifice_flow_is_antisymmetric_continuous_and_zero_at_equal_pressure() {
        let f = |pa: f64, pb: f64| orifice_mass_flow(0.62, 2e-5, pa, 293.15, pb, 293.15);
        assert_eq!(f(3e5, 3e5), 0.0);
        assert!((f(3e5, 2e5) + f(2e5, 3e5)).abs() < 1e-15);
        // Continuity across the laminar switch.
        let p_up = 4e5;
        let below = f(p_up, p_up * (LAMINAR_RATIO - 1e-9));
        let above = f(p_up, p_up * (LAMINAR_RATIO + 1e-9));
        assert!((below - above).abs() / below < 1e-5);
        // Monotone in downstream pressure.
        let mut last = f64::INFINITY;
        for i in 0..=100 {
            let q = f(p_up, p_up * i as f64 / 100.0);
            assert!(q <= last + 1e-15);
            last = q;
        }
    }

    #[test]
    fn choked_flow_of_a_5mm_hole_at_5_bar_abs() {
        // Textbook: ṁ* = Cd·A·p0·sqrt(γ/(R T0))·(2/(γ+1))^((γ+1)/(2(γ−1)))
        // = 0.62 · 19.63e-6 · 5e5 · 0.0404 ≈ 0.2459e-2 · ... ≈ 0.0143 kg/s.
        let a = std::f64::consts::PI * 0.0025 * 0.0025;
        let q = orifice_mass_flow(0.62, a, 5e5, 293.15, 1e5, 293.15);
        assert!((q - 0.01432).abs() < 2e-4, "{q}");
    }

    #[test]
    fn eccentric_gap_leaks_two_and_a_half_times_a_centred_one() {
        let c = annular_leak_mass_flow(0.041, 25e-6, 0.035, 0.0, 5e5, 293.0, 1e5, 293.0);
        let e = annular_leak_mass_flow(0.041, 25e-6, 0.035, 1.0, 5e5, 293.0, 1e5, 293.0);
        assert!((e / c - 2.5).abs() < 1e-12);
        assert!(c > 0.0);
    }

    #[test]
    fn port_area_runs_from_zero_to_the_full_hole() {
        let d = 0.005;
        assert_eq!(circular_port_area_m2(d, 0.0), 0.0);
        let full = std::f64::consts::PI * 0.25 * d * d;
        assert!((circular_port_area_m2(d, d) - full).abs() < 1e-12);
        assert!((circular_port_area_m2(d, d / 2.0) - full / 2.0).abs() < 1e-12);
    }
}
