//! Gauss-Newton over both arches at once, on the energy's own terms.
//!
//! The pixel-count energy changes only where a model's silhouette crosses pixels, and there by
//! what lies between the silhouette and the mask's edge: mask pixels the model leaves uncovered
//! (1 each), BOI pixels past the mask (λ each), and any of the model's pixels over the other
//! arch's label or the mouth interior (their weights). Along the silhouette that is the
//! integral ∮ c(s)·|d(s)| ds of the offset d to the mask's edge, weighted by what the pixels
//! between cost: the energy in the limit of small pixels, continuous in the pose. Each visible
//! silhouette sample looks along its normal for its arch's mask edge (as in
//! [`super::align`]), and Gauss-Newton minimises that integral by iteratively reweighted
//! least squares: a sample's residual is d, its weight c·length/max(|d|, ε), so that the
//! squares add up to the integral; ε, a fraction of a pixel, is the smoothing width. The
//! BOI's edge where it meets the rest of the model counts too, past the mask (λ).
//!
//! A sample's offset is measured from the model's drawn edge, not its exact silhouette: a
//! segmentation rounds the true edge to pixel centres as the rasteriser does, so the two agree
//! at the true pose, where a rounded mask against the exact silhouette is off by up to half a
//! pixel along every straight edge (the incisal edges) and nods the arch.
//!
//! The unknowns are two se(3) increments, ξ = [ξ_u; ξ_j]: the upper arch moves as
//! `U ← exp(ξ_u)·U`, the lower with it and then by the jaw's own increment,
//! `L ← exp(ξ_u)·exp(ξ_j)·L`. The jaw pose `U⁻¹·L` then changes with ξ_j alone, so what
//! anatomy says of the jaw (the arches do not pass through each other, the jaw moves on a
//! low-dimensional manifold) are residuals in ξ_j only, and a lower-arch sample's row is
//! `[r, r]` for its single-arch row `r` (both increments move it in the world, to first order
//! alike). A motion prior on each arch's displacement from the frame's start holds the
//! directions the masks barely see where the last frame left them.
//!
//! Each stage (a reach, coarse to fine) draws both arches' depth and class buffer once per
//! camera and samples their visible silhouettes; its steps move those samples by their
//! Jacobians rather than drawing again, which is exact to first order and keeps a step to a
//! few hundred projected points per camera.

use nalgebra::{SMatrix, SVector, Vector2, Vector6};
use rayon::prelude::*;

use super::align::{OCCLUSION_MM, edge_offset};
use super::search::GaussNewtonSettings;
use super::search::RADIUS_MM;
use crate::arch::ArchPoses;
use crate::energy::contour::{ContourEdges, ContourPoint, bilinear};
use crate::energy::raster::render_target_fitted;
use crate::energy::target::{CLASS_BODY, CLASS_BOI, Target};
use crate::geometry::{Camera, Pose, hat};
use crate::mesh::Mesh;

pub type Matrix12 = SMatrix<f64, 12, 12>;
type Vector12 = SVector<f64, 12>;

/// A pixel-position read of a mask or of a cost.
pub type Read<'a> = &'a (dyn Fn(Vector2<f64>) -> f64 + Sync);

/// One camera and what its masks say for each arch (upper, lower).
pub struct JointView<'a> {
    pub camera: &'a Camera,
    /// The arch's mask: 1 on its label, 0 off it (a bilinear read of a binary mask, or a
    /// soft mask's probability).
    pub masks: [Read<'a>; 2],
    /// What any pixel of the arch's model costs at a pixel besides the paper's terms (the
    /// cross-label and over-mouth weights); `None`: nothing.
    pub extra: [Option<Read<'a>>; 2],
}

/// A residual of the jaw pose (upper_from_lower) that is zero within a tolerance: the
/// penalties of the objective, as least squares.
pub struct JawHinge<'a> {
    /// How far (mm) the jaw pose lies outside what anatomy allows.
    pub distance_mm: &'a (dyn Fn(&Pose) -> f64 + Sync),
    pub tolerance_mm: f64,
    /// Cost per mm² beyond the tolerance, in the silhouette residuals' unit (pixels of area
    /// times pixels of offset).
    pub stiffness: f64,
}

