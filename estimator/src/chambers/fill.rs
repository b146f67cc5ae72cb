//! The feed's effective area, from the energy equation of the fill.
//!
//! Air entering a chamber at the supply temperature T_s obeys
//! ṁ·γ·R·T_s = V·dp/dt + γ·p·dV/dt; over the fill's first
//! [`FILL_S`] that integrates to Δ(p·V) + (γ − 1)·∫p dV. Set against the
//! isentropic orifice law, ṁ = A·p_s·Ψ(p/p_s)/√(R·T_s), it gives the area A
//! that the valve and the line in front of it present together: a supply
//! restriction or a worn valve shows as a smaller one. The supply is taken
//! at the configured pressure and 20 °C (a calibration term: a wrong supply
//! pressure scales every area alike, and cancels against a reference record).

use super::closed::P_ATM_PA;
use super::Series;
use crate::math;

/// How long after the onset the fill is read.
pub const FILL_S: f32 = 1e-3;
/// Samples averaged either side of each end of the window (the ends carry
/// the Δ(p·V) term, where the pressure's noise would otherwise count whole).
const END_HALF_S: f32 = 1e-4;
pub(super) const GAMMA: f32 = 1.4;
const R_AIR: f32 = 287.05;
const T_SUPPLY_K: f32 = 293.15;
/// √(R·T_s) of the supply's air: the orifice law's R·T_s·ṁ = A·p_s·Ψ·√(R·T_s).
pub(super) fn sqrt_rt_supply() -> f32 {
    math::sqrt(R_AIR * T_SUPPLY_K)
}

/// The area and its standard uncertainty from the pressure's noise.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FillArea {
    pub area_m2: f32,
    pub sigma_m2: f32,
}

const NONE: FillArea = FillArea {
    area_m2: f32::NAN,
    sigma_m2: f32::NAN,
};

/// Isentropic flow function Ψ(p_down/p_up) for air: choked below the
/// critical ratio 0.528.
pub(super) fn psi(ratio: f32) -> f32 {
    const CRITICAL: f32 = 0.528_28;
    const CHOKED: f32 = 0.684_7;
    if ratio <= CRITICAL {
        CHOKED
    } else if ratio < 1.0 {
        // r^(2/γ) − r^((γ+1)/γ) = a·(a − r) with a = r^(1/γ): one power,
        // not two (a board reads this for every sample of a feed).
        let g = GAMMA;
        let a = math::powf(ratio, 1.0 / g);
        math::sqrt(2.0 * g / (g - 1.0) * (a * (a - ratio)))
    } else {
        0.0
    }
}

/// The area over [`FILL_S`] from `onset_s` (from the slice's start);
/// `noise_ln` is the pressure's noise in ln p (the closed fit's residual).
pub fn feed_area(
    p: &(impl Series + ?Sized),
    x: &[f32],
    volume: &impl Fn(f32) -> f32,
    dt_s: f32,
    onset_s: f32,
    supply_abs_pa: f32,
    noise_ln: f32,
) -> FillArea {
    let len = p.len().min(x.len());
    let half = ((END_HALF_S / dt_s) as usize).max(1);
    let k0 = math::round(onset_s / dt_s);
    if !(supply_abs_pa > P_ATM_PA) || !(k0 >= 0.0) {
        return NONE;
    }
    let i0 = k0 as usize;
    let i1 = i0 + (FILL_S / dt_s) as usize;
    if i1 + half >= len {
        return NONE;
    }
    let p_abs = |i: usize| p.at(i) + P_ATM_PA;
    let m = (2 * half + 1) as f32;
    // The end, averaged over ±`half` samples (a straight stretch's mean is its middle).
    let (mut p1, mut v1) = (0.0f32, 0.0f32);
    for j in i1 - half..=i1 + half {
        p1 += p_abs(j) / m;
        v1 += volume(x[j]) / m;
    }
    // The start sits on the knee, where a mean would lean into the rise:
    // there the line through the 2·half + 1 samples after it, at its foot.
    let (mut sk, mut sp, mut skk, mut skp) = (0.0f32, 0.0f32, 0.0f32, 0.0f32);
    for k in 0..=2 * half {
        let (kf, pv) = (k as f32, p_abs(i0 + k));
        sk += kf;
        sp += pv;
        skk += kf * kf;
        skp += kf * pv;
    }
    let slope = (m * skp - sk * sp) / (m * skk - sk * sk);
    let p0 = (sp - slope * sk) / m;
    let v0 = volume(x[i0]);
    let mut p_dv = 0.0f32;
    let mut flow = 0.0f32;
    for i in i0..i1 {
        let pm = 0.5 * (p_abs(i) + p_abs(i + 1));
        p_dv += pm * (volume(x[i + 1]) - volume(x[i]));
        flow += psi(pm / supply_abs_pa) * dt_s;
    }
    let work = p1 * v1 - p0 * v0 + (GAMMA - 1.0) * p_dv;
    let scale = GAMMA * supply_abs_pa * math::sqrt(R_AIR * T_SUPPLY_K) * flow;
    if !(scale > 0.0) || !(work > 0.0) {
        return NONE;
    }
    // The ends' noise: σ_p = p·σ_ln over m samples; a line's foot carries
    // about four times a mean's variance.
    let s0 = 2.0 * p0 * noise_ln * v0;
    let s1 = p1 * noise_ln * v1;
    let sigma_work = math::sqrt((s0 * s0 + s1 * s1) / m);
    FillArea {
        area_m2: work / scale,
        sigma_m2: sigma_work / scale,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A fixed chamber filled through a known choked orifice: the area
    /// read back is the orifice's (the energy equation is exact here).
    #[test]
    fn a_choked_fill_of_a_fixed_chamber_gives_its_orifice() {
        let (dt, v, area, ps) = (1e-5f32, 30e-6f32, 2e-6f32, 6e5f32);
        let mdot = area * ps * 0.6847 / math::sqrt(R_AIR * T_SUPPLY_K);
        // dp/dt = γ·R·T_s·ṁ / V, constant while choked.
        let rate = GAMMA * R_AIR * T_SUPPLY_K * mdot / v;
        let p: heapless::Vec<f32, 400> = (0..400)
            .map(|i| 1.5e5 + rate * dt * (i as f32 - 100.0).max(0.0) - P_ATM_PA)
            .collect();
        let x = [0.0f32; 400];
        let a = feed_area(&p[..], &x, &|_| v, dt, 100.0 * dt, ps, 0.0);
        assert!((a.area_m2 / area - 1.0).abs() < 0.01, "{} m²", a.area_m2);
        assert_eq!(a.sigma_m2, 0.0);
        // No supply given: no area.
        assert!(feed_area(&p[..], &x, &|_| v, dt, 100.0 * dt, f32::NAN, 0.0)
            .area_m2
            .is_nan());
    }
}
