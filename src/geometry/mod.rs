//! Geometry: SE(3)/se(3), the OpenCV camera, triangulation and rigid fitting.

mod camera;
mod distortion;
pub mod least_squares;
#[cfg(test)]
pub(crate) mod lie_suite;
mod rigid_fit;
mod se3;
mod triangulate;

pub use camera::Camera;
#[cfg(test)]
pub(crate) use camera::looking_at_origin;
pub use distortion::Distortion;
pub use rigid_fit::{RigidFitError, fit_rigid};
pub use se3::{Pose, hat, jaw_pose, so3_exp, so3_log};
pub use triangulate::{TriangulationError, triangulate};

#[cfg(test)]
mod so3_suite {
    use super::lie_suite::{LieGroup, group_axiom_suite};
    use super::*;
    use nalgebra::{Rotation3, Vector3};

    #[derive(Clone, Copy, Debug)]
    struct So3(Rotation3<f64>);

    impl LieGroup for So3 {
        type Tangent = Vector3<f64>;
        const NAME: &'static str = "SO(3)";
        fn exp(w: &Vector3<f64>) -> Self {
            So3(so3_exp(w))
        }
        fn log(&self) -> Vector3<f64> {
            so3_log(&self.0)
        }
        fn compose(&self, o: &Self) -> Self {
            So3(self.0 * o.0)
        }
        fn inverse(&self) -> Self {
            So3(self.0.inverse())
        }
        fn identity() -> Self {
            So3(Rotation3::identity())
        }
        fn adjoint_apply(&self, w: &Vector3<f64>) -> Vector3<f64> {
            self.0 * w
        }
        fn distance(&self, o: &Self) -> f64 {
            (self.0.matrix() - o.0.matrix()).abs().max()
        }
        fn tangent_distance(a: &Vector3<f64>, b: &Vector3<f64>) -> f64 {
            (a - b).norm()
        }
        fn tangents() -> Vec<Vector3<f64>> {
            let pi = std::f64::consts::PI;
            vec![
                Vector3::zeros(),
                Vector3::new(1e-10, 0.0, -1e-10),
                Vector3::new(3e-5, 2e-5, 0.0),
                Vector3::new(0.5, -1.0, 0.25),
                Vector3::new(pi - 1e-9, 0.0, 0.0),
                Vector3::new(0.0, -(pi - 1e-4), 0.0),
                Vector3::new(1.0, 1.0, 1.0).normalize() * (pi - 1e-6),
            ]
        }
    }

    #[test]
    fn so3_group_axioms() {
        group_axiom_suite::<So3>();
    }
}
