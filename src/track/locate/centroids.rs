//! What the masks show of an arch, and what a pose of it would show: each camera's teeth
//! pixels (their centroid and long axis), the world frame they give a hypothesis (the teeth's
//! triangulated centroid, the anterior and left-right axes), and the centroid an arch drawn at
//! a pose would give, for a hypothesis to be moved onto the masks'.

use nalgebra::{Matrix2, Rotation3, SymmetricEigen, Vector2, Vector3};

use crate::arch::Arch;
use crate::capture::LabelMask;
use crate::capture::masks::MOUTH_BIT;
use crate::energy::raster::render_target;
use crate::energy::target::{CLASS_BODY, CLASS_BOI, CLASS_NONE};
use crate::geometry::{Camera, Pose, triangulate};
use crate::mesh::Mesh;

/// A camera needs this many teeth pixels (at mask resolution) to take part.
pub const MIN_PIXELS: u64 = 40;
/// Rolls closer than this (degrees) to one already tried are the same guess.
const SAME_ROLL_DEG: f64 = 10.0;

/// One camera's teeth pixels: their centroid and their long axis (unit), in pixels
/// at mask resolution.
pub struct Blob<'a> {
    pub camera: &'a Camera,
    mask: &'a LabelMask,
    centroid: Vector2<f64>,
    axis: Vector2<f64>,
}

pub fn blob<'a>(camera: &'a Camera, mask: &'a LabelMask, bits: u8) -> Option<Blob<'a>> {
    let (mut n, mut sum, mut sq) = (0u64, Vector2::zeros(), Matrix2::zeros());
    for (i, &v) in mask.data.iter().enumerate() {
        if v & bits != 0 {
            let p = Vector2::new(
                (i as u32 % mask.width) as f64 + 0.5,
                (i as u32 / mask.width) as f64 + 0.5,
            );
            n += 1;
            sum += p;
            sq += p * p.transpose();
        }
    }
    if n < MIN_PIXELS {
        return None;
    }
    let centroid = sum / n as f64;
    let cov = sq / n as f64 - centroid * centroid.transpose();
    let eigen = SymmetricEigen::new(cov);
    let major = if eigen.eigenvalues[0] >= eigen.eigenvalues[1] {
        0
    } else {
        1
    };
    Some(Blob {
        camera,
        mask,
        centroid,
        axis: eigen.eigenvectors.column(major).into_owned(),
    })
}

/// The world direction of the ray through pixel `px`.
fn ray(camera: &Camera, px: Vector2<f64>) -> Vector3<f64> {
    let n = camera.pixel_to_normalised(px);
    camera.camera_from_world.rotation.inverse() * Vector3::new(n.x, n.y, 1.0)
}

/// The unit vector perpendicular to `z` that lies closest to every plane of `normals` (the
/// least-squares null direction within the plane perpendicular to `z`).
fn in_planes(normals: &[Vector3<f64>], z: &Vector3<f64>) -> Vector3<f64> {
    let e1 = z
        .cross(&Vector3::x())
        .try_normalize(1e-6)
        .unwrap_or_else(|| z.cross(&Vector3::y()).normalize());
    let e2 = z.cross(&e1);
    let mut m = Matrix2::zeros();
    for n in normals {
        let v = Vector2::new(n.dot(&e1), n.dot(&e2));
        m += v * v.transpose();
    }
    let eigen = SymmetricEigen::new(m);
    let minor = if eigen.eigenvalues[0] <= eigen.eigenvalues[1] {
        0
    } else {
        1
    };
    let c = eigen.eigenvectors.column(minor);
    (e1 * c[0] + e2 * c[1]).normalize()
}

/// Where the arches' hypotheses start: the teeth's triangulated centroid and the world axes
/// each roll guess gives (columns: left, up, anterior).
pub struct Frame {
    pub teeth: Vector3<f64>,
    pub anterior: Vector3<f64>,
    pub axes: Vec<Rotation3<f64>>,
}

