//! Both arches found in one frame from its masks alone: where a capture has no init.json, and
//! where tracking has lost them.
//!
//! The masks and the cameras' geometry give a coarse pose; the energy and the Gauss-Newton
//! solver do the rest. The teeth pixels' centroids, triangulated, place the teeth; the subject
//! faces the cameras, so the arch's anterior axis points from the teeth to the cameras' mean
//! centre; the teeth form a band across each image, whose long axis, back-projected, is the
//! arch's left-right axis (each camera's plane through its centre and that axis holds it). The
//! cameras' own "up" gives a second guess at that roll, for a mouth so wide open that the band
//! stands upright. Which way is up along the roll is not told by a band (a half turn about the
//! anterior axis looks alike), and neither are the arch's pitch (the cameras may look from
//! below) or a few degrees of yaw: those are tried on a grid, each hypothesis moved until its
//! drawn teeth's centroids triangulate to the masks', and the energy ranks them. Where the
//! masks label the mouth, only what the arch draws inside the lips' opening counts as drawn:
//! the masks show nothing behind the lips. The lower arch comes from the jaw prior on the best
//! upper arches (both ways up, for the same reason), from its own masks as the upper did, and
//! from the prior's turns moved by the energy over a grid of offsets (the prior is an average
//! joint's, which a subject's wide-open jaw can lie a centimetre from), then Gauss-Newton
//! refines both together ([`JointFrame`]), tilting both about their left-right
//! axis to get out of the valley the lips leave (they hide the gums that would tell the tilt),
//! and the energy picks the result. Per-arch masks only: one label for both arches' teeth
//! leaves the pair's common rotation loose.

mod centroids;

use nalgebra::{Rotation3, Vector3};

use rayon::prelude::*;

pub use self::centroids::MIN_PIXELS;
use self::centroids::{Blob, Frame, View, blob, drawn_centre, views, world_frame};
use super::align::{AlignSettings, FrameReads};
use super::joint_frame::{JointFound, JointFrame};
use super::penalties::Penalties;
use super::prior::{JawPrior, centre};
use super::search::RADIUS_MM;
use super::settings::TrackSettings;
use crate::anatomy::scan_frame::scan_frame;
use crate::arch::{Arch, ArchPoses};
use crate::capture::{Capture, FrameMasks, MaskMode};
use crate::energy::contour::ContourEdges;
use crate::energy::{Energy, EnergyEngine, Weights};
use crate::error::{Error, Result};
use crate::geometry::{Camera, Pose};
use crate::mesh::Mesh;

/// The pitch grid (degrees about the arch's left-right axis) and yaw grid (about its up axis).
const PITCH_DEG: [f64; 7] = [-30.0, -20.0, -10.0, 0.0, 10.0, 20.0, 30.0];
const YAW_DEG: [f64; 3] = [-15.0, 0.0, 15.0];
/// How far (pixels) an arch's alignment looks for the masks' edges, coarse to fine: wider than
/// tracking's first reach, since a hypothesis is centred only to several mm (about a centimetre
/// where the lips hide much of the arch).
const REACHES_PX: [f64; 8] = [48.0, 32.0, 16.0, 8.0, 4.0, 2.0, 1.0, 1.0];
/// Jaw turns of the average joint closer than this (degrees) to one already tried are the
/// same: the offset grid and the solver take up the rest.
const SAME_TURN_DEG: f64 = 5.0;
/// The offsets (mm, step and reach per axis) a lower arch carried by the average joint is moved
/// by, coarse to fine: a subject's joint carries a wide-open jaw up to about a centimetre from
/// where the average one does.
const OFFSET_GRID_MM: [(f64, f64); 3] = [(4.0, 8.0), (2.0, 2.0), (1.0, 1.0)];
/// Centroid-matching rounds per hypothesis, at most.
const CENTRING_ROUNDS: usize = 4;
/// How many upper-arch hypotheses go on to the solver, and lower-arch ones beside the prior's.
const KEEP: usize = 4;
const KEEP_LOWER: usize = 2;
/// Hypotheses closer than this (mm: apart at the teeth, plus turned at an arch's radius) are
/// one: most of the grid's starts align to the same pose (the best four within 0.25 mm and
/// 0.75 degrees of each other on all of 18 frames of another program's captures), and the
/// solver takes a pair this close to the same answer.
const SAME_MM: f64 = 1.0;
/// The tilts (degrees) tried about the arches' left-right axis, coarse to fine.
const TILT_DEG: [u32; 3] = [4, 2, 1];
/// Solver runs per start at most, and the share of the objective a run must gain for
/// another.
const MAX_SOLVES: usize = 6;
const MIN_GAIN: f64 = 0.01;
/// A located frame whose objective exceeds this share of its mask pixels (on either arch) is
/// not trusted: the masks did not show the arches well enough to place them.
const MAX_MISFIT: f64 = 0.5;

