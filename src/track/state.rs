//! Where tracking stands between frames, and how each frame's outcome moves it. A resumed run
//! rebuilds this state by replaying the records an earlier run wrote through the same
//! transitions, and every pose it keeps is the pose as written and read back, so the resumed
//! run continues from exactly the state the uninterrupted one had: its tracks.json is
//! byte-identical.

use std::collections::VecDeque;
use std::path::Path;

use super::edge_offsets::EdgeOffsets;
use super::manifold::JawManifold;
use super::settings::TrackSettings;
use crate::arch::{Arch, ArchPoses};
use crate::energy::Energy;
use crate::energy::smooth::Matrix12;
use crate::error::{Error, Result};
use crate::formats::{FrameRecordJson, PoseJson, Status};
use crate::geometry::Pose;

/// One tracked frame.
#[derive(Debug, Clone)]
pub struct FrameResult {
    pub frame: u32,
    pub poses: ArchPoses,
    /// Final energies (upper, lower); `None` for a frame without data.
    pub energies: Option<[Energy; 2]>,
    /// The energy's verdict, which tracking goes on from.
    pub status: Status,
    /// Why a frame the energy found `ok` is written `low-confidence` all the same.
    pub caution: Option<Caution>,
    pub evaluations: usize,
    /// Gauss-Newton steps (each a Jacobian of every silhouette sample; 0 for the paper's
    /// search).
    pub steps: usize,
    /// How sharply the masks hold the poses (Gauss-Newton's information about them, in
    /// [ξ_u; ξ_j]): what the window over frames weighs the frame by. `None` without masks,
    /// for a frame found afresh by Gauss-Newton, or with the window off.
    pub information: Option<Matrix12>,
    /// Each camera's offset of its masks' edges after this frame, where they are estimated.
    pub edge_offsets: Option<EdgeOffsets>,
    pub seconds: f64,
}

/// Why a frame tracked `ok` is flagged `low-confidence`: tracking goes on from it as from an
/// `ok` frame, and tracks.json says which (`teeth_hidden`, `recovered`), so that a resumed run
/// goes on as the first did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Caution {
    /// The masks hide an arch's incisal band (`hidden_teeth_share`): the pose is what the
    /// frames around it make of too little evidence.
    TeethHidden,
    /// The first frame tracked `ok` after frames tracked `low-confidence`: found again from a
    /// start those frames could not vouch for, it has only its own masks to say it is right,
    /// and they may have been made around that start.
    Recovered,
}

impl FrameResult {
    /// The status tracks.json gives the frame: `low-confidence` where a caution applies.
    pub fn written_status(&self) -> Status {
        match self.caution {
            Some(_) => Status::LowConfidence,
            None => self.status,
        }
    }
}

/// The last poses (and the ones before, for the velocity) and recent area errors of good
/// frames.
#[derive(Debug, Clone)]
pub struct TrackState {
    /// The poses the run started from (the capture's start): the jaw prior, contact and
    /// manifold are fitted around them, so a resumed run fits the same ones.
    pub start: ArchPoses,
    /// The last good poses, and the good ones of the frame before (for the velocity).
    pub last: ArchPoses,
    pub before: Option<ArchPoses>,
    /// The estimate of a low-confidence frame since the last good one: the next frame also
    /// tries to start from it (the motion may have gone on).
    pub since_good: Option<ArchPoses>,
    /// A frame since the last good one was tracked `low-confidence` (not merely unseen): the
    /// next good one is found again after a loss ([`Caution::Recovered`]).
    pub lost: bool,
    pub recent_area_errors: VecDeque<f64>,
    /// Each camera's offset of its masks' edges as the frames so far estimate it
    /// (`super::edge_offsets`); `None` where they are not estimated.
    pub edge_offsets: Option<EdgeOffsets>,
    /// Whether the jaw's manifold fits this subject, as the frames so far say.
    pub manifold_fit: ManifoldFit,
}

/// How many of the latest frames tracked ok judge the manifold: a window's worth, so that
/// wrong frames (a first frame placed from too little of the teeth, say) are outvoted by the
/// right ones around them, and the judgement's memory stays flat over a long take.
pub const JUDGING_FRAMES: usize = 13;

