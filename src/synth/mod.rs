//! Synthetic captures with ground truth (`jawtrack synth`): procedural or given arches, jaw
//! motion from a model of the temporomandibular joint, slow head motion, the camera rig of
//! calib/, masks at half resolution with lips and segmentation noise per preset. Writes the
//! capture format exactly, deterministically per seed.

pub mod colour;
pub use colour::Photos;
pub mod exercise;
pub mod face;
mod face_script;
pub mod mandible;
pub mod masks;
mod write;

use std::path::{Path, PathBuf};
use std::time::Instant;

use nalgebra::Vector3;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::anatomy::{JawControls, JawModel, procedural_arch, rest_bite};
use crate::arch::{Arch, ArchPoses};
use crate::capture::json::CameraJson;
use crate::energy::raster::render_labels;
use crate::error::{Error, Result};
use crate::geometry::{Camera, Distortion, Pose};
use crate::mesh::{BoiMarking, mark_boi};
use crate::mesh::{BoiSource, Mesh};
use exercise::exercise_controls;
use write::write_capture;

/// The example rig in calib/, compiled in: what `synth` films with.
pub const RIG: [(&str, &str); 3] = [
    ("cam0", include_str!("../../calib/cam0.json")),
    ("cam1", include_str!("../../calib/cam1.json")),
    ("cam2", include_str!("../../calib/cam2.json")),
];

pub const FRAMES_PER_SECOND: f64 = 24.0;
/// Mask labels written for per-arch masks (distinct greys, so a person can see them).
pub const UPPER_LABEL: u8 = 85;
pub const LOWER_LABEL: u8 = 170;
const COMBINED_TEETH: u8 = 255;
/// The mask value of the visible mouth interior (`masks.mouth`): dark, below 128 so that
/// combined masks can carry it too.
pub const MOUTH_LABEL: u8 = 40;
/// A moderate barrel lens (OpenCV's k1, k2, p1, p2, k3), for tests and benchmarks of captures
/// with distortion. At the synthetic rig's full resolution it moves a point the pinhole camera
/// puts in an image corner in by about 200 pixels, and one 200 pixels from the centre, where
/// the arches are, by about 2.5.
pub const BARREL_LENS: Distortion = Distortion::OpenCv([
    -0.25, 0.08, 0.001, -0.0005, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0,
]);

/// A strong rational lens with thin-prism terms (OpenCV's 12 coefficients), for tests of the
/// full model.
pub const RATIONAL_LENS: Distortion = Distortion::OpenCv([
    0.8, 0.3, 0.0008, -0.0006, 0.01, 1.05, 0.45, 0.02, 0.001, -0.0002, -0.0007, 0.0001,
]);

/// A fisheye (cv::fisheye's k1..k4) of the kind a GoPro's wide mode needs, for tests.
pub const FISHEYE_LENS: Distortion = Distortion::Fisheye([0.05, -0.02, 0.004, -0.0006]);

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Preset {
    /// Perfect masks of the whole crowns.
    Clean,
    /// Lips hide the gum side of the crowns; boundaries wander by a pixel or two; gums
    /// between teeth filled; a few specular holes.
    Realistic,
    /// Faster motion, more noise, and frames where the lips close.
    Hard,
}

/// Which temporomandibular joint the subject has.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum Joint {
    /// An average adult joint.
    #[default]
    Average,
    /// A second subject: condyles placed differently, a steeper eminence, less opening.
    Variant,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MaskKind {
    PerArch,
    Combined,
}

