//! The OpenCV pinhole camera: x right, y down, z forward; pixel (u, v) = (column, row) with
//! the centre of the top-left pixel at (0, 0). Distortion is OpenCV's (k1, k2, p1, p2, k3).

use nalgebra::{Matrix3x4, Vector2, Vector3};

use super::Pose;

#[derive(Clone, Debug, PartialEq)]
pub struct Camera {
    pub name: String,
    pub width: u32,
    pub height: u32,
    pub fx: f64,
    pub fy: f64,
    pub cx: f64,
    pub cy: f64,
    /// OpenCV order (k1, k2, p1, p2, k3).
    pub distortion: [f64; 5],
    pub camera_from_world: Pose,
}

impl Camera {
    pub fn has_distortion(&self) -> bool {
        self.distortion.iter().any(|&k| k != 0.0)
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

    /// The largest r² (of undistorted normalised coordinates) up to which the radial
    /// distortion's image radius r·(1 + k1 r² + k2 r⁴ + k3 r⁶) keeps growing with r. Beyond it
    /// the lens model folds back and would map points far outside the view into the image,
    /// so projections stop there. Infinite without radial distortion or when the model never
    /// folds (checked out to r = 20, 87° off the axis).
    pub fn lens_limit_r2(&self) -> f64 {
        let [k1, k2, _, _, k3] = self.distortion;
        // d(image radius)/dr as a cubic in t = r²; it is 1 at t = 0.
        let (a, b, c) = (3.0 * k1, 5.0 * k2, 7.0 * k3);
        let slope = |t: f64| 1.0 + t * (a + t * (b + t * c));
        const T_MAX: f64 = 400.0;
        // Between the cubic's turning points it is monotonic: find the first stretch where
        // it reaches zero, then bisect there.
        let mut points = [0.0, T_MAX, T_MAX, T_MAX];
        let (qa, qb, qc) = (3.0 * c, 2.0 * b, a);
        let turning: [f64; 2] = if qa != 0.0 {
            let disc = qb * qb - 4.0 * qa * qc;
            let sq = disc.max(0.0).sqrt();
            [(-qb - sq) / (2.0 * qa), (-qb + sq) / (2.0 * qa)]
        } else if qb != 0.0 {
            [-qc / qb; 2]
        } else {
            [T_MAX; 2]
        };
        for (slot, t) in points[2..].iter_mut().zip(turning) {
            if t > 0.0 && t < T_MAX {
                *slot = t;
            }
        }
        points.sort_by(f64::total_cmp);
        for w in points.windows(2) {
            let (mut lo, mut hi) = (w[0], w[1]);
            if slope(hi) > 0.0 {
                continue;
            }
            for _ in 0..100 {
                let mid = 0.5 * (lo + hi);
                if slope(mid) > 0.0 {
                    lo = mid;
                } else {
                    hi = mid;
                }
            }
            return lo;
        }
        f64::INFINITY
    }

    /// World point to camera coordinates.
    pub fn to_camera(&self, p_world: &Vector3<f64>) -> Vector3<f64> {
        self.camera_from_world.transform_point(p_world)
    }

    /// How far from the principal point (distorted, normalised) the lens model reaches before
    /// it folds back: the image radius at [`Camera::lens_limit_r2`]; infinite if it never does.
    pub fn lens_reach(&self) -> f64 {
        let limit = self.lens_limit_r2();
        if limit.is_infinite() {
            return f64::INFINITY;
        }
        let [k1, k2, _, _, k3] = self.distortion;
        limit.sqrt() * (1.0 + limit * (k1 + limit * (k2 + limit * k3)))
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
        let [k1, k2, p1, p2, k3] = self.distortion;
        let (x, y) = (n.x, n.y);
        let r2 = x * x + y * y;
        let radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3));
        Vector2::new(
            x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x),
            y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y,
        )
    }

    /// Invert [`Camera::distort`] by fixed-point iteration (as OpenCV's `undistortPoints`).
    pub fn undistort_normalised(&self, d: Vector2<f64>) -> Vector2<f64> {
        if !self.has_distortion() {
            return d;
        }
        let mut n = d;
        for _ in 0..50 {
            let err = self.distort(n) - d;
            n -= err;
            if err.norm_squared() < 1e-24 {
                break;
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
            distortion: [-0.12, 0.05, 0.001, -0.0007, -0.01],
            camera_from_world: Pose::from_euler_tuple(&[0.05, -0.3, 0.02, 10.0, -3.0, 200.0]),
        }
    }

    #[test]
    fn scaling_keeps_pixel_centres_consistent() {
        let cam = Camera {
            distortion: [0.0; 5],
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
        let with = |distortion| Camera {
            distortion,
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
