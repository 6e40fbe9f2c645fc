//! The paper's features (Section 5.1). Skin features: displacements from the neutral of
//! points on the skin found along the mandible's outward normals over the chin and the jaw
//! line. Bone features: displacements of five points spread over the mandible (menton, both
//! gonial angles, both condyles). Both in the skull frame; bone displacements are from the
//! subject's rest pose.

use nalgebra::Vector3;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::geometry::Pose;
use crate::mesh::Mesh;

/// How the skin feature points are chosen: a documented setting (`skin learn --features`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct FeatureSettings {
    /// How many skin points (the paper: 242).
    pub count: usize,
    /// Mandible vertices this far or more below the lower incisal edge are candidates: the
    /// chin and the jaw line, not the lips over the teeth (at most half the mandible's height
    /// at the front, for a mandible shorter than the setting assumes).
    pub below_incisal_mm: f64,
    /// A candidate's ray must reach the skin within this depth of soft tissue.
    pub max_depth_mm: f64,
    /// A candidate's normal must point away from the mandible's inside: its horizontal part
    /// along the direction out from the mandible's centre at least this much (cosine), or
    /// the normal point down (the underside of the jaw line).
    pub outward_cos: f64,
}

impl Default for FeatureSettings {
    fn default() -> Self {
        FeatureSettings {
            count: 242,
            below_incisal_mm: 12.0,
            max_depth_mm: 30.0,
            outward_cos: 0.3,
        }
    }
}

/// A point on the skin surface: barycentric on a triangle of the neutral's topology, so that
/// it is found in every frame and, topology being shared, on every subject.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SkinPoint {
    pub triangle: u32,
    pub barycentric: [f64; 3],
}

impl SkinPoint {
    pub fn on(&self, triangles: &[[u32; 3]], vertices: &[[f32; 3]]) -> Vector3<f64> {
        let t = triangles[self.triangle as usize];
        (0..3)
            .map(|k| {
                let v = vertices[t[k] as usize];
                Vector3::new(v[0] as f64, v[1] as f64, v[2] as f64) * self.barycentric[k]
            })
            .sum()
    }
}

/// The five bone points, in the mandible's (lower arch's) frame, named as anatomy does.
pub const BONE_POINTS: [&str; 5] = [
    "menton",
    "gonion left",
    "gonion right",
    "condyle left",
    "condyle right",
];

/// Why no features could be chosen.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FeatureError {
    #[error(
        "only {found} mandible vertices below the incisal edge see the skin along their outward normal within {depth} mm (at least 3 needed): is the mandible in the lower arch's frame and the skin in the skull frame, both in mm?"
    )]
    TooFew { found: usize, depth: f64 },
}

/// Choose skin points on `neutral` from the mandible placed at `rest` (`upper_from_lower`).
/// A mandible that is not closed has no reliable inside: both orientations of its normals are
/// tried, and the one that finds more skin kept; where the tissue is thicker than the setting
/// finds enough points through, the depth is doubled once.
pub fn choose_skin_points(
    neutral: &Mesh,
    mandible: &Mesh,
    rest: &Pose,
    s: &FeatureSettings,
) -> Result<Vec<SkinPoint>, FeatureError> {
    let (bone, normals) = surface_samples(mandible, rest);
    let flipped: Vec<Vector3<f64>> = normals.iter().map(|n| -n).collect();
    let mut hits = candidates(neutral, &bone, &normals, s, s.max_depth_mm);
    let other = candidates(neutral, &bone, &flipped, s, s.max_depth_mm);
    if other.len() > hits.len() {
        hits = other;
    }
    if hits.len() < s.count / 2 {
        let deeper = candidates(neutral, &bone, &normals, s, 2.0 * s.max_depth_mm);
        let deeper_flipped = candidates(neutral, &bone, &flipped, s, 2.0 * s.max_depth_mm);
        for h in [deeper, deeper_flipped] {
            if h.len() > hits.len() {
                hits = h;
            }
        }
    }
    if hits.len() < 3 {
        return Err(FeatureError::TooFew {
            found: hits.len(),
            depth: 2.0 * s.max_depth_mm,
        });
    }
    Ok(farthest_points(&hits, s.count))
}

