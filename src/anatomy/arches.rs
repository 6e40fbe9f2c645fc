//! Procedural dental arches (14 tooth-shaped crowns each, second molar to second molar) in the
//! frame of ../shared/data/scan-tag0: y up, +z anterior, upper crowns pointing to −y and lower
//! crowns to +y, each arch centred on its own origin.

use nalgebra::Vector3;

use super::stitch_rings;
use crate::mesh::Mesh;
use crate::mesh::{BoiMarking, mark_boi};

/// One crown type: mesiodistal width, buccolingual depth, crown height (mm), and how its
/// cross-section narrows towards the tip (0: stays full, 1: comes to an edge or point).
struct Tooth {
    width: f64,
    depth: f64,
    height: f64,
    /// Narrowing of the buccolingual (depth) axis towards the tip: incisors become chisels.
    taper_depth: f64,
    /// Narrowing of the mesiodistal (width) axis: canines become points.
    taper_width: f64,
}

const fn tooth(width: f64, depth: f64, height: f64, taper_depth: f64, taper_width: f64) -> Tooth {
    Tooth {
        width,
        depth,
        height,
        taper_depth,
        taper_width,
    }
}

/// Central incisor to second molar; typical adult crown sizes.
const UPPER_TEETH: [Tooth; 7] = [
    tooth(8.5, 7.0, 10.5, 0.85, 0.05),
    tooth(6.5, 6.0, 9.0, 0.85, 0.05),
    tooth(7.5, 8.0, 10.0, 0.6, 0.75),
    tooth(7.0, 9.0, 8.0, 0.35, 0.3),
    tooth(6.5, 9.0, 7.5, 0.35, 0.3),
    tooth(10.0, 11.0, 7.0, 0.25, 0.2),
    tooth(9.0, 11.0, 6.5, 0.25, 0.2),
];
const LOWER_TEETH: [Tooth; 7] = [
    tooth(5.0, 6.0, 9.0, 0.85, 0.05),
    tooth(5.5, 6.5, 9.5, 0.85, 0.05),
    tooth(7.0, 7.5, 11.0, 0.6, 0.75),
    tooth(7.0, 7.5, 8.0, 0.35, 0.3),
    tooth(7.0, 8.0, 8.0, 0.35, 0.3),
    tooth(11.0, 10.5, 7.5, 0.25, 0.2),
    tooth(10.5, 10.0, 7.0, 0.25, 0.2),
];

const RINGS: usize = 10;
const SEGMENTS: usize = 28;

/// The arch curve: half of an ellipse x = a·sin φ, z = b·cos φ, open to −z.
struct ArchCurve {
    a: f64,
    b: f64,
}

impl ArchCurve {
    fn point(&self, phi: f64) -> (f64, f64) {
        (self.a * phi.sin(), self.b * phi.cos())
    }
    /// Walk `s` mm along the curve from the midline (positive: towards +x).
    fn at_arc_length(&self, s: f64) -> (f64, f64, f64) {
        let (mut phi, mut acc) = (0.0f64, 0.0);
        let dphi = 1e-3 * s.signum();
        while acc < s.abs() {
            let (x0, z0) = self.point(phi);
            phi += dphi;
            let (x1, z1) = self.point(phi);
            acc += ((x1 - x0).powi(2) + (z1 - z0).powi(2)).sqrt();
        }
        let (x, z) = self.point(phi);
        // Tangent direction (towards increasing |s|).
        let (tx, tz) = (
            self.a * phi.cos() * dphi.signum(),
            -self.b * phi.sin() * dphi.signum(),
        );
        let n = (tx * tx + tz * tz).sqrt();
        (x, z, (tx / n).atan2(tz / n))
    }
}

/// A procedural arch with its boundary of interest marked automatically.
pub fn procedural_arch(upper: bool) -> Mesh {
    let (teeth, curve) = if upper {
        (&UPPER_TEETH, ArchCurve { a: 28.0, b: 42.0 })
    } else {
        (&LOWER_TEETH, ArchCurve { a: 25.0, b: 38.0 })
    };
    let mut mesh = Mesh {
        positions: Vec::new(),
        triangles: Vec::new(),
        boi: Vec::new(),
    };
    for side in [1.0, -1.0] {
        let mut s = 0.0;
        for t in teeth.iter() {
            let (x, z, heading) = curve.at_arc_length(side * (s + t.width * 0.5));
            s += t.width;
            add_crown(&mut mesh, t, x, z, heading, upper);
        }
    }
    // Centre on the origin, as the scans are.
    let (lo, hi) = mesh.bounds();
    let c = [0, 1, 2].map(|k| (lo[k] + hi[k]) * 0.5);
    for p in &mut mesh.positions {
        for k in 0..3 {
            p[k] -= c[k];
        }
    }
    mark_boi(&mut mesh, &BoiMarking::for_arch(upper));
    mesh
}

