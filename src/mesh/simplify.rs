//! Load-time simplification (meshoptimizer): a silhouette needs far fewer triangles than a
//! scan has. Body and BOI faces are simplified apart with their borders locked, so the
//! seam between them and the crowns' open gum-side edges stay where they were.

use meshopt::{SimplifyOptions, VertexDataAdapter, simplify as mo_simplify, typed_to_bytes};

use super::Mesh;

/// How far a simplification may go.
#[derive(Debug, Clone, Copy)]
pub enum Simplify {
    /// At most this many triangles, whatever the error.
    MaxTriangles(usize),
    /// As few triangles as keep the surface within this distance (mm) of the original.
    MaxErrorMm(f64),
}

pub(super) fn simplify(mesh: &Mesh, how: Simplify) -> Mesh {
    let total = mesh.triangles.len();
    let (lo, hi) = mesh.bounds();
    let extent = (0..3).map(|k| hi[k] - lo[k]).fold(0f32, f32::max);
    // meshoptimizer's error bound is relative to the mesh extent.
    let (ratio, relative_error) = match how {
        Simplify::MaxTriangles(n) if n >= total => return mesh.clone(),
        Simplify::MaxTriangles(n) => (n as f64 / total as f64, 1.0),
        Simplify::MaxErrorMm(e) if e <= 0.0 || extent <= 0.0 => return mesh.clone(),
        Simplify::MaxErrorMm(e) => (0.0, e as f32 / extent),
    };
    let adapter = VertexDataAdapter::new(typed_to_bytes(&mesh.positions), 12, 0)
        .expect("a [f32; 3] slice is a valid vertex stream");
    let mut triangles = Vec::new();
    let mut boi = Vec::new();
    for class in [false, true] {
        let indices: Vec<u32> = mesh
            .triangles
            .iter()
            .zip(&mesh.boi)
            .filter(|(_, b)| **b == class)
            .flat_map(|(t, _)| *t)
            .collect();
        if indices.is_empty() {
            continue;
        }
        let target_tris = ((indices.len() / 3) as f64 * ratio).floor() as usize;
        let out = mo_simplify(
            &indices,
            &adapter,
            target_tris.max(ratio.ceil() as usize) * 3,
            relative_error,
            SimplifyOptions::LockBorder,
            None,
        );
        for t in out.chunks_exact(3) {
            triangles.push([t[0], t[1], t[2]]);
            boi.push(class);
        }
    }
    if triangles.len() == total {
        // Nothing to take away: keep the file's face order (face lists refer to it).
        return mesh.clone();
    }
    Mesh {
        positions: mesh.positions.clone(),
        triangles,
        boi,
    }
}