/// What [`locate`] found.
pub struct Located {
    pub poses: ArchPoses,
    pub energies: [Energy; 2],
    /// Energy evaluations spent.
    pub evaluations: usize,
    /// The worse arch's objective per mask pixel: 0 for a perfect fit.
    pub misfit: f64,
}

/// A jaw pose (upper_from_lower) that puts each arch on the side of the other its `up` axes
/// (model frames) say: enough for the jaw prior, which takes only that from it.
fn jaw_guess(upper: &Mesh, lower: &Mesh, upper_up: &Vector3<f64>, lower_up: &Vector3<f64>) -> Pose {
    let (su, sl) = (scan_frame(upper, upper_up), scan_frame(lower, lower_up));
    let rotation = su.inverse() * sl;
    let (um, lm) = (upper.principal_axes().0, lower.principal_axes().0);
    let below = um - su.inverse() * Vector3::y() * 10.0;
    Pose::new(rotation, below - rotation * lm)
}

/// Why [`find`] found nothing.
enum NotFound {
    /// Combined masks: both arches' teeth are one label, and a pair of arches turned together
    /// by ten degrees fits them about as well as the true pair (measured: a 2.8 mm jaw median
    /// where the same capture with init.json has 0.37).
    Combined,
    /// The teeth show in this many cameras only.
    Unseen(usize),
    /// The teeth's centroids do not triangulate.
    Unplaced,
    /// The best pose's misfit: above [`MAX_MISFIT`]; and the evaluations spent.
    Misfit { misfit: f64, evaluations: usize },
}

/// Both arches' poses in the frame of `masks` (already given to `engine`), from the masks
/// alone. Errors (naming the capture's masks) when fewer than two cameras see the teeth or
/// when the best pose found does not fit them.
pub fn locate(
    capture: &Capture,
    engine: &dyn EnergyEngine,
    masks: &FrameMasks,
    settings: &TrackSettings,
    edges: &[ContourEdges; 2],
) -> Result<Located> {
    let problem = match find(capture, engine, masks, settings, edges)? {
        Ok(located) => return Ok(located),
        Err(NotFound::Unseen(n)) => format!(
            "the teeth show in {n} camera(s) (at least {MIN_PIXELS} mask pixels); placing the \
             arches without init.json needs two"
        ),
        Err(NotFound::Combined) => "with combined masks (one label for both arches' teeth) the \
            arches cannot be placed from the masks alone; give the first frame's poses in \
            init.json, or label each arch"
            .to_string(),
        Err(NotFound::Unplaced) => "the teeth's centroids in the cameras do not triangulate \
            to a point in front of them (check the cameras' calibration)"
            .to_string(),
        Err(NotFound::Misfit { misfit, .. }) => format!(
            "no pose of the arches fits these masks (best misfit {misfit:.2} of the mask \
             pixels, at most {MAX_MISFIT}); give the first frame's poses in init.json"
        ),
    };
    Err(Error::invalid(
        capture.mask_dir(),
        format!("frame {}", masks.frame),
        problem,
    ))
}

