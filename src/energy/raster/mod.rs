//! The CPU reference rasteriser, written to the Vulkan rasterisation rules so the GPU engine
//! can match it pixel for pixel: vertices snapped to 1/256 pixel (8 subpixel bits), samples at
//! pixel centres, integer edge functions with the top-left fill rule, triangles clipped at a
//! near plane, no face culling unless asked for (`Placed::leave_out_faces_turned_away`, for
//! closed meshes only: see `backfaces`), and a depth test on 1/z interpolated linearly in
//! screen space (what a perspective depth buffer orders by).
//!
//! Pixel convention: OpenCV's, the centre of pixel (x, y) is at (x, y); framebuffer
//! coordinates are those plus 0.5.

use super::backfaces::AwaySign;
use super::lens::{Lens, bounds_through};
use crate::geometry::{Camera, Pose};
use crate::mesh::Mesh;

pub const SUBPIXEL_BITS: u32 = 8;
const SUBPIXEL: f64 = (1 << SUBPIXEL_BITS) as f64;
const HALF_PIXEL: i64 = 1 << (SUBPIXEL_BITS - 1);
/// Geometry closer to the camera than this (mm) is clipped away.
pub const NEAR_MM: f64 = 1.0;
/// Vertices projecting further than this from the image (in pixels) are outside the guard
/// band; triangles touching them are dropped (never the case for teeth in view).
const GUARD_PIXELS: f64 = 1.0e6;

pub use super::target::{CLASS_BODY, CLASS_BOI, CLASS_NONE, Rect, Target};

/// A rigid transform as an f32 3 x 4 matrix (as a GPU would hold it).
#[derive(Debug, Clone, Copy, Default)]
struct Affine([[f32; 4]; 3]);

impl Affine {
    fn new(pose: &Pose) -> Self {
        let r = pose.rotation.matrix();
        let t = pose.translation;
        Affine(std::array::from_fn(|i| {
            [
                r[(i, 0)] as f32,
                r[(i, 1)] as f32,
                r[(i, 2)] as f32,
                t[i] as f32,
            ]
        }))
    }

    fn apply(&self, p: &[f32; 3]) -> [f32; 3] {
        let m = &self.0;
        std::array::from_fn(|i| m[i][0] * p[0] + m[i][1] * p[1] + m[i][2] * p[2] + m[i][3])
    }
}

/// A conservative pixel rectangle a set of camera-space points can touch (e.g. a bounding
/// box's corners), clamped to the image; the whole image if a point is behind the near plane
/// (or beyond the lens's limit). `lens`: [`Lens::of`] the camera.
pub fn footprint(cam: &Camera, lens: Option<&Lens>, points: &[[f32; 3]]) -> Rect {
    // Bounds in normalised coordinates first.
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for p in points {
        let z = p[2] as f64;
        if z < NEAR_MM {
            return Rect::full(cam.width, cam.height);
        }
        let n = [p[0] as f64 / z, p[1] as f64 / z];
        lo = [lo[0].min(n[0]), lo[1].min(n[1])];
        hi = [hi[0].max(n[0]), hi[1].max(n[1])];
    }
    if points.is_empty() {
        return Rect {
            x0: 0,
            y0: 0,
            width: 0,
            height: 0,
        };
    }
    // In pixels; through the lens, the rectangle's image with one more pixel for the f32
    // projection and the walk's steps.
    let (f, c) = ([cam.fx, cam.fy], [cam.cx, cam.cy]);
    let (lo, hi, slack) = match lens {
        None => (
            [0, 1].map(|k| f[k] * lo[k] + c[k]),
            [0, 1].map(|k| f[k] * hi[k] + c[k]),
            1.0,
        ),
        Some(lens) => match bounds_through(cam, lens, lo, hi) {
            Some((lo, hi)) => (lo, hi, 2.0),
            None => return Rect::full(cam.width, cam.height),
        },
    };
    // Pixel centres strictly inside the float bounds, plus one pixel for snapping.
    let x0 = (lo[0].floor() - slack).clamp(0.0, cam.width as f64) as u32;
    let y0 = (lo[1].floor() - slack).clamp(0.0, cam.height as f64) as u32;
    let x1 = (hi[0].ceil() + 1.0 + slack).clamp(0.0, cam.width as f64) as u32;
    let y1 = (hi[1].ceil() + 1.0 + slack).clamp(0.0, cam.height as f64) as u32;
    Rect {
        x0,
        y0,
        width: x1.saturating_sub(x0),
        height: y1.saturating_sub(y0),
    }
}

