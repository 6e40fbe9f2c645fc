//! The jaw's manifold: the average joint's jaw poses span a three-dimensional subspace of
//! se(3) (about the lower arch's centroid, rotations weighted by its RMS radius: the rig's
//! coordinates) to within a few tenths of a millimetre. A jaw pose farther off costs the
//! objective.

use nalgebra::Vector6;

use crate::anatomy::{Coordinates, MeshMetric, Pca};
use crate::geometry::Pose;
use crate::mesh::Mesh;

#[derive(Debug, Clone)]
pub struct JawManifold {
    coords: Coordinates,
    pca: Pca,
    weight: f64,
    tolerance_mm: f64,
}

impl JawManifold {
    /// The subspace of these jaw poses (upper_from_lower) of the `lower` arch.
    pub fn new(jaws: &[Pose], lower: &Mesh, weight: f64, tolerance_mm: f64) -> JawManifold {
        let coords = Coordinates::for_mesh(&MeshMetric::new(lower));
        let vectors: Vec<Vector6<f64>> = jaws.iter().map(|j| coords.vector(j)).collect();
        JawManifold {
            pca: Pca::fit(&vectors),
            coords,
            weight,
            tolerance_mm,
        }
    }

    /// How far `jaw` lies from the subspace (mm, about the mean vertex displacement).
    pub fn distance_mm(&self, jaw: &Pose) -> f64 {
        let v = self.coords.vector(jaw);
        (v - self.pca.reconstruct(&v, 3)).norm()
    }

    pub fn tolerance_mm(&self) -> f64 {
        self.tolerance_mm
    }

    /// The objective's penalty: `weight` per mm beyond the tolerance.
    pub fn penalty(&self, jaw: &Pose) -> f64 {
        self.weight * (self.distance_mm(jaw) - self.tolerance_mm).max(0.0)
    }
}

#[cfg(test)]
mod tests {
    use nalgebra::Vector3;

    use super::*;
    use crate::anatomy::{JawControls, JawModel, procedural_arch, rest_bite};
    use crate::track::prior::JawPrior;

    #[test]
    fn the_joints_poses_lie_on_it_and_a_tilt_about_the_incisors_does_not() {
        let (upper, lower) = (procedural_arch(true), procedural_arch(false));
        let rest = rest_bite(&upper, &lower);
        let fine = JawPrior::new(
            &upper,
            &lower,
            &rest,
            [0; 3],
            [31, 11, 6],
            0,
            Vector3::zeros(),
        )
        .fine;
        let m = JawManifold::new(&fine, &lower, 60.0, 0.3);
        let farthest = |poses: &[Pose]| poses.iter().map(|j| m.distance_mm(j)).fold(0.0, f64::max);
        let on = farthest(&fine);
        assert!(on < 0.5, "the average joint's poses: up to {on} mm off");
        // Another subject's joint (synth's `variant`) moves on a nearby manifold.
        let variant = JawModel::variant_for_arches(&upper, rest);
        let poses: Vec<Pose> = (0..=10)
            .flat_map(|i| (-2..=2).map(move |k| (i, k)))
            .map(|(i, k)| {
                variant.jaw_pose(&JawControls {
                    open: i as f64 / 10.0,
                    lateral: k as f64 / 2.0,
                    protrusion: 0.0,
                })
            })
            .collect();
        let near = farthest(&poses);
        assert!(near < 1.0, "the variant joint's poses: up to {near} mm off");
        // A tilt of 3° about a lateral axis through the lower incisors (the energy's flat
        // direction) at rest.
        let (_, hi) = lower.bounds();
        let front = Vector3::new(0.0, hi[1] as f64, hi[2] as f64);
        let tilt = Pose::from_translation(front)
            .compose(&Pose::from_euler_tuple(&[
                3f64.to_radians(),
                0.0,
                0.0,
                0.0,
                0.0,
                0.0,
            ]))
            .compose(&Pose::from_translation(-front));
        let tilted = rest.compose(&tilt);
        let d = m.distance_mm(&tilted);
        assert!(d > 1.2, "tilted 3° about the incisors: {d} mm off");
        // The penalty: 60 per mm beyond 0.3 mm.
        let at_rest = m.distance_mm(&rest);
        let expected = 60.0 * (at_rest - 0.3).max(0.0);
        assert!((m.penalty(&rest) - expected).abs() < 1e-9);
        assert!((m.penalty(&tilted) - 60.0 * (d - 0.3)).abs() < 1e-9);
    }
}
