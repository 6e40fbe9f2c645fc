//! What turns a perfect label image into a realistic segmentation: lips that hide the
//! gum-side part of the crowns (3D curves attached to each arch, so the opening follows the
//! jaw), gums between the teeth filled in, small specular holes, and boundaries that wander
//! by a pixel or two.

use nalgebra::Vector3;
use rand::RngExt;

use crate::arch::{Arch, ArchPoses};
use crate::geometry::Camera;
use crate::mesh::Mesh;

/// A lip edge: points along the front of an arch, in that arch's frame.
#[derive(Debug, Clone)]
pub struct LipLine {
    /// (x, z, tip y) across the mouth, 1 mm apart: z just in front of the labial surface,
    /// and the height of the crown tips there (the incisal edge, not the molar cusps).
    front: Vec<(f64, f64, f64)>,
    half_width: f64,
    arch: Arch,
}

impl LipLine {
    /// Half the mouth's width: the corners are at the premolars.
    pub const MOUTH_HALF_WIDTH_MM: f64 = 24.0;
    /// How far the lips come towards each other at the corners, beyond the tips (mm).
    const CORNER_MM: f64 = 2.0;
    /// Depth behind the labial surface searched for the local tip height (mm).
    const FRONT_DEPTH_MM: f64 = 8.0;

    pub fn new(mesh: &Mesh, arch: Arch) -> LipLine {
        let (lo, hi) = mesh.bounds();
        let mid = (lo[0] + hi[0]) as f64 * 0.5;
        let w = Self::MOUTH_HALF_WIDTH_MM;
        let towards_tip = if arch == Arch::Upper { -1.0 } else { 1.0 };
        let mut front = Vec::new();
        for k in -(w as i64)..=(w as i64) {
            let x = mid + k as f64;
            let column: Vec<&[f32; 3]> = mesh
                .positions
                .iter()
                .filter(|p| (p[0] as f64 - x).abs() < 1.0)
                .collect();
            let z = column
                .iter()
                .map(|p| p[2] as f64)
                .fold(f64::NEG_INFINITY, f64::max);
            if !z.is_finite() {
                continue;
            }
            let tip = column
                .iter()
                .filter(|p| p[2] as f64 > z - Self::FRONT_DEPTH_MM)
                .map(|p| towards_tip * p[1] as f64)
                .fold(f64::NEG_INFINITY, f64::max);
            // The lip lies on the teeth, 1.5 mm in front of the labial surface.
            front.push((x, z + 1.5, towards_tip * tip));
        }
        LipLine {
            front,
            half_width: w,
            arch,
        }
    }

    /// The lip edge with `show_mm` of crown visible beyond the tips at the midline, in the
    /// arch's frame; at the corners the lip reaches `CORNER_MM` past the tips.
    fn points(&self, show_mm: f64) -> Vec<Vector3<f64>> {
        let away = if self.arch == Arch::Upper { 1.0 } else { -1.0 };
        let mid = self.front.iter().map(|p| p.0).sum::<f64>() / self.front.len().max(1) as f64;
        self.front
            .iter()
            .map(|&(x, z, tip_y)| {
                let u = ((x - mid) / self.half_width).clamp(-1.0, 1.0);
                let phi = (1.0 - u * u).max(0.0).sqrt();
                let y = tip_y + away * (show_mm * phi - Self::CORNER_MM * (1.0 - phi));
                Vector3::new(x, y, z)
            })
            .collect()
    }
}

/// Per image column, the rows between the lips: visible when `top < v < bottom`.
pub fn lip_opening(
    cam: &Camera,
    poses: &ArchPoses,
    lips: &[LipLine; 2],
    show_mm: [f64; 2],
) -> Vec<(f64, f64)> {
    let w = cam.width as usize;
    let mut top = vec![f64::INFINITY; w];
    let mut bottom = vec![f64::NEG_INFINITY; w];
    // Upper lip: hides rows above its edge (take the lowest edge where it folds); lower lip:
    // hides rows below (take the highest).
    for (lip, show) in lips.iter().zip(show_mm) {
        let pose = poses.get(lip.arch);
        let pts: Vec<_> = lip
            .points(show)
            .iter()
            .filter_map(|p| cam.project(&pose.transform_point(p)))
            .collect();
        let mut edge = vec![f64::NAN; w];
        for seg in pts.windows(2) {
            let (a, b) = (seg[0], seg[1]);
            let (u0, u1) = (a.x.min(b.x), a.x.max(b.x));
            let first = u0.ceil().max(0.0) as usize;
            let last = (u1.floor() as i64).min(w as i64 - 1);
            for u in first as i64..=last {
                let t = if (b.x - a.x).abs() < 1e-12 {
                    0.0
                } else {
                    (u as f64 - a.x) / (b.x - a.x)
                };
                let v = a.y + t * (b.y - a.y);
                let e = &mut edge[u as usize];
                *e = match (lip.arch, e.is_nan()) {
                    (_, true) => v,
                    (Arch::Upper, false) => e.max(v),
                    (Arch::Lower, false) => e.min(v),
                };
            }
        }
        for u in 0..w {
            match lip.arch {
                Arch::Upper => top[u] = edge[u],
                Arch::Lower => bottom[u] = edge[u],
            }
        }
    }
    top.into_iter().zip(bottom).collect()
}

/// Clear every pixel the lips hide (columns the lip curves do not reach are closed).
pub fn apply_lips(labels: &mut [u8], width: usize, opening: &[(f64, f64)]) {
    for (i, l) in labels.iter_mut().enumerate() {
        let (u, v) = (i % width, (i / width) as f64);
        let (top, bottom) = opening[u];
        if !(v > top && v < bottom) {
            *l = 0;
        }
    }
}

