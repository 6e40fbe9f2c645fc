//! Traditional jaw rigs (Zoss et al. 2018, Sec. 3.2, Eq. 1): J = C·Rx·Ry·Rz·Tx·Ty·Tz·C⁻¹ with
//! some parameters held at zero, fitted to every pose together with the rig's origin (Eq. 6-8,
//! plus λ·softL1(|o − o_init|²), λ = 0.1).
//!
//! The data term differs from Eq. 6: instead of the Frobenius distance of the 4×4 matrices,
//! which adds radians to millimetres and depends on where the scanner put the origin (it
//! measures the motion of that one point), it is the displacement (mm) of the mandible's
//! extreme vertices between the captured and the rig's pose, the quantity the rigs are judged
//! by.
//!
//! The jaw poses are motions of the mandible relative to its neutral pose N (the captured pose
//! with the highest reference point: teeth closed): J_f = Ĵ_f · N⁻¹, in the upper frame, with
//! C = N·C_lower.

use nalgebra::{Rotation3, Vector3};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::anatomy::jaw_frame::JawFrame;
use crate::geometry::Pose;
use crate::geometry::least_squares::levenberg_marquardt;

/// Which of (φx, φy, φz, tx, ty, tz) a rig moves.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq, Eq)]
pub enum Dofs {
    /// Opening only: φx.
    One,
    /// Opening, sideways rotation, forward translation: φx, φy, tz.
    Three,
    /// Two rotations, three translations: φx, φy, tx, ty, tz.
    Five,
    /// All six.
    Six,
}

impl Dofs {
    pub fn mask(self) -> [bool; 6] {
        match self {
            Dofs::One => [true, false, false, false, false, false],
            Dofs::Three => [true, true, false, false, false, true],
            Dofs::Five => [true, true, false, true, true, true],
            Dofs::Six => [true; 6],
        }
    }

    pub fn count(self) -> usize {
        self.mask().iter().filter(|m| **m).count()
    }

    pub fn name(self) -> &'static str {
        match self {
            Dofs::One => "1-DOF",
            Dofs::Three => "3-DOF",
            Dofs::Five => "5-DOF",
            Dofs::Six => "6-DOF",
        }
    }
}

/// Rx(φx)·Ry(φy)·Rz(φz)·Tx·Ty·Tz: rotations first, then the translation in the rotated axes.
pub fn local_motion(theta: &[f64; 6]) -> Pose {
    let r = Rotation3::from_axis_angle(&Vector3::x_axis(), theta[0])
        * Rotation3::from_axis_angle(&Vector3::y_axis(), theta[1])
        * Rotation3::from_axis_angle(&Vector3::z_axis(), theta[2]);
    Pose::new(r, r * Vector3::new(theta[3], theta[4], theta[5]))
}

/// A fitted traditional rig.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct TraditionalRig {
    pub dofs: Dofs,
    /// The neutral pose N (upper_from_lower).
    #[serde(with = "super::pose_serde")]
    pub neutral: Pose,
    /// The fitted origin (lower frame, mm) and the landmarks' initial one.
    pub origin: [f64; 3],
    pub origin_init: [f64; 3],
    pub frame: JawFrame,
    /// Per pose, all six parameters (the unused ones zero).
    pub params: Vec<[f64; 6]>,
}

/// Rounds of the alternation between the poses' parameters and the origin.
const ORIGIN_ROUNDS: usize = 40;

/// λ of the origin's regulariser (Eq. 8).
pub const ORIGIN_WEIGHT: f64 = 0.1;

/// The neutral pose: the one whose reference point is highest in the upper frame.
pub fn neutral_pose(poses: &[Pose], frame: &JawFrame) -> Pose {
    let p = Vector3::from(frame.reference);
    poses
        .iter()
        .max_by(|a, b| a.transform_point(&p).y.total_cmp(&b.transform_point(&p).y))
        .copied()
        .unwrap_or(Pose::IDENTITY)
}

impl TraditionalRig {
    /// C in the upper frame for an origin (lower frame).
    fn c_upper(neutral: &Pose, frame: &JawFrame, origin: &Vector3<f64>) -> Pose {
        neutral.compose(&frame.matrix(origin))
    }

    /// The jaw pose (upper_from_lower) for parameters `theta`.
    pub fn pose(&self, theta: &[f64; 6]) -> Pose {
        let c = Self::c_upper(&self.neutral, &self.frame, &Vector3::from(self.origin));
        c.compose(&local_motion(theta))
            .compose(&c.inverse())
            .compose(&self.neutral)
    }

