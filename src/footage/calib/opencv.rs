//! One camera from an OpenCV FileStorage file: the names `cv::calibrateCamera`'s sample,
//! ROS's camera_info and common scripts write, looked up in that order.

use std::path::Path;

use nalgebra::{Matrix3, Rotation3, Vector3};

use super::filestorage::{self, Node};
use super::{ImportOptions, ImportedCamera, extrinsics, lens_from};
use crate::error::{Error, Result};
use crate::formats::ROTATION_TOLERANCE;
use crate::geometry::{Distortion, Pose, so3_exp};

const INTRINSICS: &[&str] = &[
    "camera_matrix",
    "cameraMatrix",
    "K",
    "intrinsics",
    "intrinsic",
    "intrinsic_matrix",
    "mtx",
    "M",
];
const DISTORTION: &[&str] = &[
    "distortion_coefficients",
    "dist_coeffs",
    "distCoeffs",
    "distortion_coeffs",
    "distortion",
    "dist",
    "D",
];
const SIZE: &[&str] = &["image_size", "imageSize", "size", "resolution"];
const WIDTH: &[&str] = &["image_width", "imageWidth", "width"];
const HEIGHT: &[&str] = &["image_height", "imageHeight", "height"];
const MATRIX_4X4: &[&str] = &[
    "extrinsics",
    "extrinsic",
    "extrinsic_matrix",
    "camera_from_world",
    "T_cam_world",
    "Tcw",
    "Rt",
    "RT",
    "transform",
];
const ROTATION: &[&str] = &["R", "rotation", "rotation_matrix", "rmat"];
const RVEC: &[&str] = &["rvec", "r", "rotation_vector"];
/// The largest rotation vector's angle accepted (radians): a few turns.
const MAX_RVEC_RAD: f64 = 100.0;
const TRANSLATION: &[&str] = &["T", "t", "tvec", "translation", "translation_vector"];
const MODEL: &[&str] = &["distortion_model", "model", "camera_model"];

/// Read the camera named `name` from an OpenCV FileStorage file.
pub fn read_opencv(path: &Path, name: &str, options: &ImportOptions) -> Result<ImportedCamera> {
    let root = filestorage::read(path)?;
    camera_from_storage(&root, path, name, options)
}

fn lookup<'a>(root: &'a Node, names: &[&'a str]) -> Option<(&'a str, &'a Node)> {
    names.iter().find_map(|&n| root.get(n).map(|v| (n, v)))
}

fn numbers<'a>(node: &'a Node, path: &Path, field: &str) -> Result<(usize, usize, &'a [f64])> {
    match node {
        Node::Numbers { rows, cols, data } => {
            if let Some(i) = data.iter().position(|v| !v.is_finite()) {
                return Err(Error::invalid(
                    path,
                    field,
                    format!("value {i} is {}, not a finite number", data[i]),
                ));
            }
            Ok((*rows, *cols, data))
        }
        _ => Err(Error::invalid(
            path,
            field,
            "must be numbers (a matrix or a list)",
        )),
    }
}

fn missing(path: &Path, what: &str, names: &[&str], root: &Node) -> Error {
    Error::invalid(
        path,
        names[0],
        format!(
            "no {what}: looked for {}; the file has {}",
            names.join(", "),
            root.keys().join(", ")
        ),
    )
}

pub(super) fn camera_from_storage(
    root: &Node,
    path: &Path,
    name: &str,
    options: &ImportOptions,
) -> Result<ImportedCamera> {
    let mut notes = Vec::new();
    let (kf, kn) =
        lookup(root, INTRINSICS).ok_or_else(|| missing(path, "camera matrix", INTRINSICS, root))?;
    let (rows, cols, k) = numbers(kn, path, kf)?;
    if (rows, cols) != (3, 3) {
        return Err(Error::invalid(
            path,
            kf,
            format!("the camera matrix must be 3x3, found {rows}x{cols}"),
        ));
    }
    if k[1].abs() > 1e-9 * k[0].abs() {
        notes.push(format!("skew {} in {kf} ignored", k[1]));
    }
    if k[3] != 0.0 || k[6] != 0.0 || k[7] != 0.0 || k[8] != 1.0 {
        return Err(Error::invalid(
            path,
            kf,
            "is not a camera matrix [fx s cx; 0 fy cy; 0 0 1]",
        ));
    }
    let intrinsics = [k[0], k[4], k[2], k[5]];

    let size = image_size(root, path)?;

    let model = lookup(root, MODEL).and_then(|(_, n)| match n {
        Node::Text(t) => Some(t.to_ascii_lowercase()),
        _ => None,
    });
    // cv::fisheye's files carry no model name; ROS's camera_info says `equidistant`.
    let fisheye = options.fisheye
        || model.as_deref().is_some_and(|m| {
            ["fisheye", "equidistant", "kannala_brandt", "opencv_fisheye"].contains(&m)
        });
    let distortion = match lookup(root, DISTORTION) {
        Some((df, dn)) => lens_from(numbers(dn, path, df)?.2, fisheye, path, df)?,
        None => {
            notes.push("no distortion coefficients: a pinhole lens".into());
            Distortion::NONE
        }
    };

    let pose = match read_extrinsics(root, path)? {
        Some((rotation, translation)) => extrinsics(rotation, translation, options),
        None => {
            notes.push("no extrinsics: the camera is placed at the world origin".into());
            Pose::IDENTITY
        }
    };
    ImportedCamera::new(name, path, size, intrinsics, distortion, pose, notes)
}

