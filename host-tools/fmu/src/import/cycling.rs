//! Whether a run reached steady cycling: the check `hammer fmu check`
//! makes before the diagnosis relies on a foreign model. A hammer cycles
//! once per impact; without an impact counter the rear chamber's pressure
//! marks the cycles (it rises once per stroke).

use super::model::Signals;

/// Steady cycling: cycles in the run's second half and their period.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Cycling {
    pub cycles: usize,
    pub period_s: f64,
    /// (longest − shortest) / mean period over the second half.
    pub spread: f64,
}

/// Cycles at least this many in the second half to call it cycling.
const MIN_CYCLES: usize = 3;

/// The largest period spread still called steady. The built-in model's
/// periods repeat within 1e-4 once started (tests/fmu.rs compares them at
/// 0.01 %); a model a hundred times less regular is still cycling, a
/// model that stalls or keeps changing its rhythm is not.
pub const MAX_SPREAD: f64 = 0.05;

/// The cycle starts (sample indices): increments of the impact counter,
/// else the rear pressure's upward crossings of its mid-range, with a
/// tenth of the range as hysteresis.
fn starts(s: &Signals) -> Vec<usize> {
    if let Some(c) = &s.impacts {
        return (1..c.len()).filter(|&i| c[i] > c[i - 1]).collect();
    }
    let p = &s.p_rear_pa;
    let half = &p[p.len() / 2..];
    let (lo, hi) = half
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| (a.min(x), b.max(x)));
    let span = hi - lo;
    if !(span > 1e-6 * hi.abs().max(1.0)) {
        return Vec::new();
    }
    let (up, down) = (lo + 0.6 * span, lo + 0.4 * span);
    let mut armed = false;
    let mut out = Vec::new();
    for (i, &x) in p.iter().enumerate() {
        if x < down {
            armed = true;
        } else if armed && x > up {
            out.push(i);
            armed = false;
        }
    }
    out
}

/// The run's cycling, or why it is not steady.
pub fn steady(s: &Signals) -> Result<Cycling, String> {
    let n = s.p_rear_pa.len();
    let from = n / 2;
    let st: Vec<usize> = starts(s).into_iter().filter(|&i| i >= from).collect();
    let periods: Vec<f64> = st.windows(2).map(|w| (w[1] - w[0]) as f64 * s.dt_s).collect();
    if periods.len() < MIN_CYCLES {
        return Err(format!(
            "the run never reaches steady cycling: {} cycles in its second half ({:.3} s), {MIN_CYCLES} needed",
            periods.len(),
            (n - from) as f64 * s.dt_s
        ));
    }
    let mean = periods.iter().sum::<f64>() / periods.len() as f64;
    let (lo, hi) = periods
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| (a.min(x), b.max(x)));
    let spread = (hi - lo) / mean;
    if spread > MAX_SPREAD {
        return Err(format!(
            "the run never reaches steady cycling: periods {:.2}–{:.2} ms in its second half (spread {:.0} %, {:.0} % allowed)",
            lo * 1e3,
            hi * 1e3,
            spread * 100.0,
            MAX_SPREAD * 100.0
        ));
    }
    Ok(Cycling {
        cycles: periods.len(),
        period_s: mean,
        spread,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn signals(p: Vec<f64>) -> Signals {
        Signals {
            dt_s: 1e-4,
            p_front_pa: vec![0.0; p.len()],
            accel_mps2: vec![0.0; p.len()],
            p_rear_pa: p,
            position_m: None,
            velocity_mps: None,
            impacts: None,
        }
    }

    #[test]
    fn a_steady_wave_cycles_and_a_stall_or_a_chirp_does_not() {
        let wave: Vec<f64> = (0..4000)
            .map(|i| (i as f64 * 1e-4 * 2.0 * std::f64::consts::PI * 50.0).sin())
            .collect();
        let c = steady(&signals(wave)).unwrap();
        assert!((c.period_s - 0.02).abs() < 2e-4, "{c:?}");
        assert!(steady(&signals(vec![3e5; 4000])).unwrap_err().contains("never reaches"));
        let chirp: Vec<f64> = (0..4000)
            .map(|i| {
                let t = i as f64 * 1e-4;
                (2.0 * std::f64::consts::PI * (20.0 * t + 60.0 * t * t)).sin()
            })
            .collect();
        assert!(steady(&signals(chirp)).unwrap_err().contains("spread"));
    }
}
