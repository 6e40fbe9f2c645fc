//! Closing a stack of vertex rings into triangles: the one way crowns, the mandible's tube and
//! its condyles are built.

use crate::mesh::Mesh;

/// Stitch `rings` consecutive rings of `segments` vertices each, starting at vertex `base`,
/// with two triangles per quad; each ring closes on itself.
pub(crate) fn stitch_rings(mesh: &mut Mesh, base: u32, rings: usize, segments: usize) {
    let at = |r: usize, k: usize| base + (r * segments + k % segments) as u32;
    for r in 0..rings - 1 {
        for k in 0..segments {
            let (a, b, c, d) = (at(r, k), at(r, k + 1), at(r + 1, k + 1), at(r + 1, k));
            mesh.triangles.push([a, b, c]);
            mesh.triangles.push([a, c, d]);
            mesh.boi.extend([false, false]);
        }
    }
}
