//! The face-sequence format (`../shared/spec/face-format.md`, `jawtrack-face/1`): a skin mesh
//! per frame with the neutral's topology, stabilised to the skull; the mandible in the lower
//! arch's frame; optionally the jaw pose of every frame (`jawtrack-jaw/1`) and the frames of
//! the five calibration poses.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::capture::{Folder, path_inside};
use crate::error::{Error, Result};
use crate::formats::jaw::read_jaw_file;
use crate::geometry::Pose;
use crate::io::read_json_noting_unknown;
use crate::mesh::{BoiSource, Mesh};

pub const FACE_FORMAT: &str = "jawtrack-face/1";
/// More frames than any capture has (over 11 hours at 24 fps): a count beyond it is a typo or
/// a hostile header, refused before anything is allocated for it.
pub const MAX_FRAMES: u32 = 1_000_000;

#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct FaceJson {
    pub format: String,
    pub frames: FaceFramesJson,
    pub neutral: String,
    #[serde(default = "default_frames_dir")]
    pub frames_dir: String,
    pub mandible: String,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub jaw: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub calibration: Option<CalibrationJson>,
}

fn default_frames_dir() -> String {
    "frames".into()
}

#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
pub struct FaceFramesJson {
    pub first: u32,
    pub count: u32,
}

/// The frames of the five calibration poses (the paper's Section 6.1).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct CalibrationJson {
    pub open: u32,
    pub left: u32,
    pub right: u32,
    pub forward: u32,
    pub backward: u32,
}

impl CalibrationJson {
    pub fn frames(&self) -> [(&'static str, u32); 5] {
        [
            ("open", self.open),
            ("left", self.left),
            ("right", self.right),
            ("forward", self.forward),
            ("backward", self.backward),
        ]
    }
}

/// A face sequence as read: meshes loaded, frames read on demand.
#[derive(Debug, Clone)]
pub struct FaceSequence {
    pub dir: PathBuf,
    pub first: u32,
    pub count: u32,
    pub neutral: Mesh,
    pub mandible: Mesh,
    frames_dir: PathBuf,
    /// `upper_from_lower` per frame, where `jaw.json` gives one.
    pub jaw: BTreeMap<u32, Pose>,
    pub calibration: Option<CalibrationJson>,
    /// Fields of face.json the format does not have (another program's, or a misspelling).
    pub unknown_fields: Vec<String>,
}

impl FaceSequence {
    /// Read `dir/face.json` and what it names, checking every field against the format.
    pub fn open(dir: &Path) -> Result<FaceSequence> {
        let path = dir.join("face.json");
        if !path.is_file() {
            return Err(Error::Missing {
                path,
                what: "face sequence description (face.json, format jawtrack-face/1)".into(),
            });
        }
        let (json, unknown_fields): (FaceJson, _) =
            read_json_noting_unknown(&path, "face sequence")?;
        if json.format != FACE_FORMAT {
            return Err(Error::invalid(
                &path,
                "format",
                format!("is `{}`, expected `{FACE_FORMAT}`", json.format),
            ));
        }
        let FaceFramesJson { first, count } = json.frames;
        if count == 0 || count > MAX_FRAMES {
            return Err(Error::invalid(
                &path,
                "frames.count",
                format!("is {count}; a face sequence has 1 to {MAX_FRAMES} frames"),
            ));
        }
        if first.checked_add(count).is_none() {
            return Err(Error::invalid(
                &path,
                "frames.first",
                format!("{first} + {count} frames runs past the largest frame number"),
            ));
        }
        let neutral_path = path_inside(Folder::FaceSequence, dir, &path, "neutral", &json.neutral)?;
        let neutral = Mesh::load(&neutral_path, BoiSource::None)?;
        let mandible_path =
            path_inside(Folder::FaceSequence, dir, &path, "mandible", &json.mandible)?;
        let mandible = Mesh::load(&mandible_path, BoiSource::None)?;
        let frames_dir = path_inside(
            Folder::FaceSequence,
            dir,
            &path,
            "frames_dir",
            &json.frames_dir,
        )?;
        if !frames_dir.is_dir() {
            return Err(Error::Missing {
                path: frames_dir,
                what: "folder of frame meshes (face.json `frames_dir`)".into(),
            });
        }
        let in_range = |f: u32| f >= first && f - first < count;
        let jaw = match &json.jaw {
            None => BTreeMap::new(),
            Some(rel) => read_jaw(
                &path_inside(Folder::FaceSequence, dir, &path, "jaw", rel)?,
                &in_range,
            )?,
        };
        if let Some(cal) = &json.calibration {
            for (name, frame) in cal.frames() {
                if !in_range(frame) {
                    return Err(Error::invalid(
                        &path,
                        format!("calibration.{name}"),
                        format!(
                            "frame {frame} is not in the sequence (frames {first} to {})",
                            first as u64 + count as u64 - 1
                        ),
                    ));
                }
            }
        }
        Ok(FaceSequence {
            dir: dir.to_path_buf(),
            first,
            count,
            neutral,
            mandible,
            frames_dir,
            jaw,
            calibration: json.calibration,
            unknown_fields,
        })
    }

