//! Back faces of closed meshes, which the CPU reference can leave out ([`Region::Relevant`]).
//!
//! A closed, consistently oriented mesh (every edge shared by exactly two faces that run it in
//! opposite directions) seen from outside covers each pixel centre with as many faces facing
//! the camera as facing away: projected to the image, the surface is a closed cycle, whose
//! degree is zero at every point off its edges. That holds for the rasterised picture too, as
//! long as facing is read from the *snapped* triangle's signed area and edges follow one fill
//! rule (the top-left rule gives an edge's pixel centres to both faces of a fold, or to
//! neither). So drawing only the faces towards the camera covers exactly the same pixels. What
//! a pixel shows (body or BOI; in front of the other arch or not) is the nearest face; along
//! a ray from outside the first face met always faces the camera, so only a depth near-tie at
//! a silhouette can differ. Open meshes (most raw scans) and meshes crossing the near plane are
//! drawn whole.
//!
//! [`Region::Relevant`]: super::Region::Relevant

use std::collections::HashMap;

use crate::mesh::Mesh;
use crate::mesh::signed_volume;

/// Which snapped signed area (see `raster`) marks a face turned away from the camera. With
/// image y pointing down and the camera looking along +z, a face whose normal (right-hand rule
/// over its vertex order) points away from the camera has a positive snapped area: `Positive`
/// for a closed mesh wound outwards ([`oriented_outwards`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AwaySign {
    Positive,
    Negative,
}

impl AwaySign {
    /// Whether a face of snapped signed area `area` (y down) faces away.
    #[inline]
    pub fn is_away(self, area: i64) -> bool {
        match self {
            AwaySign::Positive => area > 0,
            AwaySign::Negative => area < 0,
        }
    }
}

