//! The scan convention (y up, +z anterior, x = y × z: the frame of ../shared/data/scan-tag0
//! and of the joint model) found on a mesh in any model frame: up is the arch's thinnest
//! axis, signed towards the other arch; anterior points from the arch's centroid towards its
//! boundary of interest (the front teeth), or towards the closed end of its U.

use nalgebra::{Matrix3, Rotation3, Vector3};

use crate::mesh::Mesh;

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
pub fn rotated(mesh: &Mesh, r: &Rotation3<f64>) -> Mesh {
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
