//! A closed chamber's polytropic fit, and the onset of the feed that ends it.
//!
//! While both its ports are shut a chamber keeps p·Vⁿ constant: ln p_abs is
//! a straight line in ln V of slope −n. The fit over the closed phase gives
//! `n`; its residual r = ln p_abs + n·ln V − c stays in the noise until air
//! enters, and the feed's onset is where that residual's rise, extended back
//! along its tangent, meets zero. The tangent is fitted over a fixed band of
//! the rise (2 % to 8 %), so the same onset is read from noisy and from
//! noise-free pressures, whatever the fill's pace.

use super::Series;
use crate::math;

/// Atmospheric pressure, for gauge → absolute.
pub const P_ATM_PA: f32 = 101_325.0;
/// The adiabatic exponent, used until the closed phase's own is known (and
/// where the phase moves the volume too little to fit one).
const KAPPA: f32 = 1.4;
/// The band of the residual's rise the onset's tangent is fitted over.
const RISE_LOW: f32 = 0.02;
const RISE_HIGH: f32 = 0.08;
/// A rise must hold this long to be a feed, not noise.
const HOLD_S: f32 = 1e-4;
/// The shortest closed phase that can be fitted.
const MIN_CLOSED_S: f32 = 5e-4;
/// An exponent fitted with a standard error above this is not used for the
/// onset's residual (the volume hardly moved): the adiabatic one is.
const MAX_EXPONENT_SD: f32 = 0.05;

/// The closed phase and the feed after it, times from the slice's start.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Onset {
    pub onset_s: f32,
    /// Expanded (k = 2), random terms.
    pub onset_uncertainty_s: f32,
    pub exponent: f32,
    /// Expanded (k = 2).
    pub exponent_uncertainty: f32,
    /// RMS of the closed fit's residual in ln p: the pressure's relative noise.
    pub noise_ln: f32,
    /// Where the rise entered the band the onset is read from: the fill is
    /// under way there, whatever the port's opening pace.
    pub rise_s: f32,
}

/// The logarithms a closed fit reads, sample by sample: ln p_abs and ln V.
/// The fits read each a dozen times over (the line, its halves, the noise,
/// the baseline, the rise, and all of it twice), so the host keeps them
/// ([`Cached`]); [`Direct`] computes them as they are read. Both give the
/// same figures.
pub trait Logs {
    /// Samples that have both.
    fn len(&self) -> usize;
    /// Whether every sample has a positive absolute pressure and volume.
    fn valid(&self) -> bool;
    fn ln_p(&self, i: usize) -> f32;
    fn ln_v(&self, i: usize) -> f32;
}

/// The logarithms computed where read.
pub struct Direct<'a, P: Series + ?Sized, V: Fn(f32) -> f32> {
    pub p: &'a P,
    pub x: &'a [f32],
    pub volume: &'a V,
}

impl<P: Series + ?Sized, V: Fn(f32) -> f32> Logs for Direct<'_, P, V> {
    fn len(&self) -> usize {
        self.p.len().min(self.x.len())
    }
    fn valid(&self) -> bool {
        (0..self.len()).all(|i| self.p.at(i) + P_ATM_PA > 0.0 && (self.volume)(self.x[i]) > 0.0)
    }
    fn ln_p(&self, i: usize) -> f32 {
        math::ln(self.p.at(i) + P_ATM_PA)
    }
    fn ln_v(&self, i: usize) -> f32 {
        math::ln((self.volume)(self.x[i]))
    }
}

/// The logarithms computed once into the caller's room.
pub struct Cached<'a> {
    ln_p: &'a [f32],
    ln_v: &'a [f32],
    valid: bool,
}

impl<'a> Cached<'a> {
    /// `room` holds two floats a sample; `None` where it is shorter.
    pub fn fill(
        p: &(impl Series + ?Sized),
        x: &[f32],
        volume: &impl Fn(f32) -> f32,
        room: &'a mut [f32],
    ) -> Option<Cached<'a>> {
        let len = p.len().min(x.len());
        let (ln_p, rest) = room.split_at_mut_checked(len)?;
        let ln_v = rest.get_mut(..len)?;
        let mut valid = true;
        // The pressures first, in order (a board's from its codes).
        p.read_into(0, ln_p);
        for i in 0..len {
            let (pa, v) = (ln_p[i] + P_ATM_PA, volume(x[i]));
            valid &= pa > 0.0 && v > 0.0;
            ln_p[i] = math::ln(pa);
            ln_v[i] = math::ln(v);
        }
        Some(Cached { ln_p, ln_v, valid })
    }
}

