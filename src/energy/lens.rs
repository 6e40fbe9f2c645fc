//! Lens distortion in the energy. Masks are used as the cameras saw them; the models are drawn
//! through each camera's lens instead: every vertex goes through the camera's lens model
//! before it is snapped, and a triangle's edges stay straight between its distorted vertices.
//! The arches' triangles span a few pixels, over which the lens bends a line by well under a
//! hundredth of a pixel (`tests` below measures it against an exact rendering).
//!
//! [`Lens`] is the f32 form both rasterisers use, in the same order of operations as
//! shaders/raster.wgsl. [`bounds_through`] carries a pinhole bounding rectangle through the
//! lens for the conservative footprints.

use crate::geometry::{Camera, Distortion};

/// The lens models the shader knows: `Draw.lens_model` in shaders/raster.wgsl.
pub const MODEL_OPENCV: u32 = 1;
pub const MODEL_FISHEYE: u32 = 2;

/// A camera's lens as the projection applies it (f32).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Lens {
    /// [`MODEL_OPENCV`] or [`MODEL_FISHEYE`].
    pub model: u32,
    /// OpenCV's k1, k2, p1, p2, k3, k4, k5, k6, s1, s2, s3, s4; the fisheye's k1..k4 first.
    pub k: [f32; 12],
    /// Points further off the axis than this (r², undistorted) are not projected: the model
    /// folds back there ([`Camera::lens_limit_r2`]).
    pub limit_r2: f32,
}

impl Lens {
    /// The camera's lens; `None` without distortion (projection is then the pinhole's,
    /// computed as before to the bit).
    pub fn of(cam: &Camera) -> Option<Lens> {
        if !cam.has_distortion() {
            return None;
        }
        let mut k = [0.0f32; 12];
        let model = match cam.distortion {
            Distortion::OpenCv(c) => {
                k = c.map(|v| v as f32);
                MODEL_OPENCV
            }
            Distortion::Fisheye(c) => {
                for (dst, src) in k.iter_mut().zip(c) {
                    *dst = src as f32;
                }
                MODEL_FISHEYE
            }
        };
        Some(Lens {
            model,
            k,
            limit_r2: cam.lens_limit_r2().min(f32::MAX as f64) as f32,
        })
    }

    /// Distorted normalised coordinates of undistorted (x, y); `None` beyond the limit.
    #[inline]
    pub fn apply(&self, x: f32, y: f32) -> Option<[f32; 2]> {
        let r2 = x * x + y * y;
        if r2 > self.limit_r2 {
            return None;
        }
        let k = &self.k;
        if self.model == MODEL_FISHEYE {
            let s = fisheye_scale(k, r2);
            return Some([x * s, y * s]);
        }
        // With k4..k6 zero the quotient is by 1.0, exact: the classic model's bits.
        let radial = (1.0 + r2 * (k[0] + r2 * (k[1] + r2 * k[4])))
            / (1.0 + r2 * (k[5] + r2 * (k[6] + r2 * k[7])));
        let xy = x * y;
        Some([
            x * radial + 2.0 * k[2] * xy + k[3] * (r2 + 2.0 * x * x) + r2 * (k[8] + r2 * k[9]),
            y * radial + k[2] * (r2 + 2.0 * y * y) + 2.0 * k[3] * xy + r2 * (k[10] + r2 * k[11]),
        ])
    }
}

/// θd / r of the fisheye model in f32, with [`atan`] (the shader's twin, so both engines
/// compute the same bits where the hardware's own atan might not).
#[inline]
fn fisheye_scale(k: &[f32; 12], r2: f32) -> f32 {
    if r2 < 1e-20 {
        return 1.0;
    }
    let r = r2.sqrt();
    let t = atan(r);
    let t2 = t * t;
    t * (1.0 + t2 * (k[0] + t2 * (k[1] + t2 * (k[2] + t2 * k[3])))) / r
}

