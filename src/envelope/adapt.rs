//! Adapting an envelope rig to a new subject from five measured extremal poses (Zoss et al.
//! 2018, Sec. 5.2): open, left, right, front, back.
//!
//! 1. The source's extremal points (the envelope's lowest, leftmost, rightmost, most anterior
//!    and most posterior reference-point positions, upper frame) are aligned to the measured
//!    ones by a Procrustes fit T_C of position and scale (see [`Similarity`] for why not
//!    rotation).
//! 2. The envelope is deformed: every point of the aligned source envelope moves by a smooth
//!    field (Gaussian RBF interpolation over the unit cube, exact at the five points) that
//!    takes the five aligned points onto the measured ones. This stands in for the paper's
//!    Laplacian shell deformation: smooth, exact at the constraints, and it keeps the cube
//!    correspondence, which is all the retargeting uses.
//! 3. A dense set of poses is retargeted through the cube: for cube point s, the reference
//!    point goes to the deformed envelope's point (the translation solved so that the new
//!    subject's reference point lands exactly there: Eq. 10 with the largest weight), and the
//!    rotation is the source rig's rotation for a reference point at that same position (both
//!    frames share their anatomical axes, and where the condyles are in the joint decides how
//!    the jaw is turned, more than how far along its envelope it is; docs/rigs.md compares
//!    the two). In full adaptation
//!    it is corrected by a rotation affine in the position, fitted to the five measured poses
//!    (the role of Eq. 14 and 12: it agrees with them and varies smoothly). The origin is the
//!    landmarks' origin of the new mandible.
//! 4. The new rig is learned from those poses like any other (Eq. 8, Sec. 5.1).

use nalgebra::{Rotation3, Vector3};
use serde::{Deserialize, Serialize};

use super::model::{EnvelopeError, EnvelopeRig};
use crate::anatomy::MeshMetric;
use crate::anatomy::jaw_frame::JawFrame;
use crate::geometry::{Pose, so3_exp, so3_log};

/// The measured poses' order.
pub const EXTREMES: [&str; 5] = ["open", "left", "right", "front", "back"];

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum Adaptation {
    /// Only the reference point of each measured pose is used.
    Reduced,
    /// The whole measured poses.
    Full,
}

/// Cube points per axis of the retargeted corpus.
const SAMPLES: usize = 9;
/// Width (cube units) of the interpolating kernels over the cube.
const KERNEL: f64 = 0.2;
/// Cube points per axis scanned for the source's extremes.
const SCAN: usize = 21;

/// The index, among `points`, of the open (lowest), left (largest x), right (smallest x),
/// front (largest z) and back extreme (upper frame: y up, x the subject's left, z forward).
/// Back is the most posterior point near the top (within 15 % of the height): the wide-open
/// point lies further back, but it is the open extreme.
pub fn extremes(points: &[Vector3<f64>]) -> [usize; 5] {
    let arg = |keep: &dyn Fn(&Vector3<f64>) -> bool, key: &dyn Fn(&Vector3<f64>) -> f64| {
        points
            .iter()
            .enumerate()
            .filter(|(_, p)| keep(p))
            .max_by(|a, b| key(a.1).total_cmp(&key(b.1)))
            .map_or(0, |(i, _)| i)
    };
    let top = points.iter().map(|p| p.y).fold(f64::NEG_INFINITY, f64::max);
    let bottom = points.iter().map(|p| p.y).fold(f64::INFINITY, f64::min);
    let near_top = top - 0.15 * (top - bottom);
    let all = |_: &Vector3<f64>| true;
    [
        arg(&all, &|p| -p.y),
        arg(&all, &|p| p.x),
        arg(&all, &|p| -p.x),
        arg(&all, &|p| p.z),
        arg(&|p| p.y >= near_top, &|p| -p.z),
    ]
}

/// Procrustes with scale and without rotation: p ↦ c' + k·(p − c). Both subjects' poses are
/// in frames with the same anatomical axes (the capture format's convention: y up, z forward),
/// so only position and size differ; a rotation fitted to five points of two differently
/// shaped envelopes would be spurious, and it would turn every retargeted pose about the
/// condyles.
struct Similarity {
    translation: Vector3<f64>,
    centre: Vector3<f64>,
    /// The same on every axis.
    scale: Vector3<f64>,
}

