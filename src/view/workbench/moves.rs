//! What a drag, turn or nudge on the page does to one arch's pose.

use nalgebra::{Rotation3, Unit, Vector3, Vector6};
use serde::Deserialize;

use crate::geometry::{Camera, Pose};

/// What a drag, turn or nudge does to one arch of one frame.
#[derive(Debug, Clone, Deserialize)]
#[serde(rename_all = "lowercase", deny_unknown_fields)]
pub enum EditOp {
    /// Move parallel to camera `camera`'s picture by `pixels` (the overlay's, which are the
    /// masks').
    Drag { camera: String, pixels: [f64; 2] },
    /// Turn about the arch's centre: about the camera's viewing axis, then its x axis (a nod).
    Turn { camera: String, degrees: [f64; 2] },
    /// Move along the camera's viewing axis (mm, + away from it).
    Depth { camera: String, mm: f64 },
    /// Move and turn in the arch's own axes (x, y, z), about its centre.
    Nudge { mm: [f64; 3], degrees: [f64; 3] },
    /// Back to the frame's saved poses.
    Reset,
}

/// The largest move one request may make: more is no drag a page sends.
const MAX_PIXELS: f64 = 1e4;
const MAX_DEGREES: f64 = 180.0;
const MAX_MM: f64 = 100.0;

/// `pose` (world from arch) moved by `op` about the arch's `centre` (in its own frame);
/// `find` finds a camera by name (the masks' resolution, as the overlays show it).
pub(super) fn moved(
    mut pose: Pose,
    centre: &Vector3<f64>,
    op: &EditOp,
    find: impl Fn(&str) -> Result<Camera, String>,
) -> Result<Pose, String> {
    match op {
        EditOp::Reset => {}
        EditOp::Drag { camera, pixels } => {
            bounded(pixels, MAX_PIXELS, "pixels")?;
            let cam = find(camera)?;
            let at = cam
                .camera_from_world
                .transform_point(&pose.transform_point(centre));
            let moved = Vector3::new(pixels[0] * at.z / cam.fx, pixels[1] * at.z / cam.fy, 0.0);
            pose = shifted(&cam, moved).compose(&pose);
        }
        EditOp::Depth { camera, mm } => {
            bounded(&[*mm], MAX_MM, "mm")?;
            let cam = find(camera)?;
            pose = shifted(&cam, Vector3::new(0.0, 0.0, *mm)).compose(&pose);
        }
        EditOp::Turn { camera, degrees } => {
            bounded(degrees, MAX_DEGREES, "degrees")?;
            let cam = find(camera)?;
            let to_world = cam.camera_from_world.rotation.inverse();
            let c = pose.transform_point(centre);
            for (axis, deg) in [(Vector3::z(), degrees[0]), (Vector3::x(), degrees[1])] {
                let r = Rotation3::from_axis_angle(
                    &Unit::new_normalize(to_world * axis),
                    deg.to_radians(),
                );
                pose = Pose::new(r, c - r * c).compose(&pose);
            }
        }
        EditOp::Nudge { mm, degrees } => {
            bounded(mm, MAX_MM, "mm")?;
            bounded(degrees, MAX_DEGREES, "degrees")?;
            let d = degrees.map(f64::to_radians);
            let xi = Vector6::new(d[0], d[1], d[2], mm[0], mm[1], mm[2]);
            let about = Pose::from_translation(*centre);
            pose = pose
                .compose(&about)
                .compose(&Pose::exp(&xi))
                .compose(&about.inverse());
        }
    }
    Ok(pose)
}

/// A world translation by `moved`, given in camera `cam`'s axes.
fn shifted(cam: &Camera, moved: Vector3<f64>) -> Pose {
    Pose::from_translation(cam.camera_from_world.rotation.inverse() * moved)
}

fn bounded(values: &[f64], limit: f64, what: &str) -> Result<(), String> {
    if values.iter().all(|v| v.is_finite() && v.abs() <= limit) {
        Ok(())
    } else {
        Err(format!("{what}: finite numbers, each within ±{limit}"))
    }
}
