//! The silhouette contour of a posed mesh seen by a camera (through its lens, as the
//! rasteriser projects): the edges where the surface folds away from the camera or ends, sampled
//! along their projection, each sample with its outward normal in the image, the length of
//! contour it stands for and the Jacobian of its pixel position under a change of the pose.
//!
//! This is what a derivative of the energy is made of. A pixel count under the silhouette
//! (the mask pixels a model covers) changes, as the pose moves by ξ, by the contour integral
//! of what lies under the contour against its outward motion, ∮ f(x)·⟨J(x)·ξ, n(x)⟩ ds; the
//! points here are that integral's quadrature. Region-based trackers take their Gauss-Newton
//! steps from the same points.

use std::collections::HashMap;

use nalgebra::{Matrix2x3, Matrix2x6, Matrix3x6, Vector2, Vector3};

use super::target::Target;
use crate::geometry::{Camera, Pose, hat};
use crate::mesh::Mesh;

/// Points nearer the camera than this (mm) are not projected.
const NEAR_MM: f64 = 1e-3;

/// An edge of the mesh and the third vertex of each face on it (one face: an open edge).
#[derive(Debug, Clone, Copy)]
struct Edge {
    ends: [u32; 2],
    opposite: [u32; 2],
    face: [u32; 2],
    faces: u8,
}

/// The mesh's edges with their faces, found once per mesh; edges of three or more faces (a
/// non-manifold scan) are left out. Their vertices are numbered among the vertices the faces
/// use: a simplified scan keeps every vertex of its file (for its numbering), most of them
/// unused, and the contour places only the used ones.
#[derive(Debug, Clone)]
pub struct ContourEdges {
    edges: Vec<Edge>,
    /// The mesh's vertex of each number the edges use, in the mesh's order.
    vertices: Vec<u32>,
    /// The mesh without its unused vertices, to draw (the same faces in the same order).
    drawn: Mesh,
}

/// One sample of the silhouette contour.
#[derive(Debug, Clone, Copy)]
pub struct ContourPoint {
    /// Pixel position (pixel centres at integers, as the camera's `cx`, `cy` are given).
    pub pixel: Vector2<f64>,
    /// Unit normal in the image, pointing out of the silhouette.
    pub normal: Vector2<f64>,
    /// The length of contour (pixels) the sample stands for.
    pub length: f64,
    /// 1/z of the surface point (mm⁻¹), the depth buffer's unit.
    pub inv_depth: f64,
    /// ∂pixel/∂ξ for the pose `world_from_model ← exp(ξ)·world_from_model`, ξ = [ω; v] in the
    /// world frame (rad, mm).
    pub jacobian: Matrix2x6<f64>,
}

impl ContourEdges {
    pub fn of(mesh: &Mesh) -> ContourEdges {
        let mut on_edge: HashMap<(u32, u32), Edge> = HashMap::new();
        for (f, t) in mesh.triangles.iter().enumerate() {
            for k in 0..3 {
                let (a, b, c) = (t[k], t[(k + 1) % 3], t[(k + 2) % 3]);
                let key = (a.min(b), a.max(b));
                let e = on_edge.entry(key).or_insert(Edge {
                    ends: [key.0, key.1],
                    opposite: [c, c],
                    face: [f as u32; 2],
                    faces: 0,
                });
                if e.faces < 2 {
                    e.opposite[e.faces as usize] = c;
                    e.face[e.faces as usize] = f as u32;
                }
                e.faces = e.faces.saturating_add(1);
            }
        }
        let mut edges: Vec<Edge> = on_edge.into_values().filter(|e| e.faces <= 2).collect();
        // A fixed order, so that a contour is the same from run to run.
        edges.sort_by_key(|e| e.ends);
        // Renumbered in the mesh's order, which keeps the edges' order too.
        let mut number = vec![u32::MAX; mesh.positions.len()];
        let mut vertices: Vec<u32> = mesh.triangles.iter().flatten().copied().collect();
        vertices.sort_unstable();
        vertices.dedup();
        for (k, &v) in vertices.iter().enumerate() {
            number[v as usize] = k as u32;
        }
        for e in &mut edges {
            e.ends = e.ends.map(|v| number[v as usize]);
            e.opposite = e.opposite.map(|v| number[v as usize]);
        }
        let drawn = Mesh {
            positions: vertices
                .iter()
                .map(|&v| mesh.positions[v as usize])
                .collect(),
            triangles: mesh
                .triangles
                .iter()
                .map(|t| t.map(|v| number[v as usize]))
                .collect(),
            boi: mesh.boi.clone(),
        };
        ContourEdges {
            edges,
            vertices,
            drawn,
        }
    }

