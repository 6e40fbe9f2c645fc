//! The OpenCV pinhole camera: x right, y down, z forward; pixel (u, v) = (column, row) with
//! the centre of the top-left pixel at (0, 0). Distortion is OpenCV's ([`Distortion`]).

use nalgebra::{Matrix3x4, Vector2, Vector3};

use super::{Distortion, Pose};

#[derive(Clone, Debug, PartialEq)]
pub struct Camera {
    pub name: String,
    pub width: u32,
    pub height: u32,
    pub fx: f64,
    pub fy: f64,
    pub cx: f64,
    pub cy: f64,
    pub distortion: Distortion,
    pub camera_from_world: Pose,
}

impl Camera {
    pub fn has_distortion(&self) -> bool {
        self.distortion.is_some()
    }

    /// The same camera for an image of `width x height` (e.g. half-resolution masks):
    /// `f' = f·s`, `c' = (c + 0.5)·s − 0.5`, per axis.
    pub fn scaled_to(&self, width: u32, height: u32) -> Camera {
        let sx = width as f64 / self.width as f64;
        let sy = height as f64 / self.height as f64;
        Camera {
            width,
            height,
            fx: self.fx * sx,
            fy: self.fy * sy,
            cx: (self.cx + 0.5) * sx - 0.5,
            cy: (self.cy + 0.5) * sy - 0.5,
            ..self.clone()
        }
    }

    /// The largest r² (of undistorted normalised coordinates) up to which the lens's image
    /// radius keeps growing ([`Distortion::limit_r2`]); projections stop there.
    pub fn lens_limit_r2(&self) -> f64 {
        self.distortion.limit_r2()
    }

    /// World point to camera coordinates.
    pub fn to_camera(&self, p_world: &Vector3<f64>) -> Vector3<f64> {
        self.camera_from_world.transform_point(p_world)
    }

    /// How far from the principal point (distorted, normalised) the lens model reaches before
    /// it folds back: the image radius at [`Camera::lens_limit_r2`]; infinite if it never does.
    pub fn lens_reach(&self) -> f64 {
        self.distortion.reach()
    }

    /// Whether the whole image lies within [`Camera::lens_reach`]. When it does not, the model
    /// folds back inside the image and nothing is drawn past the fold.
    pub fn lens_covers_the_image(&self) -> bool {
        let reach = self.lens_reach();
        let (w, h) = (self.width as f64 - 1.0, self.height as f64 - 1.0);
        [(0.0, 0.0), (w, 0.0), (0.0, h), (w, h)]
            .iter()
            .all(|&(u, v)| {
                Vector2::new((u - self.cx) / self.fx, (v - self.cy) / self.fy).norm() < reach
            })
    }

    /// Apply the distortion model to normalised image coordinates.
    pub fn distort(&self, n: Vector2<f64>) -> Vector2<f64> {
        let [x, y] = self.distortion.apply(n.x, n.y);
        Vector2::new(x, y)
    }

    /// Invert [`Camera::distort`] by Newton's method (the Jacobian by central differences),
    /// which converges where fixed-point iteration (OpenCV's `undistortPoints`) does not: a
    /// fisheye's or a strong rational lens's image corners.
    pub fn undistort_normalised(&self, d: Vector2<f64>) -> Vector2<f64> {
        if !self.has_distortion() {
            return d;
        }
        let mut n = d;
        for _ in 0..50 {
            let err = self.distort(n) - d;
            if err.norm_squared() < 1e-24 {
                break;
            }
            let h = 1e-7;
            let dx = (self.distort(n + Vector2::new(h, 0.0))
                - self.distort(n - Vector2::new(h, 0.0)))
                / (2.0 * h);
            let dy = (self.distort(n + Vector2::new(0.0, h))
                - self.distort(n - Vector2::new(0.0, h)))
                / (2.0 * h);
            let j = nalgebra::Matrix2::from_columns(&[dx, dy]);
            match j.try_inverse() {
                Some(inv) => n -= inv * err,
                None => n -= err,
            }
        }
        n
    }

    /// Pixel to normalised coordinates with distortion removed.
    pub fn pixel_to_normalised(&self, px: Vector2<f64>) -> Vector2<f64> {
        let d = Vector2::new((px.x - self.cx) / self.fx, (px.y - self.cy) / self.fy);
        self.undistort_normalised(d)
    }

    pub fn normalised_to_pixel(&self, n: Vector2<f64>) -> Vector2<f64> {
        let d = self.distort(n);
        Vector2::new(self.fx * d.x + self.cx, self.fy * d.y + self.cy)
    }

    /// Project a world point; `None` when it is not in front of the camera.
    pub fn project(&self, p_world: &Vector3<f64>) -> Option<Vector2<f64>> {
        let pc = self.to_camera(p_world);
        (pc.z > 1e-9).then(|| self.normalised_to_pixel(Vector2::new(pc.x / pc.z, pc.y / pc.z)))
    }