    /// Fit every pose's parameters and the origin.
    /// `probes`: points of the mandible (lower frame) whose displacement is the data term.
    pub fn fit(
        poses: &[Pose],
        frame: &JawFrame,
        probes: &[Vector3<f64>],
        dofs: Dofs,
    ) -> TraditionalRig {
        let neutral = neutral_pose(poses, frame);
        let motions: Vec<Pose> = poses
            .iter()
            .map(|p| p.compose(&neutral.inverse()))
            .collect();
        // The probes where the neutral pose puts them (upper frame): the motions move these.
        let placed: Vec<Vector3<f64>> = probes.iter().map(|p| neutral.transform_point(p)).collect();
        let placed = &placed;
        let init = frame.origin();
        let mask = dofs.mask();
        let fit_all = |origin: &Vector3<f64>, warm: &[[f64; 6]]| -> Vec<([f64; 6], Vec<f64>)> {
            let c = Self::c_upper(&neutral, frame, origin);
            let c_inv = c.inverse();
            motions
                .par_iter()
                .zip(warm)
                .map(|(m, w)| {
                    let expand = |x: &[f64]| {
                        let mut t = [0.0; 6];
                        let mut k = 0;
                        for (i, used) in mask.iter().enumerate() {
                            if *used {
                                t[i] = x[k];
                                k += 1;
                            }
                        }
                        t
                    };
                    let residual = |x: &[f64]| {
                        displacement(
                            &c.compose(&local_motion(&expand(x))).compose(&c_inv),
                            m,
                            placed,
                        )
                    };
                    let start: Vec<f64> = (0..6).filter(|&i| mask[i]).map(|i| w[i]).collect();
                    let x = levenberg_marquardt(residual, &start, 30, 1e-7);
                    let t = expand(&x);
                    let r = residual(&x);
                    (t, r)
                })
                .collect()
        };
        // Alternate: every pose's parameters with the origin fixed (independent small fits),
        // then the origin with the parameters fixed (Levenberg-Marquardt on all residuals and
        // the regulariser's √(λ·softL1)). Each half lowers the cost. Six degrees of freedom
        // explain any pose from any origin, so there the origin stays put.
        let mut params: Vec<[f64; 6]> = vec![[0.0; 6]; poses.len()];
        let mut origin = init;
        let rounds = if dofs == Dofs::Six { 1 } else { ORIGIN_ROUNDS };
        for round in 0..rounds {
            params = fit_all(&origin, &params)
                .into_iter()
                .map(|(t, _)| t)
                .collect();
            if round + 1 == rounds {
                break;
            }
            let fixed = &params;
            let residual = |o: &[f64]| -> Vec<f64> {
                let origin = Vector3::new(o[0], o[1], o[2]);
                let c = Self::c_upper(&neutral, frame, &origin);
                let c_inv = c.inverse();
                let mut r: Vec<f64> = motions
                    .iter()
                    .zip(fixed)
                    .flat_map(|(m, t)| {
                        displacement(&c.compose(&local_motion(t)).compose(&c_inv), m, placed)
                    })
                    .collect();
                let s = (origin - init).norm_squared();
                r.push((ORIGIN_WEIGHT * 2.0 * ((1.0 + s).sqrt() - 1.0)).sqrt());
                r
            };
            let o = levenberg_marquardt(residual, &[origin.x, origin.y, origin.z], 10, 1e-4);
            origin = Vector3::new(o[0], o[1], o[2]);
        }
        TraditionalRig {
            dofs,
            neutral,
            origin: origin.into(),
            origin_init: init.into(),
            frame: frame.clone(),
            params,
        }
    }
}

/// The displacement (mm) of each point between motions `a` and `b`.
pub fn displacement(a: &Pose, b: &Pose, points: &[Vector3<f64>]) -> Vec<f64> {
    points
        .iter()
        .flat_map(|p| {
            let d = a.transform_point(p) - b.transform_point(p);
            [d.x, d.y, d.z]
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A box of points around the mandible's extent.
    fn probes() -> Vec<Vector3<f64>> {
        let mut v = Vec::new();
        for x in [-50.0, 50.0] {
            for y in [-30.0, 25.0] {
                for z in [-85.0, 10.0] {
                    v.push(Vector3::new(x, y, z));
                }
            }
        }
        v
    }

    fn frame() -> JawFrame {
        JawFrame {
            condyle_left: [50.0, 20.0, -80.0],
            condyle_right: [-50.0, 20.0, -80.0],
            reference: [0.0, -10.0, 10.0],
        }
    }

    #[test]
    fn a_hinge_is_fitted_by_one_dof_near_the_true_axis() {
        let f = frame();
        // A pure hinge about an axis 4 mm below and 3 mm in front of the landmarks' origin.
        let truth = TraditionalRig {
            dofs: Dofs::One,
            neutral: Pose::IDENTITY,
            origin: [0.0, 16.0, -77.0],
            origin_init: [0.0; 3],
            frame: f.clone(),
            params: vec![],
        };
        let poses: Vec<Pose> = (0..60)
            .map(|i| truth.pose(&[i as f64 * 0.01, 0.0, 0.0, 0.0, 0.0, 0.0]))
            .collect();
        let rig = TraditionalRig::fit(&poses, &f, &probes(), Dofs::One);
        for (p, t) in poses.iter().zip(&rig.params) {
            let (r, d) = rig.pose(t).distance_to(p);
            assert!(r < 1e-3 && d < 0.1, "{r} {d}");
        }
        // The hinge axis is x: the origin slides along it freely, and across it the data pull
        // it from the landmarks onto the true axis.
        let o = Vector3::from(rig.origin);
        let off = |o: Vector3<f64>| ((o.y - 16.0).powi(2) + (o.z + 77.0).powi(2)).sqrt();
        assert!(off(o) < 0.2, "{o:?}");
    }

    #[test]
    fn six_dofs_explain_any_pose() {
        let f = frame();
        let poses: Vec<Pose> = (0..5)
            .map(|i| {
                Pose::from_euler_tuple(&[0.1 * i as f64, 0.02, -0.03, 1.0, -2.0 * i as f64, 0.5])
            })
            .collect();
        let rig = TraditionalRig::fit(&poses, &f, &probes(), Dofs::Six);
        for (p, t) in poses.iter().zip(&rig.params) {
            let (r, d) = rig.pose(t).distance_to(p);
            assert!(r < 1e-6 && d < 1e-4, "{r} {d}");
        }
    }
}
