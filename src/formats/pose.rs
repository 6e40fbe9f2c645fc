//! A pose on disk: the rows of R and t, mapping model to world (`x = R·x_model + t`), in
//! millimetres; readers reject a non-rotation (the capture format's convention).

use std::path::Path;

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use crate::error::{Error, Result, Shown};
use crate::geometry::Pose;
use crate::io::{check_finite, read_json};

/// Tolerance for "is a rotation" in the spec: readers reject |RᵀR − I| above this.
pub const ROTATION_TOLERANCE: f64 = 1e-3;

#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq)]
pub struct PoseJson {
    pub rotation: [[f64; 3]; 3],
    pub translation: [f64; 3],
}

impl From<&Pose> for PoseJson {
    fn from(p: &Pose) -> Self {
        PoseJson {
            rotation: p.rotation_rows(),
            translation: [p.translation.x, p.translation.y, p.translation.z],
        }
    }
}

/// The largest translation a pose file may give (mm): a kilometre, far beyond any capture, and
/// far enough below f64's range that composing poses stays finite.
pub const MAX_TRANSLATION_MM: f64 = 1e6;

impl PoseJson {
    /// Validate (finite numbers, a rotation within the spec's tolerance) and re-orthonormalise.
    pub fn to_pose(&self, path: &Path, field: &str) -> Result<Pose> {
        check_finite_rows(path, &format!("{field}.rotation"), &self.rotation)?;
        check_finite(path, &format!("{field}.translation"), &self.translation)?;
        if let Some(t) = self
            .translation
            .iter()
            .find(|t| t.abs() > MAX_TRANSLATION_MM)
        {
            return Err(Error::invalid(
                path,
                format!("{field}.translation"),
                format!(
                    "{} mm is beyond {MAX_TRANSLATION_MM} mm (1 km): not a pose in millimetres",
                    Shown(*t)
                ),
            ));
        }
        let rotation = Pose::rotation_from_rows(&self.rotation, ROTATION_TOLERANCE).ok_or_else(|| {
            Error::invalid(
                path,
                format!("{field}.rotation"),
                format!(
                    "is not a rotation matrix (RᵀR must be I and det(R) = +1 within {ROTATION_TOLERANCE})"
                ),
            )
        })?;
        let [x, y, z] = self.translation;
        Ok(Pose::new(rotation, Vector3::new(x, y, z)))
    }
}

/// Read a pose file: `{"rotation": [[...], [...], [...]], "translation": [...]}`.
pub fn read_pose_file(path: &Path) -> Result<Pose> {
    let pj: PoseJson = read_json(path, "pose file")?;
    pj.to_pose(path, "pose")
}

fn check_finite_rows(path: &Path, field: &str, rows: &[[f64; 3]; 3]) -> Result<()> {
    for (i, row) in rows.iter().enumerate() {
        check_finite(path, &format!("{field}[{i}]"), row)?;
    }
    Ok(())
}
