//! The first pose picked on the page, for a take without init.json: points clicked on each
//! arch's model and the same points in two or more cameras' pictures, fitted as init.json's
//! bootstrap is (triangulated, then a rigid fit), shown over the pictures, and written as
//! init.json in the format's bootstrap form.

use std::collections::BTreeMap;
use std::path::PathBuf;

use serde::{Deserialize, Serialize};

use crate::arch::{Arch, ArchPoses};
use crate::capture::Capture;
use crate::capture::json::{ArchInitJson, InitJson, InitPointJson};
use crate::error::{Error, Result};
use crate::formats::PerArchJson;
use crate::io::write_json_atomic;

/// Points picked for both arches.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FirstPoseQuery {
    pub upper: Vec<Picked>,
    pub lower: Vec<Picked>,
    /// Write init.json (else only fit and show).
    #[serde(default)]
    pub write: bool,
}

/// A vertex of an arch's mesh and where it is in the cameras' pictures.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Picked {
    pub vertex: i64,
    /// Camera name to the pixel in its picture (the masks' resolution, as the page shows it).
    pub pixels: BTreeMap<String, [f64; 2]>,
}

#[derive(Debug, Clone, Serialize)]
pub struct FirstPoseReply {
    /// World from arch, column-major 4x4 (mm).
    pub upper: [f64; 16],
    pub lower: [f64; 16],
    /// Per point, the farthest that the fitted pose puts it from a click (the pictures' pixels).
    pub residual_px: PerArchJson<Vec<f64>>,
    /// init.json when written, and where the one it replaced was kept.
    pub written: Option<String>,
    pub kept: Option<String>,
}

/// Fit the picked points; with `write`, write init.json (an existing one is kept beside it
/// as init.before-view.json, once).
pub fn first_pose(capture: &Capture, q: &FirstPoseQuery) -> Result<(ArchPoses, FirstPoseReply)> {
    let path = capture.dir().join("init.json");
    let names = capture.camera_names();
    // Picture pixels to the calibrated image's (the masks may be smaller): pixel centres map
    // to pixel centres, as `Camera::scaled_to` has it.
    let scales: Vec<[f64; 2]> = capture
        .cameras()
        .iter()
        .map(|c| match c.mask_size {
            Some((w, h)) => [
                c.calibrated.width as f64 / w as f64,
                c.calibrated.height as f64 / h as f64,
            ],
            None => [1.0, 1.0],
        })
        .collect();
    let to_calibrated = |camera: &str, p: [f64; 2]| -> Result<(String, [f64; 2])> {
        let k = names.iter().position(|n| *n == camera).ok_or_else(|| {
            Error::invalid(
                &path,
                "pixels",
                format!("no camera {camera:?} in the capture"),
            )
        })?;
        let s = scales[k];
        Ok((
            camera.to_string(),
            [(p[0] + 0.5) * s[0] - 0.5, (p[1] + 0.5) * s[1] - 0.5],
        ))
    };
    let arch_json = |points: &[Picked]| -> Result<ArchInitJson> {
        let points = points
            .iter()
            .map(|p| {
                Ok(InitPointJson {
                    vertex: p.vertex,
                    pixels: p
                        .pixels
                        .iter()
                        .map(|(c, px)| to_calibrated(c, *px))
                        .collect::<Result<_>>()?,
                })
            })
            .collect::<Result<Vec<_>>>()?;
        Ok(ArchInitJson::Points { points })
    };
    let json = InitJson {
        upper: arch_json(&q.upper)?,
        lower: arch_json(&q.lower)?,
    };
    let init = capture.init_from(&json, &path)?;
    let poses = capture.resolve_init(&init, &path)?;
    let residuals = |arch: Arch, points: &[Picked]| -> Vec<f64> {
        let (mesh, pose) = match arch {
            Arch::Upper => (capture.upper(), &poses.upper),
            Arch::Lower => (capture.lower(), &poses.lower),
        };
        points
            .iter()
            .map(|p| {
                let v = mesh.positions[p.vertex as usize];
                let x = pose.transform_point(&nalgebra::Vector3::new(
                    v[0] as f64,
                    v[1] as f64,
                    v[2] as f64,
                ));
                p.pixels
                    .iter()
                    .map(|(c, px)| {
                        let k = names.iter().position(|n| n == c).expect("checked above");
                        let s = scales[k];
                        capture.cameras()[k]
                            .calibrated
                            .project(&x)
                            .map_or(f64::INFINITY, |at| {
                                let (_, clicked) = to_calibrated(c, *px).expect("checked above");
                                ((at.x - clicked[0]) / s[0]).hypot((at.y - clicked[1]) / s[1])
                            })
                    })
                    .fold(0.0, f64::max)
            })
            .collect()
    };
    let mut reply = FirstPoseReply {
        upper: poses.upper.column_major(),
        lower: poses.lower.column_major(),
        residual_px: PerArchJson {
            upper: residuals(Arch::Upper, &q.upper),
            lower: residuals(Arch::Lower, &q.lower),
        },
        written: None,
        kept: None,
    };
    if q.write {
        if path.exists() {
            let kept = capture.dir().join("init.before-view.json");
            if !kept.exists() {
                std::fs::copy(&path, &kept).map_err(|error| Error::Write {
                    path: kept.clone(),
                    error,
                })?;
            }
            reply.kept = Some(display(kept));
        }
        write_json_atomic(&path, &json)?;
        reply.written = Some(display(path));
    }
    Ok((poses, reply))
}

