//! The jaw prior: extra starts for the lower arch from an average temporomandibular joint (the
//! `synth` model) fitted to the capture's meshes, since the jaw moves on a low-dimensional
//! manifold. A coarse grid over the joint's whole range, and the poses of a finer grid nearest
//! to the frame's starts (fast movements outrun the search; the coarse grid's steps are too far
//! apart to land close).
//!
//! The joint model works in the scan convention (y up, +z anterior, x = y × z). Meshes in
//! another model frame are turned into it first ([`scan_frame`]): up is each arch's thinnest
//! axis, signed towards the other arch; anterior points from the arch's centroid towards its
//! boundary of interest (the front teeth).

use nalgebra::{Matrix3, Rotation3, Vector3};

use super::search::RADIUS_MM;
use crate::capture::Mesh;
use crate::geometry::Pose;
use crate::synth::tmj::{JawControls, JawModel};

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

    /// Jaw poses to try, given the jaw poses the frame starts from: the coarse grid, then the
    /// `nearest` poses of the fine one.
    pub fn candidates(&self, starts: &[Pose]) -> Vec<Pose> {
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
        let n = self.nearest.min(fine.len());
        if n > 0 && n < fine.len() {
            fine.select_nth_unstable_by(n, |a, b| a.0.total_cmp(&b.0));
        }
        let mut out = self.coarse.clone();
        out.extend(fine[..n].iter().map(|(_, j)| **j));
        out
    }
}

/// Jaw poses over a grid of the average joint's controls (openings, lateral excursions,
/// protrusions), the joint placed on the meshes as `synth` places it, in the scan convention,
/// and mapped back to the meshes' own frames. Empty when a count is 0.
pub fn joint_grid(upper: &Mesh, lower: &Mesh, jaw: &Pose, grid: [usize; 3]) -> Vec<Pose> {
    if grid.contains(&0) {
        return Vec::new();
    }
    let (upper_mean, _) = upper.principal_axes();
    let (lower_mean, _) = lower.principal_axes();
    // Each arch's "up" points from the lower arch to the upper one.
    let upper_scan = scan_frame(upper, &(upper_mean - jaw.transform_point(&lower_mean)));
    let lower_scan = scan_frame(
        lower,
        &(jaw.inverse().transform_point(&upper_mean) - lower_mean),
    );
    let (upper_s, lower_s) = (rotated(upper, &upper_scan), rotated(lower, &lower_scan));
    let rest = crate::synth::arches::rest_bite(&upper_s, &lower_s);
    let model = JawModel::for_arches(&upper_s, rest);
    let to_upper = Pose::new(upper_scan.inverse(), Vector3::zeros());
    let from_lower = Pose::new(lower_scan, Vector3::zeros());
    let steps = |n: usize, lo: f64, hi: f64| -> Vec<f64> {
        (0..n)
            .map(|i| match n {
                1 => lo,
                _ => lo + (hi - lo) * i as f64 / (n - 1) as f64,
            })
            .collect()
    };
    let mut out = Vec::new();
    for open in steps(grid[0], 0.0, 1.0) {
        for lateral in steps(grid[1], -1.0, 1.0) {
            for protrusion in steps(grid[2], 0.0, 1.0) {
                let scan_jaw = model.jaw_pose(&JawControls {
                    open,
                    lateral,
                    protrusion,
                });
                out.push(to_upper.compose(&scan_jaw).compose(&from_lower));
            }
        }
    }
    out
}

/// Axes within this angle of the model's own (signed, permuted) axes are snapped to them: a
/// scan already in a convention keeps it exactly (an arch's principal axes wander by a few
/// degrees with its curve of Spee).
const SNAP_DEG: f64 = 25.0;

