//! Reading and validating a capture (../shared/spec/capture-format.md): cameras, meshes with
//! their boundary of interest, masks read frame by frame, init.json and ground truth.

mod camera;
pub mod json;
pub mod light;
pub mod masks;
mod open;
mod paths;
pub mod resolution;
pub use paths::{Folder, capture_reads, listed_file_inside, path_inside};

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

use nalgebra::Vector2;

use crate::arch::{Arch, ArchPoses};
use crate::error::{Error, Result, Shown};
use crate::formats::FramePoses;
use crate::geometry::{Camera, Pose, fit_rigid, triangulate};
use crate::io::{check_finite, read_json};
use crate::mesh::Mesh;
pub use camera::{camera_from_json, read_camera};
use json::{ArchInitJson, InitJson};
pub use masks::{LOWER_BIT, LabelMask, MaskMode, UPPER_BIT};

/// A camera of the capture with what was found of its masks.
#[derive(Debug)]
pub struct CaptureCamera {
    /// As calibrated (full resolution, distortion included).
    pub calibrated: Camera,
    /// Mask size as the energy sees it (all masks of a camera share it; divided by
    /// [`OpenOptions::mask_reduce`] when the capture was opened so); `None` when the camera has
    /// no masks.
    pub mask_size: Option<(u32, u32)>,
    /// Frames (the capture's numbers) with a mask file.
    pub frames_present: BTreeSet<u32>,
    /// How many frames this camera's files run ahead of the capture's numbers
    /// (`frames.offsets`): frame f is file f + offset.
    pub offset: i64,
}

impl CaptureCamera {
    /// The file number of the capture's frame `frame` for this camera (`None`: before its
    /// first file).
    pub fn file_frame(&self, frame: u32) -> Option<u32> {
        u32::try_from(frame as i64 + self.offset).ok()
    }

    /// The camera the masks are seen through: calibrated intrinsics scaled to the mask size,
    /// distortion as calibrated (masks are used as they are; the energy draws the models
    /// through the lens).
    pub fn mask_camera(&self) -> Option<Camera> {
        let (w, h) = self.mask_size?;
        Some(self.calibrated.scaled_to(w, h))
    }
}

/// The bootstrap of one arch: mesh vertices seen at pixels in two or more cameras.
#[derive(Debug, Clone)]
pub struct InitPoint {
    pub vertex: u32,
    /// (camera index, pixel in the calibrated image)
    pub pixels: Vec<(usize, Vector2<f64>)>,
}

#[derive(Debug, Clone)]
pub enum ArchInit {
    Pose(Pose),
    Points(Vec<InitPoint>),
}

#[derive(Debug, Clone)]
pub struct Init {
    pub upper: ArchInit,
    pub lower: ArchInit,
}

/// A validated capture. Masks are not held: read them frame by frame with [`Capture::load_masks`].
#[derive(Debug)]
pub struct Capture {
    dir: PathBuf,
    cameras: Vec<CaptureCamera>,
    first_frame: u32,
    frame_count: u32,
    upper: Mesh,
    lower: Mesh,
    mandible: Option<Mesh>,
    mask_dir: PathBuf,
    mask_mode: MaskMode,
    /// The mask value of the visible mouth interior (`masks.mouth`), when the masks label it.
    /// The paper's energy reads it as background.
    mouth: Option<u8>,
    /// What was read but not used (fields the format does not have), for the user to see.
    notes: Vec<String>,
    /// Masks are read at 1/`mask_reduce` of their resolution ([`OpenOptions::mask_reduce`]).
    mask_reduce: u32,
    /// How far (mm) the arches were simplified at load; `None`: to a triangle count.
    simplified_mm: Option<f64>,
    init: Option<Init>,
    gt: Option<Vec<FramePoses>>,
}