#[derive(Debug, Clone)]
pub struct SynthOptions {
    pub frames: u32,
    pub seed: u64,
    pub preset: Preset,
    pub masks: MaskKind,
    /// A folder with upper.* and lower.* (OBJ, STL or PLY) to use instead of procedural arches.
    pub meshes: Option<PathBuf>,
    /// Replace `out` if it exists.
    pub force: bool,
    /// Write no masks: meshes, cameras, init and ground truth only (for learning a rig from
    /// the motion; every frame of such a capture is `no-data` to the tracker).
    pub no_masks: bool,
    pub joint: Joint,
    /// Frames each segment of the exercise (e.g. rest to wide open) takes at least: the
    /// movements' pace. 20 frames is 0.83 s a movement at the synthetic 24 fps (incisors up
    /// to ~3.5 mm a frame, 85 mm/s), an unhurried human pace. A capture shorter than the
    /// exercise at this pace plays its beginning; a longer one spreads the whole exercise
    /// over it.
    pub frames_per_segment: u32,
    /// A folder of camera files (`<name>.json`, the capture format's) to film with instead of
    /// the rig of calib/; every camera's masks are written at half its resolution.
    pub rig: Option<PathBuf>,
    /// Every camera's lens (any OpenCV model or the fisheye), replacing the camera files':
    /// written to the capture's camera files, and the masks are drawn through it. `None`
    /// keeps the cameras' own (calib/ has none).
    pub distortion: Option<Distortion>,
    /// Label the visible mouth interior (the lip opening less the teeth) in the masks of
    /// the presets with lips (`masks.mouth`); false writes teeth masks alone.
    pub mouth: bool,
    /// Segmentation errors that persist from frame to frame, as a tracked roto mask's do:
    /// each camera's wandering boundaries and specular holes are drawn once for the capture
    /// rather than afresh every frame.
    pub persistent_noise: bool,
    /// Also film the capture in colour: `images/<camera>/<frame>.png` at the masks'
    /// resolution, and the true labels they show in `gt/masks/` (for scoring masks made
    /// from the pictures).
    pub images: bool,
    /// Frames (capture numbers) during which the light is off in the colour pictures.
    pub light_off: Option<std::ops::Range<u32>>,
    /// What the colour pictures show besides teeth, mouth, lips and skin.
    pub photos: Photos,
}

impl Default for SynthOptions {
    fn default() -> Self {
        SynthOptions {
            frames: 48,
            seed: 0,
            preset: Preset::Realistic,
            masks: MaskKind::PerArch,
            meshes: None,
            force: false,
            no_masks: false,
            joint: Joint::Average,
            frames_per_segment: exercise::FRAMES_PER_SEGMENT,
            rig: None,
            distortion: None,
            mouth: true,
            persistent_noise: false,
            images: false,
            light_off: None,
            photos: Photos::Clean,
        }
    }
}

impl SynthOptions {
    /// Whether the masks label the visible mouth interior: asked for, and a preset with lips.
    pub fn writes_mouth(&self) -> bool {
        self.mouth && self.preset != Preset::Clean && !self.no_masks
    }
}

/// What a synthetic capture contains, for the user and the closing note.
#[derive(Debug, Clone, serde::Serialize)]
pub struct SynthReport {
    pub frames: u32,
    pub triangles: [usize; 2],
    pub boi_triangles: [usize; 2],
    pub cameras: Vec<CameraStats>,
    /// Largest incisal opening, lateral excursion to each side, protrusion (mm) and condylar
    /// travel reached over the capture.
    pub max_opening_mm: f64,
    pub lateral_mm: [f64; 2],
    pub max_protrusion_mm: f64,
    pub max_condylar_travel_mm: f64,
    pub seconds: f64,
}

#[derive(Debug, Clone, serde::Serialize)]
pub struct CameraStats {
    pub name: String,
    pub mask_size: [u32; 2],
    pub frames_with_mask: u32,
    /// Mean mask pixels per frame, upper and lower.
    pub mean_mask_pixels: [f64; 2],
    /// Mean pixels per frame labelled visible mouth interior.
    pub mean_mouth_pixels: f64,
    /// Share of each arch's projection (drawn alone) that is in its mask, over all frames.
    pub visible_share: [f64; 2],
}

/// The subject and the session: everything drawn from the seed before the frames.
struct Session {
    upper: Mesh,
    lower: Mesh,
    mandible: Mesh,
    jaw: JawModel,
    lips: [masks::LipLine; 2],
    /// Each camera with the text of its file, written to the capture as read.
    cameras: Vec<(Camera, String)>,
    mask_cameras: Vec<Camera>,
    /// world_from_upper at rest: the upper incisal point at the world origin.
    world_from_upper_rest: Pose,
    gain: [f64; 3],
    head_phase: [f64; 6],
    lip_phase: [f64; 2],
    /// The lower incisal point, lower frame (for the motion report).
    lower_incisor: Vector3<f64>,
}