impl Logs for Cached<'_> {
    fn len(&self) -> usize {
        self.ln_p.len()
    }
    fn valid(&self) -> bool {
        self.valid
    }
    // No panic path (the fits read `..len`): small enough to inline into
    // the fits' passes.
    #[inline(always)]
    fn ln_p(&self, i: usize) -> f32 {
        self.ln_p.get(i).copied().unwrap_or(f32::NAN)
    }
    #[inline(always)]
    fn ln_v(&self, i: usize) -> f32 {
        self.ln_v.get(i).copied().unwrap_or(f32::NAN)
    }
}

/// `p` (gauge) and `x` start in the closed phase and run past the feed.
pub fn onset(p: &(impl Series + ?Sized), x: &[f32], volume: &impl Fn(f32) -> f32, dt_s: f32) -> Option<Onset> {
    onset_of(&Direct { p, x, volume }, dt_s)
}

/// [`onset`] from the samples' logarithms.
pub fn onset_of(logs: &impl Logs, dt_s: f32) -> Option<Onset> {
    let len = logs.len();
    let hold = ((HOLD_S / dt_s) as usize).max(3);
    let min_base = ((MIN_CLOSED_S / dt_s) as usize).max(8);
    if len < min_base + 2 * hold {
        return None;
    }
    let ln_p = |i: usize| logs.ln_p(i);
    let ln_v = |i: usize| logs.ln_v(i);
    if !logs.valid() {
        return None;
    }

    // 1. A first onset with the adiabatic exponent, against the phase's start.
    let y0 = (0..min_base).map(|i| ln_p(i) + KAPPA * ln_v(i)).sum::<f32>() / min_base as f32;
    let first = rise_start(len, hold, min_base, |i| ln_p(i) + KAPPA * ln_v(i) - y0 > 3.0 * RISE_LOW)?;
    // The closed phase ends before that rise began.
    let mut base_end = first;
    while base_end > min_base && ln_p(base_end - 1) + KAPPA * ln_v(base_end - 1) - y0 > 0.25 * RISE_LOW {
        base_end -= 1;
    }
    let base_end = base_end.saturating_sub(hold);
    let first = read(logs, dt_s, base_end)?;
    // A slow rise starts well before it shows: read again with the closed
    // phase ending where the first reading put the onset.
    let onset_at = (first.onset_s / dt_s) as usize;
    if onset_at < base_end + hold {
        return read(logs, dt_s, onset_at.saturating_sub(hold)).or(Some(first));
    }
    Some(first)
}

