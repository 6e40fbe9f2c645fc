//! Carrying a mapping to a new subject (the paper's Section 6). Per skin feature v a rigid
//! transform (rotation q_v, translation t_v) applied to its displacement, chosen so that the
//! source mapping Φ gives the target's bone features on its calibration poses (Eq. 2) with
//! the regularisers of Eq. 3, by Levenberg-Marquardt with the SVRs' exact Jacobian. The
//! multi-subject mapping (Section 6.2) aligns each further subject by one transform for all
//! features.
//!
//! The rotation regulariser |q_0 · q_v⁻¹|² is taken as the squared vector part of q_v (the
//! quaternion's distance from the identity), to first order |ω_v / 2|² for the rotation
//! vector ω_v: the problem's only nonlinearity is then Φ's.

use nalgebra::{DMatrix, DVector, Matrix3, Vector3};
use serde::{Deserialize, Serialize};

use super::regress::Regressor;
use crate::geometry::{hat, so3_exp, so3_log};

#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RetargetSettings {
    /// λ1 and λ2 of Eq. 3 (the paper's: 1e-5 and 2.5e-5).
    pub lambda_rotation: f64,
    pub lambda_translation: f64,
    /// Levenberg-Marquardt iterations at most.
    pub iterations: usize,
    /// Carry the mapping by every rung of [`LADDER`](super::carry::LADDER) (from none to the
    /// paper's per-feature transforms) and average their predictions, each weighed by how well
    /// it predicts the calibration poses left out (on by default; needs three poses besides
    /// the rest). Off: the paper's per-feature transforms with its λ alone. Neither a single
    /// rung chosen by leaving poses out (five poses are each an extreme the others do not
    /// cover) nor the paper's rung alone (worse than none on some subjects) is as safe;
    /// docs/skin.md measures.
    #[serde(alias = "choose", alias = "cross_validate")]
    pub blend: bool,
}

impl Default for RetargetSettings {
    fn default() -> Self {
        RetargetSettings {
            lambda_rotation: 1e-5,
            lambda_translation: 2.5e-5,
            iterations: 50,
            blend: true,
        }
    }
}

/// A rigid transform of a displacement: d' = exp(ω) d + t.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct FeatureTransform {
    pub rotation: [f64; 3],
    pub translation: [f64; 3],
}

impl FeatureTransform {
    pub(crate) fn matrix(&self) -> Matrix3<f64> {
        *so3_exp(&Vector3::from(self.rotation)).matrix()
    }

    /// This transform applied after `first`: d ↦ R (R₁ d + t₁) + t.
    pub(crate) fn after(&self, first: &FeatureTransform) -> FeatureTransform {
        let r = so3_exp(&Vector3::from(self.rotation)) * so3_exp(&Vector3::from(first.rotation));
        let t = self.matrix() * Vector3::from(first.translation) + Vector3::from(self.translation);
        FeatureTransform {
            rotation: so3_log(&r).into(),
            translation: t.into(),
        }
    }
}

/// Apply per-feature transforms (one each, or one for all) to flattened displacements.
pub fn apply(transforms: &[FeatureTransform], f: &[f64]) -> Vec<f64> {
    if transforms.is_empty() {
        return f.to_vec();
    }
    let mats: Vec<Matrix3<f64>> = transforms.iter().map(|t| t.matrix()).collect();
    let n = f.len() / 3;
    let mut out = Vec::with_capacity(f.len());
    for v in 0..n {
        let g = if transforms.len() == 1 { 0 } else { v };
        let d = mats[g] * Vector3::new(f[3 * v], f[3 * v + 1], f[3 * v + 2])
            + Vector3::from(transforms[g].translation);
        out.extend_from_slice(d.as_slice());
    }
    out
}

/// What the solve reached: the data term Σ|Φ − B|² before and after (mm²), the steps, the
/// best rung and every rung's score on the poses left out.
#[derive(Debug, Clone, Default, Serialize)]
pub struct RetargetReport {
    pub cost_before: f64,
    pub cost_after: f64,
    pub iterations: usize,
    /// The rung of [`LADDER`](super::carry::LADDER) that scored best ("none", "global", "per-feature λ×100", …).
    pub carried: String,
    pub candidates: Vec<CandidateScore>,
    /// The rungs (of each mapping, in a multi-subject model) blended, and their weights.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub blend: Vec<(String, f64)>,
}

