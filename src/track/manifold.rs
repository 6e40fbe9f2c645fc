//! The jaw's manifold: the average joint's jaw poses span a three-dimensional subspace of
//! se(3) (about the lower arch's centroid, rotations weighted by its RMS radius: the rig's
//! coordinates) to within a few tenths of a millimetre. A jaw pose farther off costs the
//! objective. A subject's own jaw poses (their rig's, sampled over its valid range) make a
//! curved manifold instead: there the distance is to the tangent space of the nearest sample,
//! fitted to its neighbours.

use nalgebra::Vector6;

use crate::anatomy::{Coordinates, MeshMetric, Pca};
use crate::geometry::Pose;
use crate::mesh::Mesh;

#[derive(Debug, Clone)]
pub struct JawManifold {
    coords: Coordinates,
    shape: Shape,
    weight: f64,
    tolerance_mm: f64,
}

#[derive(Debug, Clone)]
enum Shape {
    /// One three-dimensional subspace.
    Flat(Pca),
    /// Samples of a curved manifold, each with its tangent space (the first three principal
    /// components of it and its neighbours) and how far along it the sample stands for the
    /// manifold (to its fourth neighbour: about one sampling step); past that the pose has left
    /// the sampled range.
    Curved(Vec<Sample>),
}

#[derive(Debug, Clone)]
struct Sample {
    at: Vector6<f64>,
    tangent: Pca,
    reach: f64,
}

/// How many samples (itself included) fit each sample's tangent space.
const NEIGHBOURS: usize = 12;

impl JawManifold {
    /// The subspace of these jaw poses (upper_from_lower) of the `lower` arch.
    pub fn new(jaws: &[Pose], lower: &Mesh, weight: f64, tolerance_mm: f64) -> JawManifold {
        let coords = Coordinates::for_mesh(&MeshMetric::new(lower));
        let vectors: Vec<Vector6<f64>> = jaws.iter().map(|j| coords.vector(j)).collect();
        JawManifold {
            shape: Shape::Flat(Pca::fit(&vectors)),
            coords,
            weight,
            tolerance_mm,
        }
    }

    /// The curved manifold these jaw poses sample (a subject's own rig over its valid range;
    /// at least four of them): poses beyond the range are off it too.
    pub fn sampled(jaws: &[Pose], lower: &Mesh, weight: f64, tolerance_mm: f64) -> JawManifold {
        let coords = Coordinates::for_mesh(&MeshMetric::new(lower));
        let vectors: Vec<Vector6<f64>> = jaws.iter().map(|j| coords.vector(j)).collect();
        let samples = vectors
            .iter()
            .map(|v| {
                let mut near: Vec<&Vector6<f64>> = vectors.iter().collect();
                near.sort_by(|a, b| (*a - v).norm_squared().total_cmp(&(*b - v).norm_squared()));
                let near: Vec<Vector6<f64>> = near.into_iter().take(NEIGHBOURS).copied().collect();
                Sample {
                    at: *v,
                    tangent: Pca::fit(&near),
                    reach: near.get(4).map_or(0.0, |n| (n - v).norm()),
                }
            })
            .collect();
        JawManifold {
            shape: Shape::Curved(samples),
            coords,
            weight,
            tolerance_mm,
        }
    }

    /// How far `jaw` lies from the manifold (mm, about the mean vertex displacement).
    pub fn distance_mm(&self, jaw: &Pose) -> f64 {
        let v = self.coords.vector(jaw);
        match &self.shape {
            Shape::Flat(pca) => (v - pca.reconstruct(&v, 3)).norm(),
            Shape::Curved(samples) => {
                let s = samples
                    .iter()
                    .min_by(|a, b| {
                        (a.at - v)
                            .norm_squared()
                            .total_cmp(&(b.at - v).norm_squared())
                    })
                    .expect("samples");
                let on = s.tangent.reconstruct(&v, 3);
                let beyond = ((on - s.at).norm() - s.reach).max(0.0);
                (v - on).norm().hypot(beyond)
            }
        }
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

    #[test]
    fn a_subjects_own_poses_hold_the_jaw_closer_than_the_average_joints() {
        let (upper, lower) = (procedural_arch(true), procedural_arch(false));
        let rest = rest_bite(&upper, &lower);
        let variant = JawModel::variant_for_arches(&upper, rest);
        let pose = |open: f64, lateral: f64, protrusion: f64| {
            variant.jaw_pose(&JawControls {
                open,
                lateral,
                protrusion,
            })
        };
        // The subject's poses on a grid, and poses between its nodes.
        let grid: Vec<Pose> = (0..=12)
            .flat_map(|i| (-3..=3).flat_map(move |k| (0..=3).map(move |p| (i, k, p))))
            .map(|(i, k, p)| pose(i as f64 / 12.0, k as f64 / 3.0, p as f64 / 3.0))
            .collect();
        let own = JawManifold::sampled(&grid, &lower, 60.0, 0.3);
        let average = JawManifold::new(&grid, &lower, 60.0, 0.3);
        let between: Vec<Pose> = (0..12)
            .map(|i| pose((i as f64 + 0.5) / 12.0, 0.5 - i as f64 / 12.0, 0.5))
            .collect();
        let worst = |m: &JawManifold| between.iter().map(|j| m.distance_mm(j)).fold(0.0, f64::max);
        // Measured: 0.053 mm from the subject's own manifold, 0.32 from its flat fit.
        let (curved, flat) = (worst(&own), worst(&average));
        assert!(
            curved < 0.1 && curved < flat / 3.0,
            "curved {curved} mm, flat {flat} mm"
        );
        // Past the sampled range: the last tenth of the opening continued five times more.
        let (wide, widest) = (pose(0.9, 0.0, 0.0), pose(1.0, 0.0, 0.0));
        let step = wide.inverse().compose(&widest);
        let beyond = (0..5).fold(widest, |p, _| p.compose(&step));
        let past = own.distance_mm(&beyond);
        assert!(past > 1.0, "opened past the range: {past} mm off");
        assert!(own.distance_mm(&widest) < 0.01);
    }
}
