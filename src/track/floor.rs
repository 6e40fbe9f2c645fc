//! The energy's floor: how close to the truth the energy's own minimum lies. A long, fine
//! search finds it, started both at the true poses and at the tracked ones (and Gauss-Newton's
//! steps from the truth, the smooth energy's); a tracked frame is then told apart from the
//! floor by its error and by its objective (higher: the search stopped short; the same: the
//! energy cannot tell the poses apart).
//!
//! Why two starts: E counts whole pixels, and where the masks' errors are the same in every
//! frame its low ground is a valley half a millimetre long, not a point. A search started at
//! the truth stops on the valley's near end and would report what E cannot tell as what it
//! can (docs/energy.md, "The floor from two starts").

use super::joint::align_both;
use super::joint_frame::{with_hinges, with_views};
use super::penalties::Penalties;
use super::prior::centre;
use super::score::FlagScore;
use super::search::{ArchSearch, GaussNewtonSettings, SearchSettings, search};
use crate::anatomy::MeshMetric;
use crate::arch::{Arch, ArchPoses};
use crate::capture::{Capture, FrameMasks, MaskMode};
use crate::energy::contour::ContourEdges;
use crate::energy::{EnergyEngine, Weights};
use crate::error::Result;
use crate::stats::Stats;

/// An objective higher than the floor's by more than this (pixels) counts as a search that
/// stopped short: below it, the two differ by the rounding of a few pixels.
pub const SHORTFALL_PX: f64 = 0.5;

/// The search's objective (E plus the terms of our own, at `weights`) of both arches.
pub fn objective_sum(
    engine: &dyn EnergyEngine,
    poses: &ArchPoses,
    weights: &Weights,
) -> Result<f64> {
    let mut sum = 0.0;
    for arch in Arch::BOTH {
        sum += engine.evaluate(arch, std::slice::from_ref(poses))?[0].objective(weights);
    }
    Ok(sum)
}

/// The floor's poses: the objective (at `weights`, without penalties) minimised by a long,
/// fine search from the true poses and from `tracked` (upper, then lower), the lower of the
/// two. `engine` holds the frame's masks.
pub fn floor_poses(
    capture: &Capture,
    engine: &dyn EnergyEngine,
    (truth, tracked): (&ArchPoses, &ArchPoses),
    frame: u32,
    weights: &Weights,
) -> Result<ArchPoses> {
    let from_truth = floor_from(capture, engine, truth, frame, weights)?;
    if tracked == truth {
        return Ok(from_truth);
    }
    let from_tracked = floor_from(capture, engine, tracked, frame, weights)?;
    let lower = objective_sum(engine, &from_tracked, weights)?
        < objective_sum(engine, &from_truth, weights)?;
    Ok(if lower { from_tracked } else { from_truth })
}

/// The objective minimised by a long, fine search from `start` (upper, then lower).
fn floor_from(
    capture: &Capture,
    engine: &dyn EnergyEngine,
    start: &ArchPoses,
    frame: u32,
    weights: &Weights,
) -> Result<ArchPoses> {
    let fine = SearchSettings {
        max_rounds: 40,
        min_gain: 0.1,
        sample_rounds: 4,
        samples: 64,
        scales: vec![1.0, 0.25, 0.06],
        lambda: weights.lambda,
        cross_weight: weights.cross,
        mouth_weight: weights.mouth,
        ..SearchSettings::default()
    };
    let mut poses = *start;
    for arch in Arch::BOTH {
        let centre = centre(capture, arch);
        let found = search(
            engine,
            &ArchSearch {
                arch,
                from: poses,
                centre: &centre,
                penalties: &Penalties::NONE,
                settings: &fine,
                seed: frame as u64,
            },
        )?;
        poses = poses.with(arch, found.pose);
    }
    Ok(poses)
}

