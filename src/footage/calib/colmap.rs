//! Cameras from a COLMAP text model (cameras.txt + images.txt, as `colmap model_converter
//! --output_type TXT` writes them). Each image names a camera: `cam0/000000.png` and
//! `cam0.png` are camera `cam0`. COLMAP puts the centre of the top-left pixel at (0.5, 0.5),
//! the capture format at (0, 0), so principal points move by half a pixel.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use nalgebra::{Quaternion, UnitQuaternion, Vector3};

use super::{ImportOptions, ImportedCamera, extrinsics, lens_from};
use crate::error::{Error, Result};
use crate::geometry::Distortion;
use crate::io::read::read_text;

/// A camera model of cameras.txt: intrinsics and OpenCV distortion from its parameters.
struct Intrinsics {
    size: (i64, i64),
    k: [f64; 4],
    distortion: Distortion,
}

/// Read the cameras of a COLMAP text model: `source` is the model's folder, or its
/// cameras.txt or images.txt (the other is taken from beside it).
pub fn read_colmap(source: &Path, options: &ImportOptions) -> Result<Vec<ImportedCamera>> {
    let dir = if source.is_dir() {
        source.to_path_buf()
    } else {
        source
            .parent()
            .map(Path::to_path_buf)
            .unwrap_or_else(|| PathBuf::from("."))
    };
    let cameras_txt = dir.join("cameras.txt");
    let images_txt = dir.join("images.txt");
    if !cameras_txt.is_file() && dir.join("cameras.bin").is_file() {
        return Err(Error::invalid(
            dir.join("cameras.bin"),
            "format",
            "a binary COLMAP model: convert it with `colmap model_converter --input_path MODEL \
             --output_path MODEL --output_type TXT`",
        ));
    }
    let intrinsics = read_cameras_txt(&cameras_txt)?;
    read_images_txt(&images_txt, &intrinsics, options)
}

fn parse<T: std::str::FromStr>(token: &str, path: &Path, field: &str) -> Result<T> {
    token.parse().map_err(|_| {
        Error::invalid(
            path,
            field,
            format!("`{}` is not a number", crate::io::read::quote(token)),
        )
    })
}

/// The camera models of cameras.txt, by CAMERA_ID.
fn read_cameras_txt(path: &Path) -> Result<BTreeMap<u64, Intrinsics>> {
    let text = read_text(path, "COLMAP cameras.txt")?;
    let mut out = BTreeMap::new();
    for (i, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let field = format!("line {}", i + 1);
        let (id, intrinsics) = camera_line(line, path, &field)?;
        if out.insert(id, intrinsics).is_some() {
            return Err(Error::invalid(
                path,
                &field,
                format!("camera {id} is listed twice"),
            ));
        }
    }
    if out.is_empty() {
        return Err(Error::invalid(path, ".", "lists no cameras"));
    }
    Ok(out)
}

/// One camera line of cameras.txt (`field` names it): its CAMERA_ID and intrinsics.
fn camera_line(line: &str, path: &Path, field: &str) -> Result<(u64, Intrinsics)> {
    let t: Vec<&str> = line.split_whitespace().collect();
    if t.len() < 4 {
        return Err(Error::invalid(
            path,
            field,
            "expected CAMERA_ID MODEL WIDTH HEIGHT PARAMS[]",
        ));
    }
    let id: u64 = parse(t[0], path, field)?;
    let size = (parse(t[2], path, field)?, parse(t[3], path, field)?);
    let p: Vec<f64> = t[4..]
        .iter()
        .map(|s| parse::<f64>(s, path, field))
        .collect::<Result<_>>()?;
    if let Some(v) = p.iter().find(|v| !v.is_finite()) {
        return Err(Error::invalid(
            path,
            field,
            format!("parameter {v} is not finite"),
        ));
    }
    let (k, distortion) = model_intrinsics(t[1], &p, path, field)?;
    Ok((
        id,
        Intrinsics {
            size,
            k,
            distortion,
        },
    ))
}