impl Capture {
    /// The capture folder.
    pub fn dir(&self) -> &Path {
        &self.dir
    }
    /// How far (mm) from the scans' surfaces the arches were simplified at load; `None` where
    /// they were simplified to a triangle count.
    pub fn simplified_mm(&self) -> Option<f64> {
        self.simplified_mm
    }
    /// The cameras, in capture.json's order.
    pub fn cameras(&self) -> &[CaptureCamera] {
        &self.cameras
    }
    pub fn first_frame(&self) -> u32 {
        self.first_frame
    }
    pub fn frame_count(&self) -> u32 {
        self.frame_count
    }
    pub fn upper(&self) -> &Mesh {
        &self.upper
    }
    pub fn lower(&self) -> &Mesh {
        &self.lower
    }
    /// The mandible (teeth, ramus, condyles) in the lower arch's frame, when the capture has one.
    pub fn mandible(&self) -> Option<&Mesh> {
        self.mandible.as_ref()
    }
    pub fn mask_dir(&self) -> &Path {
        &self.mask_dir
    }
    pub fn mask_mode(&self) -> MaskMode {
        self.mask_mode
    }
    /// The mask value of the visible mouth interior (`masks.mouth`), when the masks label it.
    pub fn mouth(&self) -> Option<u8> {
        self.mouth
    }
    /// What was read but not used (fields the format does not have), for the user to see.
    pub fn notes(&self) -> &[String] {
        &self.notes
    }
    /// Masks are read at 1/`mask_reduce` of their resolution.
    pub fn mask_reduce(&self) -> u32 {
        self.mask_reduce
    }
    pub fn init(&self) -> Option<&Init> {
        self.init.as_ref()
    }
    /// The ground truth (gt/poses.json), when the capture has it.
    pub fn gt(&self) -> Option<&[FramePoses]> {
        self.gt.as_deref()
    }

    /// Tell camera `k` that its masks, made as tracking goes (segmenting the pictures), will
    /// be `size` as the energy sees them: tracking is set up before the first mask exists.
    pub fn expect_masks(&mut self, k: usize, size: (u32, u32)) {
        self.cameras[k].mask_size = Some(size);
    }

    /// The same capture without init.json: tracking then finds the first frame's poses.
    pub fn without_init(mut self) -> Capture {
        self.init = None;
        self
    }

    /// The same capture with its mouth label read as background, as the paper's energy
    /// reads every mask (a comparison with and without the label).
    pub fn without_mouth_label(mut self) -> Capture {
        self.mouth = None;
        self
    }
}

/// Masks of one frame, one entry per camera (`None`: no mask file for that camera).
#[derive(Debug, Clone)]
pub struct FrameMasks {
    pub frame: u32,
    pub masks: Vec<Option<LabelMask>>,
}

/// Options for opening a capture.
#[derive(Debug, Clone, Copy)]
pub struct OpenOptions {
    /// Simplify each arch to at most this many triangles at load (before `simplify_mm`).
    pub max_triangles: Option<usize>,
    /// Otherwise simplify each arch as far as its surface stays within this distance (mm) of
    /// the scan's; 0 keeps every triangle; `None`: a tenth of a mask pixel where the cameras
    /// look ([`resolution::simplify_mm`]).
    pub simplify_mm: Option<f64>,
    /// Read the masks at 1/k of their resolution (each k x k block takes its most common
    /// label; the cameras are scaled as for any smaller mask): the energy's cost falls with the
    /// pixel count, its precision with the pixel size. 1 reads them as they are.
    pub mask_reduce: u32,
    /// Let capture.json name files outside the capture folder (absolute paths, `..`, links
    /// out). Off by default: a capture from elsewhere reads only its own folder.
    pub allow_outside: bool,
    /// The masks are yet to be made (`jawtrack segment`): a capture with no mask files opens,
    /// its cameras without a mask size.
    pub masks_to_come: bool,
}

impl Default for OpenOptions {
    fn default() -> Self {
        OpenOptions {
            max_triangles: None,
            simplify_mm: None,
            mask_reduce: 1,
            allow_outside: false,
            masks_to_come: false,
        }
    }
}

impl Capture {
    pub fn open(dir: &Path) -> Result<Capture> {
        Self::open_with(dir, OpenOptions::default())
    }

    /// Read and validate the capture in `dir` (capture.json, cameras, meshes, the masks
    /// present, init.json and ground truth).
    pub fn open_with(dir: &Path, options: OpenOptions) -> Result<Capture> {
        open::Opening::new(dir, options).open()
    }

