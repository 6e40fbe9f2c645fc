//! Linear (DLT) triangulation of a point seen by two or more calibrated cameras.

use nalgebra::{Matrix4, Vector2, Vector3};

use super::Camera;

/// Why a point could not be triangulated.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TriangulationError {
    #[error("a point needs pixels in at least two cameras, got {0}")]
    TooFewViews(usize),
    #[error("the views are degenerate (parallel rays or the point at infinity)")]
    Degenerate,
}

/// Triangulate from `(camera, pixel)` observations. Pixels are in the camera's own image
/// (distorted); distortion is removed first. Solves `A X = 0` for homogeneous X by the
/// eigenvector of `AᵀA` with the smallest eigenvalue.
pub fn triangulate(views: &[(&Camera, Vector2<f64>)]) -> Result<Vector3<f64>, TriangulationError> {
    if views.len() < 2 {
        return Err(TriangulationError::TooFewViews(views.len()));
    }
    let mut ata = Matrix4::<f64>::zeros();
    for (cam, px) in views {
        let n = cam.pixel_to_normalised(*px);
        let p = cam.extrinsic_matrix();
        for row in [p.row(2) * n.x - p.row(0), p.row(2) * n.y - p.row(1)] {
            ata += row.transpose() * row;
        }
    }
    let eig = ata.symmetric_eigen();
    let i = eig.eigenvalues.imin();
    let x = eig.eigenvectors.column(i);
    if x[3].abs() < 1e-12 {
        return Err(TriangulationError::Degenerate);
    }
    let point = Vector3::new(x[0] / x[3], x[1] / x[3], x[2] / x[3]);
    // Parallel rays make the second-smallest eigenvalue vanish too.
    let mut sorted: Vec<f64> = eig.eigenvalues.iter().copied().collect();
    sorted.sort_by(f64::total_cmp);
    if sorted[1] <= 1e-12 * sorted[3].max(1e-300) {
        return Err(TriangulationError::Degenerate);
    }
    Ok(point)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::Pose;

    fn cam(name: &str, yaw: f64) -> Camera {
        // Looks at the origin from 200 mm away, rotated about y.
        let world_from_cam = Pose::from_euler_tuple(&[0.0, yaw, 0.0, 0.0, 0.0, 0.0])
            .compose(&Pose::from_translation(Vector3::new(0.0, 0.0, -200.0)));
        Camera {
            name: name.into(),
            width: 1920,
            height: 1080,
            fx: 1000.0,
            fy: 1000.0,
            cx: 959.5,
            cy: 539.5,
            distortion: crate::geometry::Distortion::brown([-0.05, 0.01, 0.0, 0.0, 0.0]),
            camera_from_world: world_from_cam.inverse(),
        }
    }

    #[test]
    fn recovers_a_point_from_three_views() {
        let cams = [cam("a", -0.5), cam("b", 0.0), cam("c", 0.5)];
        let x = Vector3::new(5.0, -3.0, 12.0);
        let views: Vec<_> = cams.iter().map(|c| (c, c.project(&x).unwrap())).collect();
        let got = triangulate(&views).unwrap();
        assert!((got - x).norm() < 1e-6, "{got:?}");
        let with_noise: Vec<_> = views
            .iter()
            .map(|(c, p)| (*c, p + Vector2::new(0.3, -0.2)))
            .collect();
        assert!((triangulate(&with_noise).unwrap() - x).norm() < 0.5);
    }

    #[test]
    fn rejects_one_view() {
        let c = cam("a", 0.0);
        let err = triangulate(&[(&c, Vector2::new(1.0, 1.0))]).unwrap_err();
        assert_eq!(err, TriangulationError::TooFewViews(1));
    }
}
