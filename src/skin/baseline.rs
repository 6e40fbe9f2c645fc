//! The paper's baseline (Section 7): the rigid motion that best carries the neutral's skin
//! feature points to the frame's (Procrustes), applied to the jaw at rest. Skin slides and
//! stretches over the bone, so it sees only part of the jaw's motion.

use nalgebra::Vector3;

use super::features::SkinPoint;
use crate::geometry::{Pose, fit_rigid};

pub fn baseline_jaw(
    points: &[SkinPoint],
    triangles: &[[u32; 3]],
    neutral: &[[f32; 3]],
    frame: &[[f32; 3]],
    rest: &Pose,
) -> Pose {
    let a: Vec<Vector3<f64>> = points.iter().map(|p| p.on(triangles, neutral)).collect();
    let b: Vec<Vector3<f64>> = points.iter().map(|p| p.on(triangles, frame)).collect();
    fit_rigid(&a, &b).map(|t| t.compose(rest)).unwrap_or(*rest)
}