/// The floor of what Gauss-Newton minimises (the smooth energy, `energy::smooth`, with the
/// run's `penalties` as residuals): its steps from the true poses, at the finest reach of
/// `gn`, until they settle, without the motion prior (which holds a frame where the last one
/// left it). `engine` holds the frame's `masks`.
pub fn smooth_floor_poses(
    capture: &Capture,
    engine: &dyn EnergyEngine,
    masks: &FrameMasks,
    truth: &ArchPoses,
    (weights, gn): (&Weights, &GaussNewtonSettings),
    penalties: &Penalties,
) -> Result<ArchPoses> {
    let finest = gn.reaches_px.last().copied().unwrap_or(3.0);
    let settings = GaussNewtonSettings {
        reaches_px: vec![finest; 5],
        coarse_stages: 0,
        steps: 4,
        motion_prior: 0.0,
        ..gn.clone()
    };
    let edges = [
        ContourEdges::of(capture.upper()),
        ContourEdges::of(capture.lower()),
    ];
    let arches = [(capture.upper(), &edges[0]), (capture.lower(), &edges[1])];
    let apart = matches!(capture.mask_mode(), MaskMode::PerArch { .. });
    let found = with_hinges(penalties, gn, |hinges| {
        with_views(capture, engine, masks, |views| {
            align_both(
                arches,
                *truth,
                (views, None),
                apart,
                hinges,
                weights,
                &settings,
            )
        })
    })?;
    Ok(found.poses)
}

/// One tracked frame against the floor.
#[derive(Debug, Clone, Copy)]
pub struct FloorCheck {
    /// The floor's jaw error (mm, mean vertex error on the lower arch).
    pub jaw_mm: f64,
    /// The smooth energy's floor's jaw error (mm; [`smooth_floor_poses`]).
    pub smooth_jaw_mm: f64,
    /// The objective of both arches, tracked and at the floor.
    pub tracked: f64,
    pub floor: f64,
}

impl FloorCheck {
    /// `tracked` against the floors of `truth`; `engine` holds the frame's `masks`, and
    /// `penalties` are the run's.
    pub fn of(
        capture: &Capture,
        engine: &dyn EnergyEngine,
        masks: &FrameMasks,
        (truth, tracked): (&ArchPoses, &ArchPoses),
        (search, penalties): (&SearchSettings, &Penalties),
    ) -> Result<FloorCheck> {
        let weights = &search.weights();
        let floor = floor_poses(capture, engine, (truth, tracked), masks.frame, weights)?;
        let gn = (weights, &search.gauss_newton);
        let smooth = smooth_floor_poses(capture, engine, masks, truth, gn, penalties)?;
        let metric = MeshMetric::new(capture.lower());
        Ok(FloorCheck {
            jaw_mm: metric.mean_distance(&floor.jaw(), &truth.jaw()),
            smooth_jaw_mm: metric.mean_distance(&smooth.jaw(), &truth.jaw()),
            tracked: objective_sum(engine, tracked, weights)?,
            floor: objective_sum(engine, &floor, weights)?,
        })
    }

    pub fn stopped_short(&self) -> bool {
        self.tracked > self.floor + SHORTFALL_PX
    }
}

/// Tracked frames against the truth and the floor, over any number of captures.
#[derive(Debug, Clone, Default)]
pub struct FloorTally {
    /// Per frame: the mean vertex error (mm) of the upper arch, the lower and the jaw.
    errors: [Vec<f64>; 3],
    floors: Vec<f64>,
    smooth_floors: Vec<f64>,
    ratios: Vec<f64>,
    shortfalls: usize,
    /// Per capture, the median area error (%) of the upper and the lower arch.
    area_percent: [Vec<f64>; 2],
    /// The flags against the truth, pooled: frames off by more than `WRONG_MM` (flagged or
    /// not), the others (flagged or not), and the frames flagged with their teeth hidden.
    flags: FlagCounts,
    pub seconds: f64,
    pub evaluations: usize,
    /// Gauss-Newton steps (each a Jacobian of every silhouette sample).
    pub steps: usize,
    pub frames: usize,
}

/// How a run's flags (`low-confidence`, `no-data`) met the truth, summed over captures.
#[derive(Debug, Clone, Copy, Default, serde::Serialize)]
pub struct FlagCounts {
    /// Frames whose jaw is off by more than [`WRONG_MM`](super::score::WRONG_MM), and how many
    /// of them are flagged.
    pub wrong: usize,
    pub wrong_flagged: usize,
    /// The other frames, and how many of them are flagged anyway.
    pub right: usize,
    pub right_flagged: usize,
    /// Flagged frames whose masks hid the teeth.
    pub teeth_hidden: usize,
}