/// A mesh placed in front of a camera: its vertices in camera space and their snapped
/// framebuffer positions, each projected once.
#[derive(Debug, Clone, Default)]
pub struct Placed {
    camera_from_model: Affine,
    pub points: Vec<[f32; 3]>,
    /// `None` behind the near plane or outside the guard band.
    projected: Vec<Option<Snapped>>,
    /// Some vertex is behind the near plane (its triangles are clipped).
    crosses_near: bool,
    /// Faces of this sign are left out (see `backfaces`).
    away: Option<AwaySign>,
    /// The camera's projection (its lens included), as last placed.
    proj: Projector,
}

/// A vertex's snapped framebuffer position (1/256 pixel units; inside the guard band these
/// fit an i32) and 1/z.
type Snapped = (i32, i32, f32);

impl Placed {
    /// Transform and project every vertex of `mesh` (compact it first: see `Mesh::compacted`).
    /// Camera-space positions are f32, as a GPU would hold them.
    pub fn place(&mut self, cam: &Camera, mesh: &Mesh, camera_from_model: &Pose) {
        self.camera_from_model = Affine::new(camera_from_model);
        let m = self.camera_from_model;
        self.points.clear();
        self.points
            .extend(mesh.positions.iter().map(|p| m.apply(p)));
        self.proj = Projector::new(cam);
        let proj = &self.proj;
        self.projected.clear();
        self.crosses_near = false;
        self.away = None;
        for p in &self.points {
            if (p[2] as f64) < NEAR_MM {
                self.crosses_near = true;
                self.projected.push(None);
            } else {
                self.projected.push(proj.project(p));
            }
        }
    }

    /// Leave out the faces turned away from the camera, for a closed mesh (`sign`: see
    /// [`oriented_outwards`](super::backfaces::oriented_outwards)); not when the mesh crosses
    /// the near plane.
    pub fn leave_out_faces_turned_away(&mut self, sign: Option<AwaySign>) {
        self.away = sign.filter(|_| !self.crosses_near);
    }

    /// The pixels whose centres the placed mesh can cover, exactly (from the snapped
    /// positions); the whole image when part of it is behind the near plane.
    pub fn footprint(&self, cam: &Camera) -> Rect {
        self.footprint_of(cam, self.projected.iter().flatten())
    }

    /// A conservative pixel rectangle that a model-space box (its corners), placed as the
    /// mesh is, can touch (see [`footprint`]).
    pub fn footprint_of_box(&self, cam: &Camera, corners: &[[f32; 3]; 8]) -> Rect {
        let corners = corners.map(|p| self.camera_from_model.apply(&p));
        footprint(cam, self.proj.lens.as_ref(), &corners)
    }

    /// [`Placed::footprint`] of some of the vertices (`vertices`: indices into the mesh).
    pub fn footprint_of_vertices(&self, cam: &Camera, vertices: &[u32]) -> Rect {
        let projected = vertices
            .iter()
            .filter_map(|&i| self.projected[i as usize].as_ref());
        self.footprint_of(cam, projected)
    }

    fn footprint_of<'a>(&self, cam: &Camera, projected: impl Iterator<Item = &'a Snapped>) -> Rect {
        if self.crosses_near {
            return Rect::full(cam.width, cam.height);
        }
        let mut lo = (i64::MAX, i64::MAX);
        let mut hi = (i64::MIN, i64::MIN);
        for &(x, y, _) in projected {
            let (x, y) = (x as i64, y as i64);
            lo = (lo.0.min(x), lo.1.min(y));
            hi = (hi.0.max(x), hi.1.max(y));
        }
        if lo.0 > hi.0 {
            return Rect::full(0, 0);
        }
        let clamp = |v: i64, max: u32| v.clamp(0, max as i64) as u32;
        let (x0, y0) = (
            clamp(ceil_div(lo.0 - HALF_PIXEL), cam.width),
            clamp(ceil_div(lo.1 - HALF_PIXEL), cam.height),
        );
        let (x1, y1) = (
            clamp(floor_div(hi.0 - HALF_PIXEL) + 1, cam.width),
            clamp(floor_div(hi.1 - HALF_PIXEL) + 1, cam.height),
        );
        Rect {
            x0,
            y0,
            width: x1.saturating_sub(x0),
            height: y1.saturating_sub(y0),
        }
    }
}

