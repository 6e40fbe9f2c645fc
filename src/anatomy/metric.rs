//! The error between two poses of one mesh (an arch, the mandible): the distance between
//! corresponding vertices of the mesh placed by each, over the vertices its faces use. The
//! mean (`mean_distance`) is the "mean vertex error" every report gives; the largest
//! (`max_distance`) is the paper's.

use nalgebra::Vector3;

use crate::geometry::Pose;
use crate::mesh::Mesh;

/// Directions whose extreme vertices make the probes: the axes, the face and the corner
/// diagonals of a cube.
const PROBE_DIRECTIONS: usize = 26;

#[derive(Debug, Clone)]
pub struct MeshMetric {
    /// The mesh's vertices (lower frame, mm).
    points: Vec<Vector3<f64>>,
    /// A few extreme vertices: a lower bound on the largest distance, and the points that
    /// encoding fits.
    probes: Vec<Vector3<f64>>,
    pub centroid: Vector3<f64>,
    /// Root-mean-square distance of the vertices from the centroid (mm): how far a rotation
    /// of one radian moves the mesh, on average.
    pub rms_radius_mm: f64,
}

impl MeshMetric {
    /// From the vertices that faces use (unused vertices of a file do not count).
    pub fn new(mesh: &Mesh) -> MeshMetric {
        let mut used = vec![false; mesh.positions.len()];
        for t in &mesh.triangles {
            for &v in t {
                used[v as usize] = true;
            }
        }
        let points: Vec<Vector3<f64>> = mesh
            .positions
            .iter()
            .zip(&used)
            .filter(|(_, u)| **u)
            .map(|(p, _)| Vector3::new(p[0] as f64, p[1] as f64, p[2] as f64))
            .collect();
        Self::from_points(points)
    }

    pub fn from_points(points: Vec<Vector3<f64>>) -> MeshMetric {
        assert!(!points.is_empty(), "a metric needs at least one point");
        let centroid = points.iter().sum::<Vector3<f64>>() / points.len() as f64;
        let rms_radius_mm = (points
            .iter()
            .map(|p| (p - centroid).norm_squared())
            .sum::<f64>()
            / points.len() as f64)
            .sqrt();
        let mut probes: Vec<Vector3<f64>> = Vec::with_capacity(PROBE_DIRECTIONS);
        for dx in -1i32..=1 {
            for dy in -1i32..=1 {
                for dz in -1i32..=1 {
                    if (dx, dy, dz) == (0, 0, 0) {
                        continue;
                    }
                    let d = Vector3::new(dx as f64, dy as f64, dz as f64);
                    let best = points
                        .iter()
                        .max_by(|a, b| (*a - centroid).dot(&d).total_cmp(&(*b - centroid).dot(&d)))
                        .expect("points is not empty");
                    if !probes.contains(best) {
                        probes.push(*best);
                    }
                }
            }
        }
        MeshMetric {
            points,
            probes,
            centroid,
            rms_radius_mm,
        }
    }

    pub fn probes(&self) -> &[Vector3<f64>] {
        &self.probes
    }

    pub fn points(&self) -> &[Vector3<f64>] {
        &self.points
    }

    /// The mean vertex error: the mean distance (mm) between corresponding vertices of the
    /// mesh placed by `a` and by `b`.
    pub fn mean_distance(&self, a: &Pose, b: &Pose) -> f64 {
        let d = b.inverse().compose(a);
        let m = d.rotation.matrix() - nalgebra::Matrix3::identity();
        self.points
            .iter()
            .map(|p| (m * p + d.translation).norm())
            .sum::<f64>()
            / self.points.len() as f64
    }

    /// The mean vertex distance (mm) between the mesh placed by `a` and by `b`, each vertex
    /// weighted (`weights` in the order of [`Self::points`]).
    pub fn weighted_mean_distance(&self, a: &Pose, b: &Pose, weights: &[f64]) -> f64 {
        let d = b.inverse().compose(a);
        let m = d.rotation.matrix() - nalgebra::Matrix3::identity();
        let (sum, total) = self
            .points
            .iter()
            .zip(weights)
            .fold((0.0, 0.0), |(s, t), (p, w)| {
                (s + w * (m * p + d.translation).norm(), t + w)
            });
        if total > 0.0 { sum / total } else { 0.0 }
    }

