//! Tracking a capture frame by frame (the driver around `search`): each frame starts from the
//! previous one, extrapolated at constant velocity when that fits the new masks better; masks
//! are read on a thread one frame ahead; every finished frame goes to an observer (the output
//! writer and the progress bar), so memory does not grow with the masks of past frames.

use std::collections::VecDeque;
use std::sync::mpsc::sync_channel;
use std::time::Instant;

use nalgebra::Vector3;

use super::search::{SearchSettings, search};
use crate::capture::{Arch, ArchPoses, Capture, FrameMasks, MaskMode};
use crate::energy::{Energy, EnergyEngine};
use crate::error::Result;
use crate::geometry::Pose;

#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub struct TrackSettings {
    pub search: SearchSettings,
    /// Passes over the two arches per frame (upper, then lower with the new upper). With
    /// combined masks the arches compete for the same pixels and alternate until neither moves
    /// more than `settle_mm`, at most `combined_passes` times; per-arch masks need one pass.
    pub per_arch_passes: usize,
    pub combined_passes: usize,
    pub settle_mm: f64,
    /// A frame is `low-confidence` when an arch's area error (uncovered / mask pixels) exceeds
    /// `low_confidence_area_error`, or both `low_confidence_floor` and `low_confidence_ratio`
    /// times the median area error of the last `confidence_window` good frames (a sudden
    /// jump; the floor keeps clean data, whose area error is near zero, from tripping it).
    pub low_confidence_area_error: f64,
    pub low_confidence_floor: f64,
    pub low_confidence_ratio: f64,
    pub confidence_window: usize,
    /// Extra starts for the lower arch from an average temporomandibular joint fitted to the
    /// capture's meshes (the jaw moves on a low-dimensional manifold): a grid of this many
    /// openings, lateral excursions and protrusions, each placed on the frame's upper arch;
    /// the energy picks among them and the usual starts. Per-arch masks only. [0, 0, 0] turns
    /// it off.
    pub jaw_prior_grid: [usize; 3],
}