/// [`locate`] where finding nothing is an answer (a lost frame that stays lost), not an error;
/// and the energy evaluations spent, found or not.
pub fn relocate(
    capture: &Capture,
    engine: &dyn EnergyEngine,
    masks: &FrameMasks,
    settings: &TrackSettings,
    edges: &[ContourEdges; 2],
) -> Result<(Option<Located>, usize)> {
    Ok(match find(capture, engine, masks, settings, edges)? {
        Ok(located) => {
            let spent = located.evaluations;
            (Some(located), spent)
        }
        Err(NotFound::Misfit { evaluations, .. }) => (None, evaluations),
        Err(_) => (None, 0),
    })
}

fn find(
    capture: &Capture,
    engine: &dyn EnergyEngine,
    masks: &FrameMasks,
    settings: &TrackSettings,
    edges: &[ContourEdges; 2],
) -> Result<std::result::Result<Located, NotFound>> {
    if matches!(capture.mask_mode(), MaskMode::Combined) {
        return Ok(Err(NotFound::Combined));
    }
    let cameras: Vec<(Camera, &crate::capture::LabelMask)> = capture
        .cameras()
        .iter()
        .zip(&masks.masks)
        .filter_map(|(c, m)| Some((c.mask_camera()?, m.as_ref()?)))
        .collect();
    let teeth_bits = Arch::Upper.mask_bit() | Arch::Lower.mask_bit();
    let blobs = |bits: u8| -> Vec<Blob> {
        cameras
            .iter()
            .filter_map(|(c, m)| blob(c, m, bits))
            .collect()
    };
    let teeth = blobs(teeth_bits);
    if teeth.len() < 2 {
        return Ok(Err(NotFound::Unseen(teeth.len())));
    }
    // The upper arch's own pixels where the masks label it (its band is the one to roll by).
    let upper_blobs = blobs(Arch::Upper.mask_bit());
    let upper_seen = if upper_blobs.len() >= 2 {
        &upper_blobs
    } else {
        &teeth
    };
    let Some(frame) = world_frame(upper_seen) else {
        return Ok(Err(NotFound::Unplaced));
    };
    let opening = capture.mouth().is_some();
    let seen = views(upper_seen, opening);

    let (upper, lower) = (capture.upper(), capture.lower());
    let weights = settings.search.weights();
    let thinnest = upper.principal_axes().1[0];
    let scan = scan_frame(upper, &thinnest);
    // The upper arch's up (model frame): each hypothesis says where in the world it points.
    let up = scan.inverse() * Vector3::y();
    let anchor = anchor(upper);
    let reads = FrameReads::new(capture, masks);
    // The upper arch's hypotheses, aligned to its masks alone (the lower arch unknown yet).
    let hypotheses = arch_hypotheses(
        Arch::Upper,
        (upper, &edges[0]),
        &grid_starts(upper, &frame),
        &frame.teeth,
        &seen,
        &reads,
        &weights,
    );
    // The lower arch far behind the subject while the upper arch is ranked: it hides nothing.
    let away = Pose::from_translation(frame.teeth - frame.anterior * 5000.0);
    let candidates: Vec<ArchPoses> = hypotheses
        .iter()
        .map(|&upper| ArchPoses { upper, lower: away })
        .collect();
    let mut evaluations = candidates.len();
    let ranked = ranked_by_energy(engine, Arch::Upper, &candidates, &weights)?;
    // Which side of each arch the other lies on is the meshes' own business (their crowns face
    // each other): both ways, for each arch, and the energy decides.
    let lower_thinnest = lower.principal_axes().1[0];
    let priors: Vec<JawPrior> = [up, -up]
        .iter()
        .flat_map(|upper_up| {
            [lower_thinnest, -lower_thinnest].map(|lower_up| {
                JawPrior::new(
                    upper,
                    lower,
                    &jaw_guess(upper, lower, upper_up, &lower_up),
                    settings.jaw_prior_grid,
                    settings.jaw_prior_fine_grid,
                    settings.jaw_prior_nearest,
                    centre(capture, Arch::Lower),
                )
            })
        })
        .collect();
    // The lower arch from its own masks too: a subject's wide-open jaw can lie farther from
    // all of the average joint's poses than the solver reaches. Its hypotheses are the grid's,
    // and the turns the average joint gives it under the best upper arch, each moved to where
    // the energy says: a joint turns the jaw much as any other does, while where it carries a
    // wide-open one differs by up to a centimetre.
    let lower_blobs = blobs(Arch::Lower.mask_bit());
    let lower_own: Vec<Pose> = match world_frame(&lower_blobs) {
        Some(lower_frame) if lower_blobs.len() >= 2 => {
            let seen = views(&lower_blobs, opening);
            let mut jaws: Vec<Pose> = Vec::new();
            for jaw in priors.iter().flat_map(|p| &p.coarse) {
                if jaws
                    .iter()
                    .all(|j| j.rotation.angle_to(&jaw.rotation) > SAME_TURN_DEG.to_radians())
                {
                    jaws.push(*jaw);
                }
            }
            let carried = carried_by_jaws(engine, &ranked[0].1, &jaws, &weights, &mut evaluations)?;
            let found = arch_hypotheses(
                Arch::Lower,
                (lower, &edges[1]),
                &grid_starts(lower, &lower_frame),
                &lower_frame.teeth,
                &seen,
                &reads,
                &weights,
            );
            let with_upper: Vec<ArchPoses> = found
                .iter()
                .map(|&lower| ArchPoses {
                    upper: ranked[0].1,
                    lower,
                })
                .collect();
            evaluations += with_upper.len();
            ranked_by_energy(engine, Arch::Lower, &with_upper, &weights)?
                .into_iter()
                .take(KEEP_LOWER)
                .map(|(_, p)| p)
                .chain(carried)
                .collect()
        }
        _ => Vec::new(),
    };
    let mut best: Option<Located> = None;
    for upper_pose in distinct(ranked.iter().take(KEEP).map(|r| r.1), &anchor) {
        let (start, prior) = prior_start(engine, &priors, upper_pose, &weights, &mut evaluations)?;
        let solver = JointFrame {
            capture,
            search: &settings.search,
            prior,
            penalties: &Penalties::NONE,
            edges,
        };
        let mut found = refine(&solver, engine, masks, start, &weights, &mut evaluations)?;
        for &lower in &lower_own {
            let start = ArchPoses {
                upper: upper_pose,
                lower,
            };
            let other = refine(&solver, engine, masks, start, &weights, &mut evaluations)?;
            if total(&other, &weights) < total(&found, &weights) {
                found = other;
            }
        }
        // The nod: masks that show the teeth's edges and not the gums barely tell the occlusal
        // plane's tilt, and the solver stays near the tilt a hypothesis had; both arches are
        // tilted about their left-right axis, each tilt solved, while one pays.
        let left = found.poses.upper.rotation * (scan.inverse() * Vector3::x());
        for step in TILT_DEG {
            for sign in [-1.0, 1.0] {
                let pivot = found.poses.upper.transform_point(&anchor);
                let turn = Rotation3::from_axis_angle(
                    &nalgebra::Unit::new_normalize(left),
                    (sign * step as f64).to_radians(),
                );
                let tilt = Pose::new(turn, pivot - turn * pivot);
                let tilted = ArchPoses {
                    upper: tilt.compose(&found.poses.upper),
                    lower: tilt.compose(&found.poses.lower),
                };
                let other = refine(&solver, engine, masks, tilted, &weights, &mut evaluations)?;
                if total(&other, &weights) < total(&found, &weights) {
                    found = other;
                }
            }
        }
        // Each arch's objective per mask pixel: the worse arch says how well the frame fits.
        let misfit = found
            .energies
            .iter()
            .map(|e| e.objective(&weights) / e.mask_pixels().max(1) as f64)
            .fold(0.0, f64::max);
        if best.as_ref().is_none_or(|b| misfit < b.misfit) {
            best = Some(Located {
                poses: found.poses,
                energies: found.energies,
                evaluations: 0,
                misfit,
            });
        }
    }
    let mut best = best.expect("hypotheses");
    best.evaluations = evaluations;
    if best.misfit > MAX_MISFIT {
        return Ok(Err(NotFound::Misfit {
            misfit: best.misfit,
            evaluations,
        }));
    }
    Ok(Ok(best))
}