fn image_size(root: &Node, path: &Path) -> Result<(i64, i64)> {
    let whole = |v: f64, field: &str| -> Result<i64> {
        if v.fract() == 0.0 && v > 0.0 && v <= 1e6 {
            Ok(v as i64)
        } else {
            Err(Error::invalid(
                path,
                field,
                format!("{v} is not an image side in pixels"),
            ))
        }
    };
    if let Some((f, n)) = lookup(root, SIZE) {
        let (_, _, d) = numbers(n, path, f)?;
        if d.len() != 2 {
            return Err(Error::invalid(path, f, "must be [width, height]"));
        }
        return Ok((whole(d[0], f)?, whole(d[1], f)?));
    }
    match (lookup(root, WIDTH), lookup(root, HEIGHT)) {
        (Some((wf, wn)), Some((hf, hn))) => {
            let (_, _, w) = numbers(wn, path, wf)?;
            let (_, _, h) = numbers(hn, path, hf)?;
            if w.len() != 1 || h.len() != 1 {
                return Err(Error::invalid(path, wf, "width and height must be numbers"));
            }
            Ok((whole(w[0], wf)?, whole(h[0], hf)?))
        }
        _ => Err(missing(
            path,
            "image size",
            &[SIZE, WIDTH, HEIGHT].concat(),
            root,
        )),
    }
}

/// World-to-camera rotation and translation (file units), if the file has them.
fn read_extrinsics(root: &Node, path: &Path) -> Result<Option<(Rotation3<f64>, Vector3<f64>)>> {
    let rotation = |m: Matrix3<f64>, field: &str| -> Result<Rotation3<f64>> {
        let rows = [0, 1, 2].map(|i| [m[(i, 0)], m[(i, 1)], m[(i, 2)]]);
        Pose::rotation_from_rows(&rows, ROTATION_TOLERANCE).ok_or_else(|| {
            Error::invalid(
                path,
                field,
                format!(
                    "is not a rotation (RᵀR must be I and det(R) = +1 within {ROTATION_TOLERANCE})"
                ),
            )
        })
    };
    if let Some((f, n)) = lookup(root, MATRIX_4X4) {
        let (rows, cols, d) = numbers(n, path, f)?;
        if !(cols == 4 && (rows == 3 || rows == 4)) {
            return Err(Error::invalid(
                path,
                f,
                format!("an extrinsic matrix must be 4x4 or 3x4 [R|t], found {rows}x{cols}"),
            ));
        }
        if rows == 4 && (d[12] != 0.0 || d[13] != 0.0 || d[14] != 0.0 || d[15] != 1.0) {
            return Err(Error::invalid(
                path,
                f,
                "the last row of a 4x4 pose must be 0 0 0 1",
            ));
        }
        let m = Matrix3::from_fn(|i, j| d[4 * i + j]);
        let t = Vector3::new(d[3], d[7], d[11]);
        return Ok(Some((rotation(m, f)?, t)));
    }
    let translation = match lookup(root, TRANSLATION) {
        Some((f, n)) => {
            let (_, _, d) = numbers(n, path, f)?;
            if d.len() != 3 {
                return Err(Error::invalid(
                    path,
                    f,
                    format!("a translation has 3 values, found {}", d.len()),
                ));
            }
            Some(Vector3::new(d[0], d[1], d[2]))
        }
        None => None,
    };
    let rot = match lookup(root, ROTATION).or_else(|| lookup(root, RVEC)) {
        Some((f, n)) => {
            let (rows, cols, d) = numbers(n, path, f)?;
            Some(match rows * cols {
                9 => rotation(Matrix3::from_fn(|i, j| d[3 * i + j]), f)?,
                // A Rodrigues vector (what cv::solvePnP and cv::Rodrigues give).
                3 => {
                    let w = Vector3::new(d[0], d[1], d[2]);
                    // cv::Rodrigues writes angles within π; far beyond, the angle's square
                    // overflows and the rotation would come out as NaN.
                    if !w.norm().is_finite() || w.norm() > MAX_RVEC_RAD {
                        return Err(Error::invalid(
                            path,
                            f,
                            format!(
                                "a rotation vector of angle {} rad: OpenCV writes angles within π (at most {MAX_RVEC_RAD})",
                                crate::error::Shown(w.norm())
                            ),
                        ));
                    }
                    so3_exp(&w)
                }
                _ => {
                    return Err(Error::invalid(
                        path,
                        f,
                        format!("a rotation is a 3x3 matrix or a 3-vector, found {rows}x{cols}"),
                    ));
                }
            })
        }
        None => None,
    };
    match (rot, translation) {
        (None, None) => Ok(None),
        (Some(r), Some(t)) => Ok(Some((r, t))),
        (Some(_), None) => Err(missing(
            path,
            "translation beside the rotation",
            TRANSLATION,
            root,
        )),
        (None, Some(_)) => Err(missing(
            path,
            "rotation beside the translation",
            ROTATION,
            root,
        )),
    }
}

