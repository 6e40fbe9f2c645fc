//! Posselt's envelope and its unit-cube parameterisation (Zoss et al. 2018, Sec. 3.4, Fig. 4),
//! in the jaw frame (x to the subject's left, y up, z forward).
//!
//! The envelope is the volume the reference point's trajectory spans, described by its
//! extents: s_y runs from the top of the envelope (teeth closed, 0) to its bottom (wide
//! open, 1) through horizontal slices; in each slice s_x runs from the left limit (0) to the
//! right (1); at (s_y, s_x), s_z runs from the posterior limit (0) to the anterior one. The
//! limits are tabulated on a grid over (s_y, s_x) from the captured points (the extreme points
//! within each cell's neighbourhood; empty cells filled from their neighbours) and
//! interpolated bilinearly, so the map from the cube to the envelope and back is exact and
//! cheap. The surface of the cube maps to the surface of the envelope.

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use crate::mesh::Mesh;

#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct Shield {
    /// Top and bottom of the envelope (y, mm).
    pub y_top: f64,
    pub y_bottom: f64,
    /// Per row (s_y = i / (rows − 1)): the left (largest x) and right (smallest x) limits.
    pub left: Vec<f64>,
    pub right: Vec<f64>,
    /// Per row and column (s_x = j / (cols − 1)), row-major: posterior and anterior limits (z).
    pub back: Vec<f64>,
    pub front: Vec<f64>,
    pub rows: usize,
    pub cols: usize,
}

#[derive(Debug, Clone, thiserror::Error, PartialEq)]
pub enum ShieldError {
    #[error("the envelope needs at least {need} points, got {got}")]
    TooFewPoints { need: usize, got: usize },
    #[error("the reference point does not move up and down (its height varies by {0:.3} mm)")]
    Flat(f64),
}

/// Grid of the tabulated limits.
pub const ROWS: usize = 24;
pub const COLS: usize = 12;
/// A cell's neighbourhood, in cells, when collecting the extreme points.
const REACH: f64 = 1.5;
/// The thinnest the envelope may be in x or z (mm).
const MIN_WIDTH_MM: f64 = 0.05;

fn lerp(a: f64, b: f64, t: f64) -> f64 {
    a + (b - a) * t
}

/// Fill the `None`s of a sequence by linear interpolation (constant beyond the ends).
fn fill(values: &mut [Option<f64>]) {
    let known: Vec<usize> = (0..values.len()).filter(|&i| values[i].is_some()).collect();
    let (Some(&first), Some(&last)) = (known.first(), known.last()) else {
        return;
    };
    for i in 0..values.len() {
        if values[i].is_some() {
            continue;
        }
        values[i] = Some(if i < first {
            values[first].unwrap_or_default()
        } else if i > last {
            values[last].unwrap_or_default()
        } else {
            let a = known
                .iter()
                .rev()
                .find(|&&k| k < i)
                .copied()
                .unwrap_or(first);
            let b = known.iter().find(|&&k| k > i).copied().unwrap_or(last);
            let (va, vb) = (values[a].unwrap_or_default(), values[b].unwrap_or_default());
            lerp(va, vb, (i - a) as f64 / (b - a) as f64)
        });
    }
}

impl Shield {
    pub fn fit(points: &[Vector3<f64>]) -> Result<Shield, ShieldError> {
        const NEED: usize = 8;
        if points.len() < NEED {
            return Err(ShieldError::TooFewPoints {
                need: NEED,
                got: points.len(),
            });
        }
        let y_top = points.iter().map(|p| p.y).fold(f64::NEG_INFINITY, f64::max);
        let y_bottom = points.iter().map(|p| p.y).fold(f64::INFINITY, f64::min);
        if y_top - y_bottom < 1e-3 {
            return Err(ShieldError::Flat(y_top - y_bottom));
        }
        let dy = (y_top - y_bottom) / (ROWS - 1) as f64;
        let row_y = |i: usize| y_top - i as f64 * dy;
        let in_row = |p: &Vector3<f64>, i: usize| (p.y - row_y(i)).abs() <= REACH * dy;
        let mut left: Vec<Option<f64>> = vec![None; ROWS];
        let mut right: Vec<Option<f64>> = vec![None; ROWS];
        for i in 0..ROWS {
            for p in points.iter().filter(|p| in_row(p, i)) {
                left[i] = Some(left[i].map_or(p.x, |v: f64| v.max(p.x)));
                right[i] = Some(right[i].map_or(p.x, |v: f64| v.min(p.x)));
            }
        }
        fill(&mut left);
        fill(&mut right);
        let left: Vec<f64> = left.into_iter().map(Option::unwrap_or_default).collect();
        let mut right: Vec<f64> = right.into_iter().map(Option::unwrap_or_default).collect();
        for i in 0..ROWS {
            right[i] = right[i].min(left[i] - MIN_WIDTH_MM);
        }
        let mut back = vec![None; ROWS * COLS];
        let mut front = vec![None; ROWS * COLS];
        for i in 0..ROWS {
            let dx = (left[i] - right[i]) / (COLS - 1) as f64;
            for j in 0..COLS {
                let x = left[i] - j as f64 * dx;
                for p in points
                    .iter()
                    .filter(|p| in_row(p, i) && (p.x - x).abs() <= REACH * dx)
                {
                    let k = i * COLS + j;
                    back[k] = Some(back[k].map_or(p.z, |v: f64| v.min(p.z)));
                    front[k] = Some(front[k].map_or(p.z, |v: f64| v.max(p.z)));
                }
            }
        }
        // Empty cells: along the row, then along the column.
        for grid in [&mut back, &mut front] {
            for i in 0..ROWS {
                fill(&mut grid[i * COLS..(i + 1) * COLS]);
            }
            for j in 0..COLS {
                let mut col: Vec<Option<f64>> = (0..ROWS).map(|i| grid[i * COLS + j]).collect();
                fill(&mut col);
                for i in 0..ROWS {
                    grid[i * COLS + j] = col[i];
                }
            }
        }
        let back: Vec<f64> = back.into_iter().map(Option::unwrap_or_default).collect();
        let mut front: Vec<f64> = front.into_iter().map(Option::unwrap_or_default).collect();
        for k in 0..ROWS * COLS {
            front[k] = front[k].max(back[k] + MIN_WIDTH_MM);
        }
        Ok(Shield {
            y_top,
            y_bottom,
            left,
            right,
            back,
            front,
            rows: ROWS,
            cols: COLS,
        })
    }

