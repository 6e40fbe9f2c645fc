//! Valid parameter ranges (the paper's Fig. 7): the alpha shape of the training parameters
//! projected on the (d1, d2) and (d1, d3) planes. For a given d1, the valid d2 are where the
//! line x = d1 crosses the (d1, d2) shape; likewise d3.
//!
//! The alpha shape: the Delaunay triangles of the points (spade) whose circumradius is at most
//! α (the paper's "alpha radius", 0.12 in its parameter units), and the boundary of their union.

use std::collections::HashMap;

use rand::RngExt;
use serde::{Deserialize, Serialize};
use spade::{DelaunayTriangulation, Point2, Triangulation};

#[derive(Debug, Clone, Default, Serialize, Deserialize, PartialEq)]
pub struct AlphaShape {
    pub alpha: f64,
    /// Boundary edges of the union of kept triangles.
    pub edges: Vec<[[f64; 2]; 2]>,
    /// Delaunay edges no longer than 2α that belong to no kept triangle (the alpha complex's
    /// one-dimensional part): where the data are a single path, such as wide opening with no
    /// sideways motion, the valid range is a band of half-width `band` around it.
    #[serde(default)]
    pub paths: Vec<[[f64; 2]; 2]>,
    #[serde(default)]
    pub band: f64,
    /// The x extent of the shape.
    pub x_range: [f64; 2],
}

#[derive(Debug, Clone, thiserror::Error, PartialEq)]
pub enum RangeError {
    #[error(
        "the alpha shape is empty: no Delaunay triangle of the {points} points has a circumradius below alpha = {alpha}; use a larger alpha"
    )]
    Empty { points: usize, alpha: f64 },
    #[error("a parameter value is not a finite number")]
    NotFinite,
}

fn circumradius(p: [Point2<f64>; 3]) -> f64 {
    let (a, b, c) = (p[0], p[1], p[2]);
    let ab = ((a.x - b.x).powi(2) + (a.y - b.y).powi(2)).sqrt();
    let bc = ((b.x - c.x).powi(2) + (b.y - c.y).powi(2)).sqrt();
    let ca = ((c.x - a.x).powi(2) + (c.y - a.y).powi(2)).sqrt();
    let area2 = ((b.x - a.x) * (c.y - a.y) - (b.y - a.y) * (c.x - a.x)).abs();
    if area2 <= 0.0 {
        f64::INFINITY
    } else {
        ab * bc * ca / (2.0 * area2)
    }
}

impl AlphaShape {
    pub fn build(points: &[[f64; 2]], alpha: f64) -> Result<AlphaShape, RangeError> {
        let mut tri = DelaunayTriangulation::<Point2<f64>>::new();
        for p in points {
            if !(p[0].is_finite() && p[1].is_finite()) {
                return Err(RangeError::NotFinite);
            }
            // Points closer than spade's precision to an existing one merge with it: harmless.
            let _ = tri.insert(Point2::new(p[0], p[1]));
        }
        // Per Delaunay edge (vertex pair): how many kept triangles use it, and its ends.
        type Uses = (u32, [[f64; 2]; 2]);
        let mut count: HashMap<(usize, usize), Uses> = HashMap::new();
        let mut x_range = [f64::INFINITY, f64::NEG_INFINITY];
        let mut in_triangle = std::collections::HashSet::new();
        for face in tri.inner_faces() {
            let pos = face.positions();
            if circumradius(pos) > alpha {
                continue;
            }
            let v = face.vertices().map(|h| h.fix().index());
            for k in 0..3 {
                let (i, j) = (v[k], v[(k + 1) % 3]);
                let key = (i.min(j), i.max(j));
                let (a, b) = (pos[k], pos[(k + 1) % 3]);
                count.entry(key).or_insert((0, [[a.x, a.y], [b.x, b.y]])).0 += 1;
                in_triangle.insert(key);
                x_range = [x_range[0].min(a.x), x_range[1].max(a.x)];
            }
        }
        let mut paths = Vec::new();
        for edge in tri.undirected_edges() {
            let [a, b] = edge.positions();
            let v = edge.vertices().map(|h| h.fix().index());
            let key = (v[0].min(v[1]), v[0].max(v[1]));
            let length = ((a.x - b.x).powi(2) + (a.y - b.y).powi(2)).sqrt();
            if length <= 2.0 * alpha && !in_triangle.contains(&key) {
                paths.push([[a.x, a.y], [b.x, b.y]]);
                x_range = [x_range[0].min(a.x.min(b.x)), x_range[1].max(a.x.max(b.x))];
            }
        }
        if count.is_empty() && paths.is_empty() {
            return Err(RangeError::Empty {
                points: points.len(),
                alpha,
            });
        }
        let mut edges: Vec<_> = count
            .into_values()
            .filter(|(n, _)| *n == 1)
            .map(|(_, e)| e)
            .collect();
        // A reproducible file: segments in a fixed order.
        sort_segments(&mut edges);
        sort_segments(&mut paths);
        Ok(AlphaShape {
            alpha,
            edges,
            paths,
            band: alpha * PATH_BAND,
            x_range,
        })
    }