/// Of `priors` (each way up), the one whose coarse grid fits the masks best under `upper`, and
/// its best pose there.
fn prior_start<'p>(
    engine: &dyn EnergyEngine,
    priors: &'p [JawPrior],
    upper: Pose,
    weights: &Weights,
    evaluations: &mut usize,
) -> Result<(ArchPoses, &'p JawPrior)> {
    let mut best: Option<(f64, ArchPoses, &JawPrior)> = None;
    for prior in priors {
        let options: Vec<ArchPoses> = prior
            .coarse
            .iter()
            .map(|j| ArchPoses {
                upper,
                lower: upper.compose(j),
            })
            .collect();
        *evaluations += options.len();
        let energies = engine.evaluate(Arch::Lower, &options)?;
        for (option, energy) in options.iter().zip(energies) {
            let objective = energy.objective(weights);
            if best.as_ref().is_none_or(|b| objective < b.0) {
                best = Some((objective, *option, prior));
            }
        }
    }
    let (_, start, prior) = best.expect("the jaw priors' grids");
    Ok((start, prior))
}

/// Where an arch's teeth are (model frame): what a hypothesis is centred and tilted on.
fn anchor(mesh: &Mesh) -> Vector3<f64> {
    mesh.boi_centroid()
        .unwrap_or_else(|| mesh.principal_axes().0)
}

