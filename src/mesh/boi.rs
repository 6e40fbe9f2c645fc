//! Automatic marking of the boundary of interest: the incisal band of the front teeth,
//! canine to canine (the paper's green "roof region", Fig. 8).
//!
//! Mesh frame as in ../shared/data/scan-tag0: y up, +z anterior; upper crowns point to −y,
//! lower crowns to +y. Vertices are placed along the arch by arc length (s = 0 at the midline,
//! ±1 at the distal ends); the front teeth are |s| <= `front_fraction`; the band is the part of
//! each front tooth within `band_mm` of the locally most incisal point.

use super::Mesh;

#[derive(Debug, Clone, Copy)]
pub struct BoiMarking {
    /// Crowns point to −y (upper arch) or +y (lower arch).
    pub upper: bool,
    /// Half-arch share (by arc length) of the central incisor to canine, per side.
    pub front_fraction: f64,
    /// Depth of the band from the incisal edge, mm.
    pub band_mm: f64,
}

impl BoiMarking {
    /// Defaults from typical mesiodistal crown widths: the three front teeth take about 41%
    /// of the upper half-arch and 33% of the lower one. The cut is placed a little inside
    /// that (the canine's cusp is in, the first premolar out); the band is 1.5 mm deep.
    pub fn for_arch(upper: bool) -> Self {
        BoiMarking {
            upper,
            front_fraction: if upper { 0.37 } else { 0.29 },
            band_mm: 1.5,
        }
    }
}

const ANGLE_BINS: usize = 180;

/// Mark the BOI of `mesh` in place (replacing any previous marking); returns the face count.
pub fn mark_boi(mesh: &mut Mesh, m: &BoiMarking) -> usize {
    let (lo, hi) = mesh.bounds();
    let (lo, hi) = (lo.map(f64::from), hi.map(f64::from));
    // Angles about a point on the midline behind the incisors: a U-shaped arch is then a
    // single-valued curve of the angle.
    let centre = [(lo[0] + hi[0]) * 0.5, lo[2] + 0.3 * (hi[2] - lo[2])];
    let bite = if m.upper { -1.0 } else { 1.0 };
    let angle_bin = |p: &[f32; 3]| {
        let a = (p[0] as f64 - centre[0]).atan2(p[2] as f64 - centre[1]); // 0 = anterior
        (((a + std::f64::consts::PI) / std::f64::consts::TAU * ANGLE_BINS as f64) as usize)
            .min(ANGLE_BINS - 1)
    };
    let mut used = vec![false; mesh.positions.len()];
    for t in &mesh.triangles {
        for &v in t {
            used[v as usize] = true;
        }
    }
    // Mean (x, z) and the most incisal height per angle bin.
    let mut sum = vec![[0.0f64; 3]; ANGLE_BINS];
    let mut top = vec![f64::NEG_INFINITY; ANGLE_BINS];
    for (p, _) in mesh.positions.iter().zip(&used).filter(|(_, u)| **u) {
        let b = angle_bin(p);
        sum[b][0] += p[0] as f64;
        sum[b][1] += p[2] as f64;
        sum[b][2] += 1.0;
        top[b] = top[b].max(bite * p[1] as f64);
    }
    // Arc length along the arch: the bins' mean points, smoothed over ±3 bins so the
    // curve does not zigzag between buccal and lingual surfaces, then summed.
    let means: Vec<Option<[f64; 2]>> = sum
        .iter()
        .map(|m| (m[2] > 0.0).then(|| [m[0] / m[2], m[1] / m[2]]))
        .collect();
    let mut arc = vec![f64::NAN; ANGLE_BINS];
    let mut acc = 0.0;
    let mut prev: Option<[f64; 2]> = None;
    for b in 0..ANGLE_BINS {
        if means[b].is_none() {
            continue;
        }
        let near: Vec<[f64; 2]> = (b.saturating_sub(3)..(b + 4).min(ANGLE_BINS))
            .filter_map(|k| means[k])
            .collect();
        let n = near.len() as f64;
        let q = [
            near.iter().map(|p| p[0]).sum::<f64>() / n,
            near.iter().map(|p| p[1]).sum::<f64>() / n,
        ];
        if let Some(pq) = prev {
            acc += ((q[0] - pq[0]).powi(2) + (q[1] - pq[1]).powi(2)).sqrt();
        }
        arc[b] = acc;
        prev = Some(q);
    }
    let mid_bin = ANGLE_BINS / 2;
    let mid_arc = (mid_bin..ANGLE_BINS)
        .chain((0..mid_bin).rev())
        .map(|b| arc[b])
        .find(|a| a.is_finite())
        .unwrap_or(acc * 0.5);
    let left_len = mid_arc.max(1e-9);
    let right_len = (acc - mid_arc).max(1e-9);
    let s_of_bin = |b: usize| {
        let a = arc[b] - mid_arc;
        if a < 0.0 { a / left_len } else { a / right_len }
    };
    // A vertex is in the band when it is within band_mm of the most incisal point of its
    // neighbourhood (±2 bins, about a tooth's width at the front).
    let local_top = |b: usize| {
        (b.saturating_sub(2)..(b + 3).min(ANGLE_BINS))
            .map(|k| top[k])
            .fold(f64::NEG_INFINITY, f64::max)
    };
    let in_band: Vec<bool> = mesh
        .positions
        .iter()
        .zip(&used)
        .map(|(p, &u)| {
            if !u {
                return false;
            }
            let b = angle_bin(p);
            s_of_bin(b).abs() <= m.front_fraction && bite * p[1] as f64 >= local_top(b) - m.band_mm
        })
        .collect();
    mesh.boi = mesh
        .triangles
        .iter()
        .map(|t| t.iter().all(|&v| in_band[v as usize]))
        .collect();
    mesh.boi_face_count()
}