/// The rotation from an arch's model frame to the scan convention: y = its thinnest axis,
/// signed along `up` (model frame); z = anterior: from the centroid towards the boundary of
/// interest (the front teeth), or, without one or when it lies around the centroid, towards
/// the closed end of the arch's U (where its sides are closest); x = y × z.
pub fn scan_frame(mesh: &Mesh, up: &Vector3<f64>) -> Rotation3<f64> {
    let (mean, axes) = mesh.principal_axes();
    let y = if axes[0].dot(up) < 0.0 {
        -axes[0]
    } else {
        axes[0]
    };
    let in_plane = |v: Vector3<f64>| v - y * y.dot(&v);
    let towards_boi = mesh
        .boi_centroid()
        .map_or(Vector3::zeros(), |c| in_plane(c - mean));
    let z = if towards_boi.norm() > 2.0 {
        towards_boi.normalize()
    } else {
        closed_end(mesh, &mean, &axes[1], &axes[2])
    };
    let x = y.cross(&z);
    // Rows: the scan axes in model coordinates.
    let frame = Matrix3::from_rows(&[x.transpose(), y.transpose(), z.transpose()]);
    let snapped = frame.map(|v| {
        if v.abs() >= SNAP_DEG.to_radians().cos() {
            v.signum()
        } else {
            0.0
        }
    });
    let is_rotation = (snapped * snapped.transpose() - Matrix3::identity()).norm() < 1e-9
        && snapped.determinant() > 0.0;
    Rotation3::from_matrix_unchecked(if is_rotation { snapped } else { frame })
}

/// `front_back` signed towards the closed end of the arch's U: the half (split at the
/// centroid) whose vertices lie nearer the midline along `side`.
fn closed_end(
    mesh: &Mesh,
    mean: &Vector3<f64>,
    front_back: &Vector3<f64>,
    side: &Vector3<f64>,
) -> Vector3<f64> {
    let mut spread = [(0.0, 0usize); 2];
    for p in mesh.points() {
        let d = p - mean;
        let half = &mut spread[(d.dot(front_back) < 0.0) as usize];
        half.0 += d.dot(side).abs();
        half.1 += 1;
    }
    let [ahead, behind] = spread.map(|(sum, n)| sum / n.max(1) as f64);
    if ahead <= behind {
        *front_back
    } else {
        -front_back
    }
}

