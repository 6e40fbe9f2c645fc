//! Wavefront OBJ. Read by hand rather than with tobj: tobj re-indexes vertices per
//! group/object, and the capture format refers to vertices by the file's own numbering
//! (init.json's bootstrap points). Polygons are fan-triangulated; `v/vt/vn` forms and
//! negative (relative) indices are accepted.

use std::io::Write;
use std::path::Path;

use super::{Mesh, RawMesh};
use crate::error::{Error, Result};
use crate::io::read::quote;

const NO_TAG: u32 = u32::MAX;

pub(crate) fn read_obj(path: &Path) -> Result<RawMesh> {
    let text = crate::io::read::read_text(path, "mesh")?;
    parse_obj(&text, path)
}

fn parse_obj(text: &str, path: &Path) -> Result<RawMesh> {
    let mut mesh = RawMesh {
        positions: Vec::new(),
        triangles: Vec::new(),
        face_tags: Vec::new(),
        tags: Vec::new(),
    };
    // Current group, object and material.
    let mut current = [NO_TAG; 3];
    let mut polygon = Vec::with_capacity(8);
    for (line_no, line) in text.lines().enumerate() {
        let line = line.split('#').next().unwrap_or("").trim();
        let mut words = line.split_ascii_whitespace();
        let Some(keyword) = words.next() else {
            continue;
        };
        let at = || format!("line {}", line_no + 1);
        match keyword {
            "v" => {
                let mut p = [0f32; 3];
                for c in &mut p {
                    let w = words.next().ok_or_else(|| {
                        Error::invalid(path, at(), "a vertex needs three coordinates")
                    })?;
                    *c = w.parse().map_err(|_| {
                        Error::invalid(path, at(), format!("`{}` is not a number", quote(w)))
                    })?;
                }
                mesh.positions.push(p);
            }
            "f" => {
                polygon.clear();
                for w in words {
                    let idx = w.split('/').next().unwrap_or("");
                    let i: i64 = idx.parse().map_err(|_| {
                        Error::invalid(
                            path,
                            at(),
                            format!("`{}` is not a vertex reference", quote(w)),
                        )
                    })?;
                    let n = mesh.positions.len() as i64;
                    let resolved = if i > 0 {
                        i - 1
                    } else if i < 0 {
                        n + i
                    } else {
                        -1
                    };
                    if resolved < 0 {
                        return Err(Error::invalid(
                            path,
                            at(),
                            format!("vertex reference {i} is out of range"),
                        ));
                    }
                    // Forward references beyond the current count are checked in Mesh::validate.
                    polygon.push(resolved as u32);
                }
                if polygon.len() < 3 {
                    return Err(Error::invalid(
                        path,
                        at(),
                        "a face needs at least three vertices",
                    ));
                }
                for k in 1..polygon.len() - 1 {
                    mesh.triangles
                        .push([polygon[0], polygon[k], polygon[k + 1]]);
                    mesh.face_tags.push(current);
                }
            }
            "g" | "o" | "usemtl" => {
                let slot = match keyword {
                    "g" => 0,
                    "o" => 1,
                    _ => 2,
                };
                let name = words.collect::<Vec<_>>().join(" ");
                current[slot] = if name.is_empty() {
                    NO_TAG
                } else {
                    match mesh.tags.iter().position(|t| *t == name) {
                        Some(i) => i as u32,
                        None => {
                            mesh.tags.push(name);
                            (mesh.tags.len() - 1) as u32
                        }
                    }
                };
            }
            _ => {}
        }
    }
    Ok(mesh)
}

/// Write a mesh as OBJ: all vertices in their original order, body faces under `g body`
/// and boundary-of-interest faces under `g boi`. Written atomically.
pub fn write_obj(mesh: &Mesh, path: &Path) -> Result<()> {
    let mut out = Vec::with_capacity(mesh.positions.len() * 40 + mesh.triangles.len() * 24);
    let w = |out: &mut Vec<u8>, s: std::fmt::Arguments| out.write_fmt(s).expect("write to Vec");
    w(&mut out, format_args!("# jawtrack mesh: millimetres\n"));
    for p in &mesh.positions {
        w(&mut out, format_args!("v {} {} {}\n", p[0], p[1], p[2]));
    }
    for (name, want) in [("body", false), ("boi", true)] {
        if !mesh.boi.contains(&want) {
            continue;
        }
        w(&mut out, format_args!("g {name}\n"));
        for (t, _) in mesh
            .triangles
            .iter()
            .zip(&mesh.boi)
            .filter(|(_, b)| **b == want)
        {
            w(
                &mut out,
                format_args!("f {} {} {}\n", t[0] + 1, t[1] + 1, t[2] + 1),
            );
        }
    }
    crate::io::write_atomic(path, &out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn groups_materials_polygons_and_negative_indices() {
        let text = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n\
                    g body\nf 1 2 3\nusemtl boi\nf -4/1/1 -2//3 -1\n\
                    g front\nf 1 2 3 4\n";
        let m = parse_obj(text, Path::new("t.obj")).unwrap();
        assert_eq!(m.positions.len(), 4);
        assert_eq!(
            m.triangles,
            vec![[0, 1, 2], [0, 2, 3], [0, 1, 2], [0, 2, 3]]
        );
        let boi = m.tags.iter().position(|t| t == "boi").unwrap() as u32;
        let flagged: Vec<bool> = m.face_tags.iter().map(|ft| ft.contains(&boi)).collect();
        // The material stays in force after `g front`.
        assert_eq!(flagged, vec![false, true, true, true]);
    }

    #[test]
    fn bad_number_names_the_line() {
        let err = parse_obj("v 0 0 0\nv 1 x 0\n", Path::new("t.obj"))
            .err()
            .unwrap();
        assert!(err.to_string().contains("line 2"), "{err}");
    }
}
