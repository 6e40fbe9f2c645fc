//! The jaw prior: extra starts for the lower arch from an average temporomandibular joint (the
//! `synth` model) fitted to the capture's meshes, since the jaw moves on a low-dimensional
//! manifold. A coarse grid over the joint's whole range, and the poses of a finer grid nearest
//! to the frame's starts (fast movements outrun the search; the coarse grid's steps are too far
//! apart to land close).
//! The grid itself is anatomy's ([`joint_grid`]): the joint placed on any meshes, whatever
//! their model frames.

use nalgebra::Vector3;

use super::search::RADIUS_MM;
use crate::anatomy::joint_grid;
use crate::arch::Arch;
use crate::capture::Capture;
use crate::geometry::Pose;
use crate::mesh::Mesh;

/// The centre of an arch in its model frame (rotations of the search turn about it).
pub fn centre(capture: &Capture, arch: Arch) -> Vector3<f64> {
    let (lo, hi) = capture.mesh(arch).bounds();
    Vector3::new(
        (lo[0] + hi[0]) as f64,
        (lo[1] + hi[1]) as f64,
        (lo[2] + hi[2]) as f64,
    ) * 0.5
}

/// The jaw prior's candidates (jaw poses, upper_from_lower, in the capture's model frames).
#[derive(Debug, Clone)]
pub struct JawPrior {
    pub coarse: Vec<Pose>,
    pub fine: Vec<Pose>,
    /// How many of `fine` a frame tries: those nearest to its starts.
    pub nearest: usize,
    /// The lower arch's centre (model frame): where distances between jaw poses are taken.
    pub centre: Vector3<f64>,
}

impl JawPrior {
    /// The prior for these meshes; `jaw` is any jaw pose the capture shows (it tells which side
    /// of each arch the other is on).
    pub fn new(
        upper: &Mesh,
        lower: &Mesh,
        jaw: &Pose,
        coarse: [usize; 3],
        fine: [usize; 3],
        nearest: usize,
        centre: Vector3<f64>,
    ) -> JawPrior {
        JawPrior {
            coarse: joint_grid(upper, lower, jaw, coarse),
            fine: joint_grid(upper, lower, jaw, fine),
            nearest,
            centre,
        }
    }

    /// The prior of a subject's own jaw poses (`all`, spread over their range): all of them
    /// as the fine grid, about `coarse` of them, evenly taken, as the coarse one.
    pub fn of_poses(all: &[Pose], coarse: usize, nearest: usize, centre: Vector3<f64>) -> JawPrior {
        let step = all.len().div_ceil(coarse.max(1)).max(1);
        JawPrior {
            coarse: all.iter().step_by(step).copied().collect(),
            fine: all.to_vec(),
            nearest,
            centre,
        }
    }

    /// Jaw poses to try, given the jaw poses the frame starts from: the coarse grid, then the
    /// `nearest` poses of the fine one.
    pub fn candidates(&self, starts: &[Pose]) -> Vec<Pose> {
        let mut out = self.coarse.clone();
        out.extend(self.nearest_to(starts, self.nearest));
        out
    }

    /// The `n` poses of the fine grid nearest to any of `starts` (in no order).
    pub fn nearest_to(&self, starts: &[Pose], n: usize) -> Vec<Pose> {
        let distance = |j: &Pose| {
            starts
                .iter()
                .map(|s| {
                    let (r, _) = s.distance_to(j);
                    (s.transform_point(&self.centre) - j.transform_point(&self.centre)).norm()
                        + r * RADIUS_MM
                })
                .fold(f64::INFINITY, f64::min)
        };
        let mut fine: Vec<(f64, &Pose)> = self.fine.iter().map(|j| (distance(j), j)).collect();
        let n = n.min(fine.len());
        if n > 0 && n < fine.len() {
            fine.select_nth_unstable_by(n, |a, b| a.0.total_cmp(&b.0));
        }
        fine[..n].iter().map(|(_, j)| **j).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_fine_prior_adds_the_poses_nearest_to_the_starts() {
        let shift = |x: f64| Pose::from_translation(Vector3::new(x, 0.0, 0.0));
        let prior = JawPrior {
            coarse: vec![shift(100.0)],
            fine: (0..20).map(|i| shift(i as f64)).collect(),
            nearest: 3,
            centre: Vector3::new(0.0, -10.0, 30.0),
        };
        // Starts at x = 4.2 and x = 15.9: the nearest three are 4, 16 and then 5 (0.8 mm).
        let mut got: Vec<f64> = prior
            .candidates(&[shift(4.2), shift(15.9)])
            .iter()
            .map(|p| p.translation.x)
            .collect();
        assert_eq!(got.remove(0), 100.0, "the coarse grid comes first");
        got.sort_by(f64::total_cmp);
        assert_eq!(got, vec![4.0, 5.0, 16.0]);
        let none = JawPrior {
            nearest: 0,
            ..prior
        };
        assert_eq!(none.candidates(&[shift(4.2)]).len(), 1);
    }
}