/// The rig of calib/ (compiled in), read like any capture's camera files.
pub fn rig_cameras() -> Vec<Camera> {
    RIG.iter()
        .map(|(name, json)| {
            let path = Path::new("calib").join(format!("{name}.json"));
            let cj: CameraJson =
                serde_json::from_str(json).expect("calib/ camera files are valid JSON");
            crate::capture::camera_from_json(&cj, &path, name)
                .expect("calib/ camera files are valid cameras")
        })
        .collect()
}

/// The cameras of a rig folder (every `<name>.json` in it, by name), each with its file's
/// text; or calib/'s.
fn load_rig(rig: Option<&Path>) -> Result<Vec<(Camera, String)>> {
    let Some(dir) = rig else {
        return Ok(rig_cameras()
            .into_iter()
            .zip(RIG)
            .map(|(c, (_, json))| (c, json.to_string()))
            .collect());
    };
    let entries = std::fs::read_dir(dir).map_err(|e| Error::read(dir, "camera rig folder", e))?;
    let mut files = Vec::new();
    for entry in entries {
        let path = entry
            .map_err(|e| Error::read(dir, "camera rig folder", e))?
            .path();
        if path.extension().is_some_and(|e| e == "json") {
            files.push(path);
        }
    }
    files.sort();
    if files.is_empty() {
        return Err(Error::invalid(
            dir,
            "--rig",
            "holds no camera files (<name>.json, as in a capture's cameras/)",
        ));
    }
    files
        .iter()
        .map(|path| {
            let name = path
                .file_stem()
                .and_then(|s| s.to_str())
                .ok_or_else(|| Error::invalid(path, "file name", "is not valid UTF-8"))?;
            let text =
                std::fs::read_to_string(path).map_err(|e| Error::read(path, "camera file", e))?;
            let cj: CameraJson = crate::io::parse_json(&text, path)?;
            Ok((crate::capture::camera_from_json(&cj, path, name)?, text))
        })
        .collect()
}

fn load_arch(dir: &Path, arch: Arch) -> Result<Mesh> {
    let path = ["obj", "stl", "ply"]
        .iter()
        .map(|ext| dir.join(format!("{}.{ext}", arch.name())))
        .find(|p| p.exists())
        .ok_or_else(|| Error::Missing {
            path: dir.join(format!("{}.obj", arch.name())),
            what: format!(
                "{} arch mesh ({}.obj, .stl or .ply)",
                arch.name(),
                arch.name()
            ),
        })?;
    let mut mesh = Mesh::load(&path, BoiSource::GroupIfPresent("boi"))?;
    if mesh.boi_face_count() == 0
        && mark_boi(&mut mesh, &BoiMarking::for_arch(arch == Arch::Upper)) == 0
    {
        return Err(Error::invalid(
            &path,
            "boi",
            "no boundary of interest could be marked (is the mesh in the scan frame: y up, +z anterior?)",
        ));
    }
    Ok(mesh)
}

impl Session {
    fn new(opts: &SynthOptions) -> Result<Session> {
        let mut rng = ChaCha8Rng::seed_from_u64(opts.seed);
        let (upper, lower) = match &opts.meshes {
            Some(dir) => (load_arch(dir, Arch::Upper)?, load_arch(dir, Arch::Lower)?),
            None => (procedural_arch(true), procedural_arch(false)),
        };
        let rest = rest_bite(&upper, &lower);
        let jaw = match opts.joint {
            Joint::Average => JawModel::for_arches(&upper, rest),
            Joint::Variant => JawModel::variant_for_arches(&upper, rest),
        };
        let mandible = mandible::mandible_mesh(&lower, &jaw);
        let (ulo, uhi) = upper.bounds();
        let anchor = Vector3::new((ulo[0] + uhi[0]) as f64 * 0.5, ulo[1] as f64, uhi[2] as f64);
        let (llo, lhi) = lower.bounds();
        let lower_incisor =
            Vector3::new((llo[0] + lhi[0]) as f64 * 0.5, lhi[1] as f64, lhi[2] as f64);
        let mut cameras = load_rig(opts.rig.as_deref())?;
        if let Some(d) = opts.distortion {
            for (c, _) in &mut cameras {
                c.distortion = d;
            }
        }
        let mask_cameras: Vec<Camera> = cameras
            .iter()
            .map(|(c, _)| c.scaled_to((c.width / 2).max(1), (c.height / 2).max(1)))
            .collect();
        if let Some(c) = mask_cameras.iter().find(|c| !c.lens_covers_the_image()) {
            return Err(Error::invalid(
                Path::new(&format!("{}.json", c.name)),
                "distortion",
                format!(
                    "{:?} folds back on itself inside the image (the radial model stops growing \
                     before the corners): choose a milder lens",
                    c.distortion
                ),
            ));
        }
        let lips = [
            masks::LipLine::new(&upper, Arch::Upper),
            masks::LipLine::new(&lower, Arch::Lower),
        ];
        let mut phase = || rng.random_range(0.0..std::f64::consts::TAU);
        let head_phase = [phase(), phase(), phase(), phase(), phase(), phase()];
        let lip_phase = [phase(), phase()];
        let gain = [
            rng.random_range(0.95..=1.0),
            rng.random_range(0.95..=1.0),
            rng.random_range(0.95..=1.0),
        ];
        Ok(Session {
            upper,
            lower,
            mandible,
            jaw,
            lips,
            cameras,
            mask_cameras,
            world_from_upper_rest: Pose::from_translation(-anchor),
            gain,
            head_phase,
            lip_phase,
            lower_incisor,
        })
    }

