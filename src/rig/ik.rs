//! Inverse kinematics (the paper's Eq. 10): the valid parameters that bring a mesh point
//! closest to a target. Levenberg-Marquardt steps from the current parameters, each projected
//! onto the valid ranges, get there in a few dozen rig evaluations where the rig is smooth;
//! local sampling then finishes where they stall (against a range's edge, where a projected
//! step stops improving): the 26 neighbours of the current point (projected onto the valid
//! ranges) at a step that halves whenever none of them is better.

use nalgebra::Vector3;
use serde::Serialize;

use super::three::ThreeParameterRig;

#[derive(Debug, Clone, Copy, serde::Deserialize, Serialize, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct IkSettings {
    /// First step (parameter units).
    pub step: f64,
    /// Stop when the step is below this.
    pub min_step: f64,
    /// Rig evaluations at most.
    pub max_evaluations: usize,
    /// Stop when the point is this close to the target (mm).
    pub tolerance_mm: f64,
}

impl Default for IkSettings {
    fn default() -> Self {
        IkSettings {
            step: 0.05,
            min_step: 1e-5,
            max_evaluations: 3000,
            tolerance_mm: 1e-3,
        }
    }
}

/// A point or target this far from the origin (mm) is no question IK answers: the jaw is a
/// few centimetres across.
pub const MAX_COORDINATE_MM: f64 = 1e4;

/// The largest starting parameter accepted: a rig's parameters are of order one.
pub const MAX_START: f64 = 1e6;

/// A question IK refuses.
#[derive(Debug, Clone, thiserror::Error, PartialEq)]
pub enum IkError {
    #[error("the {0}: three finite numbers, each within ±{MAX_COORDINATE_MM} mm")]
    Coordinate(&'static str),
    #[error("the starting parameters: three finite numbers within ±{MAX_START}")]
    Start,
}

#[derive(Debug, Clone, Serialize)]
pub struct IkResult {
    pub params: [f64; 3],
    /// Distance from the moved point to the target (mm).
    pub residual_mm: f64,
    pub evaluations: usize,
}

/// `point` in the lower frame (mm), `target` in the upper frame (mm), `from` the current
/// parameters (clamped into the valid ranges first).
pub fn solve<R: ThreeParameterRig + ?Sized>(
    rig: &R,
    point: &Vector3<f64>,
    target: &Vector3<f64>,
    from: &[f64; 3],
    s: &IkSettings,
) -> Result<IkResult, IkError> {
    let bounded = |v: &Vector3<f64>| {
        v.iter()
            .all(|c| c.is_finite() && c.abs() <= MAX_COORDINATE_MM)
    };
    if !bounded(point) {
        return Err(IkError::Coordinate("point"));
    }
    if !bounded(target) {
        return Err(IkError::Coordinate("target"));
    }
    if from.iter().any(|v| !v.is_finite() || v.abs() > MAX_START) {
        return Err(IkError::Start);
    }
    let moved = |d: &[f64; 3]| rig.pose(d).transform_point(point);
    let distance = |d: &[f64; 3]| (moved(d) - target).norm();
    let (mut best, mut evaluations) = levenberg_marquardt(rig, &moved, target, from, s);
    let mut best_e = distance(&best);
    evaluations += 1;
    let mut step = s.step * LOCAL_STEP;
    while step >= s.min_step && evaluations < s.max_evaluations && best_e > s.tolerance_mm {
        let mut moved = false;
        for dx in -1i32..=1 {
            for dy in -1i32..=1 {
                for dz in -1i32..=1 {
                    if (dx, dy, dz) == (0, 0, 0) {
                        continue;
                    }
                    let trial = [
                        best[0] + step * dx as f64,
                        best[1] + step * dy as f64,
                        best[2] + step * dz as f64,
                    ];
                    let e = distance(&trial);
                    evaluations += 1;
                    if e >= best_e {
                        continue;
                    }
                    // A winner outside the valid ranges is projected onto them (the costlier
                    // test, so only for winners) and kept if it still wins: the ranges can be
                    // thin bands that a step would otherwise always leave.
                    let (trial, e) = if rig.is_valid(&trial) {
                        (trial, e)
                    } else {
                        let c = rig.clamp(&trial);
                        evaluations += 1;
                        (c, distance(&c))
                    };
                    if e < best_e {
                        best = trial;
                        best_e = e;
                        moved = true;
                    }
                }
            }
        }
        if !moved {
            step *= 0.5;
        }
    }
    Ok(IkResult {
        params: best,
        residual_mm: best_e,
        evaluations,
    })
}

/// The local search's first step after Levenberg-Marquardt, as a share of `IkSettings::step`:
/// it starts near a minimum, so a small step is enough.
const LOCAL_STEP: f64 = 0.1;

/// Projected Levenberg-Marquardt on the moved point's offset from `target` (the Jacobian by
/// central differences): the parameters where it stopped and the rig evaluations it took.
fn levenberg_marquardt<R: ThreeParameterRig + ?Sized>(
    rig: &R,
    moved: &impl Fn(&[f64; 3]) -> Vector3<f64>,
    target: &Vector3<f64>,
    from: &[f64; 3],
    s: &IkSettings,
) -> ([f64; 3], usize) {
    let mut d = rig.clamp(from);
    let mut r = moved(&d) - target;
    let mut evaluations = 1;
    let mut mu = 1e-3;
    let h = 1e-6;
    while evaluations + 7 < s.max_evaluations && r.norm() > s.tolerance_mm {
        let mut jac = nalgebra::Matrix3::zeros();
        for k in 0..3 {
            let (mut a, mut b) = (d, d);
            a[k] += h;
            b[k] -= h;
            jac.set_column(k, &((moved(&a) - moved(&b)) / (2.0 * h)));
        }
        evaluations += 6;
        let jtj = jac.transpose() * jac;
        let g = jac.transpose() * r;
        let mut accepted = false;
        // Raise the damping until a step improves, a few times at most.
        for _ in 0..8 {
            let damped = jtj + nalgebra::Matrix3::from_diagonal(&jtj.diagonal()) * mu;
            let Some(inv) = damped.try_inverse() else {
                mu *= 10.0;
                continue;
            };
            let step = inv * g;
            let trial: [f64; 3] = std::array::from_fn(|k| d[k] - step[k]);
            if trial.iter().any(|v| !v.is_finite()) {
                mu *= 4.0;
                continue;
            }
            let trial = rig.clamp(&trial);
            let rt = moved(&trial) - target;
            evaluations += 1;
            if rt.norm() < r.norm() {
                accepted = trial != d;
                d = trial;
                r = rt;
                mu = (mu / 3.0).max(1e-9);
                break;
            }
            mu *= 4.0;
        }
        if !accepted {
            break;
        }
    }
    (d, evaluations)
}