    pub fn frames(&self) -> impl Iterator<Item = u32> + use<> {
        self.first..self.first + self.count
    }

    /// The file of `frame`: `<frame:06>.obj`, else `.ply`.
    pub fn frame_path(&self, frame: u32) -> Result<PathBuf> {
        let stem = format!("{frame:06}");
        for ext in ["obj", "ply"] {
            let p = self.frames_dir.join(format!("{stem}.{ext}"));
            if p.is_file() {
                crate::capture::listed_file_inside(Folder::FaceSequence, &p, Some(&self.dir))?;
                return Ok(p);
            }
        }
        Err(Error::Missing {
            path: self.frames_dir.join(format!("{stem}.obj")),
            what: format!("skin mesh of frame {frame} ({stem}.obj or {stem}.ply)"),
        })
    }

    /// The skin's vertices in `frame`, checked against the neutral's vertex count.
    pub fn read_frame(&self, frame: u32) -> Result<Vec<[f32; 3]>> {
        let path = self.frame_path(frame)?;
        let v = Mesh::load_vertices(&path)?;
        if v.len() != self.neutral.positions.len() {
            return Err(Error::invalid(
                &path,
                "vertices",
                format!(
                    "has {} vertices; the neutral mesh has {} (every frame has the neutral's topology: same count, same order)",
                    v.len(),
                    self.neutral.positions.len()
                ),
            ));
        }
        Ok(v)
    }

    /// The jaw pose of `frame`, or an error naming what is missing.
    pub fn jaw_pose(&self, frame: u32) -> Result<Pose> {
        self.jaw.get(&frame).copied().ok_or_else(|| {
            Error::invalid(
                self.dir.join("face.json"),
                "jaw",
                format!("no jaw pose for frame {frame} (jaw.json lists the frames it knows)"),
            )
        })
    }
}

fn read_jaw(path: &Path, in_range: &dyn Fn(u32) -> bool) -> Result<BTreeMap<u32, Pose>> {
    let mut poses = BTreeMap::new();
    for (i, (frame, pose)) in read_jaw_file(path)?.into_iter().enumerate() {
        if !in_range(frame) {
            return Err(Error::invalid(
                path,
                format!("poses[{i}].frame"),
                format!("frame {frame} is not in the sequence"),
            ));
        }
        poses.insert(frame, pose);
    }
    Ok(poses)
}

/// The subjects of a set: every sub-folder of `dir` with a face.json, by name.
pub fn subject_dirs(dir: &Path) -> Result<Vec<(String, PathBuf)>> {
    if dir.join("face.json").is_file() {
        return Err(Error::invalid(
            dir,
            "folder",
            "is one face sequence; a set of subjects is a folder of them (<name>/face.json)",
        ));
    }
    let entries = std::fs::read_dir(dir).map_err(|e| Error::read(dir, "set of subjects", e))?;
    let mut out = Vec::new();
    for e in entries {
        let p = e
            .map_err(|e| Error::read(dir, "set of subjects", e))?
            .path();
        if p.join("face.json").is_file()
            && let Some(name) = p.file_name().and_then(|n| n.to_str())
        {
            out.push((name.to_string(), p));
        }
    }
    out.sort();
    Ok(out)
}
