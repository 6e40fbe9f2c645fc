//! Jaw poses (`upper_from_lower`) in and out: the jaw-pose file (`jawtrack-jaw/1`: the
//! face-sequence format's jaw.json, and what `skin predict` writes), or a tracks.json /
//! gt/poses.json, whose frames give the upper and lower arch poses.

use std::path::Path;

use serde::{Deserialize, Serialize};

use super::pose::PoseJson;
use super::tracks::{FrameRecordJson, Status, TRACKS_FORMAT};
use crate::error::{Error, Result};
use crate::geometry::{Pose, jaw_pose};
use crate::io::{read_json, write_json_atomic};

pub const JAW_FORMAT: &str = "jawtrack-jaw/1";

/// One jaw pose, `upper_from_lower`, as the jaw-pose file stores it.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct JawRecordJson {
    pub frame: u32,
    pub rotation: [[f64; 3]; 3],
    pub translation: [f64; 3],
}

#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct JawFileJson {
    pub format: String,
    pub poses: Vec<JawRecordJson>,
}

/// Either file: the format field says which.
#[derive(Deserialize)]
struct AnyPosesJson {
    format: Option<String>,
    frames: Option<Vec<FrameRecordJson>>,
    poses: Option<Vec<JawRecordJson>>,
}

/// Jaw poses (`upper_from_lower`) with their frame numbers.
#[derive(Debug, Clone, Default)]
pub struct JawPoses {
    pub frames: Vec<u32>,
    pub poses: Vec<Pose>,
    /// Frames of a tracks.json left out because their status was not `ok`.
    pub skipped: usize,
}

impl JawPoses {
    pub fn len(&self) -> usize {
        self.poses.len()
    }

    pub fn is_empty(&self) -> bool {
        self.poses.is_empty()
    }
}

/// Read a `jawtrack-jaw/1` file: the format checked, every pose a rotation and a translation
/// in range, no frame twice; in the file's order.
pub fn read_jaw_file(path: &Path) -> Result<Vec<(u32, Pose)>> {
    let file: JawFileJson = read_json(path, "jaw poses (jawtrack-jaw/1)")?;
    if file.format != JAW_FORMAT {
        return Err(Error::invalid(
            path,
            "format",
            format!("is `{}`, expected `{JAW_FORMAT}`", file.format),
        ));
    }
    jaw_records(path, &file.poses)
}

fn jaw_records(path: &Path, records: &[JawRecordJson]) -> Result<Vec<(u32, Pose)>> {
    let mut seen = std::collections::BTreeSet::new();
    records
        .iter()
        .enumerate()
        .map(|(i, r)| {
            let field = format!("poses[{i}]");
            if !seen.insert(r.frame) {
                return Err(Error::invalid(
                    path,
                    format!("{field}.frame"),
                    format!("frame {} is listed twice", r.frame),
                ));
            }
            let pose = PoseJson {
                rotation: r.rotation,
                translation: r.translation,
            };
            Ok((r.frame, pose.to_pose(path, &field)?))
        })
        .collect()
}

/// Read a tracks.json / gt/poses.json (frames whose status is `ok` or absent) or a
/// `jawtrack-jaw/1` file.
pub fn read_jaw_poses(path: &Path) -> Result<JawPoses> {
    let any: AnyPosesJson = read_json(path, "jaw poses (tracks.json or jawtrack-jaw/1)")?;
    let mut out = JawPoses::default();
    let list = if any.format.as_deref() == Some(JAW_FORMAT) {
        "poses"
    } else {
        "frames"
    };
    match any.format.as_deref() {
        Some(JAW_FORMAT) => {
            let poses = any.poses.ok_or_else(|| {
                Error::invalid(
                    path,
                    "poses",
                    format!("missing: a {JAW_FORMAT} file lists its poses under `poses`"),
                )
            })?;
            for (frame, pose) in jaw_records(path, &poses)? {
                out.frames.push(frame);
                out.poses.push(pose);
            }
        }
        None | Some(TRACKS_FORMAT) => {
            let frames = any.frames.ok_or_else(|| {
                Error::invalid(
                    path,
                    "frames",
                    format!("missing: expected a tracks file ({TRACKS_FORMAT}) with `frames`, or a jaw-pose file with \"format\": \"{JAW_FORMAT}\""),
                )
            })?;
            for (i, f) in frames.iter().enumerate() {
                if f.status() != Status::Ok {
                    out.skipped += 1;
                    continue;
                }
                let upper = f.upper.to_pose(path, &format!("frames[{i}].upper"))?;
                let lower = f.lower.to_pose(path, &format!("frames[{i}].lower"))?;
                out.frames.push(f.frame);
                out.poses.push(jaw_pose(&upper, &lower));
            }
        }
        Some(other) => {
            return Err(Error::invalid(
                path,
                "format",
                format!("unknown format {other:?}: expected {TRACKS_FORMAT:?} or {JAW_FORMAT:?}"),
            ));
        }
    }
    if out.poses.is_empty() {
        return Err(Error::invalid(
            path,
            list,
            format!(
                "no usable jaw poses ({} frames skipped for a status other than `ok`)",
                out.skipped
            ),
        ));
    }
    Ok(out)
}

/// Write jaw poses as a `jawtrack-jaw/1` file, atomically.
pub fn write_jaw_poses(path: &Path, frames: &[u32], poses: &[Pose]) -> Result<()> {
    let file = JawFileJson {
        format: JAW_FORMAT.into(),
        poses: frames
            .iter()
            .zip(poses)
            .map(|(&frame, p)| {
                let pj = PoseJson::from(p);
                JawRecordJson {
                    frame,
                    rotation: pj.rotation,
                    translation: pj.translation,
                }
            })
            .collect(),
    };
    write_json_atomic(path, &file)
}
