//! The smooth energy: the pixel-count energy in the limit of small pixels, continuous in the
//! poses, with analytic derivatives (what Gauss-Newton, `track::joint`, minimises).
//!
//! A pixel count changes only where a model's silhouette crosses pixels, and there by what
//! lies between the silhouette and the mask's edge: mask pixels the model leaves uncovered (1
//! each), BOI pixels past the mask (λ each), and any of the model's pixels over the other
//! arch's label or the mouth interior (their weights). Along the silhouette that is the
//! integral ∮ c(s)·|d(s)| ds of the offset d to the mask's edge, weighted by what the pixels
//! between cost ([`super::edge_terms::cost`]). The BOI's edge where it meets the rest of the
//! model counts too, past the mask (λ).
//!
//! [`samples`] draws both arches and samples their visible silhouettes and BOI edges; each
//! sample's term (its offset, weight and share of the energy) is computed by the engine, on
//! the CPU by [`super::edge_terms`] and on the GPU by shaders/edge_terms.wgsl
//! ([`super::EnergyEngine::edge_terms`]); [`normal_equations`] sums them. The smooth energy is
//! Σ c·length·ρ(d), ρ Huber's loss within the smoothing width ε and Tukey's biweight out to
//! the reach ([`super::edge_terms::loss`]): as ε → 0 it is the integral itself, the
//! pixel-count energy's change from where mask and model agree, less what the count charges to
//! the other arch where a silhouette is drawn over it ([`super::edge_terms::cost`]).
//!
//! A sample's offset is measured from the model's *drawn* edge, not its exact silhouette: a
//! segmentation rounds the true edge to pixel centres as the rasteriser does, so the two agree
//! at the true pose, where a rounded mask against the exact silhouette is off by up to half a
//! pixel along every straight edge (the incisal edges) and nods the arch.
//!
//! The increments are the solver's: ξ = [ξ_u; ξ_j], the upper arch moving as
//! `U ← exp(ξ_u)·U` and the lower with it and then by the jaw's own, `L ← exp(ξ_u)·exp(ξ_j)·L`,
//! so a lower-arch sample's row is `[r, r]` for its single-arch row `r = Jᵀn`.

use nalgebra::{SMatrix, SVector, Vector2};
use rayon::prelude::*;

use super::EnergyEngine;
use super::contour::{ContourEdges, ContourPoint, bilinear};
use super::edge_terms::{EdgeKind, EdgeQuery, EdgeSample, EdgeTerm, edge_offset};
use super::raster::render_target_fitted;
use super::target::{CLASS_BODY, CLASS_BOI, Target};
use crate::arch::ArchPoses;
use crate::error::Result;
use crate::geometry::{Camera, Pose};
use crate::mesh::Mesh;

pub type Matrix12 = SMatrix<f64, 12, 12>;
pub type Vector12 = SVector<f64, 12>;

/// How far (mm) in front of a contour sample its own surface may lie and the sample still
/// count as seen.
pub const OCCLUSION_MM: f64 = 2.0;

/// The render classes of the two arches (body, BOI): apart where the masks tell the arches
/// apart, so that an arch's silhouette over the other arch is an edge the masks show; the
/// same where one label covers both, which shows no edge between them.
fn classes(apart: bool) -> [[u8; 2]; 2] {
    if apart {
        [[CLASS_BODY, CLASS_BOI], [CLASS_BOI + 1, CLASS_BOI + 2]]
    } else {
        [[CLASS_BODY, CLASS_BOI]; 2]
    }
}

/// What the picture `target` shows of sample `c` (an edge of a model drawn with classes
/// `own`, body and BOI): `Some` where the pixel just inside it holds one of the `inside`
/// classes at about the sample's depth (not hidden by the model's own surface more than
/// `OCCLUSION_MM` in front) and the pixel just outside one of `outside`; the class inside.
fn shown(
    c: &ContourPoint,
    target: &Target,
    inside: &[u8],
    outside: &dyn Fn(u8) -> bool,
) -> Option<u8> {
    let i = pixel_index(target, c.pixel - 0.75 * c.normal)?;
    let class = target.class[i];
    if !inside.contains(&class) {
        return None;
    }
    let depth = target.inv_depth[i] as f64;
    if 1.0 / depth < 1.0 / c.inv_depth - OCCLUSION_MM {
        return None;
    }
    outside(class_beyond(c, target)).then_some(class)
}

/// The index in `target` of the pixel nearest `p`, if it lies within.
fn pixel_index(target: &Target, p: Vector2<f64>) -> Option<usize> {
    let rect = target.rect?;
    let (x, y) = (p.x.round() - rect.x0 as f64, p.y.round() - rect.y0 as f64);
    let within = x >= 0.0 && y >= 0.0 && x < rect.width as f64 && y < rect.height as f64;
    within.then(|| y as usize * rect.width as usize + x as usize)
}

