//! Jaw poses as vectors: the se(3) logarithm of each pose, taken about the mesh's centroid
//! and weighted so that a unit in any coordinate moves the mesh by about a millimetre.
//!
//! The paper takes `log(R, t)` in the scan's own frame. Two things are added here, both
//! linear changes of coordinates that PCA and the autoencoder then see: the pose is
//! conjugated by the translation to the mesh centroid `c` (`T_c = Tr(−c)·T·Tr(c)`), so the
//! vectors do not depend on where the scanner put its origin; and the rotation part is
//! multiplied by the mesh's RMS radius, so rotation and translation errors are counted in the
//! same unit: the squared length of a small difference is close to the mean squared vertex
//! displacement it causes.

use nalgebra::{Vector3, Vector6};
use serde::{Deserialize, Serialize};

use super::metric::MeshMetric;
use crate::geometry::Pose;

#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct Coordinates {
    /// The mesh centroid, lower frame (mm).
    pub centre_mm: [f64; 3],
    /// The length that turns radians into millimetres (the mesh's RMS radius).
    pub radius_mm: f64,
}

impl Coordinates {
    pub fn for_mesh(metric: &MeshMetric) -> Coordinates {
        let c = metric.centroid;
        Coordinates {
            centre_mm: [c.x, c.y, c.z],
            radius_mm: metric.rms_radius_mm.max(1e-6),
        }
    }

    fn centre(&self) -> Vector3<f64> {
        Vector3::from(self.centre_mm)
    }

    /// `upper_from_lower` → the weighted vector `[r·ω; v]` (mm).
    pub fn vector(&self, pose: &Pose) -> Vector6<f64> {
        let c = Pose::from_translation(self.centre());
        let centred = c.inverse().compose(pose).compose(&c);
        let mut v = centred.log();
        for k in 0..3 {
            v[k] *= self.radius_mm;
        }
        v
    }

    /// The inverse of [`Self::vector`].
    pub fn pose(&self, v: &Vector6<f64>) -> Pose {
        let mut xi = *v;
        for k in 0..3 {
            xi[k] /= self.radius_mm;
        }
        let c = Pose::from_translation(self.centre());
        c.compose(&Pose::exp(&xi)).compose(&c.inverse())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn vector_and_pose_are_inverse() {
        let coords = Coordinates {
            centre_mm: [3.0, -20.0, -40.0],
            radius_mm: 45.0,
        };
        let p = Pose::from_euler_tuple(&[0.4, -0.1, 0.05, 1.0, -12.0, 3.0]);
        let back = coords.pose(&coords.vector(&p));
        let (r, t) = back.distance_to(&p);
        assert!(r < 1e-9 && t < 1e-9, "{r} {t}");
    }

    #[test]
    fn a_translation_is_its_own_vector() {
        let coords = Coordinates {
            centre_mm: [3.0, -20.0, -40.0],
            radius_mm: 45.0,
        };
        let v = coords.vector(&Pose::from_translation(Vector3::new(1.0, 2.0, 3.0)));
        assert!((v - Vector6::new(0.0, 0.0, 0.0, 1.0, 2.0, 3.0)).norm() < 1e-12);
    }
}
