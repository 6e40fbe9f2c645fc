//! PLY, ASCII or binary (ply-rs-bw): `vertex` elements with x, y, z and `face` elements
//! with a `vertex_indices` (or `vertex_index`) list; polygons are fan-triangulated.

use std::path::Path;

use ply_rs_bw::{parser::Parser, ply::Property};

use super::RawMesh;
use crate::error::{Error, Result};
use crate::io::read::quote;

fn scalar(p: &Property) -> Option<f64> {
    Some(match *p {
        Property::Char(v) => v as f64,
        Property::UChar(v) => v as f64,
        Property::Short(v) => v as f64,
        Property::UShort(v) => v as f64,
        Property::Int(v) => v as f64,
        Property::UInt(v) => v as f64,
        Property::Float(v) => v as f64,
        Property::Double(v) => v,
        _ => return None,
    })
}

fn index_list(p: &Property) -> Option<Vec<i64>> {
    Some(match p {
        Property::ListChar(v) => v.iter().map(|&x| x as i64).collect(),
        Property::ListUChar(v) => v.iter().map(|&x| x as i64).collect(),
        Property::ListShort(v) => v.iter().map(|&x| x as i64).collect(),
        Property::ListUShort(v) => v.iter().map(|&x| x as i64).collect(),
        Property::ListInt(v) => v.iter().map(|&x| x as i64).collect(),
        Property::ListUInt(v) => v.iter().map(|&x| x as i64).collect(),
        _ => return None,
    })
}

/// The header's element counts, which the reader allocates for, must fit the file: every
/// element takes at least a byte. The reader is rewound to the start.
fn check_claimed_counts(
    path: &Path,
    reader: &mut std::io::BufReader<std::fs::File>,
    len: u64,
) -> Result<()> {
    use std::io::{BufRead, Read, Seek};
    let mut claimed: u64 = 0;
    let mut line = Vec::new();
    // The header is text up to `end_header`; a few kilobytes is plenty.
    for _ in 0..10_000 {
        line.clear();
        let n = reader
            .by_ref()
            .take(4096)
            .read_until(b'\n', &mut line)
            .map_err(|e| Error::read(path, "mesh", e))?;
        let text = String::from_utf8_lossy(&line);
        let words: Vec<&str> = text.split_ascii_whitespace().collect();
        if n == 0 || words.first() == Some(&"end_header") {
            break;
        }
        if let ["element", name, count] = words[..] {
            let count: u64 = count.parse().map_err(|_| {
                Error::invalid(path, format!("element {name}"), "the count is not a number")
            })?;
            claimed = claimed.saturating_add(count);
        }
    }
    reader.rewind().map_err(|e| Error::read(path, "mesh", e))?;
    if claimed > len {
        return Err(Error::invalid(
            path,
            "element counts",
            format!("the header claims {claimed} elements, more than the file's {len} bytes hold"),
        ));
    }
    Ok(())
}

pub(crate) fn read_ply(path: &Path) -> Result<RawMesh> {
    let (file, len) = crate::io::read::open_input(path, "mesh")?;
    let mut reader = std::io::BufReader::new(file);
    check_claimed_counts(path, &mut reader, len)?;
    let ply = Parser::<ply_rs_bw::ply::DefaultElement>::new()
        .read_ply(&mut reader)
        .map_err(|e| {
            Error::invalid(
                path,
                "file",
                format!("not a readable PLY file: {}", quote(&e.to_string())),
            )
        })?;
    let vertices = ply
        .payload
        .get("vertex")
        .ok_or_else(|| Error::invalid(path, "vertex", "the PLY file has no `vertex` element"))?;
    let mut positions = Vec::with_capacity(vertices.len());
    for (i, v) in vertices.iter().enumerate() {
        let mut p = [0f32; 3];
        for (k, name) in ["x", "y", "z"].iter().enumerate() {
            p[k] = v.get(*name).and_then(scalar).ok_or_else(|| {
                Error::invalid(
                    path,
                    format!("vertex {} (counting from 1)", i + 1),
                    format!("has no numeric `{name}`"),
                )
            })? as f32;
        }
        positions.push(p);
    }
    let mut triangles = Vec::new();
    for (i, f) in ply.payload.get("face").into_iter().flatten().enumerate() {
        let list = f
            .get("vertex_indices")
            .or_else(|| f.get("vertex_index"))
            .and_then(index_list)
            .ok_or_else(|| {
                Error::invalid(
                    path,
                    format!("face {} (counting from 1)", i + 1),
                    "has no `vertex_indices` list",
                )
            })?;
        if list.len() < 3 || list.iter().any(|&x| x < 0 || x > u32::MAX as i64) {
            return Err(Error::invalid(
                path,
                format!("face {} (counting from 1)", i + 1),
                format!("invalid vertex list {list:?} (indices count from 0 in PLY)"),
            ));
        }
        for k in 1..list.len() - 1 {
            triangles.push([list[0] as u32, list[k] as u32, list[k + 1] as u32]);
        }
    }
    Ok(RawMesh {
        positions,
        face_tags: vec![[u32::MAX; 3]; triangles.len()],
        triangles,
        tags: Vec::new(),
    })
}