/// The dead volume's correction, m³, that the closed phase before `o`
/// asks for: with u = ln V and w = V_min/V, ln p = c − n·ln(V + δ) ≈ c −
/// n·u − (n·δ/V_min)·w, a linear fit in (u, w) whose ratio of slopes gives
/// δ; three Gauss-Newton passes take the second-order term in.
///
/// Why: near the impact most of the front chamber's volume is dead volume,
/// known only from a drawing. A tenth off bends ln p·Vⁿ by about 0.1 there,
/// more than the rise that marks a feed, so a feed late in the stroke (a
/// delayed valve) is read where the bend crosses the band, milliseconds
/// early, and the exponent carries the error too. One cycle's δ is noisy
/// (δ and n trade against each other); a record's median is a hammer's
/// calibration (`hammer_diagnose`'s reading against a reference).
///
/// None where the phase moves the volume too little to tell δ from n (by
/// less than a fifth), where the fit is singular, or where δ leaves the
/// plausible range (−60 % … +100 % of the smallest volume).
pub fn dead_volume_offset(
    p: &(impl Series + ?Sized),
    x: &[f32],
    volume: &impl Fn(f32) -> f32,
    dt_s: f32,
    o: &Onset,
) -> Option<f32> {
    let hold = ((HOLD_S / dt_s) as usize).max(3);
    let len = ((o.onset_s / dt_s) as usize)
        .saturating_sub(hold)
        .min(p.len())
        .min(x.len());
    if len < ((MIN_CLOSED_S / dt_s) as usize).max(8) {
        return None;
    }
    let (mut v_min, mut v_max) = (f32::INFINITY, 0.0f32);
    for &xi in &x[..len] {
        let v = volume(xi);
        v_min = v_min.min(v);
        v_max = v_max.max(v);
    }
    if !(v_min > 0.0) || v_max < 1.2 * v_min {
        return None;
    }
    let mut delta = 0.0f64;
    for _ in 0..3 {
        let d = delta as f32;
        let vol = |i: usize| volume(x[i]) + d;
        // Normal equations of y = c + b·u + e·w in one pass, in f64 (the
        // sums are centred after: f64 holds what centring protects).
        let (mut su, mut sw, mut sy) = (0.0f64, 0.0f64, 0.0f64);
        let (mut suu, mut suw, mut sww, mut suy, mut swy) = (0.0f64, 0.0f64, 0.0f64, 0.0f64, 0.0f64);
        for i in 0..len {
            let v = vol(i);
            let u = math::ln(v) as f64;
            let w = (v_min / v) as f64;
            let y = math::ln(p.at(i) + P_ATM_PA) as f64;
            su += u;
            sw += w;
            sy += y;
            suu += u * u;
            suw += u * w;
            sww += w * w;
            suy += u * y;
            swy += w * y;
        }
        let n = len as f64;
        let (suu, suw, sww) = (suu - su * su / n, suw - su * sw / n, sww - sw * sw / n);
        let (suy, swy) = (suy - su * sy / n, swy - sw * sy / n);
        let det = suu * sww - suw * suw;
        if !(det > 1e-9 * suu * sww) {
            return None;
        }
        let b = (suy * sww - swy * suw) / det;
        let e = (swy * suu - suy * suw) / det;
        if !(b < 0.0) {
            return None;
        }
        // e = −n·δ/V_min with n = −b.
        let step = e / b * v_min as f64;
        delta += step;
        if !(delta > -0.6 * v_min as f64 && delta < v_min as f64) {
            return None;
        }
        if step.abs() < 1e-4 * v_min as f64 {
            break;
        }
    }
    Some(delta as f32)
}