/// One rung's mean bone point error (mm) on the calibration poses left out, and its standard
/// error over those poses.
#[derive(Debug, Clone, Serialize)]
pub struct CandidateScore {
    pub carry: String,
    pub mm: f64,
    pub standard_error_mm: f64,
    /// Each pose's bone features as predicted with it left out, in the calibration's order.
    #[serde(skip)]
    pub held_out: Vec<Vec<f64>>,
}

/// One transform per skin feature from `(skin features, bone features)` calibration pairs.
pub fn retarget(
    phi: &Regressor,
    pairs: &[(Vec<f64>, Vec<f64>)],
    s: &RetargetSettings,
) -> (Vec<FeatureTransform>, RetargetReport) {
    let features = pairs.first().map_or(0, |p| p.0.len() / 3);
    solve(phi, pairs, s, features)
}

/// One transform for all features (the multi-subject alignment).
pub fn align_globally(
    phi: &Regressor,
    pairs: &[(Vec<f64>, Vec<f64>)],
    s: &RetargetSettings,
) -> (FeatureTransform, RetargetReport) {
    let (t, r) = solve(phi, pairs, s, 1);
    (t[0], r)
}

pub(crate) fn data_cost(
    phi: &Regressor,
    pairs: &[(Vec<f64>, Vec<f64>)],
    t: &[FeatureTransform],
) -> f64 {
    pairs
        .iter()
        .map(|(f, b)| {
            phi.predict(&apply(t, f))
                .iter()
                .zip(b)
                .map(|(p, q)| (p - q).powi(2))
                .sum::<f64>()
        })
        .sum()
}

fn regulariser(t: &[FeatureTransform], s: &RetargetSettings) -> f64 {
    t.iter()
        .map(|t| {
            let w = Vector3::from(t.rotation);
            s.lambda_rotation * (w * 0.5).norm_squared()
                + s.lambda_translation * Vector3::from(t.translation).norm_squared()
        })
        .sum()
}

/// Levenberg-Marquardt over `groups` transforms (each feature its own, or one for all).
fn solve(
    phi: &Regressor,
    pairs: &[(Vec<f64>, Vec<f64>)],
    s: &RetargetSettings,
    groups: usize,
) -> (Vec<FeatureTransform>, RetargetReport) {
    let mut t = vec![FeatureTransform::default(); groups];
    let before = data_cost(phi, pairs, &t);
    if pairs.is_empty() || groups == 0 {
        return (
            t,
            RetargetReport {
                cost_before: before,
                cost_after: before,
                ..Default::default()
            },
        );
    }
    let n = 6 * groups;
    // The regularisers' weights per parameter: (ω/2)² and t².
    let reg: Vec<f64> = (0..n)
        .map(|i| {
            if i % 6 < 3 {
                s.lambda_rotation * 0.25
            } else {
                s.lambda_translation
            }
        })
        .collect();
    let mut mu = 1e-3;
    let mut cost = before + regulariser(&t, s);
    let mut done = 0;
    for _ in 0..s.iterations {
        done += 1;
        let (jac, res) = jacobian(phi, pairs, &t);
        let x: Vec<f64> = t
            .iter()
            .flat_map(|g| g.rotation.into_iter().chain(g.translation))
            .collect();
        let grad =
            jac.transpose() * &res + DVector::from_iterator(n, (0..n).map(|i| reg[i] * x[i]));
        let colnorm: Vec<f64> = (0..n).map(|c| jac.column(c).norm_squared()).collect();
        let mut improved = false;
        for _ in 0..10 {
            let d: Vec<f64> = (0..n)
                .map(|i| reg[i] + mu * (colnorm[i] + reg[i]).max(1e-12))
                .collect();
            let Some(step) = damped_solve(&jac, &d, &grad) else {
                mu *= 10.0;
                continue;
            };
            let trial: Vec<FeatureTransform> = (0..groups)
                .map(|g| {
                    let mut tr = t[g];
                    for k in 0..3 {
                        tr.rotation[k] -= step[6 * g + k];
                        tr.translation[k] -= step[6 * g + 3 + k];
                    }
                    tr
                })
                .collect();
            let c = data_cost(phi, pairs, &trial) + regulariser(&trial, s);
            if c < cost {
                let gain = (cost - c) / cost.max(1e-300);
                t = trial;
                cost = c;
                mu = (mu * 0.3).max(1e-9);
                improved = gain > 1e-9;
                break;
            }
            mu *= 10.0;
        }
        if !improved {
            break;
        }
    }
    let after = data_cost(phi, pairs, &t);
    (
        t,
        RetargetReport {
            cost_before: before,
            cost_after: after,
            iterations: done,
            ..Default::default()
        },
    )
}