    /// The y intervals where the vertical line at `x` is inside the shape, bottom to top.
    pub fn intervals(&self, x: f64) -> Vec<[f64; 2]> {
        let mut ys: Vec<f64> = self
            .edges
            .iter()
            .filter(|[a, b]| (a[0] <= x) != (b[0] <= x))
            .map(|[a, b]| a[1] + (x - a[0]) * (b[1] - a[1]) / (b[0] - a[0]))
            .collect();
        ys.sort_by(f64::total_cmp);
        let mut out: Vec<[f64; 2]> = ys.chunks_exact(2).map(|p| [p[0], p[1]]).collect();
        for [a, b] in &self.paths {
            let (lo, hi) = (a[0].min(b[0]), a[0].max(b[0]));
            if x < lo || x > hi {
                continue;
            }
            let y = if hi > lo {
                a[1] + (x - a[0]) * (b[1] - a[1]) / (b[0] - a[0])
            } else {
                a[1]
            };
            let (ylo, yhi) = if hi > lo {
                (y, y)
            } else {
                (a[1].min(b[1]), a[1].max(b[1]))
            };
            out.push([ylo - self.band, yhi + self.band]);
        }
        // Merge overlaps: bands may touch each other or the triangles' intervals.
        out.sort_by(|p, q| p[0].total_cmp(&q[0]));
        let mut merged: Vec<[f64; 2]> = Vec::with_capacity(out.len());
        for iv in out {
            match merged.last_mut() {
                Some(last) if iv[0] <= last[1] => last[1] = last[1].max(iv[1]),
                _ => merged.push(iv),
            }
        }
        merged
    }

    pub fn contains(&self, p: [f64; 2]) -> bool {
        self.intervals(p[0])
            .iter()
            .any(|[lo, hi]| (*lo..=*hi).contains(&p[1]))
    }
}

fn sort_segments(segments: &mut [[[f64; 2]; 2]]) {
    segments.sort_by(|a, b| {
        a.iter()
            .flatten()
            .zip(b.iter().flatten())
            .map(|(p, q)| p.total_cmp(q))
            .find(|o| o.is_ne())
            .unwrap_or(std::cmp::Ordering::Equal)
    });
}

/// Half-width of the band around one-dimensional parts, as a share of alpha.
const PATH_BAND: f64 = 0.1;

/// The nearest value to `y` in a union of intervals (or `y` when there are none).
fn nearest_in(intervals: &[[f64; 2]], y: f64) -> f64 {
    intervals
        .iter()
        .filter(|[lo, hi]| lo <= hi)
        .map(|[lo, hi]| y.max(*lo).min(*hi))
        .min_by(|a, b| (a - y).abs().total_cmp(&(b - y).abs()))
        .unwrap_or(y)
}