/// Steps 2 and 3 of [`onset`], with the closed phase taken as `..base_end`.
fn read(logs: &impl Logs, dt_s: f32, base_end: usize) -> Option<Onset> {
    let len = logs.len();
    let hold = ((HOLD_S / dt_s) as usize).max(3);
    let min_base = ((MIN_CLOSED_S / dt_s) as usize).max(8);
    if base_end < min_base {
        return None;
    }
    let ln_p = |i: usize| logs.ln_p(i);
    let ln_v = |i: usize| logs.ln_v(i);

    // 2. The closed phase's exponent: ln p = c − n·ln V.
    // With each half's line in the same two passes (the noise's share, and
    // the form's: a chamber that is not exactly polytropic (heat, leaks)
    // gives each half of its closed phase another exponent, a spread the
    // residual's noise does not show).
    let halves = base_end >= 2 * min_base;
    let [line, first_half, second_half] = Line::fit_with_halves(|i| (ln_v(i), ln_p(i)), base_end, halves);
    let line = line?;
    let fitted = -line.slope;
    let (rms, rho) = residual_noise((0..base_end).map(|i| ln_p(i) - line.at(ln_v(i))));
    let inflation = (1.0 + rho) / (1.0 - rho);
    let half = |l: Option<Line>| l.map_or(0.0, |l| -l.slope);
    let split = if halves {
        half(first_half) - half(second_half)
    } else {
        0.0
    };
    let exponent_sd = math::sqrt(rms * rms * inflation / line.sxx + 0.25 * split * split);
    let n_used = if exponent_sd < MAX_EXPONENT_SD { fitted } else { KAPPA };
    let c = (0..base_end).map(|i| ln_p(i) + n_used * ln_v(i)).sum::<f32>() / base_end as f32;
    let r = |i: usize| ln_p(i) + n_used * ln_v(i) - c;

    // 3. The rise: where it holds above the band's foot, then the tangent
    // over the band, extended back to zero.
    let low = RISE_LOW.max(4.0 * rms);
    let high = RISE_HIGH.max(4.0 * low);
    let det = rise_start(len, hold, base_end, |i| r(i) > low)?;
    let mut lo = det;
    while lo > base_end && r(lo - 1) > low {
        lo -= 1;
    }
    let mut hi = det;
    while hi < len && r(hi) <= high {
        hi += 1;
    }
    // At least three samples on a steep rise: one either side of the band.
    let lo = if hi - lo < 3 {
        lo.saturating_sub(1).max(base_end)
    } else {
        lo
    };
    let hi = if hi - lo < 3 { (hi + 1).min(len) } else { hi };
    // A port opened by a moving spool grows in area from zero, so the
    // rise starts as (t − t0)²: its square root is the straight line.
    let root = |i: usize| math::sqrt(if r(i) > 0.0 { r(i) } else { 0.0 });
    let kept = Roots::around(lo, root);
    let g = |i: usize| kept.at(i);
    let first = Line::fit((lo..hi).map(|i| (i as f32, g(i))))?;
    if !(first.slope > 0.0) {
        return None;
    }
    // The band was chosen by the noisy values themselves: a sample enters
    // at its foot only when its noise lifts it, and leaves at its top only
    // when its noise lowers it, which flattens the line and reads the
    // onset early. Chosen again by the fitted line, the band holds the
    // samples whatever their noise.
    let (lo, hi) = band_of(&first, low, high, base_end, len).unwrap_or((lo, hi));
    let tangent = Line::fit((lo..hi).map(|i| (i as f32, g(i))))?;
    if !(tangent.slope > 0.0) {
        return None;
    }
    let k0 = tangent.root();
    // Its uncertainty: the band's mean and slope (independent about the
    // band's centre), the baseline's level, the sample grid; a noise σ in r
    // is σ/(2√r) in √r.
    let m = (hi - lo) as f32;
    let r_mid = tangent.y_mean * tangent.y_mean;
    let var_g = rms * rms * inflation / (4.0 * r_mid);
    let b = tangent.slope;
    let d = k0 - tangent.x_mean;
    // And the form's: where the rise is not (t − t0)² the band's points
    // scatter about the line by more than the noise; the variance is scaled
    // by that excess (the reduced χ², when above one).
    let chi2 = if hi - lo > 2 {
        let ss: f32 = (lo..hi).map(|i| g(i) - tangent.at(i as f32)).map(|e| e * e).sum();
        ss / ((hi - lo - 2) as f32 * var_g)
    } else {
        1.0
    };
    let birge = if chi2 > 1.0 { chi2 } else { 1.0 };
    let var_k = birge
        * (var_g / (m * b * b) + d * d * var_g / (tangent.sxx * b * b) + var_g / (base_end as f32 * b * b))
        + 1.0 / 12.0;
    let onset_s = k0 * dt_s;
    Some(Onset {
        onset_s,
        onset_uncertainty_s: 2.0 * math::sqrt(var_k) * dt_s,
        exponent: fitted,
        exponent_uncertainty: 2.0 * exponent_sd,
        noise_ln: rms,
        rise_s: lo as f32 * dt_s,
    })
}

/// Samples of the rise whose square roots are kept: the band's fits read
/// each five times (two lines of two passes, the χ²), and a board's square
/// root is software (~120 instructions).
const KEPT_ROOTS: usize = 512;

/// √r of the rise's samples from `base` on, each computed once when first
/// read (the same value as computed each time); outside the kept span, as read.
struct Roots<F: Fn(usize) -> f32> {
    base: usize,
    kept: [core::cell::Cell<f32>; KEPT_ROOTS],
    root: F,
}

impl<F: Fn(usize) -> f32> Roots<F> {
    /// Kept from a little before `lo` (the band chosen again by the line
    /// can start earlier). NaN marks a root not yet computed: √ of a
    /// non-negative float is never NaN.
    fn around(lo: usize, root: F) -> Self {
        Self {
            base: lo.saturating_sub(KEPT_ROOTS / 4),
            kept: core::array::from_fn(|_| core::cell::Cell::new(f32::NAN)),
            root,
        }
    }

    fn at(&self, i: usize) -> f32 {
        match i.checked_sub(self.base).and_then(|k| self.kept.get(k)) {
            Some(c) if !c.get().is_nan() => c.get(),
            Some(c) => {
                let v = (self.root)(i);
                c.set(v);
                v
            }
            None => (self.root)(i),
        }
    }
}