/// Whether the jaw's manifold (the average joint's, or a rig's: `super::manifold`) fits this
/// subject. The average joint's own poses lie within 0.4 mm of its subspace, and those of a
/// take of such a joint, tracked, within 0.7 mm (13 frames' median at most 0.61, on errors that
/// persist); another subject's joint lies 1-2 mm off it from the first frame on (13 frames'
/// median 1.0-2.0), and a manifold that holds the jaw there pulls both arches off what the
/// masks show (docs/tracking.md, "A joint that is not the average one"). Once the median distance of the last [`JUDGING_FRAMES`] frames tracked
/// ok exceeds the release distance (`TrackSettings::jaw_manifold_release_mm`), the manifold is
/// let go for the rest of the take.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ManifoldFit {
    /// The jaw's distance from the manifold (mm) in the last frames tracked ok.
    pub recent_mm: VecDeque<f64>,
    /// The manifold is let go: the masks and the contact hold the jaw from here on.
    pub released: bool,
}

impl ManifoldFit {
    /// A frame came out `status` with its jaw `off_mm` from the manifold.
    pub fn note(&mut self, status: Status, off_mm: f64, release_mm: f64) {
        if self.released || release_mm <= 0.0 || status != Status::Ok {
            return;
        }
        self.recent_mm.push_back(off_mm);
        if self.recent_mm.len() > JUDGING_FRAMES {
            self.recent_mm.pop_front();
        }
        if self.recent_mm.len() == JUDGING_FRAMES {
            let mut sorted: Vec<f64> = self.recent_mm.iter().copied().collect();
            sorted.sort_by(f64::total_cmp);
            self.released = sorted[JUDGING_FRAMES / 2] > release_mm;
        }
    }
}

impl TrackState {
    pub fn new(start: ArchPoses) -> Self {
        TrackState {
            start,
            last: start,
            before: None,
            since_good: None,
            lost: false,
            recent_area_errors: VecDeque::new(),
            edge_offsets: None,
            manifold_fit: ManifoldFit::default(),
        }
    }

    /// `ok`, or `low-confidence` when a frame's worst area error is above the settings' bound
    /// or jumps over the recent typical one.
    pub fn confidence(&self, settings: &TrackSettings, worst_area_error: f64) -> Status {
        let mut recent: Vec<f64> = self.recent_area_errors.iter().copied().collect();
        recent.sort_by(f64::total_cmp);
        let typical = recent.get(recent.len() / 2).copied();
        // A sudden jump over the recent typical area error; the floor keeps clean data, whose
        // area error is near zero, from tripping it. One good frame is enough to jump from:
        // the second frame has no velocity to start from, and a fast jaw is lost there first.
        let jump = typical.is_some_and(|m| {
            worst_area_error
                > (settings.low_confidence_ratio * m).max(settings.low_confidence_floor)
        });
        if worst_area_error > settings.low_confidence_area_error || jump {
            Status::LowConfidence
        } else {
            Status::Ok
        }
    }

    /// A frame where no camera saw anything: the last good pose stays; the velocity restarts.
    pub fn no_data(&mut self) {
        self.before = None;
        self.since_good = self.since_good.or(Some(self.last));
    }

    /// A tracked frame came out `status` at `poses` (as written: [`as_written`]), its worse
    /// arch's area error `worst_area_error`; the last `window` good ones are kept.
    pub fn advance(
        &mut self,
        status: Status,
        poses: ArchPoses,
        worst_area_error: f64,
        window: usize,
    ) {
        match status {
            Status::Ok => {
                // The velocity needs two good frames in a row.
                self.before = self.since_good.is_none().then_some(self.last);
                self.since_good = None;
                self.lost = false;
                self.last = poses;
                self.recent_area_errors.push_back(worst_area_error);
                if self.recent_area_errors.len() > window {
                    self.recent_area_errors.pop_front();
                }
            }
            // The last good pose stays a start; so does this estimate.
            Status::LowConfidence => {
                self.since_good = Some(poses);
                self.lost = true;
            }
            Status::NoData => self.no_data(),
        }
    }

    /// The state after the `records` of `path` (frames an earlier run tracked from `start`, in
    /// order, as that run wrote them), the run's jaw `manifold` with its release distance
    /// where it has one.
    pub fn replay(
        start: ArchPoses,
        records: &[FrameRecordJson],
        path: &Path,
        window: usize,
        manifold: Option<(&JawManifold, f64)>,
    ) -> Result<TrackState> {
        let mut state = TrackState::new(start);
        for r in records {
            let (poses, status) = (r.poses(path)?, r.tracked_status());
            let worst = match status {
                Status::Ok => worst_area_error(path, r)?,
                _ => f64::NAN,
            };
            state.advance(status, poses, worst, window);
            if let Some((m, release_mm)) = manifold {
                (state.manifold_fit).note(status, m.distance_mm(&poses.jaw()), release_mm);
            }
            if let Some(j) = &r.edge_offsets {
                let field = format!("frame {}.edge_offsets", r.frame);
                let offsets = EdgeOffsets::from_json(j).ok_or_else(|| {
                    Error::invalid(path, &field, "needs as many rows of information as offsets")
                })?;
                state.edge_offsets = Some(offsets);
            }
        }
        Ok(state)
    }
}