    pub fn camera_names(&self) -> Vec<&str> {
        self.cameras
            .iter()
            .map(|c| c.calibrated.name.as_str())
            .collect()
    }

    pub fn frames(&self) -> std::ops::Range<u32> {
        self.first_frame..self.first_frame + self.frame_count
    }

    pub fn mesh(&self, arch: Arch) -> &Mesh {
        match arch {
            Arch::Upper => &self.upper,
            Arch::Lower => &self.lower,
        }
    }

    /// The mask file of the capture's frame `frame` for a camera (through its offset).
    pub fn mask_path(&self, camera: usize, frame: u32) -> PathBuf {
        let cam = &self.cameras[camera];
        let file = cam.file_frame(frame).unwrap_or(frame);
        self.mask_dir
            .join(&cam.calibrated.name)
            .join(format!("{file:06}.png"))
    }

    /// A camera's video frame (images/<camera>/<file>.png|jpg, the file number through the
    /// camera's offset), if the capture has it.
    pub fn image_path(&self, camera: usize, frame: u32) -> Option<PathBuf> {
        let cam = &self.cameras[camera];
        let (name, file) = (&cam.calibrated.name, cam.file_frame(frame)?);
        ["png", "jpg", "jpeg"]
            .iter()
            .map(|ext| {
                self.dir
                    .join("images")
                    .join(name)
                    .join(format!("{file:06}.{ext}"))
            })
            .find(|p| p.exists())
    }

    /// Decode the masks of one frame, as they are (see [`CaptureCamera::mask_camera`]).
    pub fn load_masks(&self, frame: u32) -> Result<FrameMasks> {
        let mut masks = Vec::with_capacity(self.cameras.len());
        for (i, cam) in self.cameras.iter().enumerate() {
            if !cam.frames_present.contains(&frame) {
                masks.push(None);
                continue;
            }
            let path = self.mask_path(i, frame);
            let mask = masks::decode_mask(&path, self.mask_mode, self.mouth)?;
            let (w, h) = cam
                .mask_size
                .expect("a camera with mask files has a mask size");
            let expected = (w * self.mask_reduce, h * self.mask_reduce);
            if (mask.width, mask.height) != expected {
                return Err(Error::invalid(
                    &path,
                    "size",
                    format!(
                        "{}x{} differs from the camera's other masks ({}x{})",
                        mask.width, mask.height, expected.0, expected.1
                    ),
                ));
            }
            masks.push(Some(mask.reduced(self.mask_reduce)));
        }
        Ok(FrameMasks { frame, masks })
    }

    /// First-frame poses from init.json: given, or bootstrapped (triangulate the points,
    /// then fit the mesh vertices to them rigidly).
    pub fn initial_poses(&self) -> Result<ArchPoses> {
        let init_path = self.dir.join("init.json");
        let init = self.init.as_ref().ok_or_else(|| Error::Missing {
            path: init_path.clone(),
            what: "init.json (the first frame's poses, or bootstrap points per arch)".into(),
        })?;
        self.resolve_init(init, &init_path)
    }

    /// The first frame's poses an init gives: as written, or its points triangulated and
    /// fitted rigidly; `init_path` names it in errors.
    pub fn resolve_init(&self, init: &Init, init_path: &Path) -> Result<ArchPoses> {
        let resolve = |arch: Arch, ai: &ArchInit| -> Result<Pose> {
            match ai {
                ArchInit::Pose(p) => Ok(*p),
                ArchInit::Points(points) => {
                    let mesh = self.mesh(arch);
                    let mut model = Vec::new();
                    let mut world = Vec::new();
                    for (k, p) in points.iter().enumerate() {
                        let views: Vec<_> = p
                            .pixels
                            .iter()
                            .map(|(c, px)| (&self.cameras[*c].calibrated, *px))
                            .collect();
                        let x = triangulate(&views).map_err(|e| {
                            Error::invalid(
                                init_path,
                                format!("{}.points[{k}]", arch.name()),
                                e.to_string(),
                            )
                        })?;
                        let v = mesh.positions[p.vertex as usize];
                        model.push(nalgebra::Vector3::new(
                            v[0] as f64,
                            v[1] as f64,
                            v[2] as f64,
                        ));
                        world.push(x);
                    }
                    let fitted = fit_rigid(&model, &world).map_err(|e| {
                        Error::invalid(init_path, format!("{}.points", arch.name()), e.to_string())
                    })?;
                    // Pixels in the image can still triangulate to nonsense (rays nearly
                    // parallel): the pose must be one a pose file could give.
                    crate::formats::PoseJson::from(&fitted)
                        .to_pose(
                            init_path,
                            &format!("{}.points (the pose they give)", arch.name()),
                        )
                        .map(|_| fitted)
                }
            }
        };
        Ok(ArchPoses {
            upper: resolve(Arch::Upper, &init.upper)?,
            lower: resolve(Arch::Lower, &init.lower)?,
        })
    }

