//! The manifold map Φ3D→6D (Zoss et al. 2018, Eq. 3, 9): normalised Gaussian radial basis
//! functions, centres spread uniformly inside the envelope (a grid in the unit cube), a width
//! per kernel (its spacing to the nearest centres times a common factor), weights in the
//! 6-DOF rig's parameters.
//!
//! Eq. 9 fits weights and widths together; here, for a given width factor the weights are a
//! linear least-squares problem (normalised RBFs are linear in their weights), and the factor
//! is chosen among a few by the error on every fifth pose held out, then the weights refitted
//! on all. The kernels fit what an affine map of the point leaves (a polynomial tail, as is
//! usual with RBFs), with a small ridge: where the envelope holds no captured pose, the map
//! falls back to the affine trend rather than to zero.

use nalgebra::{DMatrix, Vector3};
use serde::{Deserialize, Serialize};

use super::shield::Shield;

#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct Rbf {
    pub centres: Vec<[f64; 3]>,
    pub sigmas: Vec<f64>,
    /// One row of six weights per centre.
    pub weights: Vec<[f64; 6]>,
    /// The affine tail: rows for x, y, z and the constant.
    pub affine: [[f64; 6]; 4],
}

/// Centres per cube axis at most; fewer for few poses (about three poses per kernel), so that
/// a short or noisy capture does not get a map that swings between its points: with more
/// kernels than its poses can pin down, the fit is free between them.
pub const GRID: usize = 6;
const MIN_GRID: usize = 2;
/// Width factors tried.
const FACTORS: [f64; 5] = [0.5, 0.75, 1.0, 1.5, 2.0];
/// Ridges tried, relative to the mean diagonal of the normal equations.
const RIDGES: [f64; 3] = [1e-6, 1e-4, 1e-2];
/// Nearest centres whose mean distance sets a kernel's spacing.
const SPACING_NEIGHBOURS: usize = 6;

impl Rbf {
    fn features(centres: &[[f64; 3]], sigmas: &[f64], p: &Vector3<f64>, out: &mut [f64]) {
        let d2 = |c: &[f64; 3]| (p - Vector3::from(*c)).norm_squared();
        let mut total = 0.0;
        for ((c, s), o) in centres.iter().zip(sigmas).zip(out.iter_mut()) {
            *o = (-0.5 * d2(c) / (s * s)).exp();
            total += *o;
        }
        if total > 0.0 {
            out.iter_mut().for_each(|v| *v /= total);
        } else {
            // Far from every kernel: the nearest one alone.
            let nearest = centres
                .iter()
                .enumerate()
                .min_by(|a, b| d2(a.1).total_cmp(&d2(b.1)))
                .map_or(0, |(i, _)| i);
            out.iter_mut()
                .enumerate()
                .for_each(|(i, v)| *v = (i == nearest) as u8 as f64);
        }
    }

    pub fn eval(&self, p: &Vector3<f64>) -> [f64; 6] {
        let mut f = vec![0.0; self.centres.len()];
        Self::features(&self.centres, &self.sigmas, p, &mut f);
        let a = &self.affine;
        let mut out: [f64; 6] =
            std::array::from_fn(|k| a[3][k] + a[0][k] * p.x + a[1][k] * p.y + a[2][k] * p.z);
        for (w, fi) in self.weights.iter().zip(&f) {
            out.iter_mut().zip(w).for_each(|(o, wk)| *o += wk * fi);
        }
        out
    }

    fn solve(
        centres: &[[f64; 3]],
        sigmas: &[f64],
        points: &[Vector3<f64>],
        targets: &[[f64; 6]],
        ridge: f64,
    ) -> Vec<[f64; 6]> {
        let n = centres.len();
        let mut a = DMatrix::<f64>::zeros(points.len(), n);
        let mut f = vec![0.0; n];
        for (r, p) in points.iter().enumerate() {
            Self::features(centres, sigmas, p, &mut f);
            for c in 0..n {
                a[(r, c)] = f[c];
            }
        }
        let mut ata = a.transpose() * &a;
        let ridge = ridge * (0..n).map(|i| ata[(i, i)]).sum::<f64>() / n as f64;
        for i in 0..n {
            ata[(i, i)] += ridge.max(1e-12);
        }
        let b = DMatrix::from_fn(points.len(), 6, |r, k| targets[r][k]);
        let atb = a.transpose() * b;
        let x = ata
            .cholesky()
            .map(|c| c.solve(&atb))
            .unwrap_or_else(|| DMatrix::zeros(n, 6));
        (0..n).map(|i| std::array::from_fn(|k| x[(i, k)])).collect()
    }

