//! How far each arch moves in a camera's picture while the shutter is open, from the frames
//! tracked last: the smear whose ramps [`super::smear`] reads.

use nalgebra::Vector3;

use crate::arch::ArchPoses;
use crate::geometry::{Camera, Pose};
use crate::mesh::Mesh;

/// The most points of each arch whose motion is averaged.
const SAMPLES: usize = 256;

/// The arches' poses at the latest two frames tracked.
#[derive(Debug, Clone)]
pub(super) struct Motion {
    /// Points of each arch (upper, lower) in its own frame: its boundary of interest's
    /// vertices (the crowns the cameras see), or all of them where it has none.
    points: [Vec<Vector3<f64>>; 2],
    /// The latest two frames tracked and their poses, the latest last.
    recent: Vec<(u32, ArchPoses)>,
}

impl Motion {
    pub(super) fn new(upper: &Mesh, lower: &Mesh) -> Motion {
        Motion {
            points: [sample_points(upper), sample_points(lower)],
            recent: Vec::new(),
        }
    }

    /// `frame` was tracked at `poses`.
    pub(super) fn tracked(&mut self, frame: u32, poses: &ArchPoses) {
        self.recent.retain(|&(f, _)| f < frame);
        self.recent.push((frame, *poses));
        if self.recent.len() > 2 {
            self.recent.remove(0);
        }
    }

    /// Each arch's smear (upper, lower) in `camera`'s picture at `frame`: its mean motion
    /// over a frame between the latest two frames tracked, times `shutter` (the share of the
    /// time between frames the shutter is open). None (zero) until two frames are tracked,
    /// or when the latest is more than two frames before `frame`.
    pub(super) fn smear(&self, camera: &Camera, frame: u32, shutter: f64) -> [[f32; 2]; 2] {
        let [(before, b), (last, a)] = self.recent.as_slice() else {
            return [[0.0; 2]; 2];
        };
        if shutter == 0.0 || frame <= *last || frame - last > 2 {
            return [[0.0; 2]; 2];
        }
        let scale = shutter / (last - before) as f64;
        let arch = |points: &[Vector3<f64>], from: &Pose, to: &Pose| {
            let (mut sum, mut n) = ([0.0f64; 2], 0usize);
            for p in points {
                let (Some(p0), Some(p1)) = (
                    camera.project(&from.transform_point(p)),
                    camera.project(&to.transform_point(p)),
                ) else {
                    continue;
                };
                sum[0] += p1.x - p0.x;
                sum[1] += p1.y - p0.y;
                n += 1;
            }
            if n == 0 {
                return [0.0; 2];
            }
            sum.map(|s| (s / n as f64 * scale) as f32)
        };
        [
            arch(&self.points[0], &b.upper, &a.upper),
            arch(&self.points[1], &b.lower, &a.lower),
        ]
    }
}

/// Up to [`SAMPLES`] of `mesh`'s points, spread over its boundary of interest (or over the
/// whole mesh where it has none).
fn sample_points(mesh: &Mesh) -> Vec<Vector3<f64>> {
    let mut wanted = vec![false; mesh.positions.len()];
    let any_boi = mesh.boi.iter().any(|&b| b);
    for (t, tri) in mesh.triangles.iter().enumerate() {
        if !any_boi || mesh.boi.get(t).copied().unwrap_or(false) {
            for &v in tri {
                if let Some(w) = wanted.get_mut(v as usize) {
                    *w = true;
                }
            }
        }
    }
    let chosen: Vec<usize> = (0..wanted.len()).filter(|&v| wanted[v]).collect();
    let stride = chosen.len().div_ceil(SAMPLES).max(1);
    chosen
        .into_iter()
        .step_by(stride)
        .map(|v| {
            let p = mesh.positions[v];
            Vector3::new(p[0] as f64, p[1] as f64, p[2] as f64)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    use crate::geometry::looking_at_origin;
    use crate::mesh::cuboid;

    #[test]
    fn the_smear_is_the_shutters_share_of_a_frames_motion() {
        let camera = looking_at_origin(Vector3::new(0.0, 0.0, -200.0));
        let (upper, lower) = (cuboid([-5.0; 3], [5.0; 3]), cuboid([-5.0; 3], [5.0; 3]));
        let mut motion = Motion::new(&upper, &lower);
        let at = |down_mm: f64| ArchPoses {
            upper: Pose::IDENTITY,
            lower: Pose::from_translation(Vector3::new(0.0, down_mm, 0.0)),
        };
        // 800 px of focal length at 200 mm: 4 px a millimetre.
        assert_eq!(motion.smear(&camera, 2, 0.5), [[0.0; 2]; 2]);
        motion.tracked(0, &at(0.0));
        motion.tracked(1, &at(2.0));
        let [upper_smear, lower_smear] = motion.smear(&camera, 2, 0.5);
        assert_eq!(upper_smear, [0.0, 0.0]);
        assert!(
            lower_smear[0].abs() < 0.05 && (lower_smear[1].abs() - 4.0).abs() < 0.2,
            "{lower_smear:?}"
        );
        // A frame tracked twice counts once; no shutter, no smear; stale motion, none either.
        motion.tracked(1, &at(2.0));
        assert_eq!(motion.smear(&camera, 2, 0.5), [upper_smear, lower_smear]);
        assert_eq!(motion.smear(&camera, 2, 0.0), [[0.0; 2]; 2]);
        assert_eq!(motion.smear(&camera, 9, 0.5), [[0.0; 2]; 2]);
    }
}
