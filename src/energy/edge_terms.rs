//! The smooth energy's edge terms ([`super::smooth`]), one sample at a time: the CPU twin of
//! shaders/edge_terms.wgsl, line for line.
//!
//! A sample, moved by its arch's increment since it was drawn, looks along its normal for its
//! arch's mask edge within the reach; the pixels between cost what [`cost`] says; its term is
//! the offset `d`, the iteratively reweighted least-squares weight
//! `cost·tukey(d/reach)·length/max(|d|, ε)` and its share of the smooth energy
//! `cost·length·ρ(d)` ([`loss`]). The GPU computes the same in f32.

use nalgebra::{Vector2, Vector6};
use rayon::prelude::*;

use super::Weights;
use super::contour::{ContourPoint, bilinear, bilinear_by};
use crate::arch::Arch;
use crate::capture::LabelMask;
use crate::capture::masks::MOUTH_BIT;

/// What a sample is an edge of.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EdgeKind {
    /// The silhouette, the model's BOI just inside it (else its body).
    Silhouette { boi: bool },
    /// The BOI's edge where it meets the rest of the model.
    Region,
}

/// A sample of an arch's drawn edge, frozen where its stage drew it.
#[derive(Debug, Clone, Copy)]
pub struct EdgeSample {
    /// 0: the upper arch, 1: the lower.
    pub arch: usize,
    /// The view (of the query's cameras) it was drawn in.
    pub view: usize,
    pub point: ContourPoint,
    pub kind: EdgeKind,
    /// The other arch's model lies just beyond it (per-arch masks): the edge between two
    /// labels of teeth, which a segmentation's bias between teeth and the rest does not move
    /// (`track::edge_offsets`).
    pub beside_other: bool,
}

/// How the terms are read.
#[derive(Debug, Clone, Copy)]
pub struct EdgeParams {
    /// How far (pixels) along its normal a sample looks for its mask's edge.
    pub reach_px: f64,
    /// The smoothing width ε (pixels).
    pub smoothing_px: f64,
    /// λ, and the cross-label and over-mouth weights of the pixels past a silhouette.
    pub weights: Weights,
    /// The level of the masks' pyramid ([`super::pyramid`]) the samples were drawn at and the
    /// masks are read at: 0, the masks themselves; reach and smoothing are in its pixels.
    pub level: usize,
}

/// A sample's term.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EdgeTerm {
    /// The offset (pixels, along the normal) to the mask's edge.
    pub offset_px: f64,
    /// Its weight in the least squares (cost·tukey·length/max(|d|, ε)).
    pub weight: f64,
    /// Its share of the smooth energy (cost·length·ρ(d)).
    pub energy: f64,
}

/// A stage's edge terms asked of an engine, over the frame's masks.
pub struct EdgeQuery<'a> {
    pub samples: &'a [EdgeSample],
    /// The camera (its index in the scene) of each view the samples name.
    pub cameras: &'a [usize],
    /// Each arch's world increment since the samples were drawn (upper, lower).
    pub moved: [Vector6<f64>; 2],
    pub params: EdgeParams,
}

/// A pixel-position read of a mask or of a cost.
pub type Read<'a> = &'a (dyn Fn(Vector2<f64>) -> f64 + Sync);

