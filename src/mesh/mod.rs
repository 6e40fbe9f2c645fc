//! Triangle meshes in millimetres, with the boundary of interest (BOI, the paper's green
//! region) as a per-face flag. Vertex numbering is the file's: init.json refers to it.

mod boi;
mod obj;
mod ply;
mod simplify;
pub use simplify::Simplify;
mod stl;

use std::path::Path;

use crate::error::{Error, Result};

pub use boi::{BoiMarking, mark_boi};
pub use obj::write_obj;

/// [`Mesh::bounds`] of some faces.
pub fn bounds(positions: &[[f32; 3]], triangles: &[[u32; 3]]) -> ([f32; 3], [f32; 3]) {
    let mut lo = [f32::INFINITY; 3];
    let mut hi = [f32::NEG_INFINITY; 3];
    for t in triangles {
        for &v in t {
            let p = positions[v as usize];
            for k in 0..3 {
                lo[k] = lo[k].min(p[k]);
                hi[k] = hi[k].max(p[k]);
            }
        }
    }
    (lo, hi)
}

/// [`Mesh::signed_volume`] of some faces.
pub fn signed_volume(positions: &[[f32; 3]], triangles: &[[u32; 3]]) -> f64 {
    let det: f64 = triangles
        .iter()
        .map(|t| {
            let [a, b, c] = t.map(|v| positions[v as usize].map(f64::from));
            a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0])
                + a[2] * (b[0] * c[1] - b[1] * c[0])
        })
        .sum();
    det / 6.0
}

#[derive(Debug, Clone, PartialEq)]
pub struct Mesh {
    pub positions: Vec<[f32; 3]>,
    pub triangles: Vec<[u32; 3]>,
    /// One flag per triangle: part of the boundary of interest.
    pub boi: Vec<bool>,
}

/// Where a mesh's boundary of interest comes from.
#[derive(Debug, Clone, Copy)]
pub enum BoiSource<'a> {
    /// Faces of the OBJ group, object or material with this name.
    Group(&'a str),
    /// A JSON list of face indices.
    FaceList(&'a Path),
    /// The group if the file has one of that name with faces, else no BOI.
    GroupIfPresent(&'a str),
    /// No BOI (all faces are body).
    None,
}

/// A mesh as read from a file, before the BOI is resolved: faces with the OBJ
/// group/object/material names they were declared under.
pub(crate) struct RawMesh {
    pub positions: Vec<[f32; 3]>,
    pub triangles: Vec<[u32; 3]>,
    /// Per triangle, an index into `tags` for each of group, object and material (u32::MAX: none).
    pub face_tags: Vec<[u32; 3]>,
    pub tags: Vec<String>,
}

/// The largest coordinate a mesh may have (mm): a kilometre, far beyond any head, and far enough
/// below `f32`'s range that distances and products of coordinates stay finite.
pub const MAX_COORDINATE_MM: f32 = 1e6;

/// Every coordinate finite and within [`MAX_COORDINATE_MM`]; an error names the first vertex
/// that is not.
fn check_coordinates(path: &Path, positions: &[[f32; 3]]) -> Result<()> {
    let Some(i) = positions
        .iter()
        .position(|p| p.iter().any(|c| c.is_nan() || c.abs() > MAX_COORDINATE_MM))
    else {
        return Ok(());
    };
    let p = positions[i];
    let why = if p.iter().all(|c| c.is_finite()) {
        format!("has a coordinate beyond ±{MAX_COORDINATE_MM} mm {p:?}: meshes are in millimetres")
    } else {
        format!("has a non-finite coordinate {p:?}")
    };
    Err(Error::invalid(
        path,
        format!("vertex {} (counting from 1)", i + 1),
        why,
    ))
}

/// The extensions of the mesh formats read (lower case).
pub const EXTENSIONS: [&str; 3] = ["obj", "stl", "ply"];

/// The file read by its extension's reader, and the extension (lower case). STL, which keeps
/// no vertex order, only where `stl` allows it.
fn read_raw(path: &Path, stl: bool) -> Result<(RawMesh, String)> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase)
        .unwrap_or_default();
    let raw = match ext.as_str() {
        "obj" => obj::read_obj(path)?,
        "stl" if stl => stl::read_stl(path)?,
        "ply" => ply::read_ply(path)?,
        _ => {
            let expected = if stl {
                ".obj, .stl or .ply"
            } else {
                ".obj or .ply"
            };
            return Err(Error::invalid(
                path,
                "extension",
                format!("unsupported mesh format `.{ext}` (expected {expected})"),
            ));
        }
    };
    Ok((raw, ext))
}

