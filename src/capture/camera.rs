//! A camera file (cameras/<name>.json): every field checked, the camera built.

use std::path::Path;

use super::json::CameraJson;
use crate::error::{Error, Result, Shown};
use crate::formats::PoseJson;
use crate::geometry::{Camera, Distortion, Pose};
use crate::io::{check_finite, read_json};

/// Read a cameras/<name>.json file and validate every field.
pub fn read_camera(path: &Path, name: &str) -> Result<Camera> {
    let cj: CameraJson = read_json(path, &format!("camera file for `{name}`"))?;
    camera_from_json(&cj, path, name)
}

/// The smallest image side: a mask of fewer pixels says nothing about a pose.
const MIN_SIDE: i64 = 8;
/// The longest focal length (pixels): a 1000 mm lens on a 1 µm pixel.
const MAX_FOCAL_PX: f64 = 1e6;
/// The shortest (pixels): below a pixel, the whole sphere of view fits in one pixel.
const MIN_FOCAL_PX: f64 = 1.0;
/// The largest distortion coefficient: OpenCV's calibrations, rational and fisheye models
/// included, stay within a few hundred; far beyond, the lens overflows single precision.
pub const MAX_DISTORTION: f64 = 1e4;

/// Validate a camera document (`path` names it in errors) and build the camera.
pub fn camera_from_json(cj: &CameraJson, path: &Path, name: &str) -> Result<Camera> {
    check_size(cj, path)?;
    check_intrinsics(cj, path)?;
    let distortion = read_distortion(cj, path)?;
    let pose = read_pose(cj, path)?;
    Ok(Camera {
        name: name.to_string(),
        width: cj.width as u32,
        height: cj.height as u32,
        fx: cj.fx,
        fy: cj.fy,
        cx: cj.cx,
        cy: cj.cy,
        distortion,
        camera_from_world: pose,
    })
}

/// Refuses an image side below `MIN_SIDE` or beyond 65536 pixels.
fn check_size(cj: &CameraJson, path: &Path) -> Result<()> {
    if cj.width < MIN_SIDE || cj.height < MIN_SIDE || cj.width > 1 << 16 || cj.height > 1 << 16 {
        return Err(Error::invalid(
            path,
            "width/height",
            format!(
                "image size {}x{} is not valid: each side must be {MIN_SIDE} to 65536 pixels",
                cj.width, cj.height
            ),
        ));
    }
    Ok(())
}

/// Refuses intrinsics that are not finite, focal lengths out of range and a principal point
/// far off the image.
fn check_intrinsics(cj: &CameraJson, path: &Path) -> Result<()> {
    for (field, v) in [("fx", cj.fx), ("fy", cj.fy), ("cx", cj.cx), ("cy", cj.cy)] {
        check_finite(path, field, &[v])?;
    }
    for (field, v) in [("fx", cj.fx), ("fy", cj.fy)] {
        check_focal(path, field, v)?;
    }
    for (field, v, side) in [("cx", cj.cx, cj.width), ("cy", cj.cy, cj.height)] {
        if v.abs() > 10.0 * side as f64 {
            return Err(Error::invalid(
                path,
                field,
                format!(
                    "the principal point {} lies more than ten image sides away",
                    Shown(v)
                ),
            ));
        }
    }
    Ok(())
}

/// Refuses a focal length (`field`, pixels) that is not positive or not between
/// `MIN_FOCAL_PX` and `MAX_FOCAL_PX`.
fn check_focal(path: &Path, field: &str, v: f64) -> Result<()> {
    if v <= 0.0 {
        return Err(Error::invalid(
            path,
            field,
            format!("the focal length must be positive, found {}", Shown(v)),
        ));
    }
    if v < MIN_FOCAL_PX {
        return Err(Error::invalid(
            path,
            field,
            format!(
                "a focal length of {} px is below {MIN_FOCAL_PX} px: not a camera",
                Shown(v)
            ),
        ));
    }
    if v > MAX_FOCAL_PX {
        return Err(Error::invalid(
            path,
            field,
            format!(
                "a focal length of {} px is beyond {MAX_FOCAL_PX} px: not a camera",
                Shown(v)
            ),
        ));
    }
    Ok(())
}

/// Whether the file's lens model is the fisheye (`"opencv"`, the default, is not).
fn is_fisheye(cj: &CameraJson, path: &Path) -> Result<bool> {
    match cj.lens.as_deref() {
        None | Some("opencv") => Ok(false),
        Some("fisheye") => Ok(true),
        Some(other) => Err(Error::invalid(
            path,
            "lens",
            format!(
                "`{}` is not a lens model: use \"opencv\" or \"fisheye\"",
                crate::io::read::quote(other)
            ),
        )),
    }
}

/// The lens's distortion, its coefficients checked; none without coefficients, which a
/// fisheye must have.
fn read_distortion(cj: &CameraJson, path: &Path) -> Result<Distortion> {
    let fisheye = is_fisheye(cj, path)?;
    match &cj.distortion {
        Some(d) => {
            check_finite(path, "distortion", d)?;
            if let Some((i, v)) = d.iter().enumerate().find(|(_, v)| v.abs() > MAX_DISTORTION) {
                return Err(Error::invalid(
                    path,
                    format!("distortion[{i}]"),
                    format!(
                        "{} is beyond ±{MAX_DISTORTION}: no lens OpenCV calibrates has such a coefficient",
                        Shown(*v)
                    ),
                ));
            }
            Distortion::from_coefficients(d, fisheye)
                .map_err(|problem| Error::invalid(path, "distortion", problem))
        }
        None if fisheye => Err(Error::invalid(
            path,
            "distortion",
            "a fisheye lens needs its 4 coefficients",
        )),
        None => Ok(Distortion::NONE),
    }
}

/// The camera's pose (camera_from_world), errors naming the file's top-level fields.
fn read_pose(cj: &CameraJson, path: &Path) -> Result<Pose> {
    PoseJson {
        rotation: cj.rotation,
        translation: cj.translation,
    }
    .to_pose(path, "extrinsics")
    .map_err(|e| match e {
        // The camera file keeps rotation/translation at the top level.
        Error::Invalid {
            path,
            field,
            problem,
        } => Error::Invalid {
            path,
            field: field.trim_start_matches("extrinsics.").to_string(),
            problem,
        },
        other => other,
    })
}
