//! How finely the cameras see the arches: the size of a mask pixel where the cameras look,
//! which bounds how far a scan can be simplified before any silhouette could tell.

use nalgebra::Vector2;

use super::CaptureCamera;
use crate::geometry::{Camera, triangulate};

/// The simplification bound where none is given, in mask pixels of the camera that sees the
/// arches finest: a tenth of a pixel moves no pixel centre's coverage in ten.
pub const SIMPLIFY_PX: f64 = 0.1;

/// The bound where the cameras' axes meet nowhere (one camera, parallel axes): a twentieth
/// of a pixel of a GoPro's half-resolution mask at 20 cm (0.4 mm a pixel).
pub const FALLBACK_SIMPLIFY_MM: f64 = 0.02;

/// The bounds are kept within this range (mm) whatever the cameras say.
const SIMPLIFY_RANGE_MM: (f64, f64) = (0.005, 0.1);

/// The simplification bound (mm) for these cameras: [`SIMPLIFY_PX`] of [`finest_pixel_mm`].
pub fn simplify_mm(cameras: &[CaptureCamera]) -> f64 {
    finest_pixel_mm(cameras).map_or(FALLBACK_SIMPLIFY_MM, |p| {
        (SIMPLIFY_PX * p).clamp(SIMPLIFY_RANGE_MM.0, SIMPLIFY_RANGE_MM.1)
    })
}

/// The smallest mask pixel (mm) of any camera at the point its and the others' optical axes
/// pass nearest, which is where a rig filming a mouth looks. A camera without masks yet (they
/// are to be made from its pictures) counts at its calibrated resolution. `None` where the
/// axes do not meet in front of the cameras.
pub fn finest_pixel_mm(cameras: &[CaptureCamera]) -> Option<f64> {
    let cams: Vec<Camera> = cameras
        .iter()
        .map(|c| c.mask_camera().unwrap_or_else(|| c.calibrated.clone()))
        .collect();
    let axes: Vec<(&Camera, Vector2<f64>)> =
        cams.iter().map(|c| (c, Vector2::new(c.cx, c.cy))).collect();
    let looked_at = triangulate(&axes).ok()?;
    cams.iter()
        .map(|c| {
            let depth = c.to_camera(&looked_at).z;
            (depth > 0.0).then(|| depth / c.fx.max(c.fy))
        })
        .collect::<Option<Vec<f64>>>()?
        .into_iter()
        .min_by(f64::total_cmp)
}

#[cfg(test)]
mod tests {
    use std::collections::BTreeSet;

    use nalgebra::Vector3;

    use super::*;
    use crate::geometry::looking_at_origin;

    /// A camera at `centre` looking at the origin with `fx` pixels of focal length at
    /// 1920x1080, its masks `mask_width` wide.
    fn camera(centre: Vector3<f64>, fx: f64, mask_width: Option<u32>) -> CaptureCamera {
        let calibrated = Camera {
            width: 1920,
            height: 1080,
            fx,
            fy: fx,
            cx: 959.5,
            cy: 539.5,
            ..looking_at_origin(centre)
        };
        CaptureCamera {
            calibrated,
            mask_size: mask_width.map(|w| (w, w * 9 / 16)),
            frames_present: BTreeSet::new(),
            offset: 0,
        }
    }

    #[test]
    fn the_pixel_is_the_finest_cameras_where_the_axes_meet() {
        // Two cameras 200 mm from the origin, one 412 mm: the near ones see 200 / 515 mm a
        // pixel in their half-resolution masks.
        let cams = [
            camera(Vector3::new(-120.0, 0.0, 160.0), 1030.0, Some(960)),
            camera(Vector3::new(0.0, 0.0, 200.0), 1030.0, Some(960)),
            camera(Vector3::new(0.0, 100.0, 400.0), 1030.0, Some(960)),
        ];
        let px = finest_pixel_mm(&cams).expect("the axes meet");
        assert!((px - 200.0 / 515.0).abs() < 1e-6, "{px}");
        let half = simplify_mm(&cams);
        assert!((half - SIMPLIFY_PX * px).abs() < 1e-9);
        // Full-resolution masks halve the pixel, and the bound with it.
        let full = cams.map(|mut c| {
            c.mask_size = Some((1920, 1080));
            c
        });
        assert!((simplify_mm(&full) - half / 2.0).abs() < 1e-9);
    }

    #[test]
    fn cameras_whose_axes_do_not_meet_get_the_fallback() {
        let one = [camera(Vector3::new(0.0, 0.0, 200.0), 1030.0, Some(960))];
        assert_eq!(finest_pixel_mm(&one), None);
        assert_eq!(simplify_mm(&one), FALLBACK_SIMPLIFY_MM);
    }
}
