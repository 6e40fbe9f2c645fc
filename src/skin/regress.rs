//! The mapping Φ from skin features to bone features (the paper's Section 5.2): one ε-SVR
//! with an RBF kernel per bone point and coordinate (linfa-svm's SMO solver), all reading the
//! same inputs. The skin features are first projected on their principal components (most of
//! the variance in a few dozen of the ~700 coordinates: the rest is tracker noise), which
//! makes the kernel cheap to learn and to evaluate and smooths the noise away. The kernel's
//! width and the penalty C are chosen on held-out frames.

use linfa::prelude::*;
use linfa_svm::Svm;
use nalgebra::{DMatrix, SymmetricEigen};
use ndarray::{Array1, Array2};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// How the mapping is learned: a documented setting.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RegressSettings {
    /// Keep principal components up to this share of the skin features' variance …
    pub variance: f64,
    /// … and at most this many.
    pub max_components: usize,
    /// Frames the final SVRs learn from at most (evenly spaced over the training frames): the
    /// solver's time grows with the square of it.
    pub max_samples: usize,
    /// Frames the hyperparameter search learns from at most.
    pub search_samples: usize,
    /// The ε-insensitive zone, in standard deviations of each bone coordinate.
    pub epsilon: f64,
    /// Kernel widths tried, as multiples of the median squared distance between inputs.
    pub widths: Vec<f64>,
    /// Penalties C tried (the targets are standardised).
    pub penalties: Vec<f64>,
    /// Share of the training frames (the last ones) held out to choose the hyperparameters.
    pub held_out: f64,
    /// The SMO solver's stopping tolerance (on the standardised targets). linfa's default,
    /// 1e-7, is far stricter than the skin's noise warrants and many times slower (docs/skin.md
    /// has the trade). linfa's shrinking is left off: in linfa-svm 0.8.1 it indexes out of
    /// bounds on regression problems.
    pub tolerance: f64,
}

impl Default for RegressSettings {
    fn default() -> Self {
        RegressSettings {
            variance: 0.9995,
            max_components: 40,
            max_samples: 1500,
            search_samples: 400,
            epsilon: 0.01,
            widths: vec![4.0, 16.0],
            penalties: vec![30.0, 100.0],
            held_out: 0.2,
            tolerance: 0.02,
        }
    }
}

#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RegressError {
    #[error("{0} training frames; the mapping needs at least 8")]
    TooFewFrames(usize),
    #[error("the skin features do not vary over the training frames")]
    NoVariance,
    #[error("the SVR solver failed: {0}")]
    Solver(String),
}

/// One bone coordinate's regressor over the shared support rows.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Output {
    pub alpha: Vec<f64>,
    pub rho: f64,
    /// The target's standardisation: value = mean + scale · SVR output.
    pub mean: f64,
    pub scale: f64,
}

/// A learned mapping: skin features (flattened displacements) → bone features.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Regressor {
    /// Mean of the skin features, and the principal directions (one row each).
    pub mean: Vec<f64>,
    pub basis: Vec<Vec<f64>>,
    /// Inputs (in principal coordinates) that are a support vector of any output.
    pub support: Vec<Vec<f64>>,
    /// The kernel exp(−|z − z_i|² / width).
    pub width: f64,
    pub outputs: Vec<Output>,
    /// What the search chose and what it measured on the held-out frames (mean bone point
    /// error, mm).
    pub penalty: f64,
    pub width_multiple: f64,
    pub held_out_mm: f64,
    pub components: usize,
    pub samples: usize,
}