/// The larger of a record's two area errors, as the tracker took it (`f64::max`: an arch
/// without mask pixels, written as null, does not count).
fn worst_area_error(path: &Path, r: &FrameRecordJson) -> Result<f64> {
    let field = format!("frame {}.area_error", r.frame);
    let errors = r.area_error.as_ref().ok_or_else(|| {
        Error::invalid(
            path,
            &field,
            "missing in an `ok` frame: the run cannot be continued exactly (--force starts over)",
        )
    })?;
    let of = |arch| errors.get(arch).unwrap_or(f64::NAN);
    Ok(of(Arch::Upper).max(of(Arch::Lower)))
}

/// `poses` as a reader of their written record gets them back (the record's rotation matrix
/// re-orthonormalised): what the tracker keeps, so that a resumed run, which can only read the
/// record, starts the next frame from the same bits.
pub fn as_written(poses: &ArchPoses) -> ArchPoses {
    let read_back = |p: &Pose| {
        PoseJson::from(p)
            .to_pose(Path::new("tracks.json"), "pose")
            .unwrap_or(*p)
    };
    ArchPoses {
        upper: read_back(&poses.upper),
        lower: read_back(&poses.lower),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn poses(x: f64, turn: f64) -> ArchPoses {
        ArchPoses {
            upper: Pose::from_euler_tuple(&[0.01, turn, 0.0, x, 0.0, 0.0]),
            lower: Pose::from_euler_tuple(&[0.2, turn, 0.03, x, -10.0, 3.0]),
        }
    }

    fn record(frame: u32, status: Status, p: &ArchPoses, area: Option<[f64; 2]>) -> String {
        let pose = |p: &Pose| serde_json::to_value(PoseJson::from(p)).unwrap();
        let mut r = serde_json::json!({
            "frame": frame, "upper": pose(&p.upper), "lower": pose(&p.lower),
            "status": status.as_str(),
        });
        if let Some([u, l]) = area {
            r["area_error"] = serde_json::json!({"upper": u, "lower": l});
        }
        r.to_string()
    }

    /// Every transition, replayed from the written records, leaves the state the live run had,
    /// to the bit. As the tracker does, the live run keeps each pose as written and writes the
    /// pose it found.
    #[test]
    fn replaying_the_written_records_rebuilds_the_state_exactly() {
        let start = as_written(&poses(0.0, 0.0));
        let frames = [
            (Status::Ok, poses(0.1, 0.001), 0.031),
            (Status::Ok, poses(0.2, 0.002), 0.0299999999999),
            (Status::LowConfidence, poses(2.0, 0.05), 0.4),
            (Status::NoData, poses(0.2, 0.002), f64::NAN),
            (Status::Ok, poses(0.3, 1.0 / 3.0), 0.07),
            (Status::Ok, poses(0.4, 0.1), 0.011),
            (Status::Ok, poses(0.5, 0.2), 0.012),
        ];
        // A manifold the frames' jaws lie far off (it turns the jaw about y and z and slides it
        // along x; theirs is turned about x and lowered).
        let lower = crate::anatomy::procedural_arch(false);
        let spanned: Vec<Pose> = (0..27)
            .map(|k| {
                let (a, b, c) = ((k % 3) as f64, (k / 3 % 3) as f64, (k / 9) as f64);
                Pose::from_euler_tuple(&[0.0, 0.05 * a, 0.05 * b, c, 0.0, 0.0])
            })
            .collect();
        let manifold = JawManifold::new(&spanned, &lower, 60.0, 0.3);
        let mut live = TrackState::new(start);
        let mut records = Vec::new();
        for (i, &(status, p, area)) in frames.iter().enumerate() {
            live.advance(status, as_written(&p), area, 3);
            let off_mm = manifold.distance_mm(&as_written(&p).jaw());
            live.manifold_fit.note(status, off_mm, 1.0);
            let area = (status != Status::NoData).then_some([area, area / 3.0]);
            // The first frame found again after the loss is written flagged, as the tracker
            // writes it; tracking went on from it as from an `ok` one.
            let recovered = i == 4;
            let written = match recovered {
                true => Status::LowConfidence,
                false => status,
            };
            let mut line: serde_json::Value =
                serde_json::from_str(&record(i as u32, written, &p, area)).unwrap();
            if recovered {
                line["recovered"] = true.into();
            }
            // The cameras' edge offsets as they stood after the frame, from the fifth frame on.
            if i >= 4 {
                let mut offsets = EdgeOffsets::unknown(2);
                offsets.px[1] = -0.1 * i as f64 - 1.0 / 3.0;
                offsets.information[(0, 1)] = 1e3 / 7.0;
                line["edge_offsets"] = serde_json::to_value(offsets.to_json()).unwrap();
                live.edge_offsets = Some(offsets);
            }
            records.push(serde_json::from_value(line).unwrap());
        }
        let replayed =
            TrackState::replay(start, &records, Path::new("j"), 3, Some((&manifold, 1.0))).unwrap();
        assert_eq!(format!("{replayed:?}"), format!("{live:?}"));
        // Five frames tracked ok, each one's distance kept as the live run had it.
        assert_eq!(replayed.manifold_fit.recent_mm.len(), 5);
        assert_eq!(replayed.recent_area_errors.len(), 3);
        assert!(replayed.before.is_some() && replayed.since_good.is_none() && !replayed.lost);
        assert!(replayed.edge_offsets.is_some());
    }

    /// The second frame is judged against the first: a jaw lost there (it moved fast, and no
    /// velocity yet said where to start) is flagged, not taken as the start of the next.
    #[test]
    fn a_jump_in_area_error_is_flagged_from_the_second_frame_on() {
        let settings = TrackSettings::default();
        let mut state = TrackState::new(poses(0.0, 0.0));
        assert_eq!(
            state.confidence(&settings, 0.08),
            Status::Ok,
            "nothing to jump from"
        );
        state.advance(Status::Ok, poses(0.0, 0.0), 0.015, 15);
        assert_eq!(state.confidence(&settings, 0.08), Status::LowConfidence);
        assert_eq!(
            state.confidence(&settings, 0.025),
            Status::Ok,
            "under the floor"
        );
        state.advance(Status::Ok, poses(0.0, 0.0), 0.05, 15);
        assert_eq!(
            state.confidence(&settings, 0.08),
            Status::Ok,
            "within 2.5 of the median"
        );
    }

    #[test]
    fn the_manifold_is_let_go_once_most_of_a_window_of_ok_frames_lie_beyond_the_release() {
        let after = |frames: &[(Status, f64)]| {
            let mut fit = ManifoldFit::default();
            for &(status, off_mm) in frames {
                fit.note(status, off_mm, 1.0);
            }
            fit.released
        };
        let (ok, low) = (Status::Ok, Status::LowConfidence);
        let far = |n: usize| vec![(ok, 1.5); n];
        assert!(after(&far(13)));
        // Not before a window's worth of frames tracked ok; low-confidence ones do not count.
        assert!(!after(&far(12)));
        assert!(!after(&[far(12), vec![(low, 1.5)]].concat()));
        // Wrong frames at the start are outvoted by the right ones after them.
        assert!(!after(&[far(6), vec![(ok, 0.3); 7]].concat()));
        assert!(after(&[far(7), vec![(ok, 0.3); 6]].concat()));
        // The judgement moves with the take, and once let go, the manifold stays let go.
        assert!(after(&[vec![(ok, 0.3); 20], far(7)].concat()));
        assert!(after(&[far(13), vec![(ok, 0.1); 13]].concat()));
        // A release distance of 0 never lets go.
        let mut fit = ManifoldFit::default();
        (0..20).for_each(|_| fit.note(ok, 9.0, 0.0));
        assert!(!fit.released);
    }

    #[test]
    fn an_ok_record_without_its_area_error_cannot_be_continued_exactly() {
        let p = poses(0.0, 0.0);
        let r = serde_json::from_str(&record(0, Status::Ok, &p, None)).unwrap();
        let e = TrackState::replay(p, &[r], Path::new("t.json"), 3, None).unwrap_err();
        assert!(e.to_string().contains("frame 0.area_error"), "{e}");
        let mut bad: serde_json::Value =
            serde_json::from_str(&record(0, Status::Ok, &p, Some([0.1, 0.2]))).unwrap();
        // A value that is not a number does not make a record at all (the reader names the
        // field, as for any JSON that does not fit the format).
        bad["area_error"]["lower"] = serde_json::json!("x");
        let text = serde_json::to_string(&bad).unwrap();
        let e = crate::io::parse_json::<FrameRecordJson>(&text, Path::new("t.json")).unwrap_err();
        assert!(e.to_string().contains("area_error.lower"), "{e}");
    }
}