    /// `[R | t]`, the normalised-coordinates projection matrix used by triangulation.
    pub fn extrinsic_matrix(&self) -> Matrix3x4<f64> {
        let mut m = Matrix3x4::zeros();
        m.fixed_view_mut::<3, 3>(0, 0)
            .copy_from(self.camera_from_world.rotation.matrix());
        m.fixed_view_mut::<3, 1>(0, 3)
            .copy_from(&self.camera_from_world.translation);
        m
    }

    /// Camera centre in world coordinates.
    pub fn centre_world(&self) -> Vector3<f64> {
        self.camera_from_world.inverse().translation
    }
}

/// A camera at `eye` looking at the origin (y down in the image), 640x480 with 800 px of
/// focal length: for tests that need a view, not a calibration.
#[cfg(test)]
pub(crate) fn looking_at_origin(eye: Vector3<f64>) -> Camera {
    let forward = (-eye).normalize();
    let right = Vector3::new(0.0, -1.0, 0.0).cross(&forward).normalize();
    let down = forward.cross(&right);
    let r = nalgebra::Rotation3::from_matrix_unchecked(nalgebra::Matrix3::from_rows(&[
        right.transpose(),
        down.transpose(),
        forward.transpose(),
    ]));
    Camera {
        name: "c".into(),
        width: 640,
        height: 480,
        fx: 800.0,
        fy: 800.0,
        cx: 320.0,
        cy: 240.0,
        distortion: Distortion::NONE,
        camera_from_world: Pose::new(r, -(r * eye)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    pub(crate) fn test_camera() -> Camera {
        Camera {
            name: "cam".into(),
            width: 1920,
            height: 1080,
            fx: 1400.0,
            fy: 1390.0,
            cx: 959.5,
            cy: 539.5,
            distortion: Distortion::brown([-0.12, 0.05, 0.001, -0.0007, -0.01]),
            camera_from_world: Pose::from_euler_tuple(&[0.05, -0.3, 0.02, 10.0, -3.0, 200.0]),
        }
    }

    #[test]
    fn scaling_keeps_pixel_centres_consistent() {
        let cam = Camera {
            distortion: Distortion::NONE,
            ..test_camera()
        };
        let half = cam.scaled_to(960, 540);
        let p = Vector3::new(3.0, -2.0, 5.0);
        let full = cam.project(&p).unwrap();
        let h = half.project(&p).unwrap();
        // Centre of full-res pixel u maps to (u + 0.5)/2 − 0.5 in the half-res image.
        assert!((h.x - ((full.x + 0.5) * 0.5 - 0.5)).abs() < 1e-9);
        assert!((h.y - ((full.y + 0.5) * 0.5 - 0.5)).abs() < 1e-9);
    }

    #[test]
    fn the_lens_limit_is_where_the_radial_model_turns_back() {
        let with = |k| Camera {
            distortion: Distortion::brown(k),
            ..test_camera()
        };
        // r (1 - 0.5 r²) peaks at r² = 2/3.
        let r2 = with([-0.5, 0.0, 0.0, 0.0, 0.0]).lens_limit_r2();
        assert!(r2 < 2.0 / 3.0 && r2 > 0.66, "{r2}");
        // Pincushion, and no distortion, never turn back.
        assert_eq!(
            with([0.1, 0.0, 0.0, 0.0, 0.0]).lens_limit_r2(),
            f64::INFINITY
        );
        assert_eq!(with([0.0; 5]).lens_limit_r2(), f64::INFINITY);
        // The test camera's moderate barrel turns back far outside its image.
        let cam = test_camera();
        let corner = Vector2::new(cam.cx / cam.fx, cam.cy / cam.fy).norm_squared();
        assert!(cam.lens_limit_r2() > 4.0 * corner);
        assert!(cam.lens_covers_the_image());
        assert!(!with([-0.5, 0.0, 0.0, 0.0, 0.0]).lens_covers_the_image());
    }

    #[test]
    fn undistort_inverts_distort() {
        let cam = test_camera();
        for &(x, y) in &[(0.0, 0.0), (0.3, -0.2), (-0.5, 0.4), (0.6, 0.3)] {
            let n = Vector2::new(x, y);
            let px = cam.normalised_to_pixel(n);
            let back = cam.pixel_to_normalised(px);
            assert!((back - n).norm() < 1e-10, "{n:?} -> {back:?}");
        }
    }

    #[test]
    fn principal_point_projects_from_optical_axis() {
        let cam = test_camera();
        let on_axis = cam
            .camera_from_world
            .inverse()
            .transform_point(&Vector3::new(0.0, 0.0, 50.0));
        let px = cam.project(&on_axis).unwrap();
        assert!((px - Vector2::new(cam.cx, cam.cy)).norm() < 1e-9);
        let behind = cam
            .camera_from_world
            .inverse()
            .transform_point(&Vector3::new(0.0, 0.0, -5.0));
        assert!(cam.project(&behind).is_none());
    }
}