    /// Row coordinate: index and fraction.
    fn row(&self, sy: f64) -> (usize, f64) {
        let t = sy.clamp(0.0, 1.0) * (self.rows - 1) as f64;
        let i = (t.floor() as usize).min(self.rows - 2);
        (i, t - i as f64)
    }

    fn limits_x(&self, sy: f64) -> (f64, f64) {
        let (i, f) = self.row(sy);
        (
            lerp(self.left[i], self.left[i + 1], f),
            lerp(self.right[i], self.right[i + 1], f),
        )
    }

    fn limits_z(&self, sy: f64, sx: f64) -> (f64, f64) {
        let (i, f) = self.row(sy);
        let t = sx.clamp(0.0, 1.0) * (self.cols - 1) as f64;
        let j = (t.floor() as usize).min(self.cols - 2);
        let g = t - j as f64;
        let at = |grid: &[f64]| {
            let a = lerp(grid[i * self.cols + j], grid[i * self.cols + j + 1], g);
            let b = lerp(
                grid[(i + 1) * self.cols + j],
                grid[(i + 1) * self.cols + j + 1],
                g,
            );
            lerp(a, b, f)
        };
        (at(&self.back), at(&self.front))
    }

    /// The point of the envelope at cube coordinates `s` (each clamped into [0, 1]).
    pub fn point(&self, s: &[f64; 3]) -> Vector3<f64> {
        let [sx, sy, sz] = s.map(|v| v.clamp(0.0, 1.0));
        let y = lerp(self.y_top, self.y_bottom, sy);
        let (l, r) = self.limits_x(sy);
        let x = lerp(l, r, sx);
        let (b, f) = self.limits_z(sy, sx);
        Vector3::new(x, y, lerp(b, f, sz))
    }

    /// The cube coordinates of a point, not clamped: inside the envelope they are all in [0, 1].
    pub fn cube(&self, p: &Vector3<f64>) -> [f64; 3] {
        let sy = (self.y_top - p.y) / (self.y_top - self.y_bottom);
        let (l, r) = self.limits_x(sy);
        let sx = (l - p.x) / (l - r);
        let (b, f) = self.limits_z(sy, sx);
        let sz = (p.z - b) / (f - b);
        [sx, sy, sz]
    }

    pub fn contains(&self, p: &Vector3<f64>) -> bool {
        self.cube(p)
            .iter()
            .all(|v| (-1e-9..=1.0 + 1e-9).contains(v))
    }

    /// A point moved into the envelope: its cube coordinates clamped (each limit pulls the
    /// point along its own axis: up/down, then left/right in the slice, then back/front).
    pub fn project(&self, p: &Vector3<f64>) -> Vector3<f64> {
        if self.contains(p) {
            return *p;
        }
        self.point(&self.cube(p))
    }