/// Candidate skin points: where the outward normals of the mandible's points below the incisal
/// edge meet the skin within `depth`.
fn candidates(
    neutral: &Mesh,
    bone: &[Vector3<f64>],
    normals: &[Vector3<f64>],
    s: &FeatureSettings,
    depth: f64,
) -> Vec<(SkinPoint, Vector3<f64>)> {
    let centre = bone.iter().sum::<Vector3<f64>>() / bone.len().max(1) as f64;
    let (_, hi) = bounds(bone);
    let front_y = || bone.iter().filter(|p| p.z > hi.z - 15.0).map(|p| p.y);
    let front = front_y().fold(f64::NEG_INFINITY, f64::max);
    let chin = front_y().fold(f64::INFINITY, f64::min);
    // A mandible with teeth is 30-40 mm tall at the front, so the setting leaves the chin; one
    // without (a bone model, another program's stand-in) may be shorter than the setting:
    // its lower half stays a candidate.
    let top = front - s.below_incisal_mm.min((front - chin) / 2.0);
    bone.par_iter()
        .zip(normals.par_iter())
        .filter_map(|(p, n)| {
            if p.y > top || n.norm() < 0.5 {
                return None;
            }
            let out = Vector3::new(p.x - centre.x, 0.0, p.z - centre.z);
            let outward = out.norm() > 1e-9 && n.dot(&out.normalize()) >= s.outward_cos;
            if !outward && n.y > -0.6 {
                return None;
            }
            let (tri, bary, t) = cast(p, n, &neutral.triangles, &neutral.positions)?;
            let point = SkinPoint {
                triangle: tri,
                barycentric: bary,
            };
            (t <= depth).then_some((point, p + n * t))
        })
        .collect()
}

/// Farthest-point sampling: spread the points evenly, starting from the most anterior.
fn farthest_points(hits: &[(SkinPoint, Vector3<f64>)], count: usize) -> Vec<SkinPoint> {
    let first = (0..hits.len())
        .max_by(|&a, &b| hits[a].1.z.total_cmp(&hits[b].1.z))
        .unwrap_or(0);
    let mut chosen = vec![first];
    let mut dist: Vec<f64> = hits.iter().map(|h| (h.1 - hits[first].1).norm()).collect();
    while chosen.len() < count.min(hits.len()) {
        let (next, d) = dist
            .iter()
            .enumerate()
            .max_by(|a, b| a.1.total_cmp(b.1))
            .map(|(i, d)| (i, *d))
            .unwrap_or((0, 0.0));
        if d <= 1e-9 {
            break;
        }
        chosen.push(next);
        for (i, h) in hits.iter().enumerate() {
            dist[i] = dist[i].min((h.1 - hits[next].1).norm());
        }
    }
    chosen.into_iter().map(|i| hits[i].0).collect()
}

/// The nearest hit of the ray `o + t·d` (t > 0) on the triangles: triangle, barycentric, t.
fn cast(
    o: &Vector3<f64>,
    d: &Vector3<f64>,
    tris: &[[u32; 3]],
    v: &[[f32; 3]],
) -> Option<(u32, [f64; 3], f64)> {
    let p = |i: u32| {
        let q = v[i as usize];
        Vector3::new(q[0] as f64, q[1] as f64, q[2] as f64)
    };
    let mut best: Option<(u32, [f64; 3], f64)> = None;
    for (k, t) in tris.iter().enumerate() {
        let (a, b, c) = (p(t[0]), p(t[1]), p(t[2]));
        // Möller-Trumbore.
        let (e1, e2) = (b - a, c - a);
        let h = d.cross(&e2);
        let det = e1.dot(&h);
        if det.abs() < 1e-12 {
            continue;
        }
        let f = 1.0 / det;
        let s = o - a;
        let u = f * s.dot(&h);
        if !(0.0..=1.0).contains(&u) {
            continue;
        }
        let q = s.cross(&e1);
        let w = f * d.dot(&q);
        if w < 0.0 || u + w > 1.0 {
            continue;
        }
        let dist = f * e2.dot(&q);
        if dist > 1e-6 && best.is_none_or(|b| dist < b.2) {
            best = Some((k as u32, [1.0 - u - w, u, w], dist));
        }
    }
    best
}