/// The samples whose line value lies in the band [`low`, `high`] of the
/// residual (the line is of its square root), at least three, within
/// `from..len`; None where the line leaves no such samples.
fn band_of(line: &Line, low: f32, high: f32, from: usize, len: usize) -> Option<(usize, usize)> {
    let k0 = line.root();
    let start = k0 + math::sqrt(low) / line.slope;
    let end = k0 + math::sqrt(high) / line.slope;
    if !(start.is_finite() && end.is_finite()) || start < from as f32 || end < start || start >= len as f32 {
        return None;
    }
    // Non-negative and below `len` here: `as` is the floor.
    let lo = start as usize + usize::from((start as usize as f32) < start);
    let hi = (end.min(len as f32) as usize + 1).min(len);
    if hi < lo + 3 {
        let mid = (lo + hi) / 2;
        let lo = mid.saturating_sub(1).max(from);
        return (lo + 3 <= len).then_some((lo, lo + 3));
    }
    Some((lo, hi))
}

/// The first index from `from` at which `above` holds for `hold` samples running.
fn rise_start(len: usize, hold: usize, from: usize, above: impl Fn(usize) -> bool) -> Option<usize> {
    let mut run = 0;
    for i in from..len {
        if above(i) {
            run += 1;
            if run == hold {
                return Some(i + 1 - hold);
            }
        } else {
            run = 0;
        }
    }
    None
}

/// RMS of a residual and its lag-one autocorrelation (clamped to [0, 0.9]):
/// a sensor's anti-alias filter correlates neighbouring samples, and a mean
/// over correlated samples is worth fewer independent ones.
fn residual_noise(r: impl Iterator<Item = f32> + Clone) -> (f32, f32) {
    let (mut n, mut ss, mut lag, mut prev) = (0.0f32, 0.0f32, 0.0f32, None::<f32>);
    for v in r {
        n += 1.0;
        ss += v * v;
        if let Some(p) = prev {
            lag += p * v;
        }
        prev = Some(v);
    }
    if n < 3.0 || !(ss > 0.0) {
        return (0.0, 0.0);
    }
    let rho = math::clamp(lag / ss, 0.0, 0.9);
    (math::sqrt(ss / (n - 2.0)), rho)
}

/// A least-squares line's sums, as [`Line::fit`] adds them.
#[derive(Clone, Copy, Default)]
struct Sums {
    n: f32,
    sx: f32,
    sy: f32,
    xm: f32,
    ym: f32,
    sxx: f32,
    sxy: f32,
}

impl Sums {
    fn add(&mut self, x: f32, y: f32) {
        self.n += 1.0;
        self.sx += x;
        self.sy += y;
    }

    fn centre(&mut self) {
        if self.n >= 2.0 {
            (self.xm, self.ym) = (self.sx / self.n, self.sy / self.n);
        }
    }

    fn add_centred(&mut self, x: f32, y: f32) {
        self.sxx += (x - self.xm) * (x - self.xm);
        self.sxy += (x - self.xm) * (y - self.ym);
    }

    fn line(&self) -> Option<Line> {
        (self.n >= 2.0 && self.sxx > 0.0).then(|| Line {
            x_mean: self.xm,
            y_mean: self.ym,
            slope: self.sxy / self.sxx,
            sxx: self.sxx,
        })
    }
}

/// A least-squares line y = y_mean + slope·(x − x_mean).
struct Line {
    x_mean: f32,
    y_mean: f32,
    slope: f32,
    sxx: f32,
}

impl Line {
    fn fit(pts: impl Iterator<Item = (f32, f32)> + Clone) -> Option<Line> {
        let mut s = Sums::default();
        for (x, y) in pts.clone() {
            s.add(x, y);
        }
        if s.n < 2.0 {
            return None;
        }
        s.centre();
        for (x, y) in pts {
            s.add_centred(x, y);
        }
        s.line()
    }

