//! The average joint placed on any pair of arches: jaw poses over a grid of its controls,
//! in the meshes' own model frames. The joint model works in the scan convention (y up, +z
//! anterior, x = y × z); meshes in another frame are turned into it first ([`scan_frame`]).

use nalgebra::Vector3;

use super::scan_frame::{rotated, scan_frame};
use super::{JawControls, JawModel, rest_bite};
use crate::geometry::Pose;
use crate::mesh::Mesh;

/// Jaw poses over a grid of the average joint's controls (openings, lateral excursions,
/// protrusions), the joint placed on the meshes as [`JawModel::for_arches`] places it, in the scan convention,
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
    let rest = rest_bite(&upper_s, &lower_s);
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

#[cfg(test)]
mod tests {
    use nalgebra::Rotation3;

    use super::*;
    use crate::anatomy::procedural_arch;

    /// An arch's radius (mm): rotations count as this many mm per radian in the distances.
    const RADIUS_MM: f64 = 30.0;

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
    fn meshes_in_the_scan_convention_get_the_joints_own_grid() {
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
            let angle = crate::geometry::so3_log(&(frame * half_turn)).norm();
            assert!(angle < 1e-9, "upper: {upper}: {angle} rad");
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