impl Default for TrackSettings {
    fn default() -> Self {
        TrackSettings {
            search: SearchSettings::default(),
            per_arch_passes: 1,
            combined_passes: 3,
            settle_mm: 0.02,
            low_confidence_area_error: 0.25,
            low_confidence_floor: 0.03,
            low_confidence_ratio: 2.5,
            confidence_window: 15,
            jaw_prior_grid: [7, 5, 3],
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Status {
    Ok,
    LowConfidence,
    NoData,
}

impl Status {
    pub fn as_str(self) -> &'static str {
        match self {
            Status::Ok => "ok",
            Status::LowConfidence => "low-confidence",
            Status::NoData => "no-data",
        }
    }
}

/// One tracked frame.
#[derive(Debug, Clone)]
pub struct FrameResult {
    pub frame: u32,
    pub poses: ArchPoses,
    /// Final energies (upper, lower); `None` for a frame without data.
    pub energies: Option<[Energy; 2]>,
    pub status: Status,
    pub evaluations: usize,
    pub seconds: f64,
}

/// Where tracking stands: the last poses (and the ones before, for the velocity) and recent
/// area errors of good frames.
#[derive(Debug, Clone)]
pub struct TrackState {
    /// The last good poses, and the good ones of the frame before (for the velocity).
    pub last: ArchPoses,
    pub before: Option<ArchPoses>,
    /// The estimate of a low-confidence frame since the last good one: the next frame also
    /// tries to start from it (the motion may have gone on).
    pub since_good: Option<ArchPoses>,
    pub recent_area_errors: VecDeque<f64>,
}

impl TrackState {
    pub fn new(first: ArchPoses) -> Self {
        TrackState {
            last: first,
            before: None,
            since_good: None,
            recent_area_errors: VecDeque::new(),
        }
    }
}

/// The centre of an arch in its model frame (rotations of the search turn about it).
pub fn centre(capture: &Capture, arch: Arch) -> Vector3<f64> {
    let (lo, hi) = capture.mesh(arch).bounds();
    Vector3::new(
        (lo[0] + hi[0]) as f64,
        (lo[1] + hi[1]) as f64,
        (lo[2] + hi[2]) as f64,
    ) * 0.5
}

/// Constant-velocity prediction: the last motion applied once more.
fn extrapolate(last: &Pose, before: &Pose) -> Pose {
    last.compose(&before.inverse()).compose(last)
}

/// Track `frames` (in order), starting from `state`; `on_frame` receives every frame with its
/// masks (for overlays, without reading them again).
pub fn track_frames(
    capture: &Capture,
    engine: &mut dyn EnergyEngine,
    settings: &TrackSettings,
    frames: std::ops::Range<u32>,
    state: &mut TrackState,
    on_frame: &mut dyn FnMut(&FrameResult, &FrameMasks) -> Result<()>,
) -> Result<()> {
    let centres = [centre(capture, Arch::Upper), centre(capture, Arch::Lower)];
    // With combined masks a lower-arch candidate can win by covering the upper arch's pixels
    // (measured: jaw median 5.98 → 7.13 mm with the prior), so the prior is for per-arch masks.
    let prior = match capture.mask_mode {
        MaskMode::PerArch { .. } => jaw_prior(capture, settings.jaw_prior_grid),
        MaskMode::Combined => Vec::new(),
    };
    std::thread::scope(|scope| {
        let (tx, rx) = sync_channel::<(u32, Result<FrameMasks>)>(2);
        let reader_frames = frames.clone();
        scope.spawn(move || {
            for f in reader_frames {
                if tx.send((f, capture.load_masks(f))).is_err() {
                    break; // the tracker stopped
                }
            }
        });
        for (frame, masks) in rx {
            let started = Instant::now();
            let masks = masks?;
            let result = track_frame(
                capture, engine, settings, &centres, &prior, frame, &masks, state,
            )?;
            let result = FrameResult {
                seconds: started.elapsed().as_secs_f64(),
                ..result
            };
            on_frame(&result, &masks)?;
        }
        Ok(())
    })
}

/// Jaw poses (upper_from_lower) over a grid of an average joint's controls, the joint placed
/// from the capture's meshes as `synth` places it (it assumes the scan frame: y up, +z
/// anterior; on meshes in another frame the candidates are wrong, and the energy ignores them).
fn jaw_prior(capture: &Capture, grid: [usize; 3]) -> Vec<Pose> {
    use crate::synth::tmj::{JawControls, JawModel};
    if grid.contains(&0) {
        return Vec::new();
    }
    let rest = crate::synth::arches::rest_bite(&capture.upper, &capture.lower);
    let model = JawModel::for_arches(&capture.upper, rest);
    let steps = |n: usize, lo: f64, hi: f64| -> Vec<f64> {
        (0..n)
            .map(|i| {
                if n == 1 {
                    lo
                } else {
                    lo + (hi - lo) * i as f64 / (n - 1) as f64
                }
            })
            .collect()
    };
    let mut out = Vec::new();
    for open in steps(grid[0], 0.0, 1.0) {
        for lateral in steps(grid[1], -1.0, 1.0) {
            for protrusion in steps(grid[2], 0.0, 1.0) {
                out.push(model.jaw_pose(&JawControls {
                    open,
                    lateral,
                    protrusion,
                }));
            }
        }
    }
    out
}

#[allow(clippy::too_many_arguments)]
fn track_frame(
    capture: &Capture,
    engine: &mut dyn EnergyEngine,
    settings: &TrackSettings,
    centres: &[Vector3<f64>; 2],
    prior: &[Pose],
    frame: u32,
    masks: &FrameMasks,
    state: &mut TrackState,
) -> Result<FrameResult> {
    if masks.masks.iter().all(Option::is_none) {
        // No camera saw anything: keep the last good pose; the velocity restarts after.
        state.before = None;
        state.since_good = state.since_good.or(Some(state.last));
        return Ok(FrameResult {
            frame,
            poses: state.last,
            energies: None,
            status: Status::NoData,
            evaluations: 0,
            seconds: 0.0,
        });
    }
    engine.set_frame(masks)?;
    let objective = |e: &Energy| e.objective(settings.search.lambda, settings.search.cross_weight);
    let mut evaluations = 0;
    // Start, per arch, from whichever fits this frame best: the last good pose, its
    // constant-velocity extrapolation, or the latest low-confidence estimate since.
    let mut starts = vec![state.last];
    if let Some(before) = &state.before {
        starts.push(ArchPoses {
            upper: extrapolate(&state.last.upper, &before.upper),
            lower: extrapolate(&state.last.lower, &before.lower),
        });
    }
    starts.extend(state.since_good);
    let mut poses = state.last;
    if starts.len() > 1 || !prior.is_empty() {
        for arch in Arch::BOTH {
            let mut options: Vec<ArchPoses> = starts
                .iter()
                .map(|s| poses.with(arch, *s.get(arch)))
                .collect();
            if arch == Arch::Lower {
                // The jaw prior, on the upper arch as just chosen.
                options.extend(
                    prior
                        .iter()
                        .map(|j| poses.with(arch, poses.upper.compose(j))),
                );
            }
            let e = engine.evaluate(arch, &options)?;
            evaluations += options.len();
            let best = (0..e.len())
                .min_by(|&i, &j| objective(&e[i]).total_cmp(&objective(&e[j])))
                .expect("starts");
            poses = options[best];
        }
    }
    let passes = match capture.mask_mode {
        MaskMode::PerArch { .. } => settings.per_arch_passes,
        MaskMode::Combined => settings.combined_passes,
    };
    for pass in 0..passes.max(1) {
        let mut moved: f64 = 0.0;
        for arch in Arch::BOTH {
            let seed = (frame as u64) << 8 | (pass as u64) << 1 | (arch == Arch::Lower) as u64;
            let found = search(
                &*engine,
                arch,
                &poses,
                *poses.get(arch),
                &centres[(arch == Arch::Lower) as usize],
                &settings.search,
                seed,
            )?;
            evaluations += found.evaluations;
            let (r, t) = poses.get(arch).distance_to(&found.pose);
            moved = moved.max(t + r * 30.0); // 30 mm: about an arch's radius
            poses = poses.with(arch, found.pose);
        }
        if moved < settings.settle_mm {
            break;
        }
    }
    let upper = engine.evaluate(Arch::Upper, &[poses])?.remove(0);
    let lower = engine.evaluate(Arch::Lower, &[poses])?.remove(0);
    evaluations += 2;
    let worst_area_error = upper.area_error().max(lower.area_error());
    let mut recent: Vec<f64> = state.recent_area_errors.iter().copied().collect();
    recent.sort_by(f64::total_cmp);
    let typical = recent.get(recent.len() / 2).copied();
    // A sudden jump over the recent typical area error; the floor keeps clean data, whose
    // area error is near zero, from tripping it.
    let jump = typical.is_some_and(|m| {
        recent.len() >= 3
            && worst_area_error
                > (settings.low_confidence_ratio * m).max(settings.low_confidence_floor)
    });
    let poor = worst_area_error > settings.low_confidence_area_error || jump;
    let status = if poor {
        Status::LowConfidence
    } else {
        Status::Ok
    };
    if status == Status::Ok {
        // The velocity needs two good frames in a row.
        state.before = state.since_good.is_none().then_some(state.last);
        state.since_good = None;
        state.last = poses;
        state.recent_area_errors.push_back(worst_area_error);
        if state.recent_area_errors.len() > settings.confidence_window {
            state.recent_area_errors.pop_front();
        }
    } else {
        // The last good pose stays a start; so does this estimate.
        state.since_good = Some(poses);
    }
    Ok(FrameResult {
        frame,
        poses,
        energies: Some([upper, lower]),
        status,
        evaluations,
        seconds: 0.0,
    })
}