impl Mesh {
    /// Load an OBJ, STL (binary or ASCII) or PLY file, chosen by extension, and validate it.
    pub fn load(path: &Path, boi: BoiSource) -> Result<Mesh> {
        let (raw, ext) = read_raw(path, true)?;
        // Before the boundary of interest is looked for: an empty file is not "a mesh without
        // the group".
        if raw.triangles.is_empty() {
            return Err(Error::invalid(
                path,
                "faces",
                format!("the mesh has no faces ({} vertices)", raw.positions.len()),
            ));
        }
        let boi_flags = match boi {
            BoiSource::None => vec![false; raw.triangles.len()],
            BoiSource::GroupIfPresent(name) => {
                let tag = raw.tags.iter().position(|t| t == name).map(|i| i as u32);
                raw.face_tags
                    .iter()
                    .map(|ft| tag.is_some_and(|t| ft.contains(&t)))
                    .collect()
            }
            BoiSource::Group(name) => {
                if ext != "obj" {
                    return Err(Error::invalid(
                        path,
                        "boi.group",
                        format!(
                            "a .{ext} file has no groups; give the boundary of interest as face-index lists \
                             (\"boi\": {{\"upper\": ..., \"lower\": ...}})"
                        ),
                    ));
                }
                let tag = raw.tags.iter().position(|t| t == name).map(|i| i as u32);
                let flags: Vec<bool> = raw
                    .face_tags
                    .iter()
                    .map(|ft| tag.is_some_and(|t| ft.contains(&t)))
                    .collect();
                if tag.is_none() {
                    return Err(Error::invalid(
                        path,
                        "boi.group",
                        format!("no group, object or material named `{name}` in the mesh"),
                    ));
                }
                if !flags.iter().any(|&b| b) {
                    return Err(Error::invalid(
                        path,
                        "boi.group",
                        format!("the group `{name}` has no faces"),
                    ));
                }
                flags
            }
            BoiSource::FaceList(list) => read_face_list(list, raw.triangles.len())?,
        };
        let mesh = Mesh {
            positions: raw.positions,
            triangles: raw.triangles,
            boi: boi_flags,
        };
        mesh.validate(path)?;
        Ok(mesh)
    }

    /// The vertices alone of an OBJ or PLY file (faces, if any, are not needed): a frame of a
    /// face sequence, whose topology is its neutral mesh's.
    pub fn load_vertices(path: &Path) -> Result<Vec<[f32; 3]>> {
        let (raw, _) = read_raw(path, false)?;
        check_coordinates(path, &raw.positions)?;
        Ok(raw.positions)
    }

    /// Area-weighted vertex normals, unit length (zero where a vertex has no area), oriented
    /// as the triangles wind: a caller that knows the inside orients them.
    pub fn vertex_normals(&self) -> Vec<nalgebra::Vector3<f64>> {
        let mut n = vec![nalgebra::Vector3::zeros(); self.positions.len()];
        for t in &self.triangles {
            let [a, b, c] = t.map(|i| self.point(i as usize));
            let face = (b - a).cross(&(c - a));
            for &i in t {
                n[i as usize] += face;
            }
        }
        n.into_iter()
            .map(|v| v.try_normalize(1e-12).unwrap_or_default())
            .collect()
    }

    /// Check the invariants every consumer relies on.
    pub fn validate(&self, path: &Path) -> Result<()> {
        if self.triangles.is_empty() {
            return Err(Error::invalid(path, "faces", "the mesh has no faces"));
        }
        check_coordinates(path, &self.positions)?;
        let n = self.positions.len() as u32;
        if let Some(i) = self
            .triangles
            .iter()
            .position(|t| t.iter().any(|&v| v >= n))
        {
            return Err(Error::invalid(
                path,
                format!("face {} (counting from 1)", i + 1),
                format!(
                    "refers to vertex {} (counting from 1) but the mesh has {n} vertices",
                    self.triangles[i].iter().max().map_or(0, |&v| v as u64 + 1)
                ),
            ));
        }
        if self.boi.len() != self.triangles.len() {
            return Err(Error::invalid(path, "boi", "one flag per face expected"));
        }
        Ok(())
    }

    pub fn boi_face_count(&self) -> usize {
        self.boi.iter().filter(|&&b| b).count()
    }

    /// Vertex `i` in double precision.
    pub fn point(&self, i: usize) -> nalgebra::Vector3<f64> {
        let p = self.positions[i];
        nalgebra::Vector3::new(p[0] as f64, p[1] as f64, p[2] as f64)
    }