/// A uniform draw from a union of intervals.
fn draw_in(intervals: &[[f64; 2]], rng: &mut impl rand::Rng) -> Option<f64> {
    let total: f64 = intervals.iter().map(|[lo, hi]| hi - lo).sum();
    if intervals.is_empty() {
        return None;
    }
    let mut u = rng.random_range(0.0..=total.max(0.0));
    for [lo, hi] in intervals {
        if u <= hi - lo {
            return Some(lo + u);
        }
        u -= hi - lo;
    }
    intervals.last().map(|i| i[1])
}

/// The rig's valid parameters: d1-dependent ranges of d2 and d3, and the plain per-parameter
/// bounds of the training data (the "without dynamic ranges" of the paper's Fig. 13).
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct Ranges {
    /// (d1, d2): opening against lateral excursion.
    pub lateral: AlphaShape,
    /// (d1, d3): opening against protrusion.
    pub protrusion: AlphaShape,
    /// Smallest and largest value of each parameter over the training data.
    pub bounds: [[f64; 2]; 3],
}

/// Steps of the scan for the nearest covered d1 when a shape has a gap.
const D1_SCAN: usize = 512;

impl Ranges {
    pub fn build(params: &[[f64; 3]], alpha: f64) -> Result<Ranges, RangeError> {
        let plane = |k: usize| params.iter().map(|d| [d[0], d[k]]).collect::<Vec<_>>();
        let mut bounds = [[f64::INFINITY, f64::NEG_INFINITY]; 3];
        for d in params {
            for k in 0..3 {
                bounds[k] = [bounds[k][0].min(d[k]), bounds[k][1].max(d[k])];
            }
        }
        Ok(Ranges {
            lateral: AlphaShape::build(&plane(1), alpha)?,
            protrusion: AlphaShape::build(&plane(2), alpha)?,
            bounds,
        })
    }

    /// The d1 extent both shapes cover.
    pub fn d1_range(&self) -> [f64; 2] {
        [
            self.lateral.x_range[0].max(self.protrusion.x_range[0]),
            self.lateral.x_range[1].min(self.protrusion.x_range[1]),
        ]
    }

    /// Valid d2 and d3 intervals at `d1`.
    pub fn at(&self, d1: f64) -> (Vec<[f64; 2]>, Vec<[f64; 2]>) {
        (self.lateral.intervals(d1), self.protrusion.intervals(d1))
    }

    pub fn is_valid(&self, d: &[f64; 3]) -> bool {
        self.lateral.contains([d[0], d[1]]) && self.protrusion.contains([d[0], d[2]])
    }

    /// The nearest valid parameters: d1 into the covered range (the nearest d1 where both
    /// shapes have an interval, if they have gaps), then d2 and d3 into their ranges there.
    pub fn clamp(&self, d: &[f64; 3]) -> [f64; 3] {
        if self.is_valid(d) {
            return *d;
        }
        // A parameter that is not a number is taken as 0 (the rest of a centred rig), so the
        // answer is always a valid, finite vector.
        let d = &d.map(|v| if v.is_nan() { 0.0 } else { v });
        let [lo, hi] = self.d1_range();
        let covered = |x: f64| {
            let (a, b) = self.at(x);
            !a.is_empty() && !b.is_empty()
        };
        let mut d1 = d[0].max(lo).min(hi);
        if !covered(d1) {
            d1 = (0..=D1_SCAN)
                .map(|i| lo + (hi - lo) * (i as f64 + 0.5) / (D1_SCAN as f64 + 1.0))
                .filter(|&x| covered(x))
                .min_by(|a, b| (a - d[0]).abs().total_cmp(&(b - d[0]).abs()))
                .unwrap_or(d1);
        }
        let (i2, i3) = self.at(d1);
        [d1, nearest_in(&i2, d[1]), nearest_in(&i3, d[2])]
    }