    /// The mesh these edges are of, without its unused vertices: the same faces, drawn the
    /// same.
    pub fn drawn(&self) -> &Mesh {
        &self.drawn
    }

    /// The contour of `mesh` (the mesh these edges are of) at `world_from_model` in `cam`,
    /// sampled about every `spacing_px` pixels along each silhouette edge. Hidden parts are
    /// included: [`visible`] leaves them out against a depth buffer.
    pub fn contour(
        &self,
        mesh: &Mesh,
        world_from_model: &Pose,
        cam: &Camera,
        spacing_px: f64,
    ) -> Vec<ContourPoint> {
        self.outline(mesh, world_from_model, cam, spacing_px, None)
    }

    /// [`Self::contour`], and with `region` (a flag per face) also the edges where a face of
    /// the region meets one outside it, their normals pointing out of the region: together the
    /// outline of the region's visible part, once [`visible`] keeps only the samples whose
    /// inside shows the region.
    pub fn outline(
        &self,
        mesh: &Mesh,
        world_from_model: &Pose,
        cam: &Camera,
        spacing_px: f64,
        region: Option<&[bool]>,
    ) -> Vec<ContourPoint> {
        let mut out = Vec::new();
        self.sampled(mesh, world_from_model, cam, spacing_px, region, |_, p| {
            out.push(p)
        });
        out
    }

    /// [`Self::contour`], and apart from it the edges where a face of `region` meets one
    /// outside it and neither is turned away (no silhouette), normals pointing out of the
    /// region: the mesh placed and projected, and its edges walked, once for both.
    pub fn contour_and_region_edges(
        &self,
        mesh: &Mesh,
        world_from_model: &Pose,
        cam: &Camera,
        spacing_px: f64,
        region: &[bool],
    ) -> (Vec<ContourPoint>, Vec<ContourPoint>) {
        let (mut contour, mut edges) = (Vec::new(), Vec::new());
        let sink = |silhouette: bool, p| {
            if silhouette {
                contour.push(p)
            } else {
                edges.push(p)
            }
        };
        self.sampled(mesh, world_from_model, cam, spacing_px, Some(region), sink);
        (contour, edges)
    }

    /// The samples of the silhouette edges and of the edges where `region` meets the rest of
    /// the mesh, each given to `sink` with whether it is of a silhouette.
    fn sampled(
        &self,
        mesh: &Mesh,
        world_from_model: &Pose,
        cam: &Camera,
        spacing_px: f64,
        region: Option<&[bool]>,
        mut sink: impl FnMut(bool, ContourPoint),
    ) {
        let view = View { cam };
        let world: Vec<Vector3<f64>> = self
            .vertices
            .iter()
            .map(|&v| world_from_model.transform_point(&mesh.point(v as usize)))
            .collect();
        // Each vertex projected once: an edge's ends and opposite vertices are shared.
        let pixels: Vec<Option<Vector2<f64>>> = world.iter().map(|p| view.pixel(p)).collect();
        for e in &self.edges {
            let [a, b] = e.ends.map(|v| world[v as usize]);
            let (Some(pa), Some(pb)) = (pixels[e.ends[0] as usize], pixels[e.ends[1] as usize])
            else {
                continue;
            };
            let along = pb - pa;
            let length = along.norm();
            if length < 1e-9 {
                continue;
            }
            let across = Vector2::new(-along.y, along.x) / length;
            let side = |v: u32| pixels[v as usize].map_or(0.0, |p| (p - pa).dot(&across).signum());
            let first = side(e.opposite[0]);
            if first == 0.0 {
                continue;
            }
            // A fold: both faces on one side of the edge's projection; an open edge: its one
            // face on one side. The silhouette's outside is the other side. Where the region
            // ends, its outside is the side of the face that is not in it.
            let silhouette = e.faces == 1 || side(e.opposite[1]) == first;
            let inside = region.and_then(|r| {
                let (a, b) = (r[e.face[0] as usize], r[e.face[1] as usize]);
                (e.faces == 2 && a != b).then_some(if a { first } else { -first })
            });
            let normal = match (silhouette, inside) {
                (true, _) => -first * across,
                (false, Some(inside)) => -inside * across,
                (false, None) => continue,
            };
            let n = (length / spacing_px).ceil().max(1.0) as usize;
            for i in 0..n {
                let s = (i as f64 + 0.5) / n as f64;
                let p = a + (b - a) * s;
                if let Some((pixel, inv_depth, jacobian)) = view.point(&p) {
                    let point = ContourPoint {
                        pixel,
                        normal,
                        length: length / n as f64,
                        inv_depth,
                        jacobian,
                    };
                    sink(silhouette, point);
                }
            }
        }
    }
}