/// Those of `poses` (in their order) that are not the same as one before them ([`SAME_MM`],
/// apart at `anchor`).
fn distinct(poses: impl Iterator<Item = Pose>, anchor: &Vector3<f64>) -> Vec<Pose> {
    let mut kept: Vec<Pose> = Vec::new();
    for pose in poses {
        let same = |k: &Pose| {
            let apart = (k.transform_point(anchor) - pose.transform_point(anchor)).norm();
            apart + k.distance_to(&pose).0 * RADIUS_MM < SAME_MM
        };
        if !kept.iter().any(same) {
            kept.push(pose);
        }
    }
    kept
}

/// Where an arch's hypotheses in `frame` start (the roll guesses its masks' band gives): its
/// scan frame turned to each roll and to each pitch and yaw of the grid, its teeth on the
/// masks' triangulated centroid.
fn grid_starts(mesh: &Mesh, frame: &Frame) -> Vec<Pose> {
    let scan = scan_frame(mesh, &mesh.principal_axes().1[0]);
    let anchor = anchor(mesh);
    let mut starts = Vec::new();
    for axes in &frame.axes {
        for pitch in PITCH_DEG {
            for yaw in YAW_DEG {
                let turn = Rotation3::from_axis_angle(&Vector3::y_axis(), yaw.to_radians())
                    * Rotation3::from_axis_angle(&Vector3::x_axis(), pitch.to_radians());
                let rotation = axes * turn * scan;
                starts.push(Pose::new(rotation, frame.teeth - rotation * anchor));
            }
        }
    }
    starts
}

/// An arch's hypotheses from `starts`: each moved while that brings its drawn teeth's
/// centroids, triangulated, nearer the masks' (`teeth`, in the cameras `seen`), then aligned
/// to its own masks alone. A move is kept only where it brings them nearer: the part of an arch
/// the lips' opening shows changes as it moves, and with it the drawn centroid.
fn arch_hypotheses(
    arch: Arch,
    (mesh, edges): (&Mesh, &ContourEdges),
    starts: &[Pose],
    teeth: &Vector3<f64>,
    seen: &[View],
    reads: &FrameReads,
    weights: &Weights,
) -> Vec<Pose> {
    let align_settings = AlignSettings {
        reaches_px: REACHES_PX.to_vec(),
        ..AlignSettings::default()
    };
    starts
        .par_iter()
        .map(|&start| {
            let mut pose = start;
            let mut off = drawn_centre(arch, mesh, &pose, seen).map(|d| teeth - d);
            for _ in 0..CENTRING_ROUNDS {
                let Some(step) = off else { break };
                let moved = Pose::new(pose.rotation, pose.translation + step);
                match drawn_centre(arch, mesh, &moved, seen).map(|d| teeth - d) {
                    Some(after) if after.norm() < step.norm() => {
                        pose = moved;
                        off = Some(after);
                    }
                    _ => break,
                }
            }
            reads
                .align(arch, weights, (mesh, edges), pose, &[], &align_settings)
                .pose
        })
        .collect()
}

