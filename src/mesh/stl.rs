//! STL, binary or ASCII (stl_io). Identical vertices are merged by the reader.

use std::path::Path;

use super::RawMesh;
use crate::error::{Error, Result};
use crate::io::read::quote;

/// A binary STL header gives its triangle count, and the reader allocates for it: a count the
/// file's size cannot hold is refused first. (An ASCII file starts with `solid` and has no
/// count; a binary file that happens to start so is recognised by its exact size.)
fn check_claimed_size(path: &Path, file: &mut std::fs::File, len: u64) -> Result<()> {
    use std::io::{Read, Seek};
    let mut header = [0u8; 84];
    let read = file
        .read(&mut header)
        .map_err(|e| Error::read(path, "mesh", e))?;
    file.rewind().map_err(|e| Error::read(path, "mesh", e))?;
    if read < 84 {
        return if header[..read].starts_with(b"solid") {
            Ok(())
        } else {
            Err(Error::invalid(
                path,
                "file",
                format!("not a readable STL file: {read} bytes, shorter than a binary STL header"),
            ))
        };
    }
    let count = u32::from_le_bytes([header[80], header[81], header[82], header[83]]) as u64;
    let binary_len = 84 + 50 * count;
    if binary_len == len || header.starts_with(b"solid") {
        return Ok(());
    }
    Err(Error::invalid(
        path,
        "triangle count",
        format!(
            "the binary STL header claims {count} triangles ({binary_len} bytes), but the file has {len}"
        ),
    ))
}

pub(crate) fn read_stl(path: &Path) -> Result<RawMesh> {
    let (mut file, len) = crate::io::read::open_input(path, "mesh")?;
    check_claimed_size(path, &mut file, len)?;
    let stl = stl_io::read_stl(&mut file).map_err(|e| {
        Error::invalid(
            path,
            "file",
            format!("not a readable STL file: {}", quote(&e.to_string())),
        )
    })?;
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