/// `None` when the centroids do not triangulate (rays that do not meet in front of the
/// cameras).
pub fn world_frame(blobs: &[Blob]) -> Option<Frame> {
    let views: Vec<_> = blobs.iter().map(|b| (b.camera, b.centroid)).collect();
    let teeth = triangulate(&views).ok()?;
    let centres: Vector3<f64> = blobs
        .iter()
        .map(|b| b.camera.centre_world())
        .sum::<Vector3<f64>>()
        / blobs.len() as f64;
    let anterior = (centres - teeth).normalize();
    let normals: Vec<_> = blobs
        .iter()
        .map(|b| {
            ray(b.camera, b.centroid)
                .cross(&ray(b.camera, b.centroid + b.axis * 10.0))
                .normalize()
        })
        .collect();
    let from_band = in_planes(&normals, &anterior);
    // The cameras' up (image −y) averaged, as a left-right axis: up × anterior.
    let up: Vector3<f64> = blobs
        .iter()
        .map(|b| b.camera.camera_from_world.rotation.inverse() * -Vector3::y())
        .sum();
    let from_cameras = up.cross(&anterior).try_normalize(1e-6);
    let mut lefts = vec![from_band];
    if let Some(l) = from_cameras
        && l.dot(&from_band).abs() < SAME_ROLL_DEG.to_radians().cos()
    {
        lefts.push(l);
    }
    let axes = lefts
        .iter()
        .flat_map(|&l| [l, -l])
        .map(|left| {
            let left = (left - anterior * anterior.dot(&left)).normalize();
            let up = anterior.cross(&left);
            Rotation3::from_matrix_unchecked(nalgebra::Matrix3::from_columns(&[left, up, anterior]))
        })
        .collect();
    Some(Frame {
        teeth,
        anterior,
        axes,
    })
}

/// A camera an arch's teeth show in, and where its mask says they can show: inside the lips'
/// opening (teeth or mouth labels) where the masks label the mouth, anywhere otherwise.
pub struct View<'a> {
    camera: &'a Camera,
    opening: Option<&'a LabelMask>,
}

/// The cameras of `blobs`, each bounded by its mask's opening where the masks label the mouth.
pub fn views<'a>(blobs: &[Blob<'a>], opening: bool) -> Vec<View<'a>> {
    blobs
        .iter()
        .map(|b| View {
            camera: b.camera,
            opening: opening.then_some(b.mask),
        })
        .collect()
}

/// Where `mesh` at `pose` shows in each view, as the masks' teeth would show it: their centroids
/// triangulated. Inside the lips' opening that is all the arch draws there (a front-teeth BOI
/// would centre the whole arch on its incisors, millimetres ahead of the molars the masks also
/// show); with no opening known, the BOI (or all of the arch without one), since teeth drawn
/// behind the lips count for nothing in the masks' centroid.
pub fn drawn_centre(arch: Arch, mesh: &Mesh, pose: &Pose, views: &[View]) -> Option<Vector3<f64>> {
    let has_boi = mesh.boi.iter().any(|&b| b);
    let opening = arch.mask_bit() | MOUTH_BIT;
    let mut centres = Vec::new();
    for view in views {
        let cam = view.camera;
        let target = render_target(cam, &[(mesh, pose, CLASS_BODY, CLASS_BOI)]);
        let (mut n, mut sum) = (0u64, Vector2::zeros());
        for (i, &c) in target.class.iter().enumerate() {
            let shows = match view.opening {
                Some(mask) => c != CLASS_NONE && mask.data[i] & opening != 0,
                None if has_boi => c == CLASS_BOI,
                None => c != CLASS_NONE,
            };
            if shows {
                n += 1;
                sum += Vector2::new(
                    (i as u32 % cam.width) as f64 + 0.5,
                    (i as u32 / cam.width) as f64 + 0.5,
                );
            }
        }
        if n >= MIN_PIXELS {
            centres.push((cam, sum / n as f64));
        }
    }
    (centres.len() >= 2)
        .then(|| triangulate(&centres).ok())
        .flatten()
}
