//! A coarse mandible in the lower arch's frame: the lower teeth, then a tube swept along the
//! body under the teeth and up both rami, and an ellipsoidal condyle head on each side, so
//! that rig errors can be measured where they are largest (the condyles). The lower arch's
//! vertices come first, so its vertex numbering carries over.

use nalgebra::Vector3;

use crate::anatomy::{JawModel, stitch_rings};
use crate::mesh::Mesh;

const RING: usize = 12;

pub fn mandible_mesh(lower: &Mesh, jaw: &JawModel) -> Mesh {
    let mut mesh = lower.clone();
    let lower_from_upper = jaw.rest.inverse();
    let cond_l = lower_from_upper.transform_point(&jaw.condyle_left);
    let cond_r = lower_from_upper.transform_point(&jaw.condyle_right);
    let (lo, hi) = lower.bounds();
    let (lo, hi) = (lo.map(f64::from), hi.map(f64::from));
    let body_y = lo[1] - 8.0;
    let a = (hi[0] - lo[0]) * 0.5 - 3.0;
    let b = (hi[2] - lo[2]) - 8.0;
    let front_z = hi[2] - 4.0;
    let mid_x = (lo[0] + hi[0]) * 0.5;
    // Centre line: right condyle neck → right ramus → body → left ramus → left condyle neck.
    let mut line = Vec::new();
    let ramus = |c: &Vector3<f64>, side: f64| {
        [
            Vector3::new(c.x - side * 2.0, c.y - 8.0, c.z),
            Vector3::new(c.x - side * 3.0, (c.y + body_y) * 0.5, c.z - 2.0),
            Vector3::new(mid_x + side * (a + 4.0), body_y - 6.0, c.z + 4.0),
        ]
    };
    line.extend(ramus(&cond_r, -1.0));
    for k in 0..=12 {
        let phi = (-100.0 + 200.0 * k as f64 / 12.0f64).to_radians();
        line.push(Vector3::new(
            mid_x + a * phi.sin(),
            body_y,
            front_z - b + b * phi.cos(),
        ));
    }
    line.extend(ramus(&cond_l, 1.0).into_iter().rev());
    sweep_tube(&mut mesh, &line, 4.5, 9.0);
    for c in [cond_l, cond_r] {
        add_ellipsoid(&mut mesh, c, Vector3::new(10.0, 5.0, 4.5));
    }
    mesh
}

/// A tube of elliptical cross-section (radii `r_side`, `r_up`) along a polyline, with frames
/// carried along by parallel transport so the tube does not twist.
fn sweep_tube(mesh: &mut Mesh, line: &[Vector3<f64>], r_side: f64, r_up: f64) {
    let base = mesh.positions.len() as u32;
    let n = line.len();
    let tangent = |i: usize| (line[(i + 1).min(n - 1)] - line[i.saturating_sub(1)]).normalize();
    let mut side = tangent(0).cross(&Vector3::y()).normalize();
    for (i, centre) in line.iter().enumerate() {
        let t = tangent(i);
        side = (side - t * side.dot(&t)).normalize();
        let up = side.cross(&t);
        for k in 0..RING {
            let a = k as f64 / RING as f64 * std::f64::consts::TAU;
            let p = centre + side * (r_side * a.cos()) + up * (r_up * a.sin());
            mesh.positions.push([p.x as f32, p.y as f32, p.z as f32]);
        }
    }
    stitch_rings(mesh, base, n, RING);
}

fn add_ellipsoid(mesh: &mut Mesh, c: Vector3<f64>, r: Vector3<f64>) {
    const LAT: usize = 8;
    let base = mesh.positions.len() as u32;
    for i in 0..=LAT {
        let th = std::f64::consts::PI * i as f64 / LAT as f64;
        for k in 0..RING {
            let ph = std::f64::consts::TAU * k as f64 / RING as f64;
            let p = c + Vector3::new(
                r.x * th.sin() * ph.cos(),
                r.y * th.cos(),
                r.z * th.sin() * ph.sin(),
            );
            mesh.positions.push([p.x as f32, p.y as f32, p.z as f32]);
        }
    }
    stitch_rings(mesh, base, LAT + 1, RING);
}