/// What a tally comes to: medians and 95th percentiles, the floor's where it was measured.
#[derive(Debug, Clone, Copy, serde::Serialize)]
pub struct FloorSummary {
    pub frames: usize,
    pub seconds_per_frame: f64,
    pub evaluations_per_frame: f64,
    /// Gauss-Newton steps a frame: the derivative evaluations.
    pub steps_per_frame: f64,
    /// Jaw and per-arch mean vertex error (mm): median, 95th percentile.
    pub jaw_error_mm: [f64; 2],
    pub upper_error_mm: [f64; 2],
    pub lower_error_mm: [f64; 2],
    /// The error of E's minimum found from the truth (jaw; median, 95th percentile).
    pub jaw_floor_mm: [f64; 2],
    /// The same of the smooth energy's minimum ([`smooth_floor_poses`]).
    pub jaw_smooth_floor_mm: [f64; 2],
    /// Median over frames of tracked error / floor (jaw; floors under 0.01 mm count as 0.01).
    pub median_ratio_to_floor: f64,
    /// Share of frames whose tracked poses have a higher objective than the floor's.
    pub search_shortfall: f64,
    pub area_error_percent_median: [f64; 2],
    pub flags: FlagCounts,
}

impl FloorTally {
    /// A tracked frame's errors (upper, lower, jaw), with its floor when measured.
    pub fn frame(&mut self, errors: [f64; 3], floor: Option<FloorCheck>) {
        for (list, e) in self.errors.iter_mut().zip(errors) {
            list.push(e);
        }
        if let Some(f) = floor {
            self.floors.push(f.jaw_mm);
            self.smooth_floors.push(f.smooth_jaw_mm);
            self.ratios.push(errors[2] / f.jaw_mm.max(0.01));
            self.shortfalls += f.stopped_short() as usize;
        }
    }

    /// A capture's flags against the truth (`score`'s), and how many of its frames were
    /// flagged with their teeth hidden.
    pub fn capture_flags(&mut self, f: &FlagScore, teeth_hidden: usize) {
        let t = &mut self.flags;
        t.wrong += f.wrong;
        t.wrong_flagged += f.wrong_flagged;
        t.right += f.right;
        t.right_flagged += f.right_flagged;
        t.teeth_hidden += teeth_hidden;
    }

    /// A capture's median area errors (%), upper and lower.
    pub fn capture_area_errors(&mut self, median_percent: [f64; 2]) {
        for (list, e) in self.area_percent.iter_mut().zip(median_percent) {
            list.push(e);
        }
    }

    /// The summary; the floor's figures are NaN where no floor was measured.
    pub fn summary(&self) -> FloorSummary {
        let two = |v: &[f64]| {
            let s = Stats::of(v);
            [s.median, s.p95]
        };
        let measured = !self.floors.is_empty();
        let floor_or_nan = |v: f64| if measured { v } else { f64::NAN };
        let per_frame = |v: f64| v / self.frames.max(1) as f64;
        FloorSummary {
            frames: self.frames,
            seconds_per_frame: per_frame(self.seconds),
            evaluations_per_frame: per_frame(self.evaluations as f64),
            steps_per_frame: per_frame(self.steps as f64),
            jaw_error_mm: two(&self.errors[2]),
            upper_error_mm: two(&self.errors[0]),
            lower_error_mm: two(&self.errors[1]),
            jaw_floor_mm: two(&self.floors).map(floor_or_nan),
            jaw_smooth_floor_mm: two(&self.smooth_floors).map(floor_or_nan),
            median_ratio_to_floor: floor_or_nan(Stats::of(&self.ratios).median),
            search_shortfall: floor_or_nan(
                self.shortfalls as f64 / self.errors[2].len().max(1) as f64,
            ),
            area_error_percent_median: self.area_percent.each_ref().map(|v| Stats::of(v).median),
            flags: self.flags,
        }
    }
}
