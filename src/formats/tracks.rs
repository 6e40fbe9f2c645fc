//! tracks.json (what `jawtrack track` writes; ../shared/spec/capture-format.md) and
//! gt/poses.json, which has its schema: per frame both arches' poses, the jaw, the energy,
//! the area error and the status, typed both ways.

use std::collections::BTreeSet;
use std::path::Path;

use serde::{Deserialize, Serialize};

use super::pose::PoseJson;
use crate::arch::{Arch, ArchPoses};
use crate::error::{Error, Result};
use crate::geometry::Pose;
use crate::io::read_json;

pub const TRACKS_FORMAT: &str = "jawtrack-tracks/1";

/// tracks.json, and gt/poses.json (which needs only `frame`, `upper`, `lower`).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct TracksJson {
    #[serde(default = "tracks_format")]
    pub format: String,
    /// jawtrack's addition: the fingerprint of the capture and settings that tracked these
    /// frames, which `--resume` checks.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fingerprint: Option<String>,
    pub frames: Vec<FrameRecordJson>,
}

fn tracks_format() -> String {
    TRACKS_FORMAT.to_string()
}

#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct FrameRecordJson {
    pub frame: u32,
    pub upper: PoseJson,
    pub lower: PoseJson,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub jaw: Option<PoseJson>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub energy: Option<PerArchJson<ArchEnergyJson>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub area_error: Option<PerArchJson<Option<f64>>>,
    /// Absent in files that do not say (ground truth): such a frame counts as `ok`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub status: Option<Status>,
    /// jawtrack's addition, written by `skin fill`: where the frame's jaw pose came from.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub jaw_source: Option<JawSource>,
    /// jawtrack's addition: the frame as tracked, before the window over frames settled it
    /// (`upper` and `lower` above), where a window applies.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tracked: Option<TrackedJson>,
    /// jawtrack's addition, written by `view`'s workbench: the poses were set by hand on this
    /// frame, not tracked. A run that goes on from such a frame starts from them, and the window
    /// over frames holds them fixed.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub hand_set: bool,
    /// jawtrack's addition: the frame is `low-confidence` because the masks hide an arch's
    /// incisal edges (the lips closed over them), though its energy was as good as an `ok`
    /// frame's; tracking went on from it as from an `ok` one.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub teeth_hidden: bool,
    /// jawtrack's addition: the frame is `low-confidence` because it is the first tracked `ok`
    /// after frames tracked `low-confidence`: it was found again from a start those frames
    /// could not vouch for, and (where the masks are made around where tracking expects the
    /// arches) from masks made around that start, so only its own masks say it is right.
    /// Tracking went on from it as from an `ok` one.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub recovered: bool,
    /// jawtrack's addition: each camera's offset of its masks' edges as estimated after this
    /// frame, and what the frames so far know of them (`track::edge_offsets`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub edge_offsets: Option<EdgeOffsetsJson>,
}

/// Each camera's offset of its masks' edges (pixels of its masks, outwards: the masks' teeth
/// wider than the model's), in the capture's camera order, and their information matrix
/// (row by row, per pixel², in the tracker's residual unit).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EdgeOffsetsJson {
    pub px: Vec<f64>,
    pub information: Vec<Vec<f64>>,
}

/// A frame as tracked: its poses, and the information its masks gave about them (the 12x12
/// normal matrix in the increments of both arches and the jaw, row by row).
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TrackedJson {
    pub upper: PoseJson,
    pub lower: PoseJson,
    pub information: Vec<f64>,
}

/// A value per arch, as the record writes it (`lower` first: the keys' order).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PerArchJson<T> {
    pub lower: T,
    pub upper: T,
}

impl<T> PerArchJson<T> {
    pub fn get(&self, arch: Arch) -> &T {
        match arch {
            Arch::Upper => &self.upper,
            Arch::Lower => &self.lower,
        }
    }
}

/// One arch's energy terms, summed over the cameras (pixel counts). The spec names
/// `total`, `uncovered` and `boi_outside`; `cross` and `over_mouth` are jawtrack's terms.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ArchEnergyJson {
    pub boi_outside: u64,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cross: Option<u64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub over_mouth: Option<u64>,
    pub total: f64,
    pub uncovered: u64,
}

/// Where a frame's jaw pose came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum JawSource {
    /// The teeth tracker.
    Teeth,
    /// Predicted from the face surface (`skin fill`).
    Skin,
}