/// The class `target` holds just beyond sample `c` (0 off the drawn rectangle).
fn class_beyond(c: &ContourPoint, target: &Target) -> u8 {
    pixel_index(target, c.pixel + 0.75 * c.normal).map_or(0, |j| target.class[j])
}

/// 1 where `target` holds one of the classes `inside`, bilinear between pixel centres.
fn class_read(target: &Target, inside: &[u8], x: Vector2<f64>) -> f64 {
    let Some(rect) = target.rect else {
        return 0.0;
    };
    let local = x - Vector2::new(rect.x0 as f64, rect.y0 as f64);
    bilinear(
        &target.class,
        rect.width as usize,
        rect.height as usize,
        |k| inside.contains(&k),
        local,
    )
}

/// The visible silhouette and BOI-edge samples of both arches at `poses` in every camera;
/// `apart`: the masks label the arches apart (per-arch masks), else one label covers both.
pub fn samples(
    arches: [(&Mesh, &ContourEdges); 2],
    poses: &ArchPoses,
    cameras: &[&Camera],
    apart: bool,
    spacing_px: f64,
) -> Vec<EdgeSample> {
    let classes = classes(apart);
    let pose = [poses.upper, poses.lower];
    // The cameras draw and sample in parallel, and each camera's drawing and its two arches'
    // contours too.
    let per_view = cameras.par_iter().enumerate().map(|(v, camera)| {
        let items: Vec<_> = (0..2)
            .map(|a| (arches[a].1.drawn(), &pose[a], classes[a][0], classes[a][1]))
            .collect();
        let contour_of = |a: usize| {
            let (mesh, edges) = arches[a];
            if mesh.boi.iter().any(|&b| b) {
                edges.contour_and_region_edges(mesh, &pose[a], camera, spacing_px, &mesh.boi)
            } else {
                let contour = edges.contour(mesh, &pose[a], camera, spacing_px);
                (contour, Vec::new())
            }
        };
        let (target, contours) = rayon::join(
            || render_target_fitted(camera, &items),
            || rayon::join(|| contour_of(0), || contour_of(1)),
        );
        let mut out = Vec::new();
        for (a, (contour, region)) in [contours.0, contours.1].into_iter().enumerate() {
            let own = classes[a];
            let rendered = |inside: &[u8], point: &ContourPoint| {
                let read = |x: Vector2<f64>| class_read(&target, inside, x);
                // The drawn edge nearest the sample, where the mask's edge is compared with it:
                // drawn and segmented alike, both round to pixel centres, and at the true pose
                // the two agree to the pixel.
                let e = edge_offset(point, &read, 1.0).unwrap_or(0.0);
                ContourPoint {
                    pixel: point.pixel + e * point.normal,
                    ..*point
                }
            };
            let other = classes[1 - a];
            let mut push = |point: ContourPoint, kind: EdgeKind, beside_other: bool| {
                out.push(EdgeSample {
                    arch: a,
                    view: v,
                    point,
                    kind,
                    beside_other,
                })
            };
            for point in contour {
                if let Some(class) = shown(&point, &target, &own, &|b| !own.contains(&b)) {
                    let beside_other = other.contains(&class_beyond(&point, &target));
                    let point = rendered(&own, &point);
                    let boi = class == own[1];
                    push(point, EdgeKind::Silhouette { boi }, beside_other);
                }
            }
            for point in region {
                if shown(&point, &target, &own[1..], &|b| b == own[0]).is_some() {
                    let point = rendered(&own[1..], &point);
                    push(point, EdgeKind::Region, false);
                }
            }
        }
        out
    });
    per_view.flatten().collect()
}

/// The terms' normal equations in ξ = [ξ_u; ξ_j] (`h`, `g`: the step solves h·ξ = g), how
/// many samples of each arch found an edge that costs, and the smooth energy they add up to.
#[derive(Debug, Clone, Copy)]
pub struct NormalEquations {
    pub h: Matrix12,
    pub g: Vector12,
    pub found: [usize; 2],
    pub energy: f64,
}

impl NormalEquations {
    fn zero() -> NormalEquations {
        NormalEquations {
            h: Matrix12::zeros(),
            g: Vector12::zeros(),
            found: [0; 2],
            energy: 0.0,
        }
    }

    fn add(self, o: NormalEquations) -> NormalEquations {
        NormalEquations {
            h: self.h + o.h,
            g: self.g + o.g,
            found: [self.found[0] + o.found[0], self.found[1] + o.found[1]],
            energy: self.energy + o.energy,
        }
    }
}

/// A sample's row of the Jacobian in ξ = [ξ_u; ξ_j]: its motion along its normal, `nᵀJ`,
/// for each increment that moves it.
fn row(s: &EdgeSample) -> Vector12 {
    let r = s.point.jacobian.transpose() * s.point.normal;
    let mut row = Vector12::zeros();
    row.fixed_rows_mut::<6>(0).copy_from(&r);
    if s.arch == 1 {
        row.fixed_rows_mut::<6>(6).copy_from(&r);
    }
    row
}