    /// A random valid parameter vector: d1 uniform over its range, then d2 and d3 uniform over
    /// their ranges at that d1.
    pub fn sample_dynamic(&self, rng: &mut impl rand::Rng) -> [f64; 3] {
        let [lo, hi] = self.d1_range();
        for _ in 0..1000 {
            let d1 = rng.random_range(lo..=hi);
            let (i2, i3) = self.at(d1);
            if let (Some(d2), Some(d3)) = (draw_in(&i2, rng), draw_in(&i3, rng)) {
                return [d1, d2, d3];
            }
        }
        self.clamp(&[(lo + hi) * 0.5, 0.0, 0.0])
    }

    /// A random parameter vector with each parameter uniform over its own bounds.
    pub fn sample_static(&self, rng: &mut impl rand::Rng) -> [f64; 3] {
        std::array::from_fn(|k| {
            let [lo, hi] = self.bounds[k];
            if hi > lo {
                rng.random_range(lo..=hi)
            } else {
                lo
            }
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    /// A filled square grid with a square hole in the middle.
    fn square_with_hole() -> Vec<[f64; 2]> {
        let mut pts = Vec::new();
        for i in 0..=20 {
            for j in 0..=20 {
                let (x, y) = (i as f64 * 0.05, j as f64 * 0.05);
                if !((0.35..=0.65).contains(&x) && (0.35..=0.65).contains(&y)) {
                    pts.push([x, y]);
                }
            }
        }
        pts
    }

    #[test]
    fn alpha_shape_keeps_the_hole_and_the_outline() {
        let s = AlphaShape::build(&square_with_hole(), 0.06).unwrap();
        assert_eq!(s.x_range, [0.0, 1.0]);
        assert!(s.contains([0.1, 0.1]) && s.contains([0.5, 0.9]));
        assert!(!s.contains([0.5, 0.5]), "the hole is outside");
        assert!(!s.contains([1.2, 0.5]) && !s.contains([0.5, -0.1]));
        let iv = s.intervals(0.5);
        assert_eq!(iv.len(), 2, "{iv:?}");
        assert!((iv[0][0] - 0.0).abs() < 1e-9 && (iv[0][1] - 0.3).abs() < 1e-9);
        assert!((iv[1][0] - 0.7).abs() < 1e-9 && (iv[1][1] - 1.0).abs() < 1e-9);
        // A single path (no triangles) is valid in a band around it.
        let line: Vec<[f64; 2]> = (0..20)
            .map(|i| [i as f64 * 0.05, 0.5 * i as f64 * 0.05])
            .collect();
        let band = AlphaShape::build(&line, 0.06).unwrap();
        assert!(band.edges.is_empty() && band.paths.len() == 19);
        assert!(band.contains([0.3, 0.15 + 0.005]) && !band.contains([0.3, 0.15 + 0.01]));
        // A large alpha fills the hole: the convex hull.
        assert!(
            AlphaShape::build(&square_with_hole(), 10.0)
                .unwrap()
                .contains([0.5, 0.5])
        );
        assert!(matches!(
            AlphaShape::build(&square_with_hole(), 0.001),
            Err(RangeError::Empty { .. })
        ));
    }

    #[test]
    fn clamping_moves_to_the_nearest_valid_value() {
        let pts: Vec<[f64; 3]> = square_with_hole()
            .iter()
            .map(|p| [p[0], p[1], p[1] * 0.5])
            .collect();
        let r = Ranges::build(&pts, 0.06).unwrap();
        assert!(r.is_valid(&[0.2, 0.2, 0.1]));
        let c = r.clamp(&[0.5, 0.45, 0.2]);
        assert!((c[1] - 0.3).abs() < 1e-9 && r.is_valid(&c), "{c:?}");
        let c = r.clamp(&[1.5, 2.0, -1.0]);
        // The corner (the edge x = 1 itself counts as outside: d1 lands just inside it).
        assert!(
            (c[0] - 1.0).abs() < 2e-3 && (c[1] - 1.0).abs() < 1e-9 && c[2].abs() < 1e-9,
            "{c:?}"
        );
        assert!(r.is_valid(&c));
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
        for _ in 0..200 {
            let d = r.sample_dynamic(&mut rng);
            assert!(r.is_valid(&d) || r.clamp(&d) == d, "{d:?}");
        }
    }
}