impl Regressor {
    /// Learn from `x` (frames × skin features) and `y` (frames × bone features); the rows
    /// from `cut` on are held out to choose the hyperparameters, then all of them learn.
    pub fn learn(
        x: &[Vec<f64>],
        y: &[Vec<f64>],
        cut: usize,
        s: &RegressSettings,
    ) -> Result<Regressor, RegressError> {
        let n = x.len();
        if n < 8 {
            return Err(RegressError::TooFewFrames(n));
        }
        let (mean, basis) = principal_components(x, s)?;
        let z: Vec<Vec<f64>> = x.iter().map(|f| project(&mean, &basis, f)).collect();
        let width0 = median_sq_distance(&z).max(1e-12);
        // Hyperparameters, on held-out frames.
        let cut = cut.clamp(4, n - 2);
        let fit_rows = spaced(0..cut, s.search_samples);
        let test_rows = spaced(cut..n, s.search_samples / 2);
        let mut best = (f64::INFINITY, s.widths[0], s.penalties[0]);
        for &wm in &s.widths {
            for &c in &s.penalties {
                let m = fit_svrs(&z, y, &fit_rows, width0 * wm, c, s)?;
                let err = bone_error(&m, width0 * wm, &z, y, &test_rows);
                if err < best.0 {
                    best = (err, wm, c);
                }
            }
        }
        let rows = spaced(0..n, s.max_samples);
        let (support, outputs) = fit_svrs(&z, y, &rows, width0 * best.1, best.2, s)?;
        Ok(Regressor {
            components: basis.len(),
            mean,
            basis,
            support,
            width: width0 * best.1,
            outputs,
            penalty: best.2,
            width_multiple: best.1,
            held_out_mm: best.0,
            samples: rows.len(),
        })
    }

    /// The principal coordinates of skin features `f`.
    pub fn project(&self, f: &[f64]) -> Vec<f64> {
        project(&self.mean, &self.basis, f)
    }

    /// Bone features predicted for skin features `f`.
    pub fn predict(&self, f: &[f64]) -> Vec<f64> {
        let z = self.project(f);
        let k = self.kernel_row(&z);
        self.outputs.iter().map(|o| o.value(&k)).collect()
    }

    fn kernel_row(&self, z: &[f64]) -> Vec<f64> {
        self.support
            .iter()
            .map(|s| (-sq_dist(s, z) / self.width).exp())
            .collect()
    }

    /// The prediction and its Jacobian with respect to the skin features (outputs × inputs),
    /// for retargeting.
    pub fn predict_with_jacobian(&self, f: &[f64]) -> (Vec<f64>, DMatrix<f64>) {
        let z = self.project(f);
        let k = self.kernel_row(&z);
        let dim = z.len();
        let mut dz = DMatrix::<f64>::zeros(self.outputs.len(), dim);
        let mut value = Vec::with_capacity(self.outputs.len());
        for (o, out) in self.outputs.iter().enumerate() {
            value.push(out.value(&k));
            for (i, s) in self.support.iter().enumerate() {
                let a = out.alpha[i] * k[i];
                if a == 0.0 {
                    continue;
                }
                let g = -2.0 * a * out.scale / self.width;
                for j in 0..dim {
                    dz[(o, j)] += g * (z[j] - s[j]);
                }
            }
        }
        let basis = DMatrix::from_fn(dim, self.mean.len(), |r, c| self.basis[r][c]);
        (value, dz * basis)
    }
}

impl Output {
    fn value(&self, k: &[f64]) -> f64 {
        let s: f64 = self.alpha.iter().zip(k).map(|(a, k)| a * k).sum();
        self.mean + self.scale * (s - self.rho)
    }
}

/// Up to `most` indices spread evenly over `range`.
fn spaced(range: std::ops::Range<usize>, most: usize) -> Vec<usize> {
    let len = range.len();
    if len <= most.max(1) {
        return range.collect();
    }
    (0..most).map(|i| range.start + i * len / most).collect()
}

fn sq_dist(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(p, q)| (p - q) * (p - q)).sum()
}

fn project(mean: &[f64], basis: &[Vec<f64>], f: &[f64]) -> Vec<f64> {
    basis
        .iter()
        .map(|b| {
            b.iter()
                .zip(f.iter().zip(mean))
                .map(|(w, (x, m))| w * (x - m))
                .sum()
        })
        .collect()
}