/// A camera model's parameters `p` as OpenCV's fx, fy, cx, cy and distortion.
fn model_intrinsics(
    model: &str,
    p: &[f64],
    path: &Path,
    field: &str,
) -> Result<([f64; 4], Distortion)> {
    let want = |n: usize| -> Result<()> {
        if p.len() == n {
            Ok(())
        } else {
            Err(Error::invalid(
                path,
                field,
                format!("model {model} has {n} parameters, found {}", p.len()),
            ))
        }
    };
    // COLMAP's pixel-centre convention to OpenCV's.
    let h = 0.5;
    Ok(match model {
        "SIMPLE_PINHOLE" => {
            want(3)?;
            ([p[0], p[0], p[1] - h, p[2] - h], Distortion::NONE)
        }
        "PINHOLE" => {
            want(4)?;
            ([p[0], p[1], p[2] - h, p[3] - h], Distortion::NONE)
        }
        "SIMPLE_RADIAL" => {
            want(4)?;
            let d = lens_from(&[p[3]], false, path, field)?;
            ([p[0], p[0], p[1] - h, p[2] - h], d)
        }
        "RADIAL" => {
            want(5)?;
            let d = lens_from(&[p[3], p[4]], false, path, field)?;
            ([p[0], p[0], p[1] - h, p[2] - h], d)
        }
        "OPENCV" | "FULL_OPENCV" | "OPENCV_FISHEYE" => {
            want(match model {
                "OPENCV" | "OPENCV_FISHEYE" => 8,
                _ => 12,
            })?;
            // k1 k2 p1 p2 [k3 k4 k5 k6], or the fisheye's k1..k4: OpenCV's order already.
            let d = lens_from(&p[4..], model == "OPENCV_FISHEYE", path, field)?;
            ([p[0], p[1], p[2] - h, p[3] - h], d)
        }
        other => {
            return Err(Error::invalid(
                path,
                field,
                format!(
                    "camera model {other} is not supported: use SIMPLE_PINHOLE, PINHOLE, \
                     SIMPLE_RADIAL, RADIAL, OPENCV, FULL_OPENCV or OPENCV_FISHEYE"
                ),
            ));
        }
    })
}

/// The capture's camera name for a COLMAP image name.
fn camera_name(image: &str) -> String {
    let p = Path::new(image);
    let mut parts = p.components();
    match (parts.next(), parts.next()) {
        (Some(first), Some(_)) => first.as_os_str().to_string_lossy().into_owned(),
        _ => p
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default(),
    }
}

/// The most cameras one model may hold: a capture films the teeth with a few, and every pair's
/// distance is checked.
pub const MAX_CAMERAS: usize = 64;

/// Whether `line` reads as an image line (IMAGE_ID, a unit quaternion, a translation, a known
/// CAMERA_ID, a name) rather than as 2-D points (X Y POINT3D_ID triples).
fn looks_like_an_image_line(line: &str, intrinsics: &BTreeMap<u64, Intrinsics>) -> bool {
    let t: Vec<&str> = line.split_whitespace().collect();
    if t.len() < 10 || t[0].parse::<u64>().is_err() {
        return false;
    }
    let Ok(q) = t[1..5]
        .iter()
        .map(|s| s.parse::<f64>())
        .collect::<std::result::Result<Vec<f64>, _>>()
    else {
        return false;
    };
    let norm = q.iter().map(|v| v * v).sum::<f64>().sqrt();
    (norm - 1.0).abs() < 1e-3
        && t[8]
            .parse::<u64>()
            .is_ok_and(|id| intrinsics.contains_key(&id))
}

/// The cameras of images.txt, one per camera name, each posed by its first image.
fn read_images_txt(
    path: &Path,
    intrinsics: &BTreeMap<u64, Intrinsics>,
    options: &ImportOptions,
) -> Result<Vec<ImportedCamera>> {
    let text = read_text(path, "COLMAP images.txt")?;
    // Image lines and their 2-D point lines alternate strictly (a point line may be empty).
    let lines: Vec<(usize, &str)> = text
        .lines()
        .enumerate()
        .filter(|(_, l)| !l.trim_start().starts_with('#'))
        .collect();
    let mut seen = SeenCameras::default();
    for pair in lines.chunks(2) {
        let (i, line) = pair[0];
        let field = format!("line {}", i + 1);
        let t: Vec<&str> = line.split_whitespace().collect();
        if t.is_empty() {
            continue;
        }
        if let Some(&(j, points)) = pair.get(1)
            && looks_like_an_image_line(points, intrinsics)
        {
            return Err(Error::invalid(
                path,
                format!("line {}", j + 1),
                "an image line where the 2-D points of the image above should be: COLMAP \
                 writes a POINTS2D line (empty if it has none) after every image line",
            ));
        }

        let (name, cam, image) = image_camera(&t, path, &field, intrinsics, options)?;
        seen.add(name, cam, image, path, &field)?;
    }
    if seen.order.is_empty() {
        return Err(Error::invalid(path, ".", "lists no images"));
    }
    Ok(seen.into_cameras())
}