    /// Fit to points (jaw frame) and their 6-DOF parameters.
    pub fn fit(shield: &Shield, points: &[Vector3<f64>], targets: &[[f64; 6]]) -> Rbf {
        let affine = affine_fit(points, targets);
        let residuals: Vec<[f64; 6]> = points
            .iter()
            .zip(targets)
            .map(|(p, t)| {
                std::array::from_fn(|k| {
                    t[k] - (affine[0][k] * p.x
                        + affine[1][k] * p.y
                        + affine[2][k] * p.z
                        + affine[3][k])
                })
            })
            .collect();
        let targets = &residuals[..];
        let grid = ((points.len() as f64 / 3.0).cbrt().floor() as usize).clamp(MIN_GRID, GRID);
        let mut centres = Vec::with_capacity(grid * grid * grid);
        for i in 0..grid {
            for j in 0..grid {
                for k in 0..grid {
                    let s = [i, j, k].map(|v| (v as f64 + 0.5) / grid as f64);
                    centres.push(shield.point(&s));
                }
            }
        }
        let stored: Vec<[f64; 3]> = centres.iter().map(|c| [c.x, c.y, c.z]).collect();
        let spacing: Vec<f64> = centres
            .iter()
            .map(|c| {
                let mut d: Vec<f64> = centres
                    .iter()
                    .map(|o| (o - c).norm())
                    .filter(|&d| d > 0.0)
                    .collect();
                d.sort_by(f64::total_cmp);
                let k = d.len().clamp(1, SPACING_NEIGHBOURS);
                (d.iter().take(k).sum::<f64>() / k as f64).max(1e-3)
            })
            .collect();
        let (train, held): (Vec<usize>, Vec<usize>) = (0..points.len()).partition(|i| i % 5 != 4);
        let pick = |idx: &[usize]| -> (Vec<Vector3<f64>>, Vec<[f64; 6]>) {
            (
                idx.iter().map(|&i| points[i]).collect(),
                idx.iter().map(|&i| targets[i]).collect(),
            )
        };
        let (tp, tt) = pick(&train);
        let (hp, ht) = pick(&held);
        let error = |sigmas: &[f64], w: &[[f64; 6]]| -> f64 {
            let rbf = Rbf {
                centres: stored.clone(),
                sigmas: sigmas.to_vec(),
                weights: w.to_vec(),
                affine: [[0.0; 6]; 4],
            };
            hp.iter()
                .zip(&ht)
                .map(|(p, t)| {
                    rbf.eval(p)
                        .iter()
                        .zip(t)
                        .map(|(a, b)| (a - b).powi(2))
                        .sum::<f64>()
                })
                .sum()
        };
        let (factor, ridge) = if held.is_empty() {
            (1.0, RIDGES[0])
        } else {
            FACTORS
                .iter()
                .flat_map(|&f| RIDGES.iter().map(move |&r| (f, r)))
                .map(|(f, r)| {
                    let sigmas: Vec<f64> = spacing.iter().map(|s| s * f).collect();
                    let w = Self::solve(&stored, &sigmas, &tp, &tt, r);
                    ((f, r), error(&sigmas, &w))
                })
                .min_by(|a, b| a.1.total_cmp(&b.1))
                .map_or((1.0, RIDGES[0]), |(fr, _)| fr)
        };
        let sigmas: Vec<f64> = spacing.iter().map(|s| s * factor).collect();
        let weights = Self::solve(&stored, &sigmas, points, targets, ridge);
        Rbf {
            centres: stored,
            sigmas,
            weights,
            affine,
        }
    }
}

/// Least-squares affine map from points to targets (rows x, y, z, 1).
fn affine_fit(points: &[Vector3<f64>], targets: &[[f64; 6]]) -> [[f64; 6]; 4] {
    let a = DMatrix::from_fn(
        points.len(),
        4,
        |r, c| if c < 3 { points[r][c] } else { 1.0 },
    );
    let b = DMatrix::from_fn(points.len(), 6, |r, k| targets[r][k]);
    let mut ata = a.transpose() * &a;
    for i in 0..4 {
        ata[(i, i)] += 1e-9 * (1.0 + ata[(i, i)]);
    }
    let x = ata
        .cholesky()
        .map(|c| c.solve(&(a.transpose() * b)))
        .unwrap_or_else(|| DMatrix::zeros(4, 6));
    std::array::from_fn(|r| std::array::from_fn(|k| x[(r, k)]))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn interpolates_a_smooth_map() {
        let mut pts = Vec::new();
        for i in 0..12 {
            for j in 0..12 {
                for k in 0..6 {
                    pts.push(Vector3::new(
                        -10.0 + 20.0 * j as f64 / 11.0,
                        -40.0 * i as f64 / 11.0,
                        -5.0 + 8.0 * k as f64 / 5.0,
                    ));
                }
            }
        }
        let shield = Shield::fit(&pts).unwrap();
        let f = |p: &Vector3<f64>| -> [f64; 6] {
            [
                0.01 * p.y,
                0.002 * p.x,
                0.0,
                0.1 * p.x,
                0.3 * p.y + 0.01 * p.y * p.y,
                p.z,
            ]
        };
        let targets: Vec<[f64; 6]> = pts.iter().map(f).collect();
        let rbf = Rbf::fit(&shield, &pts, &targets);
        let q = Vector3::new(3.3, -17.0, -1.2);
        let (got, want) = (rbf.eval(&q), f(&q));
        for k in 0..6 {
            assert!(
                (got[k] - want[k]).abs() < 0.05 * (1.0 + want[k].abs()),
                "{k}: {got:?} vs {want:?}"
            );
        }
    }
}