/// The points of `contour` that the depth buffer `target` (drawn with every mesh that may hide
/// them) shows: the pixel just inside each point holds nothing, or a surface no nearer than
/// `tolerance_mm` in front of it. The tolerance is for the model's own surface, which near a
/// silhouette comes closer to the camera the further inside one looks.
pub fn visible(contour: &[ContourPoint], target: &Target, tolerance_mm: f64) -> Vec<ContourPoint> {
    showing(contour, target, tolerance_mm, None)
}

/// [`visible`], keeping only the samples where the picture changes from `class` (the region's,
/// for an [`ContourEdges::outline`]) inside to another class outside: where the region's edge
/// can show in a mask. A tooth's outline over another tooth behind it shows none.
pub fn showing(
    contour: &[ContourPoint],
    target: &Target,
    tolerance_mm: f64,
    class: Option<u8>,
) -> Vec<ContourPoint> {
    let Some(rect) = target.rect else {
        return Vec::new();
    };
    let index = |p: Vector2<f64>| {
        let (x, y) = (p.x.round(), p.y.round());
        let (x0, y0) = (rect.x0 as f64, rect.y0 as f64);
        let outside =
            x < x0 || y < y0 || x >= x0 + rect.width as f64 || y >= y0 + rect.height as f64;
        (!outside).then(|| (y - y0) as usize * rect.width as usize + (x - x0) as usize)
    };
    contour
        .iter()
        .filter(|c| {
            let Some(i) = index(c.pixel - 0.75 * c.normal) else {
                return false;
            };
            let shown = target.inv_depth[i] as f64;
            let unhidden = shown == 0.0 || 1.0 / shown >= 1.0 / c.inv_depth - tolerance_mm;
            let edge = class.is_none_or(|k| {
                let beyond = index(c.pixel + 0.75 * c.normal).map(|j| target.class[j]);
                target.class[i] == k && beyond != Some(k)
            });
            unhidden && edge
        })
        .copied()
        .collect()
}

/// The rate of change of the uncovered term (mask pixels the model does not cover) as the pose
/// moves by ξ: `−∮ M(x)·⟨J(x)·ξ, n(x)⟩ ds` over the visible contour, with `mask` the mask's
/// value at a pixel position (1 on the arch's label, 0 off it; a soft mask's probability works
/// as well). As a gradient: `−Σ M·Jᵀn·length`.
pub fn uncovered_gradient(
    contour: &[ContourPoint],
    mask: impl Fn(Vector2<f64>) -> f64,
) -> nalgebra::Vector6<f64> {
    contour.iter().fold(nalgebra::Vector6::zeros(), |g, c| {
        g - c.jacobian.transpose() * c.normal * (mask(c.pixel) * c.length)
    })
}

/// A binary mask's value at a pixel position, bilinear between pixel centres: what the
/// contour sees of a mask whose edge falls between two pixels (0 outside the image).
pub fn bilinear(
    mask: &[u8],
    width: usize,
    height: usize,
    on: impl Fn(u8) -> bool,
    x: Vector2<f64>,
) -> f64 {
    bilinear_by(width, height, |i| on(mask[i]) as u8 as f64, x)
}

