//! Calibration in: cameras from the files calibration tools write (OpenCV's FileStorage YAML
//! and XML, COLMAP's text models) as the capture format's cameras/<name>.json.
//!
//! Every camera is checked the way the capture reader checks one ([`camera_from_json`]), and
//! the layout (centres, distances) is returned so a user sees at once whether units and
//! directions came out right.

mod colmap;
mod filestorage;
mod opencv;

use std::path::{Path, PathBuf};

use nalgebra::Vector3;

pub use colmap::{MAX_CAMERAS, read_colmap};
pub use filestorage::Node;
pub use opencv::read_opencv;

use crate::capture::camera_from_json;
use crate::capture::json::CameraJson;
use crate::error::{Error, Result};
use crate::geometry::{Camera, Distortion, Pose};
use crate::io::write_json_atomic;

/// The length unit of a calibration's translations (the capture format's is the millimetre).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Unit {
    #[default]
    Mm,
    Cm,
    M,
}

impl Unit {
    pub fn to_mm(self) -> f64 {
        match self {
            Unit::Mm => 1.0,
            Unit::Cm => 10.0,
            Unit::M => 1000.0,
        }
    }
}

/// How the calibration's numbers are read.
#[derive(Debug, Clone, Copy, Default)]
pub struct ImportOptions {
    pub unit: Unit,
    /// The file's extrinsics map camera to world (a camera's pose), not world to camera
    /// (OpenCV's and COLMAP's convention, `x_cam = R·x_world + t`).
    pub camera_to_world: bool,
    /// The OpenCV files' 4 coefficients are `cv::fisheye`'s (its files do not say so).
    pub fisheye: bool,
}

/// A camera read from a calibration file, checked as the capture reader checks one.
#[derive(Debug, Clone)]
pub struct ImportedCamera {
    pub name: String,
    pub source: PathBuf,
    pub json: CameraJson,
    pub camera: Camera,
    /// What the reader chose or assumed, for the user (e.g. "no extrinsics: placed at the
    /// world origin").
    pub notes: Vec<String>,
}

impl ImportedCamera {
    /// Build from intrinsics and world-to-camera extrinsics already in millimetres.
    fn new(
        name: &str,
        source: &Path,
        size: (i64, i64),
        k: [f64; 4],
        distortion: Distortion,
        camera_from_world: Pose,
        notes: Vec<String>,
    ) -> Result<ImportedCamera> {
        let t = camera_from_world.translation;
        let json = CameraJson {
            width: size.0,
            height: size.1,
            fx: k[0],
            fy: k[1],
            cx: k[2],
            cy: k[3],
            distortion: distortion.is_some().then(|| distortion.coefficients()),
            lens: distortion.is_fisheye().then(|| "fisheye".to_string()),
            rotation: camera_from_world.rotation_rows(),
            translation: [t.x, t.y, t.z],
        };
        let camera = camera_from_json(&json, source, name)?;
        Ok(ImportedCamera {
            name: name.to_string(),
            source: source.to_path_buf(),
            json,
            camera,
            notes,
        })
    }

    /// The camera's centre in world coordinates (mm).
    pub fn centre(&self) -> Vector3<f64> {
        self.camera.camera_from_world.inverse().translation
    }

    /// The unit vector the camera looks along, in world coordinates.
    pub fn view_direction(&self) -> Vector3<f64> {
        self.camera.camera_from_world.rotation.inverse() * Vector3::z()
    }
}

/// The extrinsics as the capture format stores them (world to camera, mm) from a file's
/// rotation and translation in its own unit and direction.
fn extrinsics(
    rotation: nalgebra::Rotation3<f64>,
    translation: Vector3<f64>,
    options: &ImportOptions,
) -> Pose {
    let pose = Pose::new(rotation, translation * options.unit.to_mm());
    if options.camera_to_world {
        pose.inverse()
    } else {
        pose
    }
}

/// A lens from a calibration's coefficient list: OpenCV's model (1 to 14 coefficients; fewer
/// than 4 are the same model with zeros after) or the fisheye's 4.
fn lens_from(values: &[f64], fisheye: bool, path: &Path, field: &str) -> Result<Distortion> {
    let mut d = values.to_vec();
    if !fisheye && d.len() < 4 && !d.is_empty() {
        d.resize(4, 0.0);
    }
    if d.is_empty() {
        return Ok(Distortion::NONE);
    }
    Distortion::from_coefficients(&d, fisheye)
        .map_err(|problem| Error::invalid(path, field, problem))
}

/// Write each camera to `capture/cameras/<name>.json` (atomically); returns the paths.
pub fn write_cameras(capture: &Path, cameras: &[ImportedCamera]) -> Result<Vec<PathBuf>> {
    let mut seen = std::collections::BTreeSet::new();
    for c in cameras {
        if !seen.insert(c.name.as_str()) {
            return Err(Error::invalid(
                &c.source,
                "camera name",
                format!("`{}` is imported twice: name the files NAME=FILE", c.name),
            ));
        }
        check_name(&c.name, &c.source)?;
    }
    let dir = capture.join("cameras");
    cameras
        .iter()
        .map(|c| {
            let path = dir.join(format!("{}.json", c.name));
            write_json_atomic(&path, &c.json)?;
            Ok(path)
        })
        .collect()
}

/// A camera name becomes a file name and a folder name (masks/<name>/): plain characters only.
pub fn check_name(name: &str, source: &Path) -> Result<()> {
    let ok = !name.is_empty()
        && name.len() <= 64
        && !name.starts_with('.')
        && name
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || "-_.".contains(c));
    if ok {
        Ok(())
    } else {
        Err(Error::invalid(
            source,
            "camera name",
            format!(
                "`{}` is not a camera name: use up to 64 letters, digits, `-`, `_` and `.` (not first)",
                crate::io::read::quote(name)
            ),
        ))
    }
}

/// Distances between every pair of cameras' centres (mm), in the order given.
pub fn baselines(cameras: &[ImportedCamera]) -> Vec<(usize, usize, f64)> {
    let mut out = Vec::new();
    for i in 0..cameras.len() {
        for j in i + 1..cameras.len() {
            out.push((i, j, (cameras[i].centre() - cameras[j].centre()).norm()));
        }
    }
    out
}
