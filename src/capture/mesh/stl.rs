//! STL, binary or ASCII (stl_io). Identical vertices are merged by the reader.

use std::path::Path;

use super::RawMesh;
use crate::error::{Error, Result};

pub(crate) fn read_stl(path: &Path) -> Result<RawMesh> {
    let mut file = std::fs::File::open(path).map_err(|e| Error::read(path, "mesh", e))?;
    let stl = stl_io::read_stl(&mut file)
        .map_err(|e| Error::invalid(path, "file", format!("not a readable STL file: {e}")))?;
    let triangles: Vec<[u32; 3]> = stl
        .faces
        .iter()
        .map(|f| f.vertices.map(|v| v as u32))
        .collect();
    Ok(RawMesh {
        positions: stl.vertices.iter().map(|v| [v[0], v[1], v[2]]).collect(),
        face_tags: vec![[u32::MAX; 3]; triangles.len()],
        triangles,
        tags: Vec::new(),
    })
}