/// The lower arch turned by each of `jaws` under `upper` and moved, by the energy, to where its
/// masks say: a grid of offsets, coarse to fine, about the joint's own position. The best
/// `KEEP_LOWER` turns, each at its best offset.
fn carried_by_jaws(
    engine: &dyn EnergyEngine,
    upper: &Pose,
    jaws: &[Pose],
    weights: &Weights,
    evaluations: &mut usize,
) -> Result<Vec<Pose>> {
    let mut best: Vec<(f64, Pose)> = jaws
        .iter()
        .map(|j| (f64::INFINITY, upper.compose(j)))
        .collect();
    for (stage, &(step, reach)) in OFFSET_GRID_MM.iter().enumerate() {
        if stage == 1 {
            best.sort_by(|a, b| a.0.total_cmp(&b.0));
            best.truncate(KEEP_LOWER);
        }
        let n = (reach / step).round() as i32;
        let offsets: Vec<Vector3<f64>> = (-n..=n)
            .flat_map(|x| (-n..=n).flat_map(move |y| (-n..=n).map(move |z| (x, y, z))))
            .map(|(x, y, z)| Vector3::new(x as f64, y as f64, z as f64) * step)
            .collect();
        let options: Vec<ArchPoses> = best
            .iter()
            .flat_map(|(_, lower)| {
                offsets.iter().map(|d| ArchPoses {
                    upper: *upper,
                    lower: Pose::new(lower.rotation, lower.translation + d),
                })
            })
            .collect();
        *evaluations += options.len();
        let energies = engine.evaluate(Arch::Lower, &options)?;
        for (k, chunk) in options
            .chunks(offsets.len())
            .zip(energies.chunks(offsets.len()))
            .enumerate()
        {
            for (option, energy) in chunk.0.iter().zip(chunk.1) {
                let objective = energy.objective(weights);
                if objective < best[k].0 {
                    best[k] = (objective, option.lower);
                }
            }
        }
    }
    Ok(best.into_iter().map(|(_, p)| p).collect())
}

/// `arch`'s pose in each of `options`, best first by its objective there.
fn ranked_by_energy(
    engine: &dyn EnergyEngine,
    arch: Arch,
    options: &[ArchPoses],
    weights: &Weights,
) -> Result<Vec<(f64, Pose)>> {
    let scores = engine.evaluate(arch, options)?;
    let mut ranked: Vec<(f64, Pose)> = scores
        .iter()
        .zip(options)
        .map(|(e, o)| (e.objective(weights), *o.get(arch)))
        .collect();
    ranked.sort_by(|a, b| a.0.total_cmp(&b.0));
    Ok(ranked)
}

/// Both arches' objectives.
fn total(found: &JointFound, weights: &Weights) -> f64 {
    found.energies.iter().map(|e| e.objective(weights)).sum()
}

/// The solver's stages from `start`, and again from where they ended while that still pays:
/// a start this far off needs more than a tracked frame's few steps.
fn refine(
    solver: &JointFrame,
    engine: &dyn EnergyEngine,
    masks: &FrameMasks,
    start: ArchPoses,
    weights: &Weights,
    evaluations: &mut usize,
) -> Result<JointFound> {
    let mut found = solver.solve(engine, masks, &[start], None)?;
    *evaluations += found.evaluations;
    for _ in 1..MAX_SOLVES {
        let again = solver.solve(engine, masks, &[found.poses], None)?;
        *evaluations += again.evaluations;
        let gained = total(&again, weights) < total(&found, weights) * (1.0 - MIN_GAIN);
        if total(&again, weights) <= total(&found, weights) {
            found = again;
        }
        if !gained {
            break;
        }
    }
    Ok(found)
}