/// The mesh turned by `r` about the model origin.
fn rotated(mesh: &Mesh, r: &Rotation3<f64>) -> Mesh {
    Mesh {
        positions: mesh
            .points()
            .map(|p| {
                let q = r * p;
                [q.x as f32, q.y as f32, q.z as f32]
            })
            .collect(),
        triangles: mesh.triangles.clone(),
        boi: mesh.boi.clone(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synth::arches::{procedural_arch, rest_bite};

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

    fn arches() -> (Mesh, Mesh, Pose) {
        let (upper, lower) = (procedural_arch(true), procedural_arch(false));
        let rest = rest_bite(&upper, &lower);
        (upper, lower, rest)
    }

    /// The distances (mm, ascending) between corresponding jaw poses, at the lower arch's
    /// centre (`centre`, lower model frame) plus rotation at an arch's radius.
    fn distances(a: &[Pose], b: &[Pose], centre: &Vector3<f64>) -> Vec<f64> {
        assert_eq!(a.len(), b.len());
        let mut d: Vec<f64> = a
            .iter()
            .zip(b)
            .map(|(p, q)| {
                let (r, _) = p.distance_to(q);
                (p.transform_point(centre) - q.transform_point(centre)).norm() + r * RADIUS_MM
            })
            .collect();
        d.sort_by(f64::total_cmp);
        d
    }

    fn worst(a: &[Pose], b: &[Pose], centre: &Vector3<f64>) -> f64 {
        *distances(a, b, centre).last().expect("poses")
    }

    #[test]
    fn meshes_in_the_scan_convention_are_used_as_they_are() {
        let (upper, lower, rest) = arches();
        let up = Vector3::y();
        assert_eq!(scan_frame(&upper, &up), Rotation3::identity());
        assert_eq!(scan_frame(&lower, &up), Rotation3::identity());
        // And the grid is the joint's, unrotated.
        let model = JawModel::for_arches(&upper, rest_bite(&upper, &lower));
        let grid = joint_grid(&upper, &lower, &rest, [2, 1, 1]);
        let open = model.jaw_pose(&JawControls {
            open: 1.0,
            lateral: -1.0,
            protrusion: 0.0,
        });
        assert!(worst(&grid[1..], &[open], &lower.principal_axes().0) < 1e-9);
    }

    #[test]
    fn without_a_boundary_of_interest_the_arch_shape_tells_the_front() {
        for upper in [true, false] {
            let mut mesh = procedural_arch(upper);
            mesh.boi.iter_mut().for_each(|b| *b = false);
            // Both arches' "up" points from the lower arch to the upper: +y.
            let frame = scan_frame(&mesh, &Vector3::y());
            assert_eq!(frame, Rotation3::identity(), "upper: {upper}");
            // Turned to face -z: the frame turns it back.
            let half_turn = Rotation3::from_axis_angle(&Vector3::y_axis(), std::f64::consts::PI);
            let frame = scan_frame(&rotated(&mesh, &half_turn), &Vector3::y());
            assert!((frame * half_turn).angle() < 1e-9, "upper: {upper}");
        }
    }

    /// Both arches' model frames turned (each its own way): the prior turns with them, to
    /// within `median_mm` (median over the grid) and `worst_mm`.
    fn check_turned(
        turn_upper: Rotation3<f64>,
        turn_lower: Rotation3<f64>,
        median_mm: f64,
        worst_mm: f64,
    ) {
        let (upper, lower, rest) = arches();
        let grid = [3, 3, 2];
        let expected = joint_grid(&upper, &lower, &rest, grid);
        let (upper_t, lower_t) = (rotated(&upper, &turn_upper), rotated(&lower, &turn_lower));
        let (tu, tl) = (
            Pose::new(turn_upper, Vector3::zeros()),
            Pose::new(turn_lower, Vector3::zeros()),
        );
        // A jaw pose in the turned frames: tu ∘ jaw ∘ tl⁻¹.
        let conjugate = |j: &Pose| tu.compose(j).compose(&tl.inverse());
        let got = joint_grid(&upper_t, &lower_t, &conjugate(&rest), grid);
        let expected: Vec<Pose> = expected.iter().map(conjugate).collect();
        let centre = turn_lower * lower.principal_axes().0;
        let d = distances(&got, &expected, &centre);
        let (median, worst) = (d[d.len() / 2], d[d.len() - 1]);
        assert!(
            median <= median_mm && worst <= worst_mm,
            "{median} / {worst} mm"
        );
    }

    #[test]
    fn a_z_up_scan_gets_the_same_prior() {
        // A common CAD convention: z up, -y anterior (x kept): exactly the same candidates.
        let z_up = Rotation3::from_axis_angle(&Vector3::x_axis(), 90f64.to_radians());
        check_turned(z_up, z_up, 1e-6, 1e-6);
        // The lower arch's file in yet another frame.
        let other = Rotation3::from_axis_angle(&Vector3::y_axis(), 180f64.to_radians());
        check_turned(z_up, other, 1e-6, 1e-6);
    }

    #[test]
    fn a_scan_in_an_arbitrary_frame_gets_nearly_the_same_prior() {
        // Off every axis: the principal axes stand in for the convention's. The procedural
        // upper arch's thinnest axis is 3 degrees off y, which moves the joint's condyles,
        // ~80 mm behind the incisors, by ~4 mm: measured 4.8 mm median, 5.8 mm worst.
        let turn = Rotation3::from_euler_angles(0.5, -0.8, 1.2);
        check_turned(turn, turn, 6.0, 8.0);
    }
}