/// n / 256 rounded down (an arithmetic shift floors).
fn floor_div(n: i64) -> i64 {
    n >> SUBPIXEL_BITS
}

/// n / 256 rounded up.
fn ceil_div(n: i64) -> i64 {
    -((-n) >> SUBPIXEL_BITS)
}

/// Rasterise a placed mesh into `target` (through the camera it was placed for). Faces get
/// `class_body`, or `class_boi` where the mesh marks them as boundary of interest.
pub fn rasterise(mesh: &Mesh, placed: &Placed, class_body: u8, class_boi: u8, target: &mut Target) {
    let faces = 0..mesh.triangles.len();
    rasterise_body_where(mesh, faces, placed, [class_body, class_boi], target, |_| {
        true
    });
}

/// [`rasterise`] for some of the faces, skipping the body faces whose pixel bounds `keep`
/// turns down (BOI faces and faces clipped at the near plane are always drawn). `classes`:
/// body, BOI.
pub fn rasterise_body_where(
    mesh: &Mesh,
    faces: std::ops::Range<usize>,
    placed: &Placed,
    [class_body, class_boi]: [u8; 2],
    target: &mut Target,
    keep: impl Fn(&Bounds) -> bool,
) {
    let Some(rect) = target.rect else { return };
    if rect.area() == 0 {
        return;
    }
    for (tri, &is_boi) in mesh.triangles[faces.clone()].iter().zip(&mesh.boi[faces]) {
        let class = if is_boi { class_boi } else { class_body };
        let s = tri.map(|i| placed.projected[i as usize]);
        if let [Some(a), Some(b), Some(c)] = s {
            let v = [a, b, c];
            // Facing first (about half the faces of a closed mesh), then the pixels.
            let area = signed_area(&v);
            if area == 0 || placed.away.is_some_and(|s| s.is_away(area)) {
                continue;
            }
            if let Some(bounds) = Bounds::of(&v, rect)
                && (is_boi || keep(&bounds))
            {
                raster_triangle(v, area, bounds, class, rect, target);
            }
            continue;
        }
        if !placed.crosses_near {
            continue; // outside the guard band
        }
        let v = tri.map(|i| placed.points[i as usize]);
        let behind = v.iter().filter(|p| (p[2] as f64) < NEAR_MM).count();
        if behind == 3 {
            continue;
        }
        let poly: Vec<Snapped> = clip_near(&v)
            .iter()
            .filter_map(|p| placed.proj.project(p))
            .collect();
        for k in 1..poly.len().saturating_sub(1) {
            let v = [poly[0], poly[k], poly[k + 1]];
            if let Some(bounds) = Bounds::of(&v, rect) {
                raster_triangle(v, signed_area(&v), bounds, class, rect, target);
            }
        }
    }
}

/// Sutherland-Hodgman clip of a triangle against z >= NEAR_MM.
fn clip_near(v: &[[f32; 3]; 3]) -> Vec<[f32; 3]> {
    let near = NEAR_MM as f32;
    let mut out = Vec::with_capacity(4);
    for i in 0..3 {
        let (a, b) = (v[i], v[(i + 1) % 3]);
        let (ina, inb) = (a[2] >= near, b[2] >= near);
        if ina {
            out.push(a);
        }
        if ina != inb {
            let s = (near - a[2]) / (b[2] - a[2]);
            out.push([a[0] + s * (b[0] - a[0]), a[1] + s * (b[1] - a[1]), near]);
        }
    }
    out
}

/// Projection to snapped framebuffer positions, in f32 and in the same order of operations
/// as the GPU twin's vertex shader (shaders/raster.wgsl), so both snap alike; through the
/// camera's lens when it has one (see [`lens`](super::lens)).
#[derive(Debug, Clone, Default)]
struct Projector {
    focal: [f32; 2],
    centre: [f32; 2],
    lens: Option<Lens>,
}