/// Morphological closing of each label's region with a (2r+1)² square, filling only
/// background: the gums between neighbouring crowns become teeth, as in real segmentations.
pub fn fill_between_teeth(
    labels: &mut [u8],
    width: usize,
    height: usize,
    radius: usize,
    label_values: &[u8],
) {
    for &label in label_values {
        let region: Vec<bool> = labels.iter().map(|&l| l == label).collect();
        let dilated = filter(&region, width, height, radius, true);
        let closed = filter(&dilated, width, height, radius, false);
        for (l, &c) in labels.iter_mut().zip(&closed) {
            if c && *l == 0 {
                *l = label;
            }
        }
    }
}

/// Separable square max (dilate) or min (erode) filter of a binary image.
fn filter(src: &[bool], w: usize, h: usize, r: usize, dilate: bool) -> Vec<bool> {
    let pass = |src: &[bool], horizontal: bool| -> Vec<bool> {
        let mut out = vec![false; src.len()];
        for y in 0..h {
            for x in 0..w {
                let (c, n) = if horizontal { (x, w) } else { (y, h) };
                let lo = c.saturating_sub(r);
                let hi = (c + r).min(n - 1);
                let at = |k: usize| {
                    if horizontal {
                        src[y * w + k]
                    } else {
                        src[k * w + x]
                    }
                };
                out[y * w + x] = if dilate {
                    (lo..=hi).any(at)
                } else {
                    // Outside the image counts as set, so erosion does not eat the border.
                    (lo..=hi).all(at)
                };
            }
        }
        out
    };
    pass(&pass(src, true), false)
}

/// Small round holes where a specular highlight on a tooth (a pixel of one of `teeth`'s
/// values) defeated the segmentation: unlabelled, neither tooth nor mouth.
pub fn specular_holes(
    labels: &mut [u8],
    width: usize,
    count: usize,
    max_radius: i64,
    teeth: &[u8],
    rng: &mut impl rand::Rng,
) {
    let height = labels.len() / width;
    let teeth: Vec<usize> = (0..labels.len())
        .filter(|&i| teeth.contains(&labels[i]))
        .collect();
    if teeth.is_empty() {
        return;
    }
    for _ in 0..count {
        let c = teeth[rng.random_range(0..teeth.len())];
        let (cx, cy) = ((c % width) as i64, (c / width) as i64);
        let r = rng.random_range(1..=max_radius);
        for dy in -r..=r {
            for dx in -r..=r {
                let (x, y) = (cx + dx, cy + dy);
                if dx * dx + dy * dy <= r * r
                    && x >= 0
                    && y >= 0
                    && (x as usize) < width
                    && (y as usize) < height
                {
                    labels[y as usize * width + x as usize] = 0;
                }
            }
        }
    }
}

/// Boundaries that wander: every pixel takes its label from a point displaced by a smooth
/// random field (a 12-pixel grid of offsets in ±`amplitude` px, bilinear in between).
pub fn wander_boundaries(
    labels: &[u8],
    width: usize,
    amplitude: f64,
    rng: &mut impl rand::Rng,
) -> Vec<u8> {
    const CELL: usize = 12;
    let height = labels.len() / width;
    let gw = width / CELL + 2;
    let gh = height / CELL + 2;
    let mut grid = || -> Vec<f64> {
        (0..gw * gh)
            .map(|_| rng.random_range(-amplitude..=amplitude))
            .collect()
    };
    let (gx, gy) = (grid(), grid());
    let sample = |g: &[f64], x: usize, y: usize| {
        let (fx, fy) = (x as f64 / CELL as f64, y as f64 / CELL as f64);
        let (ix, iy) = (fx as usize, fy as usize);
        let (tx, ty) = (fx - ix as f64, fy - iy as f64);
        let at = |i: usize, j: usize| g[j * gw + i];
        (at(ix, iy) * (1.0 - tx) + at(ix + 1, iy) * tx) * (1.0 - ty)
            + (at(ix, iy + 1) * (1.0 - tx) + at(ix + 1, iy + 1) * tx) * ty
    };
    let mut out = vec![0u8; labels.len()];
    for y in 0..height {
        for x in 0..width {
            let sx = (x as f64 + sample(&gx, x, y))
                .round()
                .clamp(0.0, width as f64 - 1.0) as usize;
            let sy = (y as f64 + sample(&gy, x, y))
                .round()
                .clamp(0.0, height as f64 - 1.0) as usize;
            out[y * width + x] = labels[sy * width + sx];
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    #[test]
    fn closing_fills_a_narrow_gap_but_not_a_wide_one() {
        let (w, h) = (40, 10);
        let mut l = vec![0u8; w * h];
        for y in 2..8 {
            for x in (5..15).chain(17..25).chain(32..38) {
                l[y * w + x] = 7;
            }
        }
        fill_between_teeth(&mut l, w, h, 2, &[7]);
        assert_eq!(l[4 * w + 15], 7);
        assert_eq!(l[4 * w + 16], 7);
        assert_eq!(l[4 * w + 28], 0);
    }

    #[test]
    fn wandering_moves_edges_by_at_most_the_amplitude() {
        let (w, h) = (60, 40);
        let l: Vec<u8> = (0..w * h).map(|i| ((i % w) >= 30) as u8).collect();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
        let out = wander_boundaries(&l, w, 2.0, &mut rng);
        for y in 0..h {
            let edge = (0..w).find(|&x| out[y * w + x] == 1).unwrap();
            assert!((28..=32).contains(&edge), "row {y}: edge at {edge}");
        }
        assert_ne!(out, l);
    }
}