    /// Ground-truth poses of a frame, if the capture has them.
    pub fn gt_poses(&self, frame: u32) -> Option<ArchPoses> {
        self.gt
            .as_ref()?
            .iter()
            .find(|f| f.frame == frame)
            .map(|f| f.poses)
    }

    fn read_init(&self, path: &Path) -> Result<Init> {
        let ij: InitJson = read_json(path, "init.json")?;
        self.init_from(&ij, path)
    }

    /// An init.json's content checked against this capture (cameras, vertices); `path` names
    /// it in errors.
    pub fn init_from(&self, ij: &InitJson, path: &Path) -> Result<Init> {
        let names = self.camera_names();
        let arch_init = |arch: Arch, a: &ArchInitJson| -> Result<ArchInit> {
            let field = arch.name();
            match a {
                ArchInitJson::Pose(p) => Ok(ArchInit::Pose(p.to_pose(path, field)?)),
                ArchInitJson::Points { points } => {
                    if points.len() < 3 {
                        return Err(Error::invalid(
                            path,
                            format!("{field}.points"),
                            format!(
                                "a rigid bootstrap needs at least three points, found {}",
                                points.len()
                            ),
                        ));
                    }
                    let nv = self.mesh(arch).positions.len();
                    let mut out = Vec::with_capacity(points.len());
                    for (k, p) in points.iter().enumerate() {
                        let f = format!("{field}.points[{k}]");
                        if p.vertex < 0 || p.vertex as usize >= nv {
                            return Err(Error::invalid(
                                path,
                                format!("{f}.vertex"),
                                format!(
                                    "vertex {} is out of range (the {field} mesh has {nv} vertices)",
                                    p.vertex
                                ),
                            ));
                        }
                        if p.pixels.len() < 2 {
                            return Err(Error::invalid(
                                path,
                                format!("{f}.pixels"),
                                "a point needs its pixel in at least two cameras",
                            ));
                        }
                        let mut pixels = Vec::new();
                        for (cam, px) in &p.pixels {
                            let c = names.iter().position(|n| n == cam).ok_or_else(|| {
                                Error::invalid(
                                    path,
                                    format!("{f}.pixels.{cam}"),
                                    format!("no camera named `{cam}` in capture.json"),
                                )
                            })?;
                            check_finite(path, &format!("{f}.pixels.{cam}"), px)?;
                            let calibrated = &self.cameras[c].calibrated;
                            let (w, h) = (calibrated.width as f64, calibrated.height as f64);
                            if !(0.0..=w).contains(&px[0]) || !(0.0..=h).contains(&px[1]) {
                                return Err(Error::invalid(
                                    path,
                                    format!("{f}.pixels.{cam}"),
                                    format!(
                                        "({}, {}) lies outside the camera's {w}x{h} image: a point it sees lies in it",
                                        Shown(px[0]),
                                        Shown(px[1])
                                    ),
                                ));
                            }
                            pixels.push((c, Vector2::new(px[0], px[1])));
                        }
                        out.push(InitPoint {
                            vertex: p.vertex as u32,
                            pixels,
                        });
                    }
                    Ok(ArchInit::Points(out))
                }
            }
        };
        Ok(Init {
            upper: arch_init(Arch::Upper, &ij.upper)?,
            lower: arch_init(Arch::Lower, &ij.lower)?,
        })
    }
}
