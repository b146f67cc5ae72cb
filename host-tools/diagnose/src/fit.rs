//! Levenberg–Marquardt on weighted residuals whose Jacobian comes from finite
//! differences: each residual evaluation is a simulation, so the method must
//! need few of them and survive one that fails (a hammer that stalls).

/// One free parameter: its bounds and whether it lives on a log scale
/// (positive quantities spanning decades: a leakage gap, a time constant).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ParamSpec {
    pub key: &'static str,
    pub lo: f64,
    pub hi: f64,
    pub log: bool,
    /// Finite-difference step: relative (log scale) or absolute.
    pub step: f64,
}

impl ParamSpec {
    /// The value on the scale the fit moves in (its log for a log-scale parameter), clamped to the bounds.
    pub(crate) fn to_u(&self, x: f64) -> f64 {
        let x = x.clamp(self.lo, self.hi);
        if self.log {
            x.ln()
        } else {
            x
        }
    }

    /// Back from the fit's scale, clamped to the bounds.
    pub(crate) fn from_u(&self, u: f64) -> f64 {
        let x = if self.log { u.exp() } else { u };
        x.clamp(self.lo, self.hi)
    }
}

#[derive(Debug, Clone)]
pub struct FitResult {
    pub theta: Vec<f64>,
    /// Standard deviation of each parameter (scaled by the reduced χ² when it exceeds 1).
    pub sd: Vec<f64>,
    pub chi2: f64,
    pub evaluations: usize,
    pub iterations: usize,
}

/// Minimises Σ r² over `theta` from `theta0`. `residuals` returns the
/// weighted residual vector (fixed length) or `None` when the model fails
/// there, which counts as an infinitely bad point.
pub fn levenberg_marquardt(
    specs: &[ParamSpec],
    theta0: &[f64],
    max_iterations: usize,
    residuals: &mut dyn FnMut(&[f64]) -> Option<Vec<f64>>,
) -> Option<FitResult> {
    let k = specs.len();
    let to_theta = |u: &[f64]| -> Vec<f64> { specs.iter().zip(u).map(|(s, &u)| s.from_u(u)).collect() };
    let mut u: Vec<f64> = specs.iter().zip(theta0).map(|(s, &x)| s.to_u(x)).collect();
    let mut evaluations = 1;
    let mut r = residuals(&to_theta(&u))?;
    let chi2 = |r: &[f64]| r.iter().map(|x| x * x).sum::<f64>();
    let mut c = chi2(&r);
    let mut lambda = 1e-2;
    let mut jac = vec![vec![0.0; r.len()]; k];
    let mut iterations = 0;
    let mut fresh_jacobian = false;
    while iterations < max_iterations {
        iterations += 1;
        if !fresh_jacobian {
            for (i, s) in specs.iter().enumerate() {
                let mut up = u.clone();
                // Step away from a bound rather than into it.
                let h = if s.to_u(s.from_u(u[i] + s.step)) > u[i] {
                    s.step
                } else {
                    -s.step
                };
                up[i] += h;
                evaluations += 1;
                let rp = residuals(&to_theta(&up))?;
                for (j, (a, b)) in rp.iter().zip(&r).enumerate() {
                    jac[i][j] = (a - b) / h;
                }
            }
            fresh_jacobian = true;
        }
        let (jtj, jtr) = normal_equations(&jac, &r);
        let mut improved = false;
        for _ in 0..6 {
            let mut a = jtj.clone();
            for i in 0..k {
                a[i][i] += lambda * jtj[i][i].max(1e-12);
            }
            let Some(delta) = solve(a, jtr.iter().map(|x| -x).collect()) else {
                lambda *= 10.0;
                continue;
            };
            let trial: Vec<f64> = specs
                .iter()
                .zip(u.iter().zip(&delta))
                .map(|(s, (&u, &d))| s.to_u(s.from_u(u + d)))
                .collect();
            evaluations += 1;
            if let Some(rt) = residuals(&to_theta(&trial)) {
                let ct = chi2(&rt);
                if ct < c {
                    let gain = (c - ct) / c.max(1e-300);
                    u = trial;
                    r = rt;
                    c = ct;
                    lambda = (lambda / 5.0).max(1e-7);
                    improved = true;
                    fresh_jacobian = false;
                    if gain < 1e-4 {
                        iterations = max_iterations;
                    }
                    break;
                }
            }
            lambda *= 8.0;
        }
        if !improved {
            break;
        }
    }
    let theta = to_theta(&u);
    let (jtj, _) = normal_equations(&jac, &r);
    let dof = r.len().saturating_sub(k).max(1) as f64;
    let scale = (c / dof).max(1.0);
    let sd = match invert(jtj) {
        Some(inv) => specs
            .iter()
            .enumerate()
            .map(|(i, s)| {
                let su = (inv[i][i] * scale).max(0.0).sqrt();
                if s.log {
                    theta[i] * su
                } else {
                    su
                }
            })
            .collect(),
        None => vec![f64::INFINITY; k],
    };
    Some(FitResult {
        theta,
        sd,
        chi2: c,
        evaluations,
        iterations,
    })
}