    fn controls(&self, index: u32, opts: &SynthOptions) -> JawControls {
        let tau = if opts.frames > 1 {
            index as f64 / (opts.frames - 1) as f64
        } else {
            0.0
        };
        // `hard` moves twice as fast.
        let repeats = if opts.preset == Preset::Hard { 2 } else { 1 };
        let segments = (opts.frames as f64 / opts.frames_per_segment.max(1) as f64)
            .min(exercise::ALL_SEGMENTS as f64);
        exercise_controls(tau, segments, repeats, &self.gain)
    }

    /// Slow head motion: about ±2° and ±2 mm, periods of 4 to 9 s, about the incisors.
    fn world_from_upper(&self, index: u32) -> Pose {
        let t = index as f64 / FRAMES_PER_SECOND;
        let periods = [7.0, 9.0, 5.0, 6.0, 8.0, 4.0];
        let w: [f64; 6] = std::array::from_fn(|k| {
            (std::f64::consts::TAU * t / periods[k] + self.head_phase[k]).sin()
                - self.head_phase[k].sin()
        });
        let a = 2f64.to_radians();
        let wobble = Pose::from_euler_tuple(&[
            a * w[0],
            a * w[1],
            a * w[2],
            2.0 * w[3],
            2.0 * w[4],
            2.0 * w[5],
        ]);
        wobble.compose(&self.world_from_upper_rest)
    }

    /// Visible crown beyond the tips at the midline (mm), upper and lower lip.
    fn lip_show(&self, index: u32, opts: &SynthOptions) -> [f64; 2] {
        let t = index as f64 / FRAMES_PER_SECOND;
        let tau = if opts.frames > 1 {
            index as f64 / (opts.frames - 1) as f64
        } else {
            0.0
        };
        if opts.preset == Preset::Hard
            && ((0.30..0.34).contains(&tau) || (0.70..0.73).contains(&tau))
        {
            return [-4.0, -4.0]; // the lips close
        }
        [
            5.0 + 1.0 * (std::f64::consts::TAU * t / 5.0 + self.lip_phase[0]).sin(),
            4.0 + 1.0 * (std::f64::consts::TAU * t / 7.0 + self.lip_phase[1]).sin(),
        ]
    }
}

/// One camera's mask of one frame, and its statistics.
struct RenderedMask {
    png: Option<Vec<u8>>,
    mask_pixels: [u64; 2],
    mouth_pixels: u64,
    alone_pixels: [u64; 2],
}