    /// [`Line::fit`] of the points `0..n`, and where `halves` of
    /// `0..n / 2` and `n / 2..n` too, in the same two passes: each sum
    /// added in the same order as three fits would (the same figures),
    /// the points read half as often.
    fn fit_with_halves(pt: impl Fn(usize) -> (f32, f32), n: usize, halves: bool) -> [Option<Line>; 3] {
        let mid = n / 2;
        let mut s = [Sums::default(); 3];
        let part = |i: usize| if i < mid { 1 } else { 2 };
        for i in 0..n {
            let (x, y) = pt(i);
            s[0].add(x, y);
            if halves {
                s[part(i)].add(x, y);
            }
        }
        if s[0].n < 2.0 {
            return [None, None, None];
        }
        for t in s.iter_mut() {
            t.centre();
        }
        for i in 0..n {
            let (x, y) = pt(i);
            s[0].add_centred(x, y);
            if halves {
                s[part(i)].add_centred(x, y);
            }
        }
        s.map(|t| t.line())
    }

    fn at(&self, x: f32) -> f32 {
        self.y_mean + self.slope * (x - self.x_mean)
    }

    /// Where the line meets zero.
    fn root(&self) -> f32 {
        self.x_mean - self.y_mean / self.slope
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const DT: f32 = 1e-5;

    /// A sealed chamber of exponent `n` (at `p0_abs` to start) compressed
    /// at 2.5 m/s from `x0`, then fed from sample `feed_at` on through a
    /// port opening at a steady pace (the air let in grows as (t − t0)²,
    /// and so does ln p at first, by `k`·(t − t0)²): positions and gauge
    /// pressures.
    fn compressed_then_fed<const N: usize>(
        vol: &impl Fn(f32) -> f32,
        x0: f32,
        p0_abs: f32,
        n: f32,
        feed_at: usize,
        k: f32,
    ) -> (heapless::Vec<f32, N>, heapless::Vec<f32, N>) {
        let x: heapless::Vec<f32, N> = (0..N).map(|i| x0 + 2.5 * DT * i as f32).collect();
        let c = math::ln(p0_abs) + n * math::ln(vol(x[0]));
        let p = (0..N)
            .map(|i| {
                let rise = k * (DT * (i as f32 - feed_at as f32).max(0.0)).powi(2);
                math::exp(c - n * math::ln(vol(x[i])) + rise) - P_ATM_PA
            })
            .collect();
        (x, p)
    }

    /// A sealed adiabatic chamber compressed at a steady speed, then fed
    /// from a known sample on through a port opening at a steady pace (the
    /// air let in grows as (t − t0)², and so does ln p at first): the fitted
    /// exponent is 1.4 and the onset lies on the feed's start.
    #[test]
    fn a_sealed_chamber_gives_its_exponent_and_its_feed() {
        let vol = |x: f32| 20e-6 + 7e-4 * (0.052 - x);
        let feed_at = 600usize;
        let (x, p) = compressed_then_fed::<1000>(&vol, 0.025, 2e5, 1.4, feed_at, 2e4);
        let o = onset(&p[..], &x, &vol, DT).expect("a feed");
        assert!((o.exponent - 1.4).abs() < 1e-3, "n = {}", o.exponent);
        let t_feed = feed_at as f32 * DT;
        assert!(
            (o.onset_s - t_feed).abs() < 0.5 * DT,
            "onset {} s, fed at {t_feed} s",
            o.onset_s
        );
        assert!(o.onset_uncertainty_s < 2.0 * DT, "U = {} s", o.onset_uncertainty_s);
    }

    /// The transducer's noise (500 Pa, the simulator's default) must not
    /// pull the onset: over 2000 noisy copies of one feed the mean onset
    /// stays within a tenth of a sample of the noise-free one (one copy
    /// scatters by about 0.9 samples: the mean's standard error is 0.02).
    /// Chosen by the noisy values, the band let in samples lifted by their
    /// noise at its foot and kept out those lifted at its top, which read
    /// the onset a third of a sample early (measured: −0.33 samples).
    #[test]
    fn noise_does_not_pull_the_onset() {
        const N: usize = 1000;
        let vol = |x: f32| 20e-6 + 7e-4 * (0.052 - x);
        let (x, p) = compressed_then_fed::<N>(&vol, 0.025, 2e5, 1.4, 600, 2e5);
        let clean = onset(&p[..], &x, &vol, DT).expect("a feed").onset_s;
        let mut state = 0x2545_f491_4f6c_dd1du64;
        let mut uniform = || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 40) as f32 / (1u64 << 24) as f32
        };
        let (mut sum, mut runs) = (0.0f32, 0usize);
        for _ in 0..2000 {
            let noisy: heapless::Vec<f32, N> = p
                .iter()
                .map(|&v| v + 500.0 * ((0..12).map(|_| uniform()).sum::<f32>() - 6.0))
                .collect();
            if let Some(o) = onset(&noisy[..], &x, &vol, DT) {
                sum += (o.onset_s - clean) / DT;
                runs += 1;
            }
        }
        assert!(runs >= 1900, "{runs} of 2000 read");
        let mean = sum / runs as f32;
        assert!(mean.abs() < 0.1, "mean onset {mean:+.3} samples off the noise-free one");
    }

    /// A chamber whose dead volume is 3 cm³ (15 %) larger than the one
    /// the reading assumes: the offset fitted over the closed phase gives
    /// it back within 3 %, and the same phase read with the right volume
    /// asks for none.
    #[test]
    fn the_closed_phase_gives_the_dead_volume_back() {
        let assumed = |x: f32| 20e-6 + 7e-4 * (0.052 - x);
        let actual = |x: f32| assumed(x) + 3e-6;
        let (x, p) = compressed_then_fed::<1300>(&actual, 0.020, 1.05e5, 1.35, 1100, 2e5);
        let o = onset(&p[..], &x, &actual, DT).expect("a feed");
        let none = dead_volume_offset(&p[..], &x, &actual, DT, &o).expect("identifiable");
        assert!(none.abs() < 0.1e-6, "δ = {none} with the right volume");
        let o = onset(&p[..], &x, &assumed, DT).expect("a feed");
        let d = dead_volume_offset(&p[..], &x, &assumed, DT, &o).expect("identifiable");
        assert!((d - 3e-6).abs() < 0.09e-6, "δ = {d}, 3e-6 hidden");
    }

    /// The logarithms kept in a room read the same onset as computed ones,
    /// bit for bit; a room too short for them is refused.
    #[test]
    fn kept_logarithms_give_the_same_onset() {
        let vol = |x: f32| 20e-6 + 7e-4 * (0.052 - x);
        let (x, p) = compressed_then_fed::<1000>(&vol, 0.025, 2e5, 1.35, 640, 3e4);
        let mut room = [0.0f32; 2000];
        let kept = Cached::fill(&p[..], &x, &vol, &mut room).expect("room for 1000 samples");
        assert_eq!(onset_of(&kept, DT), onset(&p[..], &x, &vol, DT));
        assert!(onset(&p[..], &x, &vol, DT).is_some());
        assert!(Cached::fill(&p[..], &x, &vol, &mut room[..1999]).is_none());
    }

    /// The line and its halves in two passes are the three fits', bit
    /// for bit (the reading's figures do not depend on how it is read).
    #[test]
    fn a_line_and_its_halves_in_two_passes_are_three_fits() {
        let pt = |i: usize| {
            let x = 1e-3 * i as f32 + 0.25 * math::sin_small((i % 7) as f32 * 0.2);
            (x, 2.0 - 1.37 * x + 1e-3 * ((i * 7919) % 13) as f32)
        };
        for n in [0usize, 1, 2, 3, 17, 400, 401] {
            let [all, a, b] = Line::fit_with_halves(pt, n, true);
            let bits = |l: Option<Line>| l.map(|l| [l.x_mean, l.y_mean, l.slope, l.sxx].map(f32::to_bits));
            assert_eq!(bits(all), bits(Line::fit((0..n).map(pt))), "{n}");
            assert_eq!(bits(a), bits(Line::fit((0..n / 2).map(pt))), "{n}");
            assert_eq!(bits(b), bits(Line::fit((n / 2..n).map(pt))), "{n}");
        }
    }

    /// No feed: no onset (the chamber stays closed).
    #[test]
    fn a_chamber_that_stays_closed_has_no_onset() {
        let vol = |x: f32| 20e-6 + 7e-4 * (0.052 - x);
        let x: heapless::Vec<f32, 800> = (0..800).map(|i| 0.025 + 2.5e-5 * i as f32).collect();
        let c = math::ln(2e5) + 1.3 * math::ln(vol(x[0]));
        let p: heapless::Vec<f32, 800> = x
            .iter()
            .map(|&x| math::exp(c - 1.3 * math::ln(vol(x))) - P_ATM_PA)
            .collect();
        assert_eq!(onset(&p[..], &x, &vol, 1e-5), None);
    }
}