/// A closed crown: rings of a superellipse cross-section from the cervical line (ring 0) to
/// the tip, narrowing per the tooth type, with a rounded, slightly cusped top.
fn add_crown(mesh: &mut Mesh, t: &Tooth, x: f64, z: f64, heading: f64, upper: bool) {
    let base = mesh.positions.len() as u32;
    let tip_dir = if upper { -1.0 } else { 1.0 };
    // Local axes: `along` the arch (mesiodistal), `out` labial/buccal (away from the arch centre).
    let along = Vector3::new(heading.sin(), 0.0, heading.cos());
    let mut out = Vector3::new(along.z, 0.0, -along.x);
    if out.x * x + out.z * (z + 20.0) < 0.0 {
        out = -out;
    }
    let centre = Vector3::new(x, 0.0, z);
    for r in 0..=RINGS {
        let h = r as f64 / RINGS as f64;
        // Bulge at the height of contour, then narrowing towards the tip.
        let bulge = 1.0 + 0.12 * (std::f64::consts::PI * h).sin();
        let tip_shape = h.powf(2.5);
        let half_w = 0.5 * t.width * bulge * (1.0 - t.taper_width * tip_shape) * 0.98;
        let half_d = 0.5 * t.depth * bulge * (1.0 - t.taper_depth * tip_shape) * 0.85;
        // The cervical line sits `height` from the tip; the tip level is y = 0.
        let y = -tip_dir * t.height * (1.0 - h);
        for k in 0..SEGMENTS {
            let a = k as f64 / SEGMENTS as f64 * std::f64::consts::TAU;
            let (c, s) = (a.cos(), a.sin());
            // Superellipse (exponent 2/3): a rounded box.
            let cx = c.signum() * c.abs().powf(0.6);
            let sz = s.signum() * s.abs().powf(0.6);
            // Cusps: back teeth dip between cusps at the top ring.
            let cusp = if r == RINGS && t.taper_width < 0.5 {
                -tip_dir * 0.6 * (2.0 * a).cos().abs()
            } else {
                0.0
            };
            let p = centre
                + along * (half_w * cx)
                + out * (half_d * sz)
                + Vector3::new(0.0, y + cusp, 0.0);
            mesh.positions.push([p.x as f32, p.y as f32, p.z as f32]);
        }
    }
    stitch_rings(mesh, base, RINGS + 1, SEGMENTS);
    let ring = |r: usize, k: usize| base + (r * SEGMENTS + k % SEGMENTS) as u32;
    // Caps: the cervical end and the tip, fans around a centre vertex.
    for (r, y_end) in [(0, -tip_dir * t.height), (RINGS, tip_dir * 0.3)] {
        let c = mesh.positions.len() as u32;
        mesh.positions.push([x as f32, y_end as f32, z as f32]);
        for k in 0..SEGMENTS {
            mesh.triangles.push([c, ring(r, k + 1), ring(r, k)]);
            mesh.boi.push(false);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn procedural_arches_have_fourteen_crowns_and_a_front_boi() {
        for upper in [true, false] {
            let m = procedural_arch(upper);
            let per_crown = 2 * RINGS * SEGMENTS + 2 * SEGMENTS;
            assert_eq!(m.triangles.len(), 14 * per_crown);
            m.validate(std::path::Path::new("procedural")).unwrap();
            let (lo, hi) = m.bounds();
            assert!(
                hi[0] - lo[0] > 45.0 && hi[0] - lo[0] < 70.0,
                "arch width {lo:?} {hi:?}"
            );
            // BOI: on the six front crowns (central incisor to canine, each side), on each of
            // them, and on no premolar or molar; crowns are built in order from the midline.
            let per_crown = m.triangles.len() / 14;
            for k in 0..14 {
                let n = m.boi[k * per_crown..(k + 1) * per_crown]
                    .iter()
                    .filter(|&&b| b)
                    .count();
                let front = k % 7 < 3;
                assert_eq!(n > 0, front, "upper={upper} crown {k}: {n} BOI faces");
            }
            // ... and near the tips.
            for (t, _) in m.triangles.iter().zip(&m.boi).filter(|(_, b)| **b) {
                let p = m.positions[t[0] as usize];
                let tip_distance = if upper { p[1] - lo[1] } else { hi[1] - p[1] };
                assert!(tip_distance < 2.5, "BOI face too far from the tips: {p:?}");
            }
        }
    }
}