    /// The envelope's surface: the unit cube's six faces, `n` × `n` quads each, mapped into
    /// the envelope (jaw frame, mm). The bottom face collapses towards the lowest point.
    pub fn surface(&self, n: usize) -> Mesh {
        let n = n.max(1);
        let mut mesh = Mesh {
            positions: Vec::new(),
            triangles: Vec::new(),
            boi: Vec::new(),
        };
        // Each face: a fixed axis and value, and the two free axes (ordered for outward normals).
        let faces: [(usize, f64, usize, usize); 6] = [
            (0, 0.0, 2, 1),
            (0, 1.0, 1, 2),
            (1, 0.0, 0, 2),
            (1, 1.0, 2, 0),
            (2, 0.0, 1, 0),
            (2, 1.0, 0, 1),
        ];
        for (axis, value, u_axis, v_axis) in faces {
            let base = mesh.positions.len() as u32;
            for a in 0..=n {
                for b in 0..=n {
                    let mut s = [0.0; 3];
                    s[axis] = value;
                    s[u_axis] = a as f64 / n as f64;
                    s[v_axis] = b as f64 / n as f64;
                    let p = self.point(&s);
                    mesh.positions.push([p.x as f32, p.y as f32, p.z as f32]);
                }
            }
            let idx = |a: usize, b: usize| base + (a * (n + 1) + b) as u32;
            for a in 0..n {
                for b in 0..n {
                    mesh.triangles
                        .push([idx(a, b), idx(a + 1, b), idx(a + 1, b + 1)]);
                    mesh.triangles
                        .push([idx(a, b), idx(a + 1, b + 1), idx(a, b + 1)]);
                    mesh.boi.extend([false, false]);
                }
            }
        }
        mesh
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Points filling a shield-like solid: width and depth shrink towards the bottom.
    fn shield_points() -> Vec<Vector3<f64>> {
        let mut pts = Vec::new();
        for i in 0..=30 {
            for j in 0..=10 {
                for k in 0..=6 {
                    let t = i as f64 / 30.0; // 0 top .. 1 bottom
                    let half_width = 10.0 * (1.0 - 0.8 * t);
                    let x = -half_width + 2.0 * half_width * j as f64 / 10.0;
                    let back = -5.0 - 8.0 * t;
                    let depth = 8.0 * (1.0 - 0.7 * t);
                    pts.push(Vector3::new(x, -45.0 * t, back + depth * k as f64 / 6.0));
                }
            }
        }
        pts
    }

    #[test]
    fn cube_and_envelope_round_trip() {
        let shield = Shield::fit(&shield_points()).unwrap();
        for s in [
            [0.5, 0.5, 0.5],
            [0.0, 0.0, 0.0],
            [1.0, 0.3, 1.0],
            [0.2, 0.9, 0.7],
            [0.77, 0.13, 0.01],
        ] {
            let p = shield.point(&s);
            let back = shield.cube(&p);
            for k in 0..3 {
                assert!((back[k] - s[k]).abs() < 1e-9, "{s:?} -> {p:?} -> {back:?}");
            }
            assert!(shield.contains(&p));
        }
        // The top slice spans the top's width and depth.
        let (l, r) = shield.limits_x(0.0);
        assert!((l - 10.0).abs() < 0.5 && (r + 10.0).abs() < 0.5, "{l} {r}");
    }

    #[test]
    fn points_outside_are_projected_onto_the_surface() {
        let shield = Shield::fit(&shield_points()).unwrap();
        let outside = Vector3::new(30.0, -20.0, 40.0);
        assert!(!shield.contains(&outside));
        let p = shield.project(&outside);
        let s = shield.cube(&p);
        assert!(shield.contains(&p));
        // Pulled to the left limit and the anterior limit at that height.
        assert!(
            s[0].abs() < 1e-9 && (s[2] - 1.0).abs() < 1e-9 && (p.y + 20.0).abs() < 1e-9,
            "{s:?}"
        );
        let inside = shield.point(&[0.4, 0.4, 0.4]);
        assert_eq!(shield.project(&inside), inside);
    }

    #[test]
    fn the_surface_is_closed() {
        let shield = Shield::fit(&shield_points()).unwrap();
        let mesh = shield.surface(6);
        assert_eq!(mesh.triangles.len(), 6 * 6 * 6 * 2);
        // Closed once coincident corners are merged: every edge is shared by two triangles.
        let key = |v: u32| {
            let p = mesh.positions[v as usize];
            [
                (p[0] * 1e3).round() as i64,
                (p[1] * 1e3).round() as i64,
                (p[2] * 1e3).round() as i64,
            ]
        };
        let mut edges = std::collections::HashMap::new();
        for t in &mesh.triangles {
            for e in 0..3 {
                let (a, b) = (key(t[e]), key(t[(e + 1) % 3]));
                if a != b {
                    *edges
                        .entry(if a < b { (a, b) } else { (b, a) })
                        .or_insert(0) += 1;
                }
            }
        }
        assert!(
            edges.values().all(|&n| n == 2),
            "open edges: {}",
            edges.values().filter(|&&n| n != 2).count()
        );
    }

    #[test]
    fn too_few_or_flat_points_are_errors() {
        assert!(matches!(
            Shield::fit(&shield_points()[..3]),
            Err(ShieldError::TooFewPoints { .. })
        ));
        let flat: Vec<Vector3<f64>> = (0..20).map(|i| Vector3::new(i as f64, 1.0, 0.0)).collect();
        assert!(matches!(Shield::fit(&flat), Err(ShieldError::Flat(_))));
    }
}