impl Similarity {
    fn fit(a: &[Vector3<f64>], b: &[Vector3<f64>]) -> Similarity {
        let n = a.len().max(1) as f64;
        let (ca, cb) = (
            a.iter().sum::<Vector3<f64>>() / n,
            b.iter().sum::<Vector3<f64>>() / n,
        );
        // One scale for all axes: five points do not determine three scales, and per-axis
        // scales fitted to them overshoot along the axis the points barely span.
        let spread = |v: &[Vector3<f64>], c: &Vector3<f64>| {
            v.iter().map(|p| (p - c).norm_squared()).sum::<f64>()
        };
        let k = (spread(b, &cb) / spread(a, &ca).max(1e-12)).sqrt();
        let scale = Vector3::repeat(k);
        Similarity {
            translation: cb - ca,
            centre: ca,
            scale,
        }
    }

    fn point(&self, p: &Vector3<f64>) -> Vector3<f64> {
        self.centre + (p - self.centre).component_mul(&self.scale) + self.translation
    }
}

/// The five extremal poses of a subject's motion (for a test or a benchmark: the poses whose
/// reference point is the open, left, right, front and back extreme).
pub fn extremal_poses(poses: &[Pose], frame: &JawFrame) -> [Pose; 5] {
    let reference = Vector3::from(frame.reference);
    let points: Vec<Vector3<f64>> = poses
        .iter()
        .map(|p| p.transform_point(&reference))
        .collect();
    extremes(&points).map(|i| poses.get(i).copied().unwrap_or(Pose::IDENTITY))
}

/// Smooth interpolation over the cube from the five points: normalised Gaussian weights (a
/// partition of unity), so the field never exceeds the values it is given, as an
/// interpolating Gaussian field does between the points; near each point it takes that
/// point's value.
struct CubeField {
    at: Vec<[f64; 3]>,
    values: Vec<Vector3<f64>>,
}

impl CubeField {
    fn new(at: &[[f64; 3]], values: &[Vector3<f64>]) -> CubeField {
        CubeField {
            at: at.to_vec(),
            values: values.to_vec(),
        }
    }

    fn eval(&self, s: &[f64; 3]) -> Vector3<f64> {
        let mut total = 0.0;
        let mut out = Vector3::zeros();
        for (a, v) in self.at.iter().zip(&self.values) {
            let d2: f64 = a.iter().zip(s).map(|(x, y)| (x - y).powi(2)).sum();
            let k = (-0.5 * d2 / (KERNEL * KERNEL)).exp();
            out += v * k;
            total += k;
        }
        if total > 0.0 { out / total } else { out }
    }
}

/// A rotation correction (as a rotation vector) affine in the reference point's position,
/// least squares over the five measured poses with a small ridge on the slope: the correction
/// grows with how far the jaw has moved rather than being copied around each measured pose.
struct AffineField {
    centre: Vector3<f64>,
    slope: nalgebra::Matrix3<f64>,
    offset: Vector3<f64>,
}

impl AffineField {
    fn fit(points: &[Vector3<f64>], values: &[Vector3<f64>]) -> AffineField {
        let n = points.len().max(1) as f64;
        let centre = points.iter().sum::<Vector3<f64>>() / n;
        let offset = values.iter().sum::<Vector3<f64>>() / n;
        let mut xtx = nalgebra::Matrix3::<f64>::zeros();
        let mut xty = nalgebra::Matrix3::<f64>::zeros();
        for (p, v) in points.iter().zip(values) {
            let d = p - centre;
            xtx += d * d.transpose();
            xty += d * (v - offset).transpose();
        }
        let ridge = 1e-3 * xtx.trace().max(1e-9);
        let slope = (xtx + nalgebra::Matrix3::identity() * ridge)
            .try_inverse()
            .map_or(nalgebra::Matrix3::zeros(), |inv| (inv * xty).transpose());
        AffineField {
            centre,
            slope,
            offset,
        }
    }

    fn eval(&self, p: &Vector3<f64>) -> Vector3<f64> {
        self.offset + self.slope * (p - self.centre)
    }
}

