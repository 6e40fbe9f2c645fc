//! Inverse kinematics (the paper's Eq. 10): the valid parameters that bring a mesh point
//! closest to a target, by local sampling around the current parameters: the 26 neighbours
//! of the current point (projected onto the valid ranges) at a step that halves whenever none
//! of them is better.

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
) -> IkResult {
    let distance = |d: &[f64; 3]| (rig.pose(d).transform_point(point) - target).norm();
    let mut best = rig.clamp(from);
    let mut best_e = distance(&best);
    let mut evaluations = 1;
    let mut step = s.step;
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
    IkResult {
        params: best,
        residual_mm: best_e,
        evaluations,
    }
}