/// Tikhonov damping of each step, per rad² of rotation and mm² of translation (in the
/// residuals' unit): keeps a step small where few samples constrain it.
const DAMPING: [f64; 2] = [1e3, 1.0];
/// A stage ends early when a step moves no point at an arch's radius by more than this (mm):
/// more steps on the same samples would not move it further.
const SETTLE_MM: f64 = 0.002;

/// The result of [`align_both`].
#[derive(Debug, Clone, Copy)]
pub struct JointAligned {
    pub poses: ArchPoses,
    /// Gauss-Newton steps taken.
    pub steps: usize,
    /// Samples that found an edge in the last step (upper, lower).
    pub samples: [usize; 2],
    /// The last step's information from the masks alone (its normal matrix before the
    /// motion prior, hinges and damping), in the increments [ξ_u; ξ_j]: how sharply the
    /// frame's edges hold each direction, for a window over frames to weigh it by.
    pub information: Matrix12,
}

/// What a sample is an edge of.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Kind {
    /// The silhouette, the model's BOI just inside it (else its body).
    Silhouette { boi: bool },
    /// The BOI's edge where it meets the rest of the model.
    Region,
}

/// A sample frozen at its stage's linearisation point.
struct Sample {
    arch: usize,
    view: usize,
    point: ContourPoint,
    kind: Kind,
    /// `jacobianᵀ·normal`: the sample's motion along its normal per unit of increment.
    row: Vector6<f64>,
}

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
/// `own`, body and BOI): `Some` where the pixel just inside it holds the `inside` class (any
/// of `own` for `None`) at about the sample's depth (not hidden by the model's own surface more
/// than `OCCLUSION_MM` in front) and the pixel just outside one of `outside`; the class inside.
fn shown(
    c: &ContourPoint,
    target: &Target,
    inside: &[u8],
    outside: &dyn Fn(u8) -> bool,
) -> Option<u8> {
    let rect = target.rect?;
    let index = |p: Vector2<f64>| {
        let (x, y) = (p.x.round() - rect.x0 as f64, p.y.round() - rect.y0 as f64);
        let within = x >= 0.0 && y >= 0.0 && x < rect.width as f64 && y < rect.height as f64;
        within.then(|| y as usize * rect.width as usize + x as usize)
    };
    let i = index(c.pixel - 0.75 * c.normal)?;
    let class = target.class[i];
    if !inside.contains(&class) {
        return None;
    }
    let depth = target.inv_depth[i] as f64;
    if 1.0 / depth < 1.0 / c.inv_depth - OCCLUSION_MM {
        return None;
    }
    let beyond = index(c.pixel + 0.75 * c.normal).map_or(0, |j| target.class[j]);
    outside(beyond).then_some(class)
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

/// The visible silhouette and BOI-edge samples of both arches at `poses` in every view.
fn samples(
    arches: [(&Mesh, &ContourEdges); 2],
    poses: &ArchPoses,
    views: &[JointView],
    apart: bool,
    spacing_px: f64,
) -> Vec<Sample> {
    let classes = classes(apart);
    let pose = [poses.upper, poses.lower];
    // The cameras draw and sample in parallel, and each camera's drawing and its two arches'
    // contours too.
    let per_view = views.par_iter().enumerate().map(|(v, view)| {
        let items: Vec<_> = (0..2)
            .map(|a| (arches[a].1.drawn(), &pose[a], classes[a][0], classes[a][1]))
            .collect();
        let contour_of = |a: usize| {
            let (mesh, edges) = arches[a];
            if mesh.boi.iter().any(|&b| b) {
                edges.contour_and_region_edges(mesh, &pose[a], view.camera, spacing_px, &mesh.boi)
            } else {
                let contour = edges.contour(mesh, &pose[a], view.camera, spacing_px);
                (contour, Vec::new())
            }
        };
        let (target, contours) = rayon::join(
            || render_target_fitted(view.camera, &items),
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
            let mut push = |point: ContourPoint, kind: Kind| {
                out.push(Sample {
                    arch: a,
                    view: v,
                    row: point.jacobian.transpose() * point.normal,
                    point,
                    kind,
                })
            };
            for point in contour {
                if let Some(class) = shown(&point, &target, &own, &|b| !own.contains(&b)) {
                    let point = rendered(&own, &point);
                    push(
                        point,
                        Kind::Silhouette {
                            boi: class == own[1],
                        },
                    );
                }
            }
            for point in region {
                if shown(&point, &target, &own[1..], &|b| b == own[0]).is_some() {
                    let point = rendered(&own[1..], &point);
                    push(point, Kind::Region);
                }
            }
        }
        out
    });
    per_view.flatten().collect()
}

/// The jaw pose `U⁻¹·exp(ξ_j)·L`.
fn moved_jaw(poses: &ArchPoses, xi_j: &Vector6<f64>) -> Pose {
    poses
        .upper
        .inverse()
        .compose(&Pose::exp(xi_j))
        .compose(&poses.lower)
}

/// Each hinge's residual and its row in ξ_j (central differences: the distances are cheap,
/// and the contact depth is only piecewise smooth).
fn hinge_rows(hinges: &[JawHinge], poses: &ArchPoses) -> Vec<(f64, Vector6<f64>)> {
    const STEP: [f64; 2] = [2e-3, 0.05]; // rad, mm
    let residual = |h: &JawHinge, xi: &Vector6<f64>| {
        h.stiffness.sqrt() * ((h.distance_mm)(&moved_jaw(poses, xi)) - h.tolerance_mm).max(0.0)
    };
    // The jaw moved by ±step along each of its six directions, then not at all; the contact
    // depth is a search over the arches' surfaces, so the thirteen run in parallel.
    let moves: Vec<Vector6<f64>> = (0..13)
        .map(|i| {
            let mut xi = Vector6::zeros();
            if i < 12 {
                let k = i / 2;
                xi[k] = if i % 2 == 0 { 1.0 } else { -1.0 } * STEP[(k >= 3) as usize];
            }
            xi
        })
        .collect();
    hinges
        .iter()
        .map(|h| {
            let r: Vec<f64> = moves.par_iter().map(|xi| residual(h, xi)).collect();
            let row = Vector6::from_fn(|k, _| {
                (r[2 * k] - r[2 * k + 1]) / (2.0 * STEP[(k >= 3) as usize])
            });
            (r[12], row)
        })
        .collect()
}

/// Align both arches from `start` to the masks of `views`; `apart`: the masks label the
/// arches apart (per-arch masks), else one label covers both.
pub fn align_both(
    arches: [(&Mesh, &ContourEdges); 2],
    start: ArchPoses,
    views: &[JointView],
    apart: bool,
    hinges: &[JawHinge],
    lambda: f64,
    s: &GaussNewtonSettings,
) -> JointAligned {
    // Each arch's centre in the world at the start: the prior's displacements are measured
    // there.
    let centres = [0, 1].map(|a| {
        let (lo, hi) = arches[a].0.bounds();
        let mid = nalgebra::Vector3::from_fn(|k, _| (lo[k] + hi[k]) as f64 * 0.5);
        [start.upper, start.lower][a].transform_point(&mid)
    });
    let mut poses = start;
    let mut steps = 0;
    let mut found = [0; 2];
    let mut information = Matrix12::zeros();
    for &reach in &s.reaches_px {
        let at = poses;
        let frozen = samples(arches, &at, views, apart, s.spacing_px);
        for _ in 0..s.steps {
            // Each arch's world increment since the stage's linearisation point.
            let moved = [
                poses.upper.compose(&at.upper.inverse()).log(),
                poses.lower.compose(&at.lower.inverse()).log(),
            ];
            let (mut h, mut g, seen) = edge_terms(&frozen, views, &moved, reach, lambda, s);
            found = seen;
            information = h;
            // The motion prior: each arch's displacement from where the frame started, at
            // its centre and at an arch's radius.
            if s.motion_prior > 0.0 {
                for (a, centre) in centres.iter().enumerate() {
                    let (now, from) = if a == 0 {
                        (&poses.upper, &start.upper)
                    } else {
                        (&poses.lower, &start.lower)
                    };
                    let xi = now.compose(&from.inverse()).log();
                    let mut m = SMatrix::<f64, 6, 6>::zeros();
                    m.fixed_view_mut::<3, 3>(0, 0)
                        .copy_from(&(nalgebra::Matrix3::identity() * RADIUS_MM));
                    m.fixed_view_mut::<3, 3>(3, 0).copy_from(&-hat(centre));
                    m.fixed_view_mut::<3, 3>(3, 3)
                        .copy_from(&nalgebra::Matrix3::identity());
                    let r = m * xi;
                    // Both increments move the lower arch in the world.
                    let mut full = SMatrix::<f64, 6, 12>::zeros();
                    full.fixed_view_mut::<6, 6>(0, 0).copy_from(&m);
                    if a == 1 {
                        full.fixed_view_mut::<6, 6>(0, 6).copy_from(&m);
                    }
                    h += s.motion_prior * full.transpose() * full;
                    g -= s.motion_prior * full.transpose() * r;
                }
            }
            for (r, row) in hinge_rows(hinges, &poses) {
                if r == 0.0 {
                    continue;
                }
                let mut full = Vector12::zeros();
                full.fixed_rows_mut::<6>(6).copy_from(&row);
                h += full * full.transpose();
                g -= r * full;
            }
            // An arch that too few samples hold stays where it is, and the other one still
            // moves.
            for (a, &n) in found.iter().enumerate() {
                let hold = if n < 6 { 1e9 } else { 1.0 };
                for k in 0..6 {
                    h[(6 * a + k, 6 * a + k)] += hold * DAMPING[(k >= 3) as usize];
                }
            }
            if found.iter().all(|&n| n < 6) {
                break;
            }
            let Some(xi) = h.cholesky().map(|c| c.solve(&g)) else {
                break;
            };
            let xi_u = Pose::exp(&xi.fixed_rows::<6>(0).into_owned());
            let xi_j = Pose::exp(&xi.fixed_rows::<6>(6).into_owned());
            poses = ArchPoses {
                upper: xi_u.compose(&poses.upper),
                lower: xi_u.compose(&xi_j).compose(&poses.lower),
            };
            steps += 1;
            let size = |k: usize| {
                xi.fixed_rows::<3>(k).norm() * RADIUS_MM + xi.fixed_rows::<3>(k + 3).norm()
            };
            if size(0).max(size(6)) < SETTLE_MM {
                break;
            }
        }
    }
    JointAligned {
        poses,
        steps,
        samples: found,
        information,
    }
}

/// The edges' terms of the normal equations at the samples `frozen` moved by `moved` (each
/// arch's increment since they were drawn), and how many samples of each arch found an edge.
fn edge_terms(
    frozen: &[Sample],
    views: &[JointView],
    moved: &[Vector6<f64>; 2],
    reach: f64,
    lambda: f64,
    s: &GaussNewtonSettings,
) -> (Matrix12, Vector12, [usize; 2]) {
    // In chunks of a fixed size, summed in order: as fast on any number of threads, and the
    // same sums on all of them (a resumed run writes the very bytes of an uninterrupted one).
    let chunk_terms = |chunk: &[Sample]| {
        let mut h = Matrix12::zeros();
        let mut g = Vector12::zeros();
        let mut found = [0; 2];
        for c in chunk {
            let view = &views[c.view];
            let here = ContourPoint {
                pixel: c.point.pixel + c.point.jacobian * moved[c.arch],
                ..c.point
            };
            let Some(d) = edge_offset(&here, view.masks[c.arch], reach) else {
                continue;
            };
            // What the pixels between the sample and the edge cost (see the module's
            // note): past a silhouette, the model's pixels outside the mask; short of it,
            // the mask's pixels it leaves uncovered; past a BOI edge, BOI outside the mask.
            let cost = match (c.kind, d < 0.0) {
                (Kind::Silhouette { boi }, true) => {
                    let at = here.pixel + 0.5 * d * here.normal;
                    let extra = view.extra[c.arch].map_or(0.0, |e| e(at));
                    extra + if boi { lambda } else { 0.0 }
                }
                (Kind::Silhouette { .. }, false) => 1.0,
                (Kind::Region, true) => lambda,
                (Kind::Region, false) => 0.0,
            };
            if cost == 0.0 {
                continue;
            }
            // Tukey's weight on the offset, relative to the reach: an edge found far
            // off is as likely another edge.
            let u = d / reach;
            let tukey = (1.0 - u * u).max(0.0).powi(2);
            let w = cost * tukey * here.length / d.abs().max(s.smoothing_px);
            let mut row = Vector12::zeros();
            row.fixed_rows_mut::<6>(0).copy_from(&c.row);
            if c.arch == 1 {
                row.fixed_rows_mut::<6>(6).copy_from(&c.row);
            }
            h += w * row * row.transpose();
            g += w * d * row;
            found[c.arch] += 1;
        }
        (h, g, found)
    };
    let partial: Vec<_> = frozen
        .par_chunks(EDGE_TERMS_CHUNK)
        .map(chunk_terms)
        .collect();
    partial.into_iter().fold(
        (Matrix12::zeros(), Vector12::zeros(), [0; 2]),
        |(h, g, f), (ph, pg, pf)| (h + ph, g + pg, [f[0] + pf[0], f[1] + pf[1]]),
    )
}

/// Samples a thread sums at a time in [`edge_terms`].
const EDGE_TERMS_CHUNK: usize = 256;

/// The information the masks of `views` give about `poses` (as [`JointAligned::information`]),
/// at the finest reach: for frames another search found, so that the window weighs them too.
pub fn information_at(
    arches: [(&Mesh, &ContourEdges); 2],
    poses: &ArchPoses,
    views: &[JointView],
    apart: bool,
    lambda: f64,
    s: &GaussNewtonSettings,
) -> Matrix12 {
    let frozen = samples(arches, poses, views, apart, s.spacing_px);
    let reach = s.reaches_px.last().copied().unwrap_or(1.0);
    let still = [Vector6::zeros(); 2];
    edge_terms(&frozen, views, &still, reach, lambda, s).0
}

#[cfg(test)]
mod tests {
    use nalgebra::Vector3;

    use super::*;
    use crate::anatomy::{procedural_arch, rest_bite};
    use crate::energy::contour::bilinear;
    use crate::energy::raster::render_target;
    use crate::geometry::looking_at_origin;

    /// Both procedural arches at a bite opened by `open` (rad about the lateral axis), seen by
    /// three cameras 200 mm in front with per-arch teeth masks drawn at the truth, aligned
    /// from the truth moved by `offset` (upper) and `jaw_offset` (the jaw): each arch's
    /// error (degrees, mm) after.
    fn aligned(open: f64, offset: Vector6<f64>, jaw_offset: Vector6<f64>) -> [[f64; 2]; 2] {
        let (upper, lower) = (procedural_arch(true), procedural_arch(false));
        let bite = rest_bite(&upper, &lower);
        let truth_upper = Pose::from_translation(Vector3::new(0.0, 0.0, -10.0));
        let open = Pose::from_euler_tuple(&[open, 0.0, 0.0, 0.0, 0.0, 0.0]);
        let truth = ArchPoses {
            upper: truth_upper,
            lower: truth_upper.compose(&bite).compose(&open),
        };
        let cameras = [
            looking_at_origin(Vector3::new(0.0, 0.0, 200.0)),
            looking_at_origin(Vector3::new(90.0, 10.0, 180.0)),
            looking_at_origin(Vector3::new(-90.0, 10.0, 180.0)),
        ];
        let masks: Vec<Vec<u8>> = cameras
            .iter()
            .map(|c| {
                render_target(
                    c,
                    &[(&upper, &truth.upper, 1, 1), (&lower, &truth.lower, 2, 2)],
                )
                .class
            })
            .collect();
        type MaskRead<'a> = Box<dyn Fn(Vector2<f64>) -> f64 + Sync + 'a>;
        let reads: Vec<[MaskRead; 2]> = masks
            .iter()
            .map(|m| {
                [1u8, 2].map(|k| {
                    Box::new(move |x: Vector2<f64>| bilinear(m, 640, 480, |c| c == k, x))
                        as MaskRead
                })
            })
            .collect();
        let views: Vec<JointView> = cameras
            .iter()
            .zip(&reads)
            .map(|(camera, read)| JointView {
                camera,
                masks: [read[0].as_ref(), read[1].as_ref()],
                extra: [None, None],
            })
            .collect();
        let start_upper = Pose::exp(&offset).compose(&truth.upper);
        let start = ArchPoses {
            upper: start_upper,
            lower: start_upper
                .compose(&truth.jaw())
                .compose(&Pose::exp(&jaw_offset)),
        };
        let edges = [ContourEdges::of(&upper), ContourEdges::of(&lower)];
        let found = align_both(
            [(&upper, &edges[0]), (&lower, &edges[1])],
            start,
            &views,
            true,
            &[],
            0.4,
            &GaussNewtonSettings {
                reaches_px: vec![8.0, 4.0, 3.0, 3.0, 3.0],
                motion_prior: 0.0,
                ..GaussNewtonSettings::default()
            },
        );
        let err = |a: &Pose, b: &Pose| {
            let (r, t) = a.distance_to(b);
            [r.to_degrees(), t]
        };
        let out = [
            err(&found.poses.upper, &truth.upper),
            err(&found.poses.lower, &truth.lower),
        ];
        eprintln!(
            "from {:?} / {:?} to {out:?} in {} steps, samples {:?}",
            err(&start.upper, &truth.upper),
            err(&start.lower, &truth.lower),
            found.steps,
            found.samples
        );
        out
    }

    #[test]
    fn from_the_truth_both_arches_stay() {
        for open in [0.0, 0.15] {
            let [u, l] = aligned(open, Vector6::zeros(), Vector6::zeros());
            assert!(
                u[0] < 0.05 && u[1] < 0.02 && l[0] < 0.05 && l[1] < 0.02,
                "open {open}: {u:?} {l:?}"
            );
        }
    }

    /// With the mouth open both arches show their outlines (closed, the lower incisors hide
    /// behind the upper ones: the test from the truth above). From 1.5° and 1.5 mm off, more
    /// than a frame's motion, ten steps (five stages) bring each arch within a fifth of that.
    #[test]
    fn both_arches_come_back_to_their_masks() {
        let [u, l] = aligned(
            0.15,
            Vector6::new(0.02, -0.015, 0.01, 1.0, -0.8, 0.6),
            Vector6::new(-0.02, 0.01, 0.015, 0.5, 0.7, -0.5),
        );
        assert!(
            u[0] < 0.15 && u[1] < 0.1 && l[0] < 0.3 && l[1] < 0.15,
            "{u:?} {l:?}"
        );
    }
}
