//! Scoring tracked poses against ground truth: per arch and for the jaw (lower relative to
//! upper), the mean vertex distance (mm), rotation error (deg) and translation error (mm), and
//! the paper's area error; median, 95th percentile and maximum over frames.

use crate::anatomy::MeshMetric;
use crate::arch::{Arch, ArchPoses};
use crate::capture::Capture;
use crate::formats::{FrameRecordJson, Status};

pub use crate::stats::Stats;

#[derive(Debug, Clone, serde::Serialize)]
pub struct PoseErrors {
    pub mean_vertex_mm: Stats,
    pub rotation_deg: Stats,
    pub translation_mm: Stats,
}

#[derive(Debug, Clone, serde::Serialize)]
pub struct ScoreReport {
    /// What the poses are scored against: `ground truth`, or another run's file.
    pub reference: String,
    pub frames: usize,
    pub frames_ok: usize,
    pub frames_low_confidence: usize,
    /// Of the `low-confidence` frames, those flagged because the masks hid the teeth.
    pub frames_teeth_hidden: usize,
    /// Of the `low-confidence` frames, those flagged as the first found again after a loss.
    pub frames_recovered: usize,
    pub frames_no_data: usize,
    pub upper: PoseErrors,
    pub lower: PoseErrors,
    pub jaw: PoseErrors,
    /// Area error (uncovered / mask pixels) in percent, upper and lower.
    pub area_error_percent: [Stats; 2],
    /// Per frame: mean vertex error (mm) of upper, lower and jaw.
    pub per_frame: Vec<(u32, [f64; 3])>,
    /// How well the frames' flags (`low-confidence`, `no-data`) tell where the jaw is wrong.
    pub flags: FlagScore,
}

/// The frames' flags against the jaw's true error: a flag should mean what it says.
#[derive(Debug, Clone, serde::Serialize)]
pub struct FlagScore {
    /// A frame is wrong when its jaw's mean vertex error exceeds this (mm).
    pub wrong_mm: f64,
    pub wrong: usize,
    /// Wrong frames that are flagged.
    pub wrong_flagged: usize,
    pub right: usize,
    /// Right frames that are flagged anyway.
    pub right_flagged: usize,
    /// wrong_flagged / wrong (1 when no frame is wrong).
    pub recall: f64,
    /// right_flagged / right (0 when every frame is wrong).
    pub false_flag_rate: f64,
}

/// A frame is wrong past this jaw error (mm): the bar for a flag.
pub const WRONG_MM: f64 = 1.0;

impl FlagScore {
    /// From each frame's jaw error (mm) and whether it is flagged.
    pub fn of(frames: &[(f64, bool)], wrong_mm: f64) -> FlagScore {
        let count = |wrong: bool, flagged: bool| {
            frames
                .iter()
                .filter(|(e, f)| (*e > wrong_mm) == wrong && (!flagged || *f))
                .count()
        };
        let (wrong, wrong_flagged) = (count(true, false), count(true, true));
        let (right, right_flagged) = (count(false, false), count(false, true));
        FlagScore {
            wrong_mm,
            wrong,
            wrong_flagged,
            right,
            right_flagged,
            recall: if wrong == 0 {
                1.0
            } else {
                wrong_flagged as f64 / wrong as f64
            },
            false_flag_rate: if right == 0 {
                0.0
            } else {
                right_flagged as f64 / right as f64
            },
        }
    }
}

/// Score `tracked` (poses per frame, with their records for status and area error) against
/// the capture's ground truth; frames without ground truth are skipped.
pub fn score(capture: &Capture, tracked: &[(FrameRecordJson, ArchPoses)]) -> Option<ScoreReport> {
    capture.gt()?;
    Some(score_against(capture, tracked, "ground truth", &|frame| {
        capture.gt_poses(frame)
    }))
}