#[cfg(test)]
mod tests {
    use super::super::Unit;
    use super::*;

    fn yaml(body: &str) -> Node {
        filestorage::parse_yaml(&format!("%YAML:1.0\n---\n{body}"), Path::new("c.yml")).unwrap()
    }

    const K: &str = "camera_matrix: !!opencv-matrix\n   rows: 3\n   cols: 3\n   dt: d\n   data: [ 1400., 0., 959.5, 0., 1401., 539.5, 0., 0., 1. ]\n";

    #[test]
    fn rvec_tvec_and_a_4x4_give_the_same_camera() {
        let w = 0.1f64;
        let (c, s) = (w.cos(), w.sin());
        let a = yaml(&format!(
            "{K}image_width: 1920\nimage_height: 1080\nrvec: [ 0., 0., {w} ]\ntvec: [ 1., 2., 0.2 ]\n"
        ));
        let b = yaml(&format!(
            "{K}image_size: [1920, 1080]\nT_cam_world: !!opencv-matrix\n   rows: 4\n   cols: 4\n   dt: d\n   data: [ {c}, {}, 0., 1., {s}, {c}, 0., 2., 0., 0., 1., 0.2, 0., 0., 0., 1. ]\n",
            -s
        ));
        let options = ImportOptions {
            unit: Unit::M,
            ..ImportOptions::default()
        };
        let ca = camera_from_storage(&a, Path::new("a.yml"), "a", &options).unwrap();
        let cb = camera_from_storage(&b, Path::new("b.yml"), "b", &options).unwrap();
        assert_eq!(
            (ca.json.width, ca.json.fy, ca.json.cx),
            (1920, 1401.0, 959.5)
        );
        assert_eq!(ca.json.translation, [1000.0, 2000.0, 200.0]);
        for i in 0..3 {
            for j in 0..3 {
                assert!((ca.json.rotation[i][j] - cb.json.rotation[i][j]).abs() < 1e-12);
            }
        }
        assert_eq!(ca.json.translation, cb.json.translation);
        assert!(ca.notes.iter().any(|n| n.contains("pinhole")));
    }

    #[test]
    fn errors_name_the_field() {
        let p = Path::new("c.yml");
        let o = ImportOptions::default();
        let e = camera_from_storage(&yaml("image_width: 5\n"), p, "c", &o)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("no camera matrix") && e.contains("image_width"),
            "{e}"
        );
        let e = camera_from_storage(&yaml(K), p, "c", &o)
            .unwrap_err()
            .to_string();
        assert!(e.contains("no image size"), "{e}");
        let e = camera_from_storage(
            &yaml(&format!(
                "{K}image_size: [640, 480]\nR: [1, 0, 0, 0, 1, 0, 0, 0, 2]\nT: [0, 0, 1]\n"
            )),
            p,
            "c",
            &o,
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("`R`") && e.contains("not a rotation"), "{e}");
        let with_d = |d: &str| {
            camera_from_storage(
                &yaml(&format!("{K}image_size: [640, 480]\n{d}\n")),
                p,
                "c",
                &o,
            )
        };
        let e = with_d("D: [0.1, 0, 0, 0, 0, 0.2]").unwrap_err().to_string();
        assert!(e.contains("`D`") && e.contains("found 6"), "{e}");
        // A rational model, and a fisheye by ROS's model name.
        let c = with_d("D: [0.1, 0, 0, 0, 0, 0.2, 0, 0]").unwrap();
        assert_eq!(c.json.distortion.as_ref().map(Vec::len), Some(8));
        let c = with_d("distortion_model: equidistant\nD: [0.1, 0.01, 0, 0]").unwrap();
        assert_eq!(c.json.lens.as_deref(), Some("fisheye"));
        // Rational terms written as zeros are the five-coefficient model.
        let c = camera_from_storage(
            &yaml(&format!(
                "{K}image_size: [640, 480]\nD: [0.1, 0, 0, 0, 0, 0, 0, 0]\n"
            )),
            p,
            "c",
            &o,
        )
        .unwrap();
        assert_eq!(c.json.distortion, Some(vec![0.1, 0.0, 0.0, 0.0, 0.0]));
    }
}