/// One image line's tokens `t` (`field` names the line): the camera's name, the camera as
/// this image places it, and the image's name.
fn image_camera(
    t: &[&str],
    path: &Path,
    field: &str,
    intrinsics: &BTreeMap<u64, Intrinsics>,
    options: &ImportOptions,
) -> Result<(String, ImportedCamera, String)> {
    if t.len() < 10 {
        return Err(Error::invalid(
            path,
            field,
            "expected IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME",
        ));
    }
    let v: Vec<f64> = t[1..8]
        .iter()
        .map(|s| parse(s, path, field))
        .collect::<Result<_>>()?;
    if v.iter().any(|x| !x.is_finite()) {
        return Err(Error::invalid(path, field, "a pose value is not finite"));
    }
    let q = Quaternion::new(v[0], v[1], v[2], v[3]);
    if (q.norm() - 1.0).abs() > 1e-3 {
        return Err(Error::invalid(
            path,
            field,
            format!("the quaternion's norm is {}, not 1", q.norm()),
        ));
    }
    let rotation = UnitQuaternion::from_quaternion(q).to_rotation_matrix();
    let camera_id: u64 = parse(t[8], path, field)?;
    let image = t[9..].join(" ");
    let intr = intrinsics.get(&camera_id).ok_or_else(|| {
        Error::invalid(
            path,
            field,
            format!("image `{image}` uses camera {camera_id}, which cameras.txt does not list"),
        )
    })?;
    let pose = extrinsics(rotation, Vector3::new(v[4], v[5], v[6]), options);
    let name = camera_name(&image);
    let cam = ImportedCamera::new(
        &name,
        path,
        intr.size,
        intr.k,
        intr.distortion,
        pose,
        vec![format!("from image `{image}`")],
    )?;
    Ok((name, cam, image))
}

/// The cameras images.txt names, in the order first met.
#[derive(Default)]
struct SeenCameras {
    /// Per camera: as its first image places it, every image's camera centre, and that first
    /// image's name.
    by_name: BTreeMap<String, (ImportedCamera, Vec<Vector3<f64>>, String)>,
    order: Vec<String>,
}

impl SeenCameras {
    /// Records an image's camera: a new camera (up to `MAX_CAMERAS`), or one more centre of a
    /// known one.
    fn add(
        &mut self,
        name: String,
        cam: ImportedCamera,
        image: String,
        path: &Path,
        field: &str,
    ) -> Result<()> {
        let known = self.by_name.len();
        match self.by_name.get_mut(&name) {
            Some((_, centres, _)) => centres.push(cam.centre()),
            None if known >= MAX_CAMERAS => {
                return Err(Error::invalid(
                    path,
                    field,
                    format!("over {MAX_CAMERAS} cameras: a capture films the teeth with a few"),
                ));
            }
            None => {
                let centre = cam.centre();
                self.order.push(name.clone());
                self.by_name.insert(name, (cam, vec![centre], image));
            }
        }
        Ok(())
    }

    /// The cameras in order, each noting how far its other images' centres spread.
    fn into_cameras(self) -> Vec<ImportedCamera> {
        let SeenCameras { mut by_name, order } = self;
        order
            .into_iter()
            .map(|name| {
                let (mut cam, centres, first) = by_name.remove(&name).expect("listed above");
                if centres.len() > 1 {
                    let spread = centres
                        .iter()
                        .map(|c| (c - centres[0]).norm())
                        .fold(0.0, f64::max);
                    cam.notes.push(format!(
                        "{} images of this camera; the first (`{first}`) gives its pose, the \
                         others' centres lie within {spread:.3} mm of it",
                        centres.len()
                    ));
                }
                cam
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_come_from_the_folder_or_the_file() {
        assert_eq!(camera_name("cam0/000000.png"), "cam0");
        assert_eq!(camera_name("left.jpg"), "left");
    }

    #[test]
    fn a_model_round_trips_with_the_half_pixel() {
        let t = tempfile::tempdir().unwrap();
        std::fs::write(
            t.path().join("cameras.txt"),
            "# Camera list\n1 OPENCV 1920 1080 1400 1401 960 540 -0.1 0.02 0.001 -0.002\n2 PINHOLE 640 480 500 500 320 240\n",
        )
        .unwrap();
        std::fs::write(
            t.path().join("images.txt"),
            "# Image list\n1 1 0 0 0 0 0 200 1 cam0/000000.png\n\n2 0.70710678118654757 0 0.70710678118654757 0 10 0 200 2 side.png\n1.0 2.0 -1\n",
        )
        .unwrap();
        let o = ImportOptions::default();
        let cams = read_colmap(t.path(), &o).unwrap();
        assert_eq!(cams.len(), 2);
        assert_eq!(cams[0].name, "cam0");
        assert_eq!((cams[0].json.cx, cams[0].json.cy), (959.5, 539.5));
        assert_eq!(
            cams[0].json.distortion,
            Some(vec![-0.1, 0.02, 0.001, -0.002, 0.0])
        );
        assert!((cams[0].centre() - Vector3::new(0.0, 0.0, -200.0)).norm() < 1e-9);
        assert_eq!(cams[1].name, "side");
        // A quarter turn about y: the camera at x = +200 looking back along -x.
        assert!((cams[1].view_direction() + Vector3::x()).norm() < 1e-9);
        assert!((cams[1].centre() - Vector3::new(200.0, 0.0, -10.0)).norm() < 1e-6);
        std::fs::write(t.path().join("cameras.txt"), "1 FOV 10 10 1 2 3 4\n").unwrap();
        let e = read_colmap(t.path(), &o).unwrap_err().to_string();
        assert!(
            e.contains("cameras.txt") && e.contains("`line 1`") && e.contains("FOV"),
            "{e}"
        );
    }
}