/// The mesh with its faces re-wound so that every part is turned outwards (its faces turned
/// away then have [`AwaySign::Positive`]), when that is possible: every edge shared by exactly
/// two faces and each part orientable. Winding changes no pixel the rasteriser draws (it reads
/// facing only to leave faces out), so a closed mesh written with some faces the wrong way
/// round (the procedural crowns' tip caps, or another program's export) can still have its
/// back faces left out. `None` for an open or non-manifold mesh, or a non-orientable one.
pub fn oriented_outwards(mesh: &Mesh) -> Option<Mesh> {
    // Faces on each undirected edge; a closed manifold has exactly two per edge.
    let mut on_edge: HashMap<(u32, u32), Vec<usize>> = HashMap::new();
    for (f, t) in mesh.triangles.iter().enumerate() {
        if t[0] == t[1] || t[1] == t[2] || t[2] == t[0] {
            return None;
        }
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            on_edge.entry((a.min(b), a.max(b))).or_default().push(f);
        }
    }
    if on_edge.values().any(|faces| faces.len() != 2) {
        return None;
    }
    // Does face f run the edge a→b (rather than b→a)?
    let runs = |t: &[u32; 3], a: u32, b: u32| (0..3).any(|k| t[k] == a && t[(k + 1) % 3] == b);
    // Breadth-first over each part: a neighbour must run the shared edge the other way.
    let mut triangles = mesh.triangles.clone();
    let mut seen = vec![false; triangles.len()];
    for start in 0..triangles.len() {
        if seen[start] {
            continue;
        }
        seen[start] = true;
        let mut part = vec![start];
        let mut next = 0;
        while next < part.len() {
            let f = part[next];
            next += 1;
            let t = triangles[f];
            for k in 0..3 {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                let g = on_edge[&(a.min(b), a.max(b))]
                    .iter()
                    .copied()
                    .find(|&g| g != f)?;
                let consistent = !runs(&triangles[g], a, b);
                if seen[g] {
                    if !consistent {
                        return None; // not orientable
                    }
                    continue;
                }
                if !consistent {
                    triangles[g].swap(1, 2);
                }
                seen[g] = true;
                part.push(g);
            }
        }
        let faces: Vec<[u32; 3]> = part.iter().map(|&f| triangles[f]).collect();
        let volume = signed_volume(&mesh.positions, &faces);
        if volume == 0.0 {
            return None; // no inside to turn away from
        }
        if volume < 0.0 {
            part.iter().for_each(|&f| triangles[f].swap(1, 2));
        }
    }
    Some(Mesh {
        positions: mesh.positions.clone(),
        triangles,
        boi: mesh.boi.clone(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The sign of a mesh's faces turned away, as it is wound: `Positive` when every part is
    /// already turned outwards (rewinding changes nothing), `Negative` when every part is
    /// inside out (rewinding turns every face), `None` for any other mesh (open, non-manifold,
    /// or with parts turned both ways: for an inside-out part, the first face a ray meets
    /// faces away).
    fn away_sign(mesh: &Mesh) -> Option<AwaySign> {
        // Rewinding leaves every face of a mesh that already qualifies as it is, or turns every
        // one of them (the same part order and start faces, each part flipped as a whole).
        let outwards = oriented_outwards(mesh)?;
        let turned = |t: &[u32; 3]| [t[0], t[2], t[1]];
        if outwards.triangles == mesh.triangles {
            Some(AwaySign::Positive)
        } else if (outwards.triangles.iter())
            .zip(&mesh.triangles)
            .all(|(o, t)| *o == turned(t))
        {
            Some(AwaySign::Negative)
        } else {
            None
        }
    }

    /// A unit cube, outward faces (right-hand rule).
    fn cube() -> Mesh {
        crate::mesh::cuboid([0.0; 3], [1.0; 3])
    }

    #[test]
    fn closed_meshes_get_a_sign_open_or_inconsistent_ones_none() {
        let mut m = cube();
        assert!((m.signed_volume() - 1.0).abs() < 1e-12);
        assert_eq!(away_sign(&m), Some(AwaySign::Positive));
        for t in &mut m.triangles {
            t.swap(1, 2);
        }
        assert_eq!(away_sign(&m), Some(AwaySign::Negative));
        let mut open = cube();
        open.triangles.pop();
        open.boi.pop();
        assert_eq!(away_sign(&open), None);
        let mut flipped_one = cube();
        flipped_one.triangles[0].swap(1, 2);
        assert_eq!(away_sign(&flipped_one), None);
        // Two cubes apart: both outwards, both inwards, or one of each.
        let two = |flip_second: bool| {
            let mut m = cube();
            let second = cube();
            m.positions
                .extend(second.positions.iter().map(|p| [p[0] + 3.0, p[1], p[2]]));
            m.triangles.extend(second.triangles.iter().map(|t| {
                let t = t.map(|v| v + 8);
                if flip_second { [t[0], t[2], t[1]] } else { t }
            }));
            m.boi.extend(second.boi);
            m
        };
        assert_eq!(away_sign(&two(false)), Some(AwaySign::Positive));
        assert_eq!(away_sign(&two(true)), None);
    }

    #[test]
    fn closed_meshes_are_rewound_outwards_open_ones_are_not() {
        // Some faces of one cube flipped, another cube inside out, apart.
        let mut m = cube();
        m.triangles[3].swap(1, 2);
        m.triangles[8].swap(0, 1);
        let second = cube();
        m.positions
            .extend(second.positions.iter().map(|p| [p[0] + 3.0, p[1], p[2]]));
        m.triangles.extend(
            second
                .triangles
                .iter()
                .map(|t| [t[0] + 8, t[2] + 8, t[1] + 8]),
        );
        m.boi.extend(second.boi);
        assert_eq!(away_sign(&m), None);
        let o = oriented_outwards(&m).unwrap();
        assert_eq!(away_sign(&o), Some(AwaySign::Positive));
        assert!((o.signed_volume() - 2.0).abs() < 1e-9);
        // The same faces, each with the same three vertices.
        for (a, b) in m.triangles.iter().zip(&o.triangles) {
            let (mut a, mut b) = (*a, *b);
            a.sort();
            b.sort();
            assert_eq!(a, b);
        }
        let mut open = cube();
        open.triangles.pop();
        open.boi.pop();
        assert!(oriented_outwards(&open).is_none());
    }

    #[test]
    fn leaving_out_the_faces_turned_away_draws_the_same_picture() {
        use crate::energy::raster::{self, CLASS_BODY, CLASS_BOI, Placed, Rect, Target};
        use crate::geometry::Pose;
        let cam = crate::energy::hand_counted::camera();
        // A 20 mm cube 100 mm away, turned so that three faces show; the face at the back
        // (z = 1 before scaling, faces 2 and 3) is BOI: hidden.
        let mut m = cube();
        m.positions
            .iter_mut()
            .for_each(|p| *p = p.map(|c| (c - 0.5) * 20.0));
        m.boi[2] = true;
        m.boi[3] = true;
        let pose = Pose::from_euler_tuple(&[0.4, 0.5, 0.1, 3.0, -2.0, 100.0]);
        let draw = |away: Option<AwaySign>| {
            let mut placed = Placed::default();
            placed.place(&cam, &m, &pose);
            placed.leave_out_faces_turned_away(away);
            let mut t = Target::default();
            t.reset(Rect::full(100, 80));
            raster::rasterise(&m, &placed, CLASS_BODY, CLASS_BOI, &mut t);
            t.class
        };
        let all = draw(None);
        let covered = all.iter().filter(|&&c| c != 0).count();
        assert!(covered > 300, "{covered}");
        assert!(!all.contains(&CLASS_BOI), "the back face is hidden");
        assert_eq!(draw(away_sign(&m)), all);
        // Leaving out the faces towards the camera instead covers the same pixels (each is
        // covered by as many faces each way) but shows the back, BOI included.
        let wrong = draw(Some(AwaySign::Negative));
        assert_eq!(wrong.iter().filter(|&&c| c != 0).count(), covered);
        assert!(wrong.contains(&CLASS_BOI));
    }
}