/// What one camera's masks say at a pixel position, per arch (upper, lower).
pub struct EdgeReads<'a> {
    /// 1 on the arch's label, 0 off it (a bilinear read of a binary mask, or a soft mask's
    /// probability).
    pub masks: [Read<'a>; 2],
    /// What any pixel of the arch's model costs there besides the paper's terms (the
    /// cross-label and over-mouth weights); `None`: nothing.
    pub extra: [Option<Read<'a>>; 2],
}

/// The offset (pixels, along `c.normal`) to the mask's edge nearest the sample within
/// `reach`: where the mask falls through one half, from inside (behind the sample) to outside.
pub fn edge_offset(
    c: &ContourPoint,
    mask: &dyn Fn(Vector2<f64>) -> f64,
    reach: f64,
) -> Option<f64> {
    let step = 0.5;
    let n = (reach / step).ceil() as usize;
    let at = |d: f64| mask(c.pixel + d * c.normal) - 0.5;
    // Outward from the sample, both ways at once: the first crossing found is the nearest.
    let (mut ahead, mut behind) = (at(0.0), at(0.0));
    for k in 0..n {
        let (d0, d1) = (k as f64 * step, (k + 1) as f64 * step);
        let next_ahead = at(d1);
        let forward =
            (ahead >= 0.0 && next_ahead < 0.0).then(|| d0 + step * ahead / (ahead - next_ahead));
        let next_behind = at(-d1);
        let backward = (next_behind >= 0.0 && behind < 0.0)
            .then(|| -d1 + step * next_behind / (next_behind - behind));
        match (forward, backward) {
            (Some(f), Some(b)) => return Some(if f <= -b { f } else { b }),
            (Some(d), None) | (None, Some(d)) => return Some(d),
            (None, None) => {}
        }
        (ahead, behind) = (next_ahead, next_behind);
    }
    None
}

/// What each pixel between a sample and its mask's edge costs, `d` pixels away: past a
/// silhouette (d < 0), the model's pixels outside the mask (λ where the BOI shows there, plus
/// the extra weight `extra` of what the mask labels there); short of it, the mask's pixels it
/// leaves uncovered (1); past a BOI edge, BOI outside the mask (λ); short of it, nothing (both
/// sides cover the mask).
///
/// Only the sample's own arch's pixels: where its silhouette is drawn over the other arch's
/// model (per-arch masks), moving it also hides the other's label from its model or reveals
/// that model, which the pixel count charges to the other arch and this leaves out
/// (docs/energy.md: counted, it made tracking on hard footage worse).
pub fn cost(kind: EdgeKind, d: f64, lambda: f64, extra: impl FnOnce() -> f64) -> f64 {
    match (kind, d < 0.0) {
        (EdgeKind::Silhouette { boi }, true) => extra() + if boi { lambda } else { 0.0 },
        (EdgeKind::Silhouette { .. }, false) => 1.0,
        (EdgeKind::Region, true) => lambda,
        (EdgeKind::Region, false) => 0.0,
    }
}

/// ρ(d), the loss whose iteratively reweighted least squares the weights
/// `tukey(d/R)/max(|d|, ε)` solve, so that the normal equations' `g` is minus the smooth
/// energy's gradient: Huber's parabola within the smoothing width ε, Tukey's biweight out to
/// the reach R, flat beyond (an edge found far off is as likely another edge). Zero at d = 0,
/// so that the energy is continuous where the cost of the pixels between changes (at the
/// mask's edge); |d| in the limit ε → 0, R → ∞.
pub fn loss(d: f64, eps: f64, reach: f64) -> f64 {
    let (r2, eps) = (reach * reach, eps.min(reach));
    // ∫ (1 − t²/R²)² dt, and ∫ (t/ε)·(1 − t²/R²)² dt, from 0.
    let tukey = |t: f64| t - 2.0 * t.powi(3) / (3.0 * r2) + t.powi(5) / (5.0 * r2 * r2);
    let inner = |t: f64| {
        t * t / (2.0 * eps) - t.powi(4) / (2.0 * eps * r2) + t.powi(6) / (6.0 * eps * r2 * r2)
    };
    let a = d.abs().min(reach);
    if a < eps {
        inner(a)
    } else {
        inner(eps) + tukey(a) - tukey(eps)
    }
}

/// One sample's term, read through `reads` (its camera's); `None` where no edge is within
/// the reach or the pixels between cost nothing.
pub fn term(
    s: &EdgeSample,
    reads: &EdgeReads,
    moved: &[Vector6<f64>; 2],
    p: &EdgeParams,
) -> Option<EdgeTerm> {
    let here = ContourPoint {
        pixel: s.point.pixel + s.point.jacobian * moved[s.arch],
        ..s.point
    };
    let d = edge_offset(&here, reads.masks[s.arch], p.reach_px)?;
    let extra = || {
        let at = here.pixel + 0.5 * d * here.normal;
        reads.extra[s.arch].map_or(0.0, |e| e(at))
    };
    let cost = cost(s.kind, d, p.weights.lambda, extra);
    if cost == 0.0 {
        return None;
    }
    let u = d / p.reach_px;
    let tukey = (1.0 - u * u).max(0.0).powi(2);
    Some(EdgeTerm {
        offset_px: d,
        weight: cost * tukey * here.length / d.abs().max(p.smoothing_px),
        energy: cost * here.length * loss(d, p.smoothing_px, p.reach_px),
    })
}

/// Every sample's term, each read through its view's `reads`.
pub fn terms(
    samples: &[EdgeSample],
    reads: &[EdgeReads],
    moved: &[Vector6<f64>; 2],
    p: &EdgeParams,
) -> Vec<Option<EdgeTerm>> {
    samples
        .par_iter()
        .map(|s| term(s, &reads[s.view], moved, p))
        .collect()
}

/// A label mask's `arch` label: 1 on it, 0 off it, or how much of a pixel the arch's teeth
/// hold where the mask carries soft evidence; bilinear between pixel centres.
pub fn label_read(m: &LabelMask, arch: Arch) -> impl Fn(Vector2<f64>) -> f64 + Sync + '_ {
    let (w, h, bit, a) = (
        m.width as usize,
        m.height as usize,
        arch.mask_bit(),
        arch.index(),
    );
    move |x: Vector2<f64>| match &m.soft {
        Some(soft) => bilinear_by(w, h, |i| soft[i][a] as f64 / 255.0, x),
        None => bilinear(&m.data, w, h, |v| v & bit != 0, x),
    }
}