/// Points over the mandible's surface with their normals, in the skull frame: the vertices,
/// and points on every triangle (a coarse mandible has too few vertices for ~240 features).
fn surface_samples(mandible: &Mesh, rest: &Pose) -> (Vec<Vector3<f64>>, Vec<Vector3<f64>>) {
    const ON_TRIANGLE: [[f64; 3]; 4] = [
        [1.0 / 3.0, 1.0 / 3.0, 1.0 / 3.0],
        [2.0 / 3.0, 1.0 / 6.0, 1.0 / 6.0],
        [1.0 / 6.0, 2.0 / 3.0, 1.0 / 6.0],
        [1.0 / 6.0, 1.0 / 6.0, 2.0 / 3.0],
    ];
    let vn = vertex_normals(mandible);
    let mut points: Vec<Vector3<f64>> = mandible.points().collect();
    let mut normals = vn.clone();
    for t in &mandible.triangles {
        for b in ON_TRIANGLE {
            let (mut p, mut n) = (Vector3::zeros(), Vector3::zeros());
            for k in 0..3 {
                p += mandible.point(t[k] as usize) * b[k];
                n += vn[t[k] as usize] * b[k];
            }
            points.push(p);
            normals.push(n.try_normalize(1e-12).unwrap_or(Vector3::zeros()));
        }
    }
    (
        points.iter().map(|p| rest.transform_point(p)).collect(),
        normals.iter().map(|n| rest.rotation * n).collect(),
    )
}

/// Vertex normals pointing out of a closed mesh (by its signed volume).
fn vertex_normals(mesh: &Mesh) -> Vec<Vector3<f64>> {
    let sign = if mesh.signed_volume() < 0.0 {
        -1.0
    } else {
        1.0
    };
    mesh.vertex_normals()
        .into_iter()
        .map(|n| n * sign)
        .collect()
}

fn bounds(p: &[Vector3<f64>]) -> (Vector3<f64>, Vector3<f64>) {
    let mut lo = Vector3::repeat(f64::INFINITY);
    let mut hi = Vector3::repeat(f64::NEG_INFINITY);
    for q in p {
        lo = lo.inf(q);
        hi = hi.sup(q);
    }
    (lo, hi)
}

/// The five bone points of a mandible (its own frame), chosen by the same rule on every
/// subject so that they correspond: the lowest point near the midline at the front (menton),
/// the outermost points of the lower back quarter on each side (gonial angles), the highest
/// points of the back half on each side (condyles).
pub fn bone_points(mandible: &Mesh) -> [Vector3<f64>; 5] {
    let p: Vec<Vector3<f64>> = mandible.points().collect();
    let (lo, hi) = bounds(&p);
    let mid = (lo + hi) * 0.5;
    let pick = |keep: &dyn Fn(&Vector3<f64>) -> bool, score: &dyn Fn(&Vector3<f64>) -> f64| {
        p.iter()
            .filter(|q| keep(q))
            .max_by(|a, b| score(a).total_cmp(&score(b)))
            .or_else(|| p.iter().max_by(|a, b| score(a).total_cmp(&score(b))))
            .copied()
            .unwrap_or(mid)
    };
    let width = (hi.x - lo.x).max(1e-9);
    let menton = pick(
        &|q| (q.x - mid.x).abs() < 0.1 * width && q.z > mid.z,
        &|q| -q.y,
    );
    let back_low = |q: &Vector3<f64>| q.z < mid.z && q.y < mid.y;
    let gonion_l = pick(&back_low, &|q| q.x - q.y * 0.25);
    let gonion_r = pick(&back_low, &|q| -q.x - q.y * 0.25);
    let condyle_l = pick(&|q| q.z < mid.z && q.x > mid.x, &|q| q.y);
    let condyle_r = pick(&|q| q.z < mid.z && q.x < mid.x, &|q| q.y);
    [menton, gonion_l, gonion_r, condyle_l, condyle_r]
}

/// The skin features of a frame: each point's displacement from the neutral, flattened.
pub fn skin_features(
    points: &[SkinPoint],
    triangles: &[[u32; 3]],
    neutral: &[[f32; 3]],
    frame: &[[f32; 3]],
) -> Vec<f64> {
    let mut f = Vec::with_capacity(points.len() * 3);
    for p in points {
        let d = p.on(triangles, frame) - p.on(triangles, neutral);
        f.extend_from_slice(d.as_slice());
    }
    f
}

/// The bone features of a jaw pose: each bone point's displacement from its place at rest.
pub fn bone_features(bone: &[Vector3<f64>; 5], rest: &Pose, jaw: &Pose) -> Vec<f64> {
    let mut b = Vec::with_capacity(15);
    for m in bone {
        let d = jaw.transform_point(m) - rest.transform_point(m);
        b.extend_from_slice(d.as_slice());
    }
    b
}