fn normal_equations(jac: &[Vec<f64>], r: &[f64]) -> (Vec<Vec<f64>>, Vec<f64>) {
    let k = jac.len();
    let mut jtj = vec![vec![0.0; k]; k];
    let mut jtr = vec![0.0; k];
    for i in 0..k {
        for j in 0..k {
            jtj[i][j] = jac[i].iter().zip(&jac[j]).map(|(a, b)| a * b).sum();
        }
        jtr[i] = jac[i].iter().zip(r).map(|(a, b)| a * b).sum();
    }
    (jtj, jtr)
}

/// Solves a·x = b by Gaussian elimination with partial pivoting.
pub fn solve(mut a: Vec<Vec<f64>>, mut b: Vec<f64>) -> Option<Vec<f64>> {
    let n = b.len();
    for c in 0..n {
        let p = (c..n).max_by(|&x, &y| a[x][c].abs().total_cmp(&a[y][c].abs()))?;
        if a[p][c].abs() < 1e-300 || !a[p][c].is_finite() {
            return None;
        }
        a.swap(c, p);
        b.swap(c, p);
        for r in c + 1..n {
            let f = a[r][c] / a[c][c];
            for j in c..n {
                a[r][j] -= f * a[c][j];
            }
            b[r] -= f * b[c];
        }
    }
    let mut x = vec![0.0; n];
    for i in (0..n).rev() {
        let s: f64 = (i + 1..n).map(|j| a[i][j] * x[j]).sum();
        x[i] = (b[i] - s) / a[i][i];
    }
    x.iter().all(|v| v.is_finite()).then_some(x)
}

fn invert(a: Vec<Vec<f64>>) -> Option<Vec<Vec<f64>>> {
    let n = a.len();
    let mut cols = Vec::with_capacity(n);
    for i in 0..n {
        let mut e = vec![0.0; n];
        e[i] = 1.0;
        cols.push(solve(a.clone(), e)?);
    }
    Some((0..n).map(|i| (0..n).map(|j| cols[j][i]).collect()).collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fits_a_curve_with_one_log_and_one_linear_parameter() {
        // y = a·exp(−x/τ) + noise-free: recover a = 3, τ = 0.2 from far away.
        let xs: Vec<f64> = (0..40).map(|i| i as f64 * 0.025).collect();
        let specs = [
            ParamSpec {
                key: "a",
                lo: -10.0,
                hi: 10.0,
                log: false,
                step: 1e-3,
            },
            ParamSpec {
                key: "tau",
                lo: 1e-3,
                hi: 10.0,
                log: true,
                step: 1e-3,
            },
        ];
        let mut f = |t: &[f64]| -> Option<Vec<f64>> {
            Some(
                xs.iter()
                    .map(|x| (t[0] * (-x / t[1]).exp() - 3.0 * (-x / 0.2).exp()) / 0.01)
                    .collect(),
            )
        };
        let fit = levenberg_marquardt(&specs, &[1.0, 1.0], 50, &mut f).unwrap();
        assert!((fit.theta[0] - 3.0).abs() < 1e-3, "{:?}", fit.theta);
        assert!((fit.theta[1] - 0.2).abs() < 1e-4, "{:?}", fit.theta);
        assert!(fit.chi2 < 1e-4);
    }

    #[test]
    fn a_failing_model_is_stepped_around() {
        let specs = [ParamSpec {
            key: "x",
            lo: 0.0,
            hi: 10.0,
            log: false,
            step: 1e-3,
        }];
        // Fails above 6; the optimum is at 5.
        let mut f = |t: &[f64]| (t[0] <= 6.0).then(|| vec![t[0] - 5.0]);
        let fit = levenberg_marquardt(&specs, &[1.0], 50, &mut f).unwrap();
        assert!((fit.theta[0] - 5.0).abs() < 1e-3, "{:?}", fit.theta);
    }
}
