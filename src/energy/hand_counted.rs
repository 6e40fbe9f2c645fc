//! The hand-countable scene that the CPU and GPU engines are both checked on (after vello's
//! `property.rs`): a 100x80 camera at the origin with f = 100 px, so a 1 mm step at z = 100 mm
//! is exactly one pixel, and a 20 mm square whose top half is boundary of interest.

use crate::geometry::{Camera, Pose};
use crate::mesh::Mesh;

/// 100x80 pixels, f = 100, principal point (50, 40), at the world origin looking along +z.
pub fn camera() -> Camera {
    Camera {
        name: "c".into(),
        width: 100,
        height: 80,
        fx: 100.0,
        fy: 100.0,
        cx: 50.0,
        cy: 40.0,
        distortion: crate::geometry::Distortion::NONE,
        camera_from_world: Pose::IDENTITY,
    }
}

/// A 20 mm square in its model's z = 0 plane: at z = 100 it covers 20 x 20 pixels, columns
/// 40..60 and rows 30..50, and its top half (rows 30..40) is boundary of interest.
pub fn square() -> Mesh {
    Mesh {
        positions: vec![
            [-10.0, -10.0, 0.0],
            [10.0, -10.0, 0.0],
            [10.0, 0.0, 0.0],
            [-10.0, 0.0, 0.0],
            [10.0, 10.0, 0.0],
            [-10.0, 10.0, 0.0],
        ],
        triangles: vec![[0, 1, 2], [0, 2, 3], [3, 2, 4], [3, 4, 5]],
        boi: vec![true, true, false, false],
    }
}

/// A degenerate triangle standing in for an arch that plays no part.
pub fn nothing() -> Mesh {
    Mesh {
        positions: vec![[0.0; 3]; 3],
        triangles: vec![[0, 1, 2]],
        boi: vec![false],
    }
}