/// The adapted rig. `measured`: the new subject's five poses (upper_from_lower, its own
/// mandible), in the order of [`EXTREMES`]; `frame` and `metric`: its mandible.
pub fn adapt(
    source: &EnvelopeRig,
    measured: &[Pose; 5],
    frame: &JawFrame,
    metric: &MeshMetric,
    mode: Adaptation,
) -> Result<EnvelopeRig, EnvelopeError> {
    // The source's extremes, found on its envelope.
    let mut grid = Vec::with_capacity(SCAN * SCAN * SCAN);
    for i in 0..SCAN {
        for j in 0..SCAN {
            for k in 0..SCAN {
                grid.push([i, j, k].map(|v| v as f64 / (SCAN - 1) as f64));
            }
        }
    }
    let upper = |s: &[f64; 3]| source.to_upper(&source.shield.point(s));
    let grid_points: Vec<Vector3<f64>> = grid.iter().map(upper).collect();
    let cube_at: Vec<[f64; 3]> = extremes(&grid_points).iter().map(|&i| grid[i]).collect();
    let source_points: Vec<Vector3<f64>> = cube_at.iter().map(upper).collect();
    let reference = Vector3::from(frame.reference);
    let target_points: Vec<Vector3<f64>> = measured
        .iter()
        .map(|p| p.transform_point(&reference))
        .collect();
    let align = Similarity::fit(&source_points, &target_points);
    let offsets: Vec<Vector3<f64>> = source_points
        .iter()
        .zip(&target_points)
        .map(|(s, t)| t - align.point(s))
        .collect();
    let deform = CubeField::new(&cube_at, &offsets);
    // The source's rotation where its own reference point would be at `point` (upper frame;
    // both subjects' frames share their axes, and position predicts rotation better than the
    // relative place in the envelope).
    let source_rotation = |point: &Vector3<f64>| source.pose_at(&source.from_upper(point)).rotation;
    let correction = match mode {
        Adaptation::Reduced => None,
        Adaptation::Full => {
            let logs: Vec<Vector3<f64>> = target_points
                .iter()
                .zip(measured)
                .map(|(p, m)| so3_log(&(m.rotation * source_rotation(p).inverse())))
                .collect();
            Some(AffineField::fit(&target_points, &logs))
        }
    };
    let mut poses = Vec::with_capacity(SAMPLES * SAMPLES * SAMPLES);
    for i in 0..SAMPLES {
        for j in 0..SAMPLES {
            for k in 0..SAMPLES {
                let s = [i, j, k].map(|v| v as f64 / (SAMPLES - 1) as f64);
                let point = align.point(&upper(&s)) + deform.eval(&s);
                let turn = correction
                    .as_ref()
                    .map_or(Rotation3::identity(), |c| so3_exp(&c.eval(&point)));
                let rotation = turn * source_rotation(&point);
                poses.push(Pose::new(rotation, point - rotation * reference));
            }
        }
    }
    EnvelopeRig::learn(&poses, frame, metric)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_cube_field_is_bounded_and_near_exact_at_its_points() {
        let at = [
            [0.5, 1.0, 0.5],
            [0.0, 0.3, 0.5],
            [1.0, 0.3, 0.5],
            [0.5, 0.2, 1.0],
            [0.5, 0.1, 0.0],
        ];
        let values: Vec<Vector3<f64>> = (0..5)
            .map(|i| Vector3::new(i as f64, -(i as f64), 2.0))
            .collect();
        let f = CubeField::new(&at, &values);
        for (a, v) in at.iter().zip(&values) {
            assert!((f.eval(a) - v).norm() < 0.1, "{:?} vs {v:?}", f.eval(a));
        }
        // A weighted mean of the values everywhere: never beyond them.
        for s in [[0.5, 0.5, 0.5], [0.0, 0.0, 0.0], [1.0, 1.0, 1.0]] {
            let v = f.eval(&s);
            assert!(
                (-1e-9..=4.0 + 1e-9).contains(&v.x) && (v.z - 2.0).abs() < 1e-9,
                "{v:?}"
            );
        }
    }

    #[test]
    fn extremes_pick_the_expected_points() {
        let pts = [
            Vector3::new(0.0, 0.0, 0.0),
            Vector3::new(0.0, -40.0, -5.0),
            Vector3::new(10.0, -2.0, 0.0),
            Vector3::new(-10.0, -2.0, 0.0),
            Vector3::new(0.0, -3.0, 8.0),
            Vector3::new(0.0, -1.0, -2.0),
        ];
        assert_eq!(extremes(&pts), [1, 2, 3, 4, 5]);
    }
}