/// Samples summed at a time in [`normal_equations`].
const CHUNK: usize = 256;

/// The normal equations of `samples` with their `terms` (either engine's).
pub fn normal_equations(samples: &[EdgeSample], terms: &[Option<EdgeTerm>]) -> NormalEquations {
    assert_eq!(samples.len(), terms.len(), "a term per sample");
    // In chunks of a fixed size, summed in order: as fast on any number of threads, and the
    // same sums on all of them (a resumed run writes the very bytes of an uninterrupted one).
    let chunk_sum = |(samples, terms): (&[EdgeSample], &[Option<EdgeTerm>])| {
        let mut sum = NormalEquations::zero();
        for (s, t) in samples.iter().zip(terms) {
            let Some(t) = t else { continue };
            let row = row(s);
            sum.h += t.weight * row * row.transpose();
            sum.g += t.weight * t.offset_px * row;
            sum.found[s.arch] += 1;
            sum.energy += t.energy;
        }
        sum
    };
    let partial: Vec<NormalEquations> = samples
        .par_chunks(CHUNK)
        .zip(terms.par_chunks(CHUNK))
        .map(chunk_sum)
        .collect();
    partial
        .into_iter()
        .fold(NormalEquations::zero(), NormalEquations::add)
}

/// What one view's samples add to the normal equations for an offset of its mask's edges
/// against what is not teeth (the samples drawn that much wider: each offset falls by it;
/// those beside the other arch stay): the sums of the terms' weights, of weight·offset and of
/// weight·row.
#[derive(Debug, Clone, Copy)]
pub struct ViewSums {
    pub weight: f64,
    pub weighted_offset: f64,
    pub weighted_row: Vector12,
}

/// Each of `views` views' [`ViewSums`] of `samples` with their `terms`, summed in order.
pub fn view_sums(
    samples: &[EdgeSample],
    terms: &[Option<EdgeTerm>],
    views: usize,
) -> Vec<ViewSums> {
    let mut out = vec![
        ViewSums {
            weight: 0.0,
            weighted_offset: 0.0,
            weighted_row: Vector12::zeros(),
        };
        views
    ];
    for (s, t) in samples.iter().zip(terms) {
        let (Some(t), Some(v), false) = (t, out.get_mut(s.view), s.beside_other) else {
            continue;
        };
        v.weight += t.weight;
        v.weighted_offset += t.weight * t.offset_px;
        v.weighted_row += t.weight * row(s);
    }
    out
}

/// The normal equations' −g, the gradient Gauss-Newton steps along, against central
/// differences of `engine`'s smooth energy at the samples of `q` moved by ±h along each
/// increment (h: 1e-4 rad, 4e-3 mm), each component scaled by its step (the energy's change
/// over it). Only samples that keep their edge and its cost count: a switch to another edge
/// is a jump no difference quotient measures. For the tests of both engines.
#[doc(hidden)]
pub fn gradient_and_differences(
    engine: &dyn EnergyEngine,
    q: &EdgeQuery,
) -> Result<(Vector12, Vector12)> {
    let p = q.params;
    let terms = |xi: &Vector12| {
        let upper = xi.fixed_rows::<6>(0).into_owned();
        let jaw = xi.fixed_rows::<6>(6).into_owned();
        let moved = [upper, Pose::exp(&upper).compose(&Pose::exp(&jaw)).log()];
        engine.edge_terms(&EdgeQuery { moved, ..*q })
    };
    let at = terms(&Vector12::zeros())?;
    // cost·length, from the weight.
    let costed = |t: &EdgeTerm| {
        let u = t.offset_px / p.reach_px;
        t.weight * t.offset_px.abs().max(p.smoothing_px) / (1.0 - u * u).powi(2)
    };
    let (mut analytic, mut differences) = (Vector12::zeros(), Vector12::zeros());
    for k in 0..12 {
        let h = if k % 6 < 3 { 1e-4 } else { 4e-3 };
        let mut xi = Vector12::zeros();
        xi[k] = h;
        let (plus, minus) = (terms(&xi)?, terms(&-xi)?);
        for (i, s) in q.samples.iter().enumerate() {
            let (Some(t), Some(a), Some(b)) = (at[i], plus[i], minus[i]) else {
                continue;
            };
            let r = row(s)[k];
            let switched = ((a.offset_px - b.offset_px) + 2.0 * h * r).abs() > 0.05
                || a.offset_px.signum() != b.offset_px.signum()
                || (costed(&a) - costed(&b)).abs() > 1e-4 * costed(&a).abs();
            if !switched {
                analytic[k] -= h * t.weight * t.offset_px * r;
                differences[k] += (a.energy - b.energy) / 2.0;
            }
        }
    }
    Ok((analytic, differences))
}

#[cfg(test)]
pub(crate) mod tests;
