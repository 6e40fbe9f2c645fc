//! Load-time simplification (meshoptimizer): a silhouette needs far fewer triangles than a
//! scan has. Body and BOI faces are simplified apart with their borders locked, so the
//! seam between them and the crowns' open gum-side edges stay where they were.

use meshopt::{SimplifyOptions, VertexDataAdapter, simplify as mo_simplify, typed_to_bytes};

use super::Mesh;

pub(super) fn simplify(mesh: &Mesh, max_triangles: usize) -> Mesh {
    let total = mesh.triangles.len();
    if max_triangles >= total {
        return mesh.clone();
    }
    let ratio = max_triangles as f64 / total as f64;
    let adapter = VertexDataAdapter::new(typed_to_bytes(&mesh.positions), 12, 0)
        .expect("a [f32; 3] slice is a valid vertex stream");
    let mut triangles = Vec::with_capacity(max_triangles);
    let mut boi = Vec::with_capacity(max_triangles);
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
        let target_tris = ((indices.len() / 3) as f64 * ratio).floor().max(1.0) as usize;
        // The error bound is relative to the mesh extent; the triangle budget is what counts.
        let out = mo_simplify(
            &indices,
            &adapter,
            target_tris * 3,
            1.0,
            SimplifyOptions::LockBorder,
            None,
        );
        for t in out.chunks_exact(3) {
            triangles.push([t[0], t[1], t[2]]);
            boi.push(class);
        }
    }
    Mesh {
        positions: mesh.positions.clone(),
        triangles,
        boi,
    }
}