fn render_mask(
    s: &Session,
    cam: &Camera,
    poses: &ArchPoses,
    show: [f64; 2],
    opts: &SynthOptions,
    rng: &mut ChaCha8Rng,
) -> RenderedMask {
    let (w, h) = (cam.width as usize, cam.height as usize);
    // Through the lens when the camera has one, as the energy draws (`energy::lens`).
    let mut labels = render_labels(
        cam,
        &[
            (&s.upper, &poses.upper, UPPER_LABEL, UPPER_LABEL),
            (&s.lower, &poses.lower, LOWER_LABEL, LOWER_LABEL),
        ],
    );
    let alone = |mesh: &Mesh, pose: &Pose| {
        render_labels(cam, &[(mesh, pose, 1, 1)])
            .iter()
            .filter(|&&l| l != 0)
            .count() as u64
    };
    let alone_pixels = [alone(&s.upper, &poses.upper), alone(&s.lower, &poses.lower)];
    let (jitter, holes, hole_radius) = match opts.preset {
        Preset::Clean => (0.0, 0, 1),
        Preset::Realistic => (1.5, 3, 2),
        Preset::Hard => (2.5, 8, 3),
    };
    let teeth = [UPPER_LABEL, LOWER_LABEL];
    if opts.preset != Preset::Clean {
        masks::fill_between_teeth(&mut labels, w, h, 2, &teeth);
        if opts.writes_mouth() {
            // Inside the lip opening, what is not a tooth is the mouth's interior.
            labels
                .iter_mut()
                .filter(|l| **l == 0)
                .for_each(|l| *l = MOUTH_LABEL);
        }
        let opening = masks::lip_opening(cam, poses, &s.lips, show);
        masks::apply_lips(&mut labels, w, &opening);
        masks::specular_holes(&mut labels, w, holes, hole_radius, &teeth, rng);
        labels = masks::wander_boundaries(&labels, w, jitter, rng);
    }
    let count = |value: u8| labels.iter().filter(|&&l| l == value).count() as u64;
    let mask_pixels = [count(UPPER_LABEL), count(LOWER_LABEL)];
    let mouth_pixels = count(MOUTH_LABEL);
    if opts.masks == MaskKind::Combined {
        for l in &mut labels {
            if teeth.contains(l) {
                *l = COMBINED_TEETH;
            }
        }
    }
    // A camera that sees no teeth writes no mask: the format's "saw nothing usable".
    let png =
        (mask_pixels[0] + mask_pixels[1] > 0).then(|| encode_png(&labels, cam.width, cam.height));
    RenderedMask {
        png,
        mask_pixels,
        mouth_pixels,
        alone_pixels,
    }
}

fn encode_png(grey: &[u8], width: u32, height: u32) -> Vec<u8> {
    crate::io::encode_png(grey, width, height, image::ExtendedColorType::L8)
}

fn encode_png_rgb(rgb: &[u8], width: u32, height: u32) -> Vec<u8> {
    crate::io::encode_png(rgb, width, height, image::ExtendedColorType::Rgb8)
}

/// Write a synthetic capture to `out`. `progress` is called once per finished frame.
pub fn generate(
    out: &Path,
    opts: &SynthOptions,
    progress: &(dyn Fn() + Sync),
) -> Result<SynthReport> {
    let started = Instant::now();
    if opts.frames == 0 {
        return Err(Error::invalid(out, "--frames", "must be at least 1"));
    }
    check_out(out, opts.force)?;
    let session = Session::new(opts)?;
    write_staged(out, |dir| {
        write_capture(dir, &session, opts, progress, started)
    })
}

/// Refuse an existing `out` unless `force`.
pub(crate) fn check_out(out: &Path, force: bool) -> Result<()> {
    if out.exists() && !force {
        return Err(Error::invalid(
            out,
            "OUT",
            "already exists; choose another folder or pass --force to replace it",
        ));
    }
    Ok(())
}

/// Build a folder beside `out` with `write`, then move it into place: a crash never leaves
/// half a capture, and an existing `out` is replaced only once the new one is whole.
pub(crate) fn write_staged<T>(out: &Path, write: impl FnOnce(&Path) -> Result<T>) -> Result<T> {
    let parent = out
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    std::fs::create_dir_all(parent).map_err(|error| Error::Write {
        path: parent.to_path_buf(),
        error,
    })?;
    let staging = tempfile::Builder::new()
        .prefix(".jawtrack-synth-")
        .tempdir_in(parent)
        .map_err(|error| Error::Write {
            path: parent.to_path_buf(),
            error,
        })?;
    let report = write(staging.path())?;
    if out.exists() {
        std::fs::remove_dir_all(out).map_err(|error| Error::Write {
            path: out.to_path_buf(),
            error,
        })?;
    }
    let dir = staging.keep();
    std::fs::rename(&dir, out).map_err(|error| Error::Write {
        path: out.to_path_buf(),
        error,
    })?;
    Ok(report)
}