/// The mean and the leading principal directions of the rows of `x`.
fn principal_components(
    x: &[Vec<f64>],
    s: &RegressSettings,
) -> Result<(Vec<f64>, Vec<Vec<f64>>), RegressError> {
    let (n, d) = (x.len(), x[0].len());
    let mut mean = vec![0.0; d];
    for f in x {
        for (m, v) in mean.iter_mut().zip(f) {
            *m += v / n as f64;
        }
    }
    let centred = DMatrix::from_fn(n, d, |r, c| x[r][c] - mean[c]);
    // The smaller Gram or covariance matrix: the same nonzero spectrum.
    let (values, dirs): (Vec<f64>, Vec<Vec<f64>>) = if n < d {
        let gram = &centred * centred.transpose();
        let e = SymmetricEigen::new(gram);
        let mut order: Vec<usize> = (0..n).collect();
        order.sort_by(|&a, &b| e.eigenvalues[b].total_cmp(&e.eigenvalues[a]));
        order
            .into_iter()
            .filter(|&i| e.eigenvalues[i] > 0.0)
            .map(|i| {
                let u = e.eigenvectors.column(i);
                let v = centred.transpose() * u;
                let norm = v.norm().max(1e-300);
                (e.eigenvalues[i], v.iter().map(|x| x / norm).collect())
            })
            .unzip()
    } else {
        let cov = centred.transpose() * &centred;
        let e = SymmetricEigen::new(cov);
        let mut order: Vec<usize> = (0..d).collect();
        order.sort_by(|&a, &b| e.eigenvalues[b].total_cmp(&e.eigenvalues[a]));
        order
            .into_iter()
            .filter(|&i| e.eigenvalues[i] > 0.0)
            .map(|i| {
                (
                    e.eigenvalues[i],
                    e.eigenvectors.column(i).iter().copied().collect(),
                )
            })
            .unzip()
    };
    let total: f64 = values.iter().sum();
    // Variance at the level of the mean's rounding is none.
    let scale: f64 = x.iter().flatten().map(|v| v * v).sum();
    if total.is_nan() || total <= 1e-20 * scale {
        return Err(RegressError::NoVariance);
    }
    let mut keep = 0;
    let mut acc = 0.0;
    while keep < values.len() && keep < s.max_components.max(1) && acc < s.variance * total {
        acc += values[keep];
        keep += 1;
    }
    Ok((mean, dirs.into_iter().take(keep.max(1)).collect()))
}

/// The median squared distance between inputs (over a few hundred pairs): the kernel width's
/// unit.
fn median_sq_distance(z: &[Vec<f64>]) -> f64 {
    let n = z.len();
    let mut d: Vec<f64> = (0..n.min(400))
        .map(|i| {
            let a = i * n / n.min(400);
            let b = (a * 7919 + n / 2) % n;
            sq_dist(&z[a], &z[b])
        })
        .filter(|d| *d > 0.0)
        .collect();
    if d.is_empty() {
        return 1.0;
    }
    d.sort_by(f64::total_cmp);
    d[d.len() / 2]
}

/// One SVR per output on `rows`; the support rows they share and each output over them.
fn fit_svrs(
    z: &[Vec<f64>],
    y: &[Vec<f64>],
    rows: &[usize],
    width: f64,
    c: f64,
    s: &RegressSettings,
) -> Result<(Vec<Vec<f64>>, Vec<Output>), RegressError> {
    let dim = z[0].len();
    let records = Array2::from_shape_fn((rows.len(), dim), |(r, j)| z[rows[r]][j]);
    let outputs = y[0].len();
    let fitted: Vec<(Vec<f64>, Output)> = (0..outputs)
        .into_par_iter()
        .map(|o| {
            let t: Vec<f64> = rows.iter().map(|&r| y[r][o]).collect();
            let mean = t.iter().sum::<f64>() / t.len() as f64;
            let var = t.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / t.len() as f64;
            let scale = var.sqrt().max(1e-9);
            let targets = Array1::from_iter(t.iter().map(|v| (v - mean) / scale));
            let data = linfa::Dataset::new(records.clone(), targets);
            let svm = Svm::<f64, f64>::params()
                .c_svr(c, Some(s.epsilon))
                .eps(s.tolerance)
                .gaussian_kernel(width)
                .fit(&data)
                .map_err(|e| RegressError::Solver(e.to_string()))?;
            Ok((
                svm.alpha.clone(),
                Output {
                    alpha: Vec::new(),
                    rho: svm.rho,
                    mean,
                    scale,
                },
            ))
        })
        .collect::<Result<_, RegressError>>()?;
    let used: Vec<usize> = (0..rows.len())
        .filter(|&i| fitted.iter().any(|(a, _)| a[i] != 0.0))
        .collect();
    let support = used.iter().map(|&i| z[rows[i]].clone()).collect();
    let outputs = fitted
        .into_iter()
        .map(|(a, mut o)| {
            o.alpha = used.iter().map(|&i| a[i]).collect();
            o
        })
        .collect();
    Ok((support, outputs))
}