/// What any pixel of `arch`'s model costs at the pixel nearest a position of a label mask,
/// besides the paper's terms: the cross-label weight over the other arch's label, the
/// over-mouth weight over the mouth interior's.
pub fn extra_read<'m>(
    m: &'m LabelMask,
    arch: Arch,
    w: &Weights,
) -> impl Fn(Vector2<f64>) -> f64 + Sync + 'm {
    let (width, height) = (m.width as i64, m.height as i64);
    let (own, other) = (arch.mask_bit(), arch.other().mask_bit());
    let w = *w;
    move |x: Vector2<f64>| {
        let (i, j) = (x.x.round() as i64, x.y.round() as i64);
        if i < 0 || j < 0 || i >= width || j >= height {
            return 0.0;
        }
        let label = m.data[(j * width + i) as usize];
        let cross = label & other != 0 && label & own == 0;
        (if cross { w.cross } else { 0.0 }) + (if label & MOUTH_BIT != 0 { w.mouth } else { 0.0 })
    }
}

/// Every sample's term over label masks (`masks[v]`: view v's; `None`, a view without one,
/// finds no edge), with the extra weights of `p.weights`.
pub fn label_terms(
    samples: &[EdgeSample],
    masks: &[Option<&LabelMask>],
    moved: &[Vector6<f64>; 2],
    p: &EdgeParams,
) -> Vec<Option<EdgeTerm>> {
    type Boxed<'a> = Box<dyn Fn(Vector2<f64>) -> f64 + Sync + 'a>;
    let nothing = || Box::new(|_: Vector2<f64>| 0.0) as Boxed;
    let on: Vec<[Boxed; 2]> = masks
        .iter()
        .map(|&m| Arch::BOTH.map(|a| m.map_or_else(nothing, |m| Box::new(label_read(m, a)))))
        .collect();
    let extra: Vec<[Boxed; 2]> = masks
        .iter()
        .map(|&m| {
            Arch::BOTH.map(|a| m.map_or_else(nothing, |m| Box::new(extra_read(m, a, &p.weights))))
        })
        .collect();
    let reads: Vec<EdgeReads> = on
        .iter()
        .zip(&extra)
        .map(|(on, extra)| EdgeReads {
            masks: [on[0].as_ref(), on[1].as_ref()],
            extra: [Some(extra[0].as_ref()), Some(extra[1].as_ref())],
        })
        .collect();
    terms(samples, &reads, moved, p)
}