/// atan(r) for r ≥ 0 from +, ×, ÷ alone: reduced to |u| ≤ tan(π/8) by atan(r) = π/2 − atan(1/r)
/// and atan(a) = π/4 + atan((a − 1)/(a + 1)), then the odd Taylor series to u¹⁷ (its error,
/// under 0.414¹⁹/19 ≈ 3e-9, is below f32's rounding).
#[inline]
pub fn atan(r: f32) -> f32 {
    let (a, flip) = if r > 1.0 { (1.0 / r, true) } else { (r, false) };
    let (u, base) = if a > 0.414_213_57 {
        ((a - 1.0) / (a + 1.0), std::f32::consts::FRAC_PI_4)
    } else {
        (a, 0.0)
    };
    let u2 = u * u;
    let series = u
        * (1.0
            + u2 * (-1.0 / 3.0
                + u2 * (1.0 / 5.0
                    + u2 * (-1.0 / 7.0
                        + u2 * (1.0 / 9.0
                            + u2 * (-1.0 / 11.0
                                + u2 * (1.0 / 13.0 + u2 * (-1.0 / 15.0 + u2 * (1.0 / 17.0)))))))));
    let t = base + series;
    if flip {
        std::f32::consts::FRAC_PI_2 - t
    } else {
        t
    }
}

