//! The jaw coordinate frame (Zoss et al. 2018, Sec. 3.1): origin halfway between the condyles,
//! x from the right to the left condyle, z towards the reference point p on the front of the
//! mandible (the lower incisal midpoint), y completing a right-handed frame (roughly up).

use nalgebra::{Matrix3, Rotation3, Vector3};
use serde::{Deserialize, Serialize};

use crate::geometry::Pose;
use crate::mesh::Mesh;

/// Landmarks of the mandible (lower frame, mm) and the frame they define.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct JawFrame {
    pub condyle_left: [f64; 3],
    pub condyle_right: [f64; 3],
    /// The reference point p: the lower incisal midpoint.
    pub reference: [f64; 3],
}

#[derive(Debug, Clone, thiserror::Error, PartialEq)]
pub enum FrameError {
    #[error("vertex {index} does not exist (the mesh has {count} vertices)")]
    NoVertex { index: usize, count: usize },
    #[error("the landmarks are degenerate: {0}")]
    Degenerate(&'static str),
}

/// Vertices within this distance (mm) of the mesh's mid-sagittal plane count as the midline.
const MIDLINE_MM: f64 = 3.0;

impl JawFrame {
    /// Landmarks from vertex indices, or found on the mesh (y up, +z anterior, +x the
    /// subject's left): each condyle is the most posterior-superior vertex of its side (the
    /// largest y − z), the reference point the most anterior-superior vertex near the midline
    /// (the largest z + y/2 within 3 mm of it).
    pub fn from_mesh(
        mesh: &Mesh,
        condyles: Option<[usize; 2]>,
        reference: Option<usize>,
    ) -> Result<JawFrame, FrameError> {
        let p: Vec<Vector3<f64>> = mesh
            .positions
            .iter()
            .map(|v| Vector3::new(v[0] as f64, v[1] as f64, v[2] as f64))
            .collect();
        let get = |i: usize| {
            p.get(i).copied().ok_or(FrameError::NoVertex {
                index: i,
                count: p.len(),
            })
        };
        let (lo, hi) = mesh.bounds();
        let mid_x = (lo[0] + hi[0]) as f64 * 0.5;
        let best = |keep: &dyn Fn(&Vector3<f64>) -> bool, score: &dyn Fn(&Vector3<f64>) -> f64| {
            p.iter()
                .filter(|v| keep(v))
                .max_by(|a, b| score(a).total_cmp(&score(b)))
                .copied()
        };
        let (left, right) = match condyles {
            Some([l, r]) => (get(l)?, get(r)?),
            None => (
                best(&|v| v.x > mid_x, &|v| v.y - v.z)
                    .ok_or(FrameError::Degenerate("no vertex left of the midline"))?,
                best(&|v| v.x < mid_x, &|v| v.y - v.z)
                    .ok_or(FrameError::Degenerate("no vertex right of the midline"))?,
            ),
        };
        let reference = match reference {
            Some(i) => get(i)?,
            None => best(&|v| (v.x - mid_x).abs() < MIDLINE_MM, &|v| v.z + 0.5 * v.y)
                .ok_or(FrameError::Degenerate("no vertex near the midline"))?,
        };
        let frame = JawFrame {
            condyle_left: left.into(),
            condyle_right: right.into(),
            reference: reference.into(),
        };
        frame.axes()?;
        Ok(frame)
    }

    pub fn origin(&self) -> Vector3<f64> {
        (Vector3::from(self.condyle_left) + Vector3::from(self.condyle_right)) * 0.5
    }

    /// The frame's axes as the columns of a rotation (lower frame).
    pub fn axes(&self) -> Result<Rotation3<f64>, FrameError> {
        let x = Vector3::from(self.condyle_left) - Vector3::from(self.condyle_right);
        if x.norm() < 1e-6 {
            return Err(FrameError::Degenerate("the condyles coincide"));
        }
        let x = x.normalize();
        let to_p = Vector3::from(self.reference) - self.origin();
        let z = to_p - x * x.dot(&to_p);
        if z.norm() < 1e-6 {
            return Err(FrameError::Degenerate(
                "the reference point lies on the condyle axis",
            ));
        }
        let z = z.normalize();
        let y = z.cross(&x);
        Ok(Rotation3::from_matrix_unchecked(Matrix3::from_columns(&[
            x, y, z,
        ])))
    }

    /// `C`: the frame at `origin` with the landmarks' axes (lower frame ← jaw frame).
    pub fn matrix(&self, origin: &Vector3<f64>) -> Pose {
        let axes = self.axes().unwrap_or_else(|_| Rotation3::identity());
        Pose::new(axes, *origin)
    }
}