/// Score `tracked` against the `reference` poses of each frame (another run's, named
/// `reference_name`); frames without them are skipped.
pub fn score_against(
    capture: &Capture,
    tracked: &[(FrameRecordJson, ArchPoses)],
    reference_name: &str,
    reference: &dyn Fn(u32) -> Option<ArchPoses>,
) -> ScoreReport {
    let metrics = [
        MeshMetric::new(capture.upper()),
        MeshMetric::new(capture.lower()),
    ];
    let mut errors: [[Vec<f64>; 3]; 3] = Default::default(); // [upper, lower, jaw][vertex, rot, trans]
    let mut area: [Vec<f64>; 2] = Default::default();
    let mut per_frame = Vec::new();
    let mut flagged = Vec::new();
    let (mut ok, mut low, mut none, mut hidden, mut recovered) = (0, 0, 0, 0, 0);
    for (rec, poses) in tracked {
        let Some(gt) = reference(rec.frame) else {
            continue;
        };
        match rec.status() {
            Status::LowConfidence => low += 1,
            Status::NoData => none += 1,
            Status::Ok => ok += 1,
        }
        hidden += rec.teeth_hidden as usize;
        recovered += rec.recovered as usize;
        let mut frame_err = [0.0; 3];
        let pairs = [
            (poses.upper, gt.upper, &metrics[0]),
            (poses.lower, gt.lower, &metrics[1]),
            (poses.jaw(), gt.jaw(), &metrics[1]),
        ];
        for (k, (t, g, metric)) in pairs.iter().enumerate() {
            let (r, tr) = t.distance_to(g);
            let v = metric.mean_distance(t, g);
            errors[k][0].push(v);
            errors[k][1].push(r.to_degrees());
            errors[k][2].push(tr);
            frame_err[k] = v;
        }
        per_frame.push((rec.frame, frame_err));
        flagged.push((frame_err[2], rec.status() != Status::Ok));
        if let Some(a) = &rec.area_error {
            for (k, arch) in Arch::BOTH.iter().enumerate() {
                if let Some(x) = *a.get(*arch) {
                    area[k].push(100.0 * x);
                }
            }
        }
    }
    let pose_errors = |e: &[Vec<f64>; 3]| PoseErrors {
        mean_vertex_mm: Stats::of(&e[0]),
        rotation_deg: Stats::of(&e[1]),
        translation_mm: Stats::of(&e[2]),
    };
    ScoreReport {
        reference: reference_name.to_string(),
        frames: per_frame.len(),
        frames_ok: ok,
        frames_low_confidence: low,
        frames_teeth_hidden: hidden,
        frames_recovered: recovered,
        frames_no_data: none,
        upper: pose_errors(&errors[0]),
        lower: pose_errors(&errors[1]),
        jaw: pose_errors(&errors[2]),
        area_error_percent: [Stats::of(&area[0]), Stats::of(&area[1])],
        per_frame,
        flags: FlagScore::of(&flagged, WRONG_MM),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn flags_are_scored_by_recall_and_false_flags() {
        // Errors (mm) and flags: two wrong frames (one flagged), three right (one flagged).
        let frames = [
            (2.0, true),
            (1.5, false),
            (0.2, false),
            (0.3, true),
            (0.9, false),
        ];
        let f = FlagScore::of(&frames, 1.0);
        assert_eq!(
            (f.wrong, f.wrong_flagged, f.right, f.right_flagged),
            (2, 1, 3, 1)
        );
        assert_eq!(f.recall, 0.5);
        assert!((f.false_flag_rate - 1.0 / 3.0).abs() < 1e-12);
        // Nothing wrong: every wrong frame (none) is flagged.
        assert_eq!(FlagScore::of(&[(0.1, false)], 1.0).recall, 1.0);
    }

    #[test]
    fn stats_use_nearest_rank() {
        let v: Vec<f64> = (1..=100).map(f64::from).collect();
        let s = Stats::of(&v);
        assert_eq!((s.median, s.p95, s.max), (50.0, 95.0, 100.0));
        assert_eq!(Stats::of(&[3.0]).p95, 3.0);
    }
}