impl FrameRecordJson {
    /// The frame's status; a record that does not give one (ground truth) is `ok`.
    pub fn status(&self) -> Status {
        self.status.unwrap_or(Status::Ok)
    }

    /// The status tracking went on from: `ok` for a frame flagged only because its teeth were
    /// hidden or because it was found again after a loss.
    pub fn tracked_status(&self) -> Status {
        match self.teeth_hidden || self.recovered {
            true => Status::Ok,
            false => self.status(),
        }
    }

    /// The record's poses, checked as a pose file's are (errors name `path`, the file it was
    /// read from).
    pub fn poses(&self, path: &Path) -> Result<ArchPoses> {
        Ok(ArchPoses {
            upper: self
                .upper
                .to_pose(path, &format!("frame {}.upper", self.frame))?,
            lower: self
                .lower
                .to_pose(path, &format!("frame {}.lower", self.frame))?,
        })
    }

    /// The record's jaw pose (lower relative to upper), from its arches' poses, refused where
    /// the record's own `jaw` disagrees with them (edited apart) or where no jaw could be.
    pub fn checked_jaw(&self, path: &Path) -> Result<Pose> {
        let jaw = self.poses(path)?.jaw();
        let field = format!("frame {}.jaw", self.frame);
        if let Some(j) = &self.jaw {
            let stated = j.to_pose(path, &field)?;
            // Within what another program's rounding of the two may leave.
            let moved_mm = (stated.translation - jaw.translation).norm();
            let turned = (stated.rotation.matrix() - jaw.rotation.matrix()).amax();
            if !(moved_mm.is_finite() && moved_mm < 0.01 && turned < 1e-4) {
                return Err(Error::invalid(
                    path,
                    field,
                    "disagrees with the arches' poses (lower relative to upper): remove it or correct it",
                ));
            }
        }
        let apart = jaw.translation.norm();
        if apart.is_nan() || apart > MAX_JAW_MM {
            return Err(Error::invalid(
                path,
                format!("frame {}.lower", self.frame),
                format!(
                    "the lower arch lies {apart:.0} mm from the upper: no jaw opens that far (at most {MAX_JAW_MM} mm)"
                ),
            ));
        }
        Ok(jaw)
    }
}

/// The farthest the lower arch's frame may lie from the upper's (mm): a jaw opens a few
/// centimetres.
pub const MAX_JAW_MM: f64 = 200.0;

/// How a tracked frame came out (the spec's `status`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Status {
    Ok,
    /// The energy says the fit is poor.
    LowConfidence,
    /// No camera had a mask.
    NoData,
}

impl Status {
    /// The spec's spelling.
    pub fn as_str(self) -> &'static str {
        match self {
            Status::Ok => "ok",
            Status::LowConfidence => "low-confidence",
            Status::NoData => "no-data",
        }
    }
}

/// Ground-truth (or tracked) poses of one frame.
#[derive(Debug, Clone, Copy)]
pub struct FramePoses {
    pub frame: u32,
    pub poses: ArchPoses,
}

/// Read a tracks.json or gt/poses.json whole: its format checked, no frame given twice.
pub fn read_tracks(path: &Path) -> Result<TracksJson> {
    let tj: TracksJson = read_json(path, "poses file")?;
    if tj.format != TRACKS_FORMAT {
        return Err(Error::invalid(
            path,
            "format",
            format!("expected \"{}\", found \"{}\"", TRACKS_FORMAT, tj.format),
        ));
    }
    let mut seen = BTreeSet::new();
    for (i, f) in tj.frames.iter().enumerate() {
        if !seen.insert(f.frame) {
            return Err(Error::invalid(
                path,
                format!("frames[{i}].frame"),
                format!("frame {} is given twice", f.frame),
            ));
        }
    }
    Ok(tj)
}

/// Read gt/poses.json or a tracks.json (frame, upper, lower are required).
pub fn read_poses(path: &Path) -> Result<Vec<FramePoses>> {
    let tj = read_tracks(path)?;
    tj.frames
        .iter()
        .enumerate()
        .map(|(i, f)| {
            Ok(FramePoses {
                frame: f.frame,
                poses: ArchPoses {
                    upper: f.upper.to_pose(path, &format!("frames[{i}].upper"))?,
                    lower: f.lower.to_pose(path, &format!("frames[{i}].lower"))?,
                },
            })
        })
        .collect()
}