    pub fn vertex_count(&self) -> usize {
        self.points.len()
    }

    /// The largest vertex distance (mm) between the mesh placed by `a` and by `b`.
    pub fn max_distance(&self, a: &Pose, b: &Pose) -> f64 {
        Self::max_over(&self.points, a, b)
    }

    /// A lower bound on [`Self::max_distance`] from the probes alone.
    pub fn probe_distance(&self, a: &Pose, b: &Pose) -> f64 {
        Self::max_over(&self.probes, a, b)
    }

    fn max_over(points: &[Vector3<f64>], a: &Pose, b: &Pose) -> f64 {
        // |a·p − b·p| = |(b⁻¹a)·p − p|: one matrix for all points.
        let d = b.inverse().compose(a);
        let m = d.rotation.matrix() - nalgebra::Matrix3::identity();
        points
            .iter()
            .map(|p| (m * p + d.translation).norm_squared())
            .fold(0.0, f64::max)
            .sqrt()
    }

    /// The pose among `candidates` nearest to `pose` by [`Self::max_distance`], and that
    /// distance. Exact: candidates are visited by their probe bound, and the search stops when
    /// the bound exceeds the best distance found.
    pub fn nearest(&self, pose: &Pose, candidates: &[Pose]) -> Option<(usize, f64)> {
        let mut order: Vec<(f64, usize)> = candidates
            .iter()
            .enumerate()
            .map(|(i, c)| (self.probe_distance(pose, c), i))
            .collect();
        order.sort_by(|a, b| a.0.total_cmp(&b.0));
        let mut best: Option<(usize, f64)> = None;
        for (bound, i) in order {
            if best.is_some_and(|(_, d)| bound >= d) {
                break;
            }
            let d = self.max_distance(pose, &candidates[i]);
            if best.is_none_or(|(_, b)| d < b) {
                best = Some((i, d));
            }
        }
        best
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::Pose;

    fn cube() -> MeshMetric {
        let mut pts = Vec::new();
        for x in [-1.0, 1.0] {
            for y in [-1.0, 1.0] {
                for z in [-1.0, 1.0] {
                    pts.push(Vector3::new(x, y, z) * 10.0);
                }
            }
        }
        pts.push(Vector3::zeros());
        MeshMetric::from_points(pts)
    }

    #[test]
    fn translation_moves_every_vertex_alike() {
        let m = cube();
        let t = Pose::from_translation(Vector3::new(3.0, 4.0, 0.0));
        assert!((m.max_distance(&t, &Pose::IDENTITY) - 5.0).abs() < 1e-12);
    }

    #[test]
    fn rotation_error_is_largest_at_the_farthest_vertex() {
        let m = cube();
        let r = Pose::new(
            nalgebra::Rotation3::from_axis_angle(&Vector3::z_axis(), 0.1),
            Vector3::zeros(),
        );
        // A corner at radius √200 moves by 2·r·sin(θ/2).
        let want = 2.0 * 200f64.sqrt() * (0.05f64).sin();
        assert!((m.max_distance(&r, &Pose::IDENTITY) - want).abs() < 1e-9);
        assert!(m.probe_distance(&r, &Pose::IDENTITY) <= m.max_distance(&r, &Pose::IDENTITY));
    }

    #[test]
    fn nearest_agrees_with_brute_force() {
        let m = cube();
        let cands: Vec<Pose> = (0..50)
            .map(|k| {
                let a = k as f64 * 0.37;
                Pose::from_euler_tuple(&[
                    a.sin() * 0.2,
                    a.cos() * 0.1,
                    0.05 * a.sin(),
                    a.cos(),
                    0.5 * a,
                    -a.sin(),
                ])
            })
            .collect();
        let q = Pose::from_euler_tuple(&[0.05, 0.02, 0.0, 0.3, 4.0, 0.2]);
        let (i, d) = m.nearest(&q, &cands).unwrap();
        let brute = cands
            .iter()
            .map(|c| m.max_distance(&q, c))
            .fold(f64::INFINITY, f64::min);
        assert!((d - brute).abs() < 1e-12 && (m.max_distance(&q, &cands[i]) - d).abs() < 1e-12);
    }
}