impl Projector {
    fn new(cam: &Camera) -> Self {
        Projector {
            focal: [cam.fx as f32, cam.fy as f32],
            centre: [(cam.cx + 0.5) as f32, (cam.cy + 0.5) as f32],
            lens: Lens::of(cam),
        }
    }

    /// Snapped framebuffer position (1/256 pixel units) and 1/z; `None` outside the guard band
    /// (or beyond the lens's limit).
    fn project(&self, p: &[f32; 3]) -> Option<Snapped> {
        let z = p[2];
        let fb = match &self.lens {
            None => [0, 1].map(|k| self.focal[k] * p[k] / z + self.centre[k]),
            Some(lens) => {
                let d = lens.apply(p[0] / z, p[1] / z)?;
                [0, 1].map(|k| self.focal[k] * d[k] + self.centre[k])
            }
        };
        if fb.iter().any(|c| c.abs() > GUARD_PIXELS as f32) {
            return None;
        }
        // floor(x + 0.5), as the shader snaps.
        let snap = |c: f32| floor_i32(c * SUBPIXEL as f32 + 0.5);
        Some((snap(fb[0]), snap(fb[1]), 1.0 / z))
    }
}

/// `x.floor() as i32` for |x| < 2^31, without `f32::floor`, a libm call on baseline x86-64
/// (one per projected coordinate). Truncation rounds towards zero, so a negative x with a
/// fraction comes out one too high; an f32 of 2^24 or more has no fraction, so converting the
/// truncation back is exact wherever the comparison matters.
fn floor_i32(x: f32) -> i32 {
    let t = x as i32;
    t - ((t as f32) > x) as i32
}

/// Top-left rule for y down: an edge a→b of a triangle with positive area (interior where
/// the edge function is positive) is a top edge if horizontal pointing +x, a left edge if
/// pointing up (−y).
fn is_top_left(dx: i64, dy: i64) -> bool {
    (dy == 0 && dx > 0) || dy < 0
}

/// The pixels whose centres lie within a triangle's snapped bounds, within a target:
/// `x0..=x1` by `y0..=y1`, in image pixels.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Bounds {
    pub x0: i64,
    pub x1: i64,
    pub y0: i64,
    pub y1: i64,
}

impl Bounds {
    /// `None` when no pixel centre of `rect` lies within the bounds: most of a scan's
    /// triangles are smaller than a pixel and end here.
    fn of(v: &[Snapped; 3], rect: Rect) -> Option<Bounds> {
        let xs = v.map(|p| p.0 as i64);
        let ys = v.map(|p| p.1 as i64);
        let min = |c: [i64; 3]| c[0].min(c[1]).min(c[2]);
        let max = |c: [i64; 3]| c[0].max(c[1]).max(c[2]);
        let b = Bounds {
            x0: ceil_div(min(xs) - HALF_PIXEL).max(rect.x0 as i64),
            x1: floor_div(max(xs) - HALF_PIXEL).min((rect.x0 + rect.width) as i64 - 1),
            y0: ceil_div(min(ys) - HALF_PIXEL).max(rect.y0 as i64),
            y1: floor_div(max(ys) - HALF_PIXEL).min((rect.y0 + rect.height) as i64 - 1),
        };
        (b.x0 <= b.x1 && b.y0 <= b.y1).then_some(b)
    }

    /// The pixels of a rectangle (`None` when it is empty).
    pub fn of_rect(r: &Rect) -> Option<Bounds> {
        (r.area() > 0).then(|| Bounds {
            x0: r.x0 as i64,
            x1: (r.x0 + r.width) as i64 - 1,
            y0: r.y0 as i64,
            y1: (r.y0 + r.height) as i64 - 1,
        })
    }
}

/// Twice the signed area of a snapped triangle (1/256-pixel units squared; y down).
fn signed_area(v: &[Snapped; 3]) -> i64 {
    let [a, b, c] = v.map(|(x, y, _)| (x as i64, y as i64));
    (b.0 - a.0) * (c.1 - a.1) - (b.1 - a.1) * (c.0 - a.0)
}