/// (D + JᵀJ)⁻¹ g for a diagonal D: directly when there are fewer parameters than residuals,
/// else by the Woodbury identity, whose system is as small as the residuals.
fn damped_solve(jac: &DMatrix<f64>, d: &[f64], g: &DVector<f64>) -> Option<DVector<f64>> {
    let (m, n) = jac.shape();
    if n <= m {
        let mut a = jac.transpose() * jac;
        for i in 0..n {
            a[(i, i)] += d[i];
        }
        return a.cholesky().map(|c| c.solve(g));
    }
    let dinv = DVector::from_iterator(n, d.iter().map(|v| 1.0 / v));
    let dg = g.component_mul(&dinv);
    let mut jd = jac.clone();
    for c in 0..n {
        jd.column_mut(c).scale_mut(dinv[c]);
    }
    let mut small = &jd * jac.transpose();
    for i in 0..m {
        small[(i, i)] += 1.0;
    }
    let inner = small.cholesky()?.solve(&(jac * &dg));
    Some(dg - jd.transpose() * inner)
}

/// The residuals Φ(T(F_p)) − B_p of every pair and their Jacobian in (ω, t) of every group.
fn jacobian(
    phi: &Regressor,
    pairs: &[(Vec<f64>, Vec<f64>)],
    t: &[FeatureTransform],
) -> (DMatrix<f64>, DVector<f64>) {
    let groups = t.len();
    let mats: Vec<Matrix3<f64>> = t.iter().map(|t| t.matrix()).collect();
    let outputs = phi.outputs.len();
    let m = pairs.len() * outputs;
    let mut jac = DMatrix::<f64>::zeros(m, 6 * groups);
    let mut res = DVector::<f64>::zeros(m);
    for (p, (f, b)) in pairs.iter().enumerate() {
        let fp = apply(t, f);
        let (value, dphi) = phi.predict_with_jacobian(&fp);
        let features = f.len() / 3;
        for o in 0..outputs {
            let row = p * outputs + o;
            res[row] = value[o] - b[o];
            for v in 0..features {
                let g = if groups == 1 { 0 } else { v };
                let grad =
                    Vector3::new(dphi[(o, 3 * v)], dphi[(o, 3 * v + 1)], dphi[(o, 3 * v + 2)]);
                // d' = R d + t; a left increment δω turns R d by −[R d]× δω.
                let rd = mats[g] * Vector3::new(f[3 * v], f[3 * v + 1], f[3 * v + 2]);
                let dw = -(hat(&rd).transpose() * grad);
                for k in 0..3 {
                    jac[(row, 6 * g + k)] += dw[k];
                    jac[(row, 6 * g + 3 + k)] += grad[k];
                }
            }
        }
    }
    (jac, res)
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::skin::regress::RegressSettings;

    /// A mapping from four skin displacements (12 numbers) to 3 outputs.
    fn mapping() -> (Regressor, Vec<Vec<f64>>, Vec<Vec<f64>>) {
        let mut state = 99u64;
        let mut uniform = move || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
        };
        let x: Vec<Vec<f64>> = (0..200)
            .map(|_| (0..12).map(|_| uniform() * 3.0).collect())
            .collect();
        let y: Vec<Vec<f64>> = x
            .iter()
            .map(|f| vec![f[0] + f[4], f[1] - f[8], f[2] * 0.5 + f[10]])
            .collect();
        let s = RegressSettings {
            widths: vec![8.0],
            penalties: vec![30.0],
            ..RegressSettings::default()
        };
        (Regressor::learn(&x, &y, 160, &s).unwrap(), x, y)
    }

    #[test]
    fn the_jacobian_matches_finite_differences_of_the_residuals() {
        let (phi, x, y) = mapping();
        let pairs: Vec<(Vec<f64>, Vec<f64>)> =
            (0..3).map(|i| (x[i].clone(), y[i].clone())).collect();
        let t: Vec<FeatureTransform> = (0..4)
            .map(|v| FeatureTransform {
                rotation: [0.0; 3],
                translation: [0.1 * v as f64, 0.0, -0.2],
            })
            .collect();
        let (jac, res) = jacobian(&phi, &pairs, &t);
        let h = 1e-6;
        for g in 0..4 {
            for k in 0..6 {
                let bump = |d: f64| {
                    let mut t2 = t.clone();
                    if k < 3 {
                        t2[g].rotation[k] += d
                    } else {
                        t2[g].translation[k - 3] += d
                    }
                    jacobian(&phi, &pairs, &t2).1
                };
                let fd = (bump(h) - bump(-h)) / (2.0 * h);
                for r in 0..res.len() {
                    // At zero rotation the left increment and the rotation vector agree.
                    assert!(
                        (fd[r] - jac[(r, 6 * g + k)]).abs() < 1e-4 * (1.0 + fd[r].abs()),
                        "row {r}, group {g}, parameter {k}: {} vs {}",
                        fd[r],
                        jac[(r, 6 * g + k)]
                    );
                }
            }
        }
    }

    #[test]
    fn a_transform_after_another_is_the_two_applied_in_turn() {
        let first = FeatureTransform {
            rotation: [0.1, -0.3, 0.2],
            translation: [1.0, -2.0, 0.5],
        };
        let then = FeatureTransform {
            rotation: [-0.2, 0.05, 0.4],
            translation: [0.3, 0.1, -1.0],
        };
        let f = [1.0, 2.0, 3.0, -0.5, 0.25, 4.0];
        let both = apply(&[then.after(&first)], &f);
        let in_turn = apply(&[then], &apply(&[first], &f));
        for (a, b) in both.iter().zip(&in_turn) {
            assert!((a - b).abs() < 1e-12, "{both:?} vs {in_turn:?}");
        }
    }

    /// Calibration pairs: (skin features, bone features).
    pub(crate) type Pairs = Vec<(Vec<f64>, Vec<f64>)>;

    /// `n` calibration pairs of a target whose displacements are the source's turned by 20°
    /// about y and shifted, with the mapping.
    pub(crate) fn turned_pairs(n: usize) -> (Regressor, Pairs) {
        let (phi, x, y) = mapping();
        let turn = FeatureTransform {
            rotation: [0.0, 0.35, 0.0],
            translation: [0.3, 0.0, 0.0],
        };
        let turned = |i: usize| {
            let inv = turn.matrix().transpose();
            let f: Vec<f64> = (0..4)
                .flat_map(|v| {
                    let d = Vector3::new(x[i][3 * v], x[i][3 * v + 1], x[i][3 * v + 2]);
                    (inv * (d - Vector3::from(turn.translation)))
                        .iter()
                        .copied()
                        .collect::<Vec<_>>()
                })
                .collect();
            (f, y[i].clone())
        };
        (phi, (0..n).map(turned).collect())
    }

    #[test]
    fn a_subject_whose_skin_moves_turned_is_brought_back() {
        let (phi, pairs) = turned_pairs(6);
        let (_, report) = align_globally(&phi, &pairs, &RetargetSettings::default());
        assert!(report.cost_after < 0.05 * report.cost_before, "{report:?}");
        let (_, report) = retarget(&phi, &pairs, &RetargetSettings::default());
        assert!(report.cost_after < 0.05 * report.cost_before, "{report:?}");
    }
}
