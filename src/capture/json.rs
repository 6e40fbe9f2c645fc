//! The JSON documents of the capture format (../shared/spec/capture-format.md), as serde types,
//! and their conversion to validated values. Unknown fields are allowed (the format may grow).

use std::collections::BTreeMap;
use std::path::Path;

use nalgebra::Vector3;
use serde::{Deserialize, Serialize, de::DeserializeOwned};

use super::arch::ArchPoses;
use crate::error::{Error, Result, Shown};
use crate::geometry::Pose;

pub const CAPTURE_FORMAT: &str = "jawtrack-capture/1";
pub const TRACKS_FORMAT: &str = "jawtrack-tracks/1";

/// Tolerance for "is a rotation" in the spec: readers reject |RᵀR − I| above this.
pub const ROTATION_TOLERANCE: f64 = 1e-3;

#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct CaptureJson {
    pub format: String,
    pub cameras: Vec<String>,
    pub frames: FramesJson,
    pub meshes: MeshesJson,
    pub boi: BoiJson,
    pub masks: MasksJson,
}

#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct FramesJson {
    pub first: u32,
    pub count: u32,
    /// Per camera, how many frames its files run ahead of the capture's frame numbers.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub offsets: Option<std::collections::BTreeMap<String, i64>>,
}

#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct MeshesJson {
    pub upper: String,
    pub lower: String,
    /// jawtrack extension: a mandible mesh (teeth, ramus, condyles) in the lower arch's frame.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mandible: Option<String>,
}

#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(untagged)]
pub enum BoiJson {
    Group { group: String },
    FaceLists { upper: String, lower: String },
}

#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct MasksJson {
    pub dir: String,
    pub mode: String,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub upper: Option<i64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub lower: Option<i64>,
    /// The pixel value of the visible mouth interior (either mode).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mouth: Option<i64>,
}

#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct CameraJson {
    pub width: i64,
    pub height: i64,
    pub fx: f64,
    pub fy: f64,
    pub cx: f64,
    pub cy: f64,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub distortion: Option<Vec<f64>>,
    /// jawtrack extension: the lens model `distortion` is for, `opencv` (the default:
    /// 4, 5, 8, 12 or 14 coefficients) or `fisheye` (cv::fisheye's 4).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub lens: Option<String>,
    pub rotation: [[f64; 3]; 3],
    pub translation: [f64; 3],
}

#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq)]
pub struct PoseJson {
    pub rotation: [[f64; 3]; 3],
    pub translation: [f64; 3],
}

impl From<&Pose> for PoseJson {
    fn from(p: &Pose) -> Self {
        PoseJson {
            rotation: p.rotation_rows(),
            translation: [p.translation.x, p.translation.y, p.translation.z],
        }
    }
}

/// The largest translation a pose file may give (mm): a kilometre, far beyond any capture, and
/// far enough below f64's range that composing poses stays finite.
pub const MAX_TRANSLATION_MM: f64 = 1e6;

impl PoseJson {
    /// Validate (finite numbers, a rotation within the spec's tolerance) and re-orthonormalise.
    pub fn to_pose(&self, path: &Path, field: &str) -> Result<Pose> {
        check_finite_rows(path, &format!("{field}.rotation"), &self.rotation)?;
        check_finite(path, &format!("{field}.translation"), &self.translation)?;
        if let Some(t) = self
            .translation
            .iter()
            .find(|t| t.abs() > MAX_TRANSLATION_MM)
        {
            return Err(Error::invalid(
                path,
                format!("{field}.translation"),
                format!(
                    "{} mm is beyond {MAX_TRANSLATION_MM} mm (1 km): not a pose in millimetres",
                    Shown(*t)
                ),
            ));
        }
        let rotation = Pose::rotation_from_rows(&self.rotation, ROTATION_TOLERANCE).ok_or_else(|| {
            Error::invalid(
                path,
                format!("{field}.rotation"),
                format!(
                    "is not a rotation matrix (RᵀR must be I and det(R) = +1 within {ROTATION_TOLERANCE})"
                ),
            )
        })?;
        let [x, y, z] = self.translation;
        Ok(Pose::new(rotation, Vector3::new(x, y, z)))
    }
}

/// init.json: per arch either a pose or bootstrap points.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct InitJson {
    pub upper: ArchInitJson,
    pub lower: ArchInitJson,
}

#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(untagged)]
pub enum ArchInitJson {
    Pose(PoseJson),
    Points { points: Vec<InitPointJson> },
}

#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct InitPointJson {
    pub vertex: i64,
    pub pixels: BTreeMap<String, [f64; 2]>,
}

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
    pub energy: Option<serde_json::Value>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub area_error: Option<serde_json::Value>,
    /// Absent in files that do not say (ground truth): such a frame counts as `ok`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub status: Option<Status>,
    /// jawtrack's addition, written by `skin fill`: where the frame's jaw pose came from,
    /// `teeth` (the tracker) or `skin` (predicted from the face surface).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub jaw_source: Option<String>,
}

impl FrameRecordJson {
    /// The frame's status; a record that does not give one (ground truth) is `ok`.
    pub fn status(&self) -> Status {
        self.status.unwrap_or(Status::Ok)
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
        if !(apart <= MAX_JAW_MM) {
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

/// Read and parse a JSON file; a missing file is [`Error::Missing`] with `what`.
pub fn read_json<T: DeserializeOwned>(path: &Path, what: &str) -> Result<T> {
    let text = crate::capture::read::read_text(path, what)?;
    parse_json(&text, path)
}

/// JSON text read from `origin` (a file, or where else it came from, such as a command-line
/// option), with the same errors as `read_json`.
/// Read and parse a JSON file, with the paths of the fields the schema does not have (other
/// programs may add their own; a misspelt field shows here).
pub fn read_json_noting_unknown<T: DeserializeOwned>(
    path: &Path,
    what: &str,
) -> Result<(T, Vec<String>)> {
    let text = crate::capture::read::read_text(path, what)?;
    let mut unknown = Vec::new();
    let de = &mut serde_json::Deserializer::from_str(&text);
    let mut note = |field: serde_ignored::Path| unknown.push(field.to_string());
    let value = serde_path_to_error::deserialize(serde_ignored::Deserializer::new(de, &mut note))
        .map_err(|e| Error::Json {
        path: path.to_path_buf(),
        field: e.path().to_string(),
        error: e.into_inner(),
    })?;
    Ok((value, unknown))
}

pub fn parse_json<T: DeserializeOwned>(text: &str, origin: &Path) -> Result<T> {
    let de = &mut serde_json::Deserializer::from_str(text);
    serde_path_to_error::deserialize(de).map_err(|e| Error::Json {
        path: origin.to_path_buf(),
        field: e.path().to_string(),
        error: e.into_inner(),
    })
}

pub fn check_finite(path: &Path, field: &str, values: &[f64]) -> Result<()> {
    match values.iter().position(|v| !v.is_finite()) {
        None => Ok(()),
        Some(i) => Err(Error::invalid(
            path,
            if values.len() > 1 {
                format!("{field}[{i}]")
            } else {
                field.to_string()
            },
            format!("must be a finite number, found {}", values[i]),
        )),
    }
}

fn check_finite_rows(path: &Path, field: &str, rows: &[[f64; 3]; 3]) -> Result<()> {
    for (i, row) in rows.iter().enumerate() {
        check_finite(path, &format!("{field}[{i}]"), row)?;
    }
    Ok(())
}
