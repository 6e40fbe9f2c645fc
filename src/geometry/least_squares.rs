//! Small nonlinear least squares: Levenberg-Marquardt with a central-difference Jacobian, for
//! problems of a few parameters (a jaw pose's rig parameters, a rig's origin).

use nalgebra::{DMatrix, DVector};

/// Minimise Σ r(x)² from `start` in at most `steps` accepted steps; `h` is the difference
/// step. Returns the best point found.
pub fn levenberg_marquardt(
    residual: impl Fn(&[f64]) -> Vec<f64>,
    start: &[f64],
    steps: usize,
    h: f64,
) -> Vec<f64> {
    let n = start.len();
    let cost = |r: &[f64]| r.iter().map(|v| v * v).sum::<f64>();
    let mut x = start.to_vec();
    let mut r = residual(&x);
    let mut lambda = 1e-3;
    for _ in 0..steps {
        let m = r.len();
        let mut jac = DMatrix::<f64>::zeros(m, n);
        for k in 0..n {
            let (mut a, mut b) = (x.clone(), x.clone());
            a[k] += h;
            b[k] -= h;
            for (i, (p, q)) in residual(&a).iter().zip(residual(&b)).enumerate() {
                jac[(i, k)] = (p - q) / (2.0 * h);
            }
        }
        let jtj = jac.transpose() * &jac;
        let jtr = jac.transpose() * DVector::from_column_slice(&r);
        let mut improved = false;
        for _ in 0..8 {
            let mut damped = jtj.clone();
            for k in 0..n {
                damped[(k, k)] += lambda * jtj[(k, k)].max(1e-12);
            }
            let Some(step) = damped.cholesky().map(|c| c.solve(&-&jtr)) else {
                lambda *= 10.0;
                continue;
            };
            let trial: Vec<f64> = x.iter().zip(step.iter()).map(|(a, b)| a + b).collect();
            let rt = residual(&trial);
            if cost(&rt) < cost(&r) {
                x = trial;
                r = rt;
                lambda = (lambda * 0.3).max(1e-12);
                improved = true;
                break;
            }
            lambda *= 10.0;
        }
        if !improved {
            break;
        }
    }
    x
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fits_an_exponential() {
        // y = a·exp(b·t) from exact samples.
        let ts: Vec<f64> = (0..10).map(|i| i as f64 * 0.2).collect();
        let ys: Vec<f64> = ts.iter().map(|t| 2.0 * (0.7 * t).exp()).collect();
        let x = levenberg_marquardt(
            |p| {
                ts.iter()
                    .zip(&ys)
                    .map(|(t, y)| p[0] * (p[1] * t).exp() - y)
                    .collect()
            },
            &[1.0, 0.0],
            50,
            1e-6,
        );
        assert!(
            (x[0] - 2.0).abs() < 1e-6 && (x[1] - 0.7).abs() < 1e-6,
            "{x:?}"
        );
    }
}