fn display(p: PathBuf) -> String {
    p.display().to_string()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synth::{SynthOptions, generate};

    /// Four vertices per arch at their true places in two cameras' pictures (masks at half
    /// the calibrated resolution) give back the true first poses; too few points, or a camera
    /// the capture does not have, are refused in init.json's words; write keeps the old file.
    #[test]
    fn points_at_their_true_pixels_give_the_true_pose() {
        let dir = tempfile::tempdir().unwrap();
        let cap = dir.path().join("cap");
        generate(
            &cap,
            &SynthOptions {
                frames: 2,
                ..SynthOptions::default()
            },
            &|| {},
        )
        .unwrap();
        let capture = Capture::open(&cap).unwrap();
        let c0 = &capture.cameras()[0];
        assert!(
            c0.mask_size.unwrap().0 < c0.calibrated.width,
            "masks smaller than the images"
        );
        let truth = capture.gt_poses(0).unwrap();
        let picked = |mesh: &crate::mesh::Mesh, pose: &crate::geometry::Pose| -> Vec<Picked> {
            let n = mesh.positions.len();
            [0, n / 3, 2 * n / 3, n - 1]
                .iter()
                .map(|&v| {
                    let p = mesh.positions[v];
                    let x = pose.transform_point(&nalgebra::Vector3::new(
                        p[0] as f64,
                        p[1] as f64,
                        p[2] as f64,
                    ));
                    let pixels = ["cam0", "cam2"]
                        .iter()
                        .map(|name| {
                            let k = capture
                                .camera_names()
                                .iter()
                                .position(|c| c == name)
                                .unwrap();
                            let at = capture.cameras()[k]
                                .mask_camera()
                                .unwrap()
                                .project(&x)
                                .unwrap();
                            (name.to_string(), [at.x, at.y])
                        })
                        .collect();
                    Picked {
                        vertex: v as i64,
                        pixels,
                    }
                })
                .collect()
        };
        let mut q = FirstPoseQuery {
            upper: picked(capture.upper(), &truth.upper),
            lower: picked(capture.lower(), &truth.lower),
            write: true,
        };
        let (poses, reply) = first_pose(&capture, &q).unwrap();
        for (got, want) in [(poses.upper, truth.upper), (poses.lower, truth.lower)] {
            assert!((got.translation - want.translation).norm() < 1e-6);
            assert!((got.rotation.matrix() - want.rotation.matrix()).norm() < 1e-8);
        }
        assert!(
            reply.residual_px.upper.iter().all(|r| *r < 1e-6),
            "{reply:?}"
        );
        assert!(
            reply.kept.is_some(),
            "the synthetic capture had an init.json"
        );
        let written = Capture::open(&cap).unwrap().initial_poses().unwrap();
        assert!((written.lower.translation - truth.lower.translation).norm() < 1e-6);

        q.upper.truncate(2);
        let e = first_pose(&capture, &q).unwrap_err().to_string();
        assert!(
            e.contains("init.json") && e.contains("upper.points") && e.contains("three"),
            "{e}"
        );
        q.upper = picked(capture.upper(), &truth.upper);
        q.lower[0].pixels.insert("cam9".into(), [1.0, 1.0]);
        let e = first_pose(&capture, &q).unwrap_err().to_string();
        assert!(e.contains("cam9"), "{e}");
    }
}
