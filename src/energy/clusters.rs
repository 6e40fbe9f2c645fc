//! A mesh's faces in spatial order, grouped into small clusters with their bounding boxes, so
//! that the CPU reference can skip a whole cluster that cannot change the energy (see
//! `relevance`) before looking at its faces one by one.

use std::ops::Range;

use crate::mesh::Mesh;
use crate::mesh::bounds;

/// Faces per cluster.
pub const CLUSTER_FACES: usize = 32;

/// A cluster of consecutive faces of a [`spatially_sorted`] mesh.
#[derive(Debug, Clone)]
pub struct Cluster {
    pub faces: Range<usize>,
    /// Corners of the model-space bounding box of its faces.
    pub corners: [[f32; 3]; 8],
    /// Some face is boundary of interest (always drawn).
    pub has_boi: bool,
}

/// The mesh with its faces sorted along a Morton (Z-order) curve through their centroids:
/// consecutive faces lie close together. Vertices are untouched; ties keep the file's order.
pub fn spatially_sorted(mesh: &Mesh) -> Mesh {
    let (lo, hi) = mesh.bounds();
    let centroid = |t: &[u32; 3]| -> [f32; 3] {
        std::array::from_fn(|k| {
            t.iter()
                .map(|&v| mesh.positions[v as usize][k])
                .sum::<f32>()
                / 3.0
        })
    };
    let mut order: Vec<(u32, usize)> = mesh
        .triangles
        .iter()
        .enumerate()
        .map(|(i, t)| {
            let c = centroid(t);
            let cell = std::array::from_fn(|k| {
                let span = (hi[k] - lo[k]).max(f32::MIN_POSITIVE);
                (((c[k] - lo[k]) / span) * 1023.0).clamp(0.0, 1023.0) as u32
            });
            (morton(cell), i)
        })
        .collect();
    order.sort_unstable();
    Mesh {
        positions: mesh.positions.clone(),
        triangles: order.iter().map(|&(_, i)| mesh.triangles[i]).collect(),
        boi: order.iter().map(|&(_, i)| mesh.boi[i]).collect(),
    }
}

/// Interleave three 10-bit coordinates (x in the lowest bit).
fn morton(cell: [u32; 3]) -> u32 {
    let spread = |mut v: u32| {
        v &= 0x3ff;
        v = (v | (v << 16)) & 0x0300_00ff;
        v = (v | (v << 8)) & 0x0300_f00f;
        v = (v | (v << 4)) & 0x030c_30c3;
        (v | (v << 2)) & 0x0924_9249
    };
    spread(cell[0]) | (spread(cell[1]) << 1) | (spread(cell[2]) << 2)
}

/// The corners of the box `lo`..`hi` (bit k of the index picks the high end on axis k).
pub fn box_corners(lo: [f32; 3], hi: [f32; 3]) -> [[f32; 3]; 8] {
    std::array::from_fn(|i| std::array::from_fn(|k| if i >> k & 1 == 0 { lo[k] } else { hi[k] }))
}

/// Runs of [`CLUSTER_FACES`] consecutive faces with their bounds.
pub fn clusters(mesh: &Mesh) -> Vec<Cluster> {
    (0..mesh.triangles.len())
        .step_by(CLUSTER_FACES)
        .map(|start| {
            let faces = start..(start + CLUSTER_FACES).min(mesh.triangles.len());
            let (lo, hi) = bounds(&mesh.positions, &mesh.triangles[faces.clone()]);
            Cluster {
                corners: box_corners(lo, hi),
                has_boi: mesh.boi[faces.clone()].iter().any(|&b| b),
                faces,
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn morton_interleaves_the_axes() {
        assert_eq!(morton([1, 0, 0]), 0b001);
        assert_eq!(morton([0, 1, 0]), 0b010);
        assert_eq!(morton([0, 0, 1]), 0b100);
        assert_eq!(morton([3, 0, 0]), 0b001_001);
        assert_eq!(morton([1023, 1023, 1023]), (1 << 30) - 1);
    }

    #[test]
    fn sorting_keeps_every_face_with_its_flag_and_makes_clusters_compact() {
        // A 40 x 40 grid of unit squares in row order, the BOI on one column.
        let n = 40u32;
        let positions: Vec<[f32; 3]> = (0..=n)
            .flat_map(|y| (0..=n).map(move |x| [x as f32, y as f32, 0.0]))
            .collect();
        let mut mesh = Mesh {
            positions,
            triangles: Vec::new(),
            boi: Vec::new(),
        };
        let at = |x: u32, y: u32| y * (n + 1) + x;
        for y in 0..n {
            for x in 0..n {
                mesh.triangles
                    .push([at(x, y), at(x + 1, y), at(x + 1, y + 1)]);
                mesh.triangles
                    .push([at(x, y), at(x + 1, y + 1), at(x, y + 1)]);
                mesh.boi.extend([x == 7, x == 7]);
            }
        }
        let sorted = spatially_sorted(&mesh);
        let mut before: Vec<_> = mesh.triangles.iter().zip(&mesh.boi).collect();
        let mut after: Vec<_> = sorted.triangles.iter().zip(&sorted.boi).collect();
        before.sort();
        after.sort();
        assert_eq!(before, after);
        let diagonal = |m: &Mesh| {
            let c = clusters(m);
            let sum: f32 = c
                .iter()
                .map(|c| {
                    let (lo, hi) = (c.corners[0], c.corners[7]);
                    (hi[0] - lo[0]).hypot(hi[1] - lo[1])
                })
                .sum();
            sum / c.len() as f32
        };
        // In row order a cluster of 32 faces is a 16 x 1 strip; sorted, a run along the
        // Z-order curve through blocks of about 4 x 4.
        assert!(diagonal(&mesh) > 16.0, "{}", diagonal(&mesh));
        assert!(
            diagonal(&sorted) < 0.65 * diagonal(&mesh),
            "{} against {}",
            diagonal(&sorted),
            diagonal(&mesh)
        );
        // The clusters cover every face once, in order; the BOI column meets fewer of the
        // sorted clusters (about 10 of 100) than of the row-order strips (about 40).
        let c = clusters(&sorted);
        assert!(c.windows(2).all(|w| w[0].faces.end == w[1].faces.start));
        assert_eq!((c[0].faces.start, c.last().unwrap().faces.end), (0, 3200));
        let with_boi = |c: &[Cluster]| c.iter().filter(|c| c.has_boi).count();
        assert!(
            with_boi(&c) * 2 < with_boi(&clusters(&mesh)),
            "{}",
            with_boi(&c)
        );
    }
}