    /// Every vertex (used by faces or not) in double precision.
    pub fn points(&self) -> impl Iterator<Item = nalgebra::Vector3<f64>> + '_ {
        (0..self.positions.len()).map(|i| self.point(i))
    }

    /// The mean of the boundary of interest's face corners; `None` without a BOI.
    pub fn boi_centroid(&self) -> Option<nalgebra::Vector3<f64>> {
        let corners = self
            .triangles
            .iter()
            .zip(&self.boi)
            .filter(|(_, b)| **b)
            .flat_map(|(t, _)| t.map(|i| self.point(i as usize)));
        let (sum, n) = corners.fold((nalgebra::Vector3::zeros(), 0usize), |(s, n), p| {
            (s + p, n + 1)
        });
        (n > 0).then(|| sum / n as f64)
    }

    /// The vertices' centroid and principal axes (unit, signs arbitrary), thinnest spread
    /// first: for a dental arch, the occlusal axis, then front to back, then side to side.
    pub fn principal_axes(&self) -> (nalgebra::Vector3<f64>, [nalgebra::Vector3<f64>; 3]) {
        use nalgebra::{Matrix3, SymmetricEigen, Vector3};
        let n = self.positions.len().max(1) as f64;
        let mean = self.points().sum::<Vector3<f64>>() / n;
        let mut cov = Matrix3::zeros();
        for p in self.points() {
            let d = p - mean;
            cov += d * d.transpose();
        }
        let eigen = SymmetricEigen::new(cov);
        let mut order = [0usize, 1, 2];
        order.sort_by(|&a, &b| eigen.eigenvalues[a].total_cmp(&eigen.eigenvalues[b]));
        (
            mean,
            order.map(|i| eigen.eigenvectors.column(i).into_owned()),
        )
    }

    /// The volume the faces enclose, signed: positive when they turn outwards (right-hand rule
    /// over each face's vertex order), negative inwards; meaningful for a closed surface.
    pub fn signed_volume(&self) -> f64 {
        signed_volume(&self.positions, &self.triangles)
    }

    /// Axis-aligned bounds (min, max) of the vertices used by faces.
    pub fn bounds(&self) -> ([f32; 3], [f32; 3]) {
        bounds(&self.positions, &self.triangles)
    }

    /// A copy without the vertices no face uses (renumbered): what a renderer needs. A
    /// simplified mesh keeps every vertex of the file to keep its numbering.
    pub fn compacted(&self) -> Mesh {
        let mut new_index = vec![u32::MAX; self.positions.len()];
        let mut positions = Vec::new();
        let triangles = self
            .triangles
            .iter()
            .map(|t| {
                t.map(|v| {
                    let slot = &mut new_index[v as usize];
                    if *slot == u32::MAX {
                        *slot = positions.len() as u32;
                        positions.push(self.positions[v as usize]);
                    }
                    *slot
                })
            })
            .collect();
        Mesh {
            positions,
            triangles,
            boi: self.boi.clone(),
        }
    }

    /// A simplified copy (meshoptimizer), keeping the file's vertex numbering and the BOI:
    /// body and BOI are simplified apart with their borders locked.
    pub fn simplified(&self, how: Simplify) -> Mesh {
        simplify::simplify(self, how)
    }
}

fn read_face_list(path: &Path, face_count: usize) -> Result<Vec<bool>> {
    let faces: Vec<i64> = crate::io::read_json(path, "boundary-of-interest face list")?;
    if faces.is_empty() {
        return Err(Error::invalid(
            path,
            "faces",
            "the boundary-of-interest face list is empty",
        ));
    }
    let mut flags = vec![false; face_count];
    for (i, &f) in faces.iter().enumerate() {
        if f < 0 || f as usize >= face_count {
            return Err(Error::invalid(
                path,
                format!("[{i}]"),
                format!("face index {f} is out of range (the mesh has {face_count} faces)"),
            ));
        }
        flags[f as usize] = true;
    }
    Ok(flags)
}

/// The box `[lo, hi]` as twelve triangles wound outwards (right-hand rule), vertex `i` at
/// (bit 0: x, bit 1: y, bit 2: z) of `hi` where the bit is set and of `lo` where not: the
/// tests' closed mesh.
#[cfg(test)]
pub(crate) fn cuboid(lo: [f32; 3], hi: [f32; 3]) -> Mesh {
    let positions = (0..8)
        .map(|i| std::array::from_fn(|k| if i >> k & 1 == 1 { hi[k] } else { lo[k] }))
        .collect();
    let quads = [
        [0, 2, 3, 1], // z = lo, normal -z
        [4, 5, 7, 6], // z = hi, +z
        [0, 1, 5, 4], // y = lo, -y
        [2, 6, 7, 3], // y = hi, +y
        [0, 4, 6, 2], // x = lo, -x
        [1, 3, 7, 5], // x = hi, +x
    ];
    let triangles: Vec<[u32; 3]> = quads
        .iter()
        .flat_map(|q| [[q[0], q[1], q[2]], [q[0], q[2], q[3]]])
        .collect();
    Mesh {
        boi: vec![false; triangles.len()],
        positions,
        triangles,
    }
}