/// Draw a triangle of signed area `area` ([`signed_area`]) within its pixel bounds.
fn raster_triangle(
    v: [Snapped; 3],
    mut area: i64,
    bounds: Bounds,
    class: u8,
    rect: Rect,
    target: &mut Target,
) {
    let [mut a, mut b, c] = v.map(|(x, y, inv_z)| (x as i64, y as i64, inv_z));
    let Bounds {
        x0: px0,
        x1: px1,
        y0: py0,
        y1: py1,
    } = bounds;
    if area == 0 {
        return;
    }
    if area < 0 {
        std::mem::swap(&mut a, &mut b);
        area = -area;
    }
    // Edge e_k is opposite vertex k: e0 = b→c, e1 = c→a, e2 = a→b.
    let edges = [(b, c), (c, a), (a, b)];
    let bias: [i64; 3] = edges.map(|(p, q)| {
        if is_top_left(q.0 - p.0, q.1 - p.1) {
            0
        } else {
            -1
        }
    });
    let sx0 = px0 * (1 << SUBPIXEL_BITS) + HALF_PIXEL;
    let sy0 = py0 * (1 << SUBPIXEL_BITS) + HALF_PIXEL;
    let edge_at = |(p, q): ((i64, i64, f32), (i64, i64, f32)), x: i64, y: i64| {
        (q.0 - p.0) * (y - p.1) - (q.1 - p.1) * (x - p.0)
    };
    let mut row = edges.map(|e| edge_at(e, sx0, sy0));
    let step_x = edges.map(|(p, q)| -(q.1 - p.1) << SUBPIXEL_BITS);
    let step_y = edges.map(|(p, q)| (q.0 - p.0) << SUBPIXEL_BITS);
    let inv_area = 1.0 / area as f32;
    let iz = [a.2, b.2, c.2];
    let width = rect.width as usize;
    for py in py0..=py1 {
        let mut w = row;
        let base = (py - rect.y0 as i64) as usize * width;
        for px in px0..=px1 {
            if w[0] + bias[0] >= 0 && w[1] + bias[1] >= 0 && w[2] + bias[2] >= 0 {
                let inv_z =
                    (w[0] as f32 * iz[0] + w[1] as f32 * iz[1] + w[2] as f32 * iz[2]) * inv_area;
                let i = base + (px - rect.x0 as i64) as usize;
                if inv_z > target.inv_depth[i] {
                    target.inv_depth[i] = inv_z;
                    target.class[i] = class;
                }
            }
            for k in 0..3 {
                w[k] += step_x[k];
            }
        }
        for k in 0..3 {
            row[k] += step_y[k];
        }
    }
}

/// A label image over the whole image: each mesh drawn at its pose with its labels (body,
/// boundary of interest), depth-tested: what a perfect segmentation of those meshes shows.
pub fn render_labels(cam: &Camera, items: &[(&Mesh, &Pose, u8, u8)]) -> Vec<u8> {
    render_target(cam, items).class
}

/// [`render_labels`] with the depth buffer (1/z per pixel, 0 where nothing was drawn), for
/// pictures that shade the surfaces.
pub fn render_target(cam: &Camera, items: &[(&Mesh, &Pose, u8, u8)]) -> Target {
    let mut placed = Placed::default();
    let mut target = Target::default();
    target.reset(Rect::full(cam.width, cam.height));
    for (mesh, world_from_model, body, boi) in items {
        placed.place(cam, mesh, &cam.camera_from_world.compose(world_from_model));
        rasterise(mesh, &placed, *body, *boi, &mut target);
    }
    target
}

/// [`render_target`] over only the pixels the meshes can cover (their footprints' union), for
/// readers that take the target's rectangle into account: clearing and walking the whole image
/// for a model a tenth of its size costs more than drawing the model.
pub fn render_target_fitted(cam: &Camera, items: &[(&Mesh, &Pose, u8, u8)]) -> Target {
    let placed: Vec<Placed> = items
        .iter()
        .map(|(mesh, world_from_model, ..)| {
            let mut placed = Placed::default();
            placed.place(cam, mesh, &cam.camera_from_world.compose(world_from_model));
            placed
        })
        .collect();
    let rect = placed
        .iter()
        .map(|p| p.footprint(cam))
        .fold(Rect::full(0, 0), |all, r| all.union(&r));
    let mut target = Target::default();
    target.reset(rect);
    for ((mesh, _, body, boi), placed) in items.iter().zip(&placed) {
        rasterise(mesh, placed, *body, *boi, &mut target);
    }
    target
}

#[cfg(test)]
mod tests;