/// A picture's value at a pixel position, bilinear between pixel centres (0 outside it);
/// `value(i)`: the value of the pixel at row-major index `i`.
pub fn bilinear_by(
    width: usize,
    height: usize,
    value: impl Fn(usize) -> f64,
    x: Vector2<f64>,
) -> f64 {
    let (fx, fy) = (floor(x.x), floor(x.y));
    let (tx, ty) = (x.x - fx, x.y - fy);
    let at = |i: f64, j: f64| {
        if i < 0.0 || j < 0.0 || i >= width as f64 || j >= height as f64 {
            return 0.0;
        }
        value(j as usize * width + i as usize)
    };
    (1.0 - ty) * ((1.0 - tx) * at(fx, fy) + tx * at(fx + 1.0, fy))
        + ty * ((1.0 - tx) * at(fx, fy + 1.0) + tx * at(fx + 1.0, fy + 1.0))
}

/// `x.floor()` without the library call (the baseline x86-64 target has no rounding
/// instruction), for reads of pixels around a point, exact for any pixel coordinate.
fn floor(x: f64) -> f64 {
    let t = x as i64 as f64;
    if t > x { t - 1.0 } else { t }
}

/// The camera and the pose, for projecting world points with their Jacobians.
struct View<'a> {
    cam: &'a Camera,
}

impl View<'_> {
    fn pixel(&self, p_world: &Vector3<f64>) -> Option<Vector2<f64>> {
        let pc = self.cam.camera_from_world.transform_point(p_world);
        (pc.z > NEAR_MM).then(|| self.image(pc.x / pc.z, pc.y / pc.z))
    }

    /// The pixel of normalised coordinates (x, y), through the lens.
    fn image(&self, x: f64, y: f64) -> Vector2<f64> {
        let [u, v] = if self.cam.has_distortion() {
            self.cam.distortion.apply(x, y)
        } else {
            [x, y]
        };
        Vector2::new(self.cam.fx * u + self.cam.cx, self.cam.fy * v + self.cam.cy)
    }

    /// ∂pixel/∂(x, y) of [`Self::image`]: the focal lengths, times the lens's derivative by
    /// central differences (the lens models are smooth and cheap to evaluate).
    fn image_jacobian(&self, x: f64, y: f64) -> nalgebra::Matrix2<f64> {
        if !self.cam.has_distortion() {
            return nalgebra::Matrix2::new(self.cam.fx, 0.0, 0.0, self.cam.fy);
        }
        let h = 1e-7;
        let d = |dx: f64, dy: f64| self.image(x + dx, y + dy);
        let cx = (d(h, 0.0) - d(-h, 0.0)) / (2.0 * h);
        let cy = (d(0.0, h) - d(0.0, -h)) / (2.0 * h);
        nalgebra::Matrix2::from_columns(&[cx, cy])
    }

    /// Pixel, 1/z and ∂pixel/∂ξ of a world point moved by `exp(ξ)` (left, in the world frame).
    fn point(&self, p_world: &Vector3<f64>) -> Option<(Vector2<f64>, f64, Matrix2x6<f64>)> {
        let pc = self.cam.camera_from_world.transform_point(p_world);
        if pc.z <= NEAR_MM {
            return None;
        }
        let iz = 1.0 / pc.z;
        let (x, y) = (pc.x * iz, pc.y * iz);
        let pixel = self.image(x, y);
        let d_normalised_d_camera = Matrix2x3::new(iz, 0.0, -x * iz, 0.0, iz, -y * iz);
        let d_pixel_d_camera = self.image_jacobian(x, y) * d_normalised_d_camera;
        // exp(ξ)·p ≈ p + ω × p + v = p − [p]×·ω + v.
        let mut d_world_d_xi = Matrix3x6::zeros();
        d_world_d_xi
            .fixed_view_mut::<3, 3>(0, 0)
            .copy_from(&(-hat(p_world)));
        d_world_d_xi
            .fixed_view_mut::<3, 3>(0, 3)
            .copy_from(&nalgebra::Matrix3::identity());
        let rotation = self.cam.camera_from_world.rotation.matrix();
        Some((pixel, iz, d_pixel_d_camera * rotation * d_world_d_xi))
    }
}

#[cfg(test)]
mod tests;
