//! The JSON documents of the capture format (../shared/spec/capture-format.md), as serde types,
//! and their conversion to validated values. Unknown fields are allowed (the format may grow).

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use crate::formats::PoseJson;

pub const CAPTURE_FORMAT: &str = "jawtrack-capture/1";

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