/// Mean bone point error (mm) on `rows` of SVRs over `support`.
fn bone_error(
    (support, outputs): &(Vec<Vec<f64>>, Vec<Output>),
    width: f64,
    z: &[Vec<f64>],
    y: &[Vec<f64>],
    rows: &[usize],
) -> f64 {
    let mut total = 0.0;
    for &r in rows {
        let k: Vec<f64> = support
            .iter()
            .map(|s| (-sq_dist(s, &z[r]) / width).exp())
            .collect();
        let pred: Vec<f64> = outputs.iter().map(|o| o.value(&k)).collect();
        total += point_errors(&pred, &y[r]);
    }
    total / rows.len().max(1) as f64
}

/// Mean distance between two sets of points given as flattened coordinates.
pub fn point_errors(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len() / 3;
    (0..n)
        .map(|i| sq_dist(&a[3 * i..3 * i + 3], &b[3 * i..3 * i + 3]).sqrt())
        .sum::<f64>()
        / n.max(1) as f64
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A smooth nonlinear map of 12 inputs (uniform in a cube, most of them irrelevant) to
    /// 3 outputs.
    fn data(n: usize) -> (Vec<Vec<f64>>, Vec<Vec<f64>>) {
        let mut state = 12345u64;
        let mut uniform = move || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
        };
        let x: Vec<Vec<f64>> = (0..n)
            .map(|_| (0..12).map(|_| uniform()).collect())
            .collect();
        let y = x
            .iter()
            .map(|f| vec![2.0 * f[0] + f[1], (2.0 * f[2]).sin(), f[0] * f[1]])
            .collect();
        (x, y)
    }

    fn small() -> RegressSettings {
        RegressSettings {
            widths: vec![1.0, 4.0],
            penalties: vec![10.0],
            ..RegressSettings::default()
        }
    }

    #[test]
    fn learns_a_smooth_map_better_than_its_mean() {
        let (x, y) = data(300);
        let r = Regressor::learn(&x[..250], &y[..250], 200, &small()).unwrap();
        let (mut err, mut spread) = (0.0, 0.0);
        let mean: Vec<f64> = (0..3)
            .map(|o| y[..250].iter().map(|v| v[o]).sum::<f64>() / 250.0)
            .collect();
        for i in 250..300 {
            let p = r.predict(&x[i]);
            err += point_errors(&p, &y[i]);
            spread += point_errors(&mean, &y[i]);
        }
        assert!(
            err < 0.2 * spread,
            "error {err} vs predicting the mean {spread}"
        );
    }

    #[test]
    fn the_jacobian_matches_finite_differences() {
        let (x, y) = data(120);
        let r = Regressor::learn(&x, &y, 100, &small()).unwrap();
        let f = x[7].iter().map(|v| v + 0.1).collect::<Vec<_>>();
        let (value, jac) = r.predict_with_jacobian(&f);
        assert_eq!(value, r.predict(&f));
        let h = 1e-5;
        for j in 0..f.len() {
            let (mut a, mut b) = (f.clone(), f.clone());
            a[j] += h;
            b[j] -= h;
            let (pa, pb) = (r.predict(&a), r.predict(&b));
            for o in 0..3 {
                let fd = (pa[o] - pb[o]) / (2.0 * h);
                assert!(
                    (fd - jac[(o, j)]).abs() < 1e-5 * (1.0 + fd.abs()),
                    "output {o}, input {j}: {fd} vs {}",
                    jac[(o, j)]
                );
            }
        }
    }

    #[test]
    fn too_few_frames_is_an_error_not_a_panic() {
        let (x, y) = data(5);
        assert_eq!(
            Regressor::learn(&x, &y, 4, &small()).unwrap_err(),
            RegressError::TooFewFrames(5)
        );
        let flat = vec![vec![1.0; 4]; 20];
        let y = vec![vec![0.0; 3]; 20];
        assert_eq!(
            Regressor::learn(&flat, &y, 16, &small()).unwrap_err(),
            RegressError::NoVariance
        );
    }
}