/// The pixel bounds of what a rectangle `[lo, hi]` of undistorted normalised coordinates
/// becomes through the camera's lens (`lens`, [`Lens::of`] the camera), or `None` (take the
/// whole image) when part of it lies beyond the lens limit or it spans over four times the
/// image (points near the camera's plane). The lens is one-to-one inside its limit, so the
/// rectangle's image is bounded by the image of its border, which is walked in steps of at
/// most 16 pixels. Between steps an edge bends by about |D''|·16²/8 pixels, D'' the lens's
/// second derivative (about 6·|k1|·r/f per pixel): 0.1 pixel for k1 = −0.4 at r = 0.7 with
/// f = 515 px (the synthetic rig's half-resolution masks), a few thousandths where the arches
/// are. Callers add a pixel.
pub fn bounds_through(
    cam: &Camera,
    lens: &Lens,
    lo: [f64; 2],
    hi: [f64; 2],
) -> Option<([f64; 2], [f64; 2])> {
    let f = [cam.fx, cam.fy];
    let span = [0, 1].map(|k| (hi[k] - lo[k]) * f[k]);
    if span[0] > 4.0 * cam.width as f64 || span[1] > 4.0 * cam.height as f64 {
        return None;
    }
    let (mut dlo, mut dhi) = ([f32::INFINITY; 2], [f32::NEG_INFINITY; 2]);
    let mut visit = |x: f64, y: f64| -> Option<()> {
        let d = lens.apply(x as f32, y as f32)?;
        dlo = [dlo[0].min(d[0]), dlo[1].min(d[1])];
        dhi = [dhi[0].max(d[0]), dhi[1].max(d[1])];
        Some(())
    };
    let [nu, nv] = span.map(|s| ((s / 16.0).ceil() as usize).max(1));
    // Top and bottom edges, corners included, then the sides between them.
    for i in 0..=nu {
        let x = lo[0] + (hi[0] - lo[0]) * i as f64 / nu as f64;
        visit(x, lo[1])?;
        visit(x, hi[1])?;
    }
    for j in 1..nv {
        let y = lo[1] + (hi[1] - lo[1]) * j as f64 / nv as f64;
        visit(lo[0], y)?;
        visit(hi[0], y)?;
    }
    let c = [cam.cx, cam.cy];
    Some((
        [0, 1].map(|k| f[k] * dlo[k] as f64 + c[k]),
        [0, 1].map(|k| f[k] * dhi[k] as f64 + c[k]),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::Pose;
    use nalgebra::Vector2;

    fn camera(k: [f64; 5]) -> Camera {
        with_lens(Distortion::brown(k))
    }

    fn with_lens(distortion: Distortion) -> Camera {
        Camera {
            name: "c".into(),
            width: 960,
            height: 540,
            fx: 515.0,
            fy: 515.0,
            cx: 479.5,
            cy: 269.5,
            distortion,
            camera_from_world: Pose::IDENTITY,
        }
    }

    use crate::synth::{FISHEYE_LENS as FISHEYE, RATIONAL_LENS as RATIONAL};

    #[test]
    fn the_f32_atan_is_atan() {
        for i in 0..=4000 {
            let r = i as f32 * 0.005;
            let err = (atan(r) as f64 - (r as f64).atan()).abs();
            assert!(err < 3e-7, "atan({r}): off by {err}");
        }
    }

    #[test]
    fn every_f32_model_is_the_cameras() {
        for lens in [RATIONAL, FISHEYE] {
            let cam = with_lens(lens);
            let f32_lens = Lens::of(&cam).unwrap();
            for (x, y) in [(0.0, 0.0), (0.3, -0.2), (-0.9, 0.5), (1.2, 0.7)] {
                let d = cam.distort(Vector2::new(x, y));
                let f = f32_lens.apply(x as f32, y as f32).unwrap();
                let err = (f[0] as f64 - d.x).abs().max((f[1] as f64 - d.y).abs());
                assert!(err < 2e-6, "{lens:?} ({x}, {y}): off by {err}");
            }
        }
    }

    #[test]
    fn the_f32_lens_is_the_cameras_model() {
        let cam = camera([-0.25, 0.08, 0.001, -0.0005, 0.01]);
        let lens = Lens::of(&cam).unwrap();
        for (x, y) in [(0.0, 0.0), (0.3, -0.2), (-0.9, 0.5), (1.2, 0.7)] {
            let d = cam.distort(Vector2::new(x, y));
            let f = lens.apply(x as f32, y as f32).unwrap();
            assert!((f[0] as f64 - d.x).abs() < 1e-6 && (f[1] as f64 - d.y).abs() < 1e-6);
        }
        assert!(Lens::of(&camera([0.0; 5])).is_none());
        let folding = Lens::of(&camera([-0.5, 0.0, 0.0, 0.0, 0.0])).unwrap();
        assert!(folding.apply(0.8, 0.0).is_some() && folding.apply(0.9, 0.0).is_none());
    }

    #[test]
    fn a_rectangles_bounds_through_the_lens_hold_its_points() {
        let cam = camera([-0.25, 0.08, 0.001, -0.0005, 0.0]);
        let (lo, hi) = ([100.0, 50.0], [700.0, 400.0]);
        let to_n = |p: [f64; 2]| [(p[0] - cam.cx) / cam.fx, (p[1] - cam.cy) / cam.fy];
        let lens = Lens::of(&cam).unwrap();
        let (blo, bhi) = bounds_through(&cam, &lens, to_n(lo), to_n(hi)).unwrap();
        let mut touched = [false; 4];
        for i in 0..=60 {
            for j in 0..=35 {
                let u = lo[0] + (hi[0] - lo[0]) * i as f64 / 60.0;
                let v = lo[1] + (hi[1] - lo[1]) * j as f64 / 35.0;
                let p = cam.normalised_to_pixel(Vector2::new(
                    (u - cam.cx) / cam.fx,
                    (v - cam.cy) / cam.fy,
                ));
                assert!(p.x >= blo[0] - 1e-9 && p.x <= bhi[0] + 1e-9, "{p}");
                assert!(p.y >= blo[1] - 1e-9 && p.y <= bhi[1] + 1e-9, "{p}");
                touched[0] |= (p.x - blo[0]).abs() < 0.5;
                touched[1] |= (p.x - bhi[0]).abs() < 0.5;
                touched[2] |= (p.y - blo[1]).abs() < 0.5;
                touched[3] |= (p.y - bhi[1]).abs() < 0.5;
            }
        }
        assert_eq!(touched, [true; 4], "the bounds are tight");
        // Barrel: the far corner comes in.
        assert!(bhi[0] < hi[0] - 5.0);
        let beyond = camera([-0.5, 0.0, 0.0, 0.0, 0.0]);
        let folding = Lens::of(&beyond).unwrap();
        assert!(bounds_through(&beyond, &folding, [-0.93, -0.52], [0.93, 0.52]).is_none());
        // Far larger than the image: not walked.
        assert!(bounds_through(&cam, &lens, [-1e4, 0.0], [1e4, 0.01]).is_none());
    }

    /// An independent rendering through the lens: the labels drawn on a pinhole canvas three
    /// times finer that covers what the distorted image sees, then each distorted pixel takes
    /// the label at its undistorted position (the nearest canvas pixel, at most 1/6 pixel off).
    fn through_a_canvas(cam: &Camera, items: &[(&crate::mesh::Mesh, &Pose, u8, u8)]) -> Vec<u8> {
        const FINE: f64 = 3.0;
        let (w, h) = (cam.width as usize, cam.height as usize);
        let undistorted: Vec<Vector2<f64>> = (0..w * h)
            .map(|i| {
                let px = Vector2::new((i % w) as f64, (i / w) as f64);
                let n = cam.pixel_to_normalised(px);
                assert!((cam.normalised_to_pixel(n) - px).norm() < 1e-6);
                Vector2::new(cam.fx * n.x + cam.cx, cam.fy * n.y + cam.cy)
            })
            .collect();
        let lo = undistorted
            .iter()
            .fold(Vector2::repeat(f64::INFINITY), |a, p| a.inf(p))
            .map(|x| x.floor() - 1.0);
        let hi = undistorted
            .iter()
            .fold(Vector2::repeat(f64::NEG_INFINITY), |a, p| a.sup(p));
        let size = ((hi - lo) * FINE).map(|x| x.ceil() as u32 + 2);
        let canvas = Camera {
            width: size.x,
            height: size.y,
            fx: cam.fx * FINE,
            fy: cam.fy * FINE,
            cx: (cam.cx - lo.x) * FINE,
            cy: (cam.cy - lo.y) * FINE,
            distortion: Distortion::NONE,
            ..cam.clone()
        };
        let fine = crate::energy::raster::render_labels(&canvas, items);
        undistorted
            .iter()
            .map(|p| {
                let c = ((p - lo) * FINE).map(|x| x.round() as usize);
                fine[c.y * size.x as usize + c.x]
            })
            .collect()
    }

    /// Labelled pixels with a 4-neighbour of another label.
    fn edge_pixels(labels: &[u8], w: usize) -> usize {
        (0..labels.len())
            .filter(|&i| {
                let (x, y) = (i % w, i / w);
                let l = labels[i];
                l != 0
                    && [
                        (x > 0, i.wrapping_sub(1)),
                        (x + 1 < w, i + 1),
                        (y > 0, i.wrapping_sub(w)),
                        (i + w < labels.len(), i + w),
                    ]
                    .iter()
                    .any(|&(ok, j)| ok && labels[j] != l)
            })
            .count()
    }

    /// The energy bends no triangle edge; the canvas renders the lens exactly up to its
    /// sampling. On the procedural arches, seen by the synthetic rig at half resolution, the
    /// two differ only in pixels the canvas's 1/6-pixel sampling can flip: under a tenth of
    /// the edge pixels (about 2-5% measured), and none without distortion.
    #[test]
    fn the_energys_lens_draws_what_an_exact_rendering_draws() {
        let arches = [
            crate::anatomy::procedural_arch(true),
            crate::anatomy::procedural_arch(false),
        ];
        let rest = crate::anatomy::rest_bite(&arches[0], &arches[1]);
        for distortion in [
            Distortion::NONE,
            Distortion::brown([-0.25, 0.08, 0.001, -0.0005, 0.0]),
            Distortion::brown([0.15, 0.0, 0.0, 0.0, 0.0]),
            RATIONAL,
            FISHEYE,
        ] {
            for cam in crate::synth::rig_cameras() {
                let cam = Camera {
                    distortion,
                    ..cam.scaled_to(cam.width / 2, cam.height / 2)
                };
                let items = [
                    (&arches[0], &Pose::IDENTITY, 1, 2),
                    (&arches[1], &rest, 3, 4),
                ];
                let direct = crate::energy::raster::render_labels(&cam, &items);
                let exact = through_a_canvas(&cam, &items);
                let differ = direct.iter().zip(&exact).filter(|(a, b)| a != b).count();
                let edges = edge_pixels(&direct, cam.width as usize);
                assert!(edges > 500);
                if distortion == Distortion::NONE {
                    assert_eq!(differ, 0, "{}", cam.name);
                } else {
                    assert!(
                        10 * differ <= edges,
                        "{distortion:?} {}: {differ} pixels differ, {edges} edge pixels",
                        cam.name
                    );
                }
            }
        }
    }
}
