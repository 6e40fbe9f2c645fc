//! Masks the program makes from the colour frames (`jawtrack segment`), as tracking goes:
//! each frame's prior is the models drawn where tracking expects them (init.json's poses at
//! the first frame, then the tracked ones and their constant-velocity extrapolation), the
//! colour models of teeth, mouth interior and lips/skin are learned per camera from the first
//! picture and follow the later ones (the region-based idea of PWP3D, RBOT and M3T), and two
//! graph cuts make the labels spatially coherent (`picture`). Every mask is written in the
//! capture format, so a user can look at any frame, correct it and track again.

mod arches;
pub mod colour_model;
mod distance;
mod edges;
mod evidence;
pub mod graph_cut;
mod motion;
mod opening;
pub mod picture;
pub mod score;
mod seeds;
pub mod settings;
mod shaded_crowns;
mod smear;
mod smoothness;

use std::path::Path;

use rayon::prelude::*;

use crate::arch::ArchPoses;
use crate::capture::masks::MOUTH_BIT;
use crate::capture::{Capture, FrameMasks, LOWER_BIT, LabelMask, MaskMode, UPPER_BIT};
use crate::energy::raster::render_labels;
use crate::error::{Error, Result};
use crate::formats::Status;
use crate::geometry::Camera;
use crate::io::{encode_png, write_atomic};
use crate::track::MaskSource;
use motion::Motion;
use picture::{Expected, Lesson, Models, Outcome, segment_picture};
pub use settings::SegmentSettings;

/// The largest picture read (pixels): a GoPro's 5.3K is 15.9 Mpx.
const MAX_PIXELS: u64 = 1 << 26;

/// How the pictures of one camera came out over a run.
#[derive(Debug, Clone, Default, serde::Serialize)]
pub struct CameraCounts {
    pub segmented: usize,
    pub dark: usize,
    pub out_of_view: usize,
    pub no_picture: usize,
}

/// Makes each frame's masks from its pictures, writes them, and hands them to tracking.
pub struct Segmenter<'c> {
    capture: &'c Capture,
    /// Per camera, the calibrated camera scaled to its pictures.
    cameras: Vec<Camera>,
    models: Vec<Option<Models>>,
    settings: SegmentSettings,
    pub counts: Vec<CameraCounts>,
    /// Seconds spent segmenting (reading pictures and writing masks included).
    pub seconds: f64,
    /// Where each picture's posteriors go (`segment --debug`), if anywhere.
    debug: Option<std::path::PathBuf>,
    /// The latest frame segmented, with the colour models and counts from before it: a frame
    /// segmented again starts from those.
    before: Option<(u32, Vec<Option<Models>>, Vec<CameraCounts>)>,
    /// Per camera, what the latest picture segmented teaches the models once its frame is
    /// tracked.
    lessons: Vec<Option<Lesson>>,
    /// How the arches moved over the latest frames tracked `ok`.
    motion: Motion,
}

/// The size of each camera's pictures (from its first picture in the capture's frames), and
/// the capture's cameras told that their masks will have that size (divided by the
/// capture's `mask_reduce`), so tracking can be set up before the first mask exists.
pub fn prepare(capture: &mut Capture) -> Result<Vec<(u32, u32)>> {
    let mut sizes = Vec::with_capacity(capture.cameras().len());
    for k in 0..capture.cameras().len() {
        let path = capture
            .frames()
            .find_map(|f| capture.image_path(k, f))
            .ok_or_else(|| Error::Missing {
                path: capture
                    .dir()
                    .join("images")
                    .join(&capture.cameras()[k].calibrated.name),
                what: "pictures of the capture's frames (images/<camera>/<frame:06>.png|jpg, \
                       from `jawtrack import video`)"
                    .into(),
            })?;
        let (w, h) = image::image_dimensions(&path).map_err(|e| Error::Image {
            path: path.clone(),
            problem: e.to_string(),
        })?;
        check_size(&path, (w, h), &capture.cameras()[k].calibrated)?;
        let r = capture.mask_reduce().max(1);
        if w % r != 0 || h % r != 0 {
            return Err(Error::invalid(
                &path,
                "size",
                format!("{w}x{h} is not divisible by the mask reduction {r}"),
            ));
        }
        capture.expect_masks(k, (w / r, h / r));
        sizes.push((w, h));
    }
    Ok(sizes)
}

/// A picture must be within the size limit and have the calibrated image's shape.
fn check_size(path: &Path, (w, h): (u32, u32), cam: &Camera) -> Result<()> {
    if w == 0 || h == 0 || w as u64 * h as u64 > MAX_PIXELS {
        return Err(Error::invalid(
            path,
            "size",
            format!("{w}x{h} is not a picture this reads (at most {MAX_PIXELS} pixels)"),
        ));
    }
    let (sx, sy) = (w as f64 / cam.width as f64, h as f64 / cam.height as f64);
    if (sx / sy - 1.0).abs() > 0.01 {
        return Err(Error::invalid(
            path,
            "size",
            format!(
                "{w}x{h} does not have the shape of camera {}'s calibrated {}x{}",
                cam.name, cam.width, cam.height
            ),
        ));
    }
    Ok(())
}

impl<'c> Segmenter<'c> {
    /// `sizes`: what [`prepare`] found.
    pub fn new(
        capture: &'c Capture,
        sizes: &[(u32, u32)],
        settings: SegmentSettings,
    ) -> Segmenter<'c> {
        Segmenter {
            cameras: capture
                .cameras()
                .iter()
                .zip(sizes)
                .map(|(c, &(w, h))| c.calibrated.scaled_to(w, h))
                .collect(),
            models: vec![None; capture.cameras().len()],
            counts: vec![CameraCounts::default(); capture.cameras().len()],
            capture,
            settings,
            seconds: 0.0,
            debug: None,
            before: None,
            lessons: vec![None; capture.cameras().len()],
            motion: Motion::new(capture.upper(), capture.lower()),
        }
    }

    /// Also write each picture's posteriors into `dir`/<camera>/<frame:06>.png: red teeth,
    /// green mouth interior, blue lips and skin, each as bright as it is probable, from the
    /// colour models and the spatial prior before the graph cuts smooth them; and with soft
    /// evidence on, its shares into <frame:06>-shares.png (red the upper arch's, green the
    /// lower's).
    pub fn with_debug(mut self, dir: std::path::PathBuf) -> Self {
        self.debug = Some(dir);
        self
    }

    /// One camera's picture of `frame` segmented and its mask written (`None` where it gave
    /// no mask), with what it teaches the colour models once the frame is tracked.
    fn camera_mask(
        &self,
        k: usize,
        frame: u32,
        expected: &[ArchPoses],
        models: &mut Option<Models>,
        counts: &mut CameraCounts,
    ) -> Result<(Option<LabelMask>, Option<Lesson>)> {
        let capture = self.capture;
        let mask_path = capture.mask_path(k, frame);
        let Some(path) = capture.image_path(k, frame) else {
            counts.no_picture += 1;
            return remove_stale(&mask_path).map(|_| (None, None));
        };
        let cam = &self.cameras[k];
        let (w, h) = image::image_dimensions(&path).map_err(|e| Error::Image {
            path: path.clone(),
            problem: e.to_string(),
        })?;
        if (w, h) != (cam.width, cam.height) {
            return Err(Error::invalid(
                &path,
                "size",
                format!(
                    "{w}x{h} differs from the camera's other pictures ({}x{})",
                    cam.width, cam.height
                ),
            ));
        }
        let rgb = image::open(&path)
            .map_err(|e| Error::Image {
                path: path.clone(),
                problem: e.to_string(),
            })?
            .into_rgb8()
            .into_raw();
        // The prior: the models drawn at every pose tracking will start from.
        let mut prior = vec![0u8; (w * h) as usize];
        for poses in expected {
            let drawn = render_labels(
                cam,
                &[
                    (capture.upper(), &poses.upper, UPPER_BIT, UPPER_BIT),
                    (capture.lower(), &poses.lower, LOWER_BIT, LOWER_BIT),
                ],
            );
            for (p, d) in prior.iter_mut().zip(drawn) {
                if *p == 0 {
                    *p = d;
                }
            }
        }
        let mut posteriors = Vec::new();
        let wanted = self.debug.is_some().then_some(&mut posteriors);
        let expected = Expected {
            prior: &prior,
            smear: self.motion.smear(cam, frame, self.settings.shutter),
        };
        let outcome = segment_picture(
            &rgb,
            w as usize,
            h as usize,
            expected,
            models,
            &self.settings,
            wanted,
        );
        if let Some(dir) = &self.debug
            && !posteriors.is_empty()
        {
            write_atomic(
                &dir.join(&cam.name).join(format!("{frame:06}.png")),
                &encode_png(&posteriors, w, h, image::ExtendedColorType::Rgb8),
            )?;
        }
        let (labels, soft, lesson) = match outcome {
            Outcome::Labels {
                labels,
                soft,
                lesson,
            } => (labels, soft, lesson),
            Outcome::Dark => {
                counts.dark += 1;
                return remove_stale(&mask_path).map(|_| (None, None));
            }
            Outcome::OutOfView => {
                counts.out_of_view += 1;
                return remove_stale(&mask_path).map(|_| (None, None));
            }
        };
        counts.segmented += 1;
        if let (Some(dir), Some(soft)) = (&self.debug, &soft) {
            let rgb: Vec<u8> = soft.iter().flat_map(|&[u, l]| [u, l, 0]).collect();
            write_atomic(
                &dir.join(&cam.name).join(format!("{frame:06}-shares.png")),
                &encode_png(&rgb, w, h, image::ExtendedColorType::Rgb8),
            )?;
        }
        let values = encode_values(&labels, capture.mask_mode(), capture.mouth());
        write_atomic(
            &mask_path,
            &encode_png(&values, w, h, image::ExtendedColorType::L8),
        )?;
        let mask = LabelMask {
            soft: soft.map(|soft| match capture.mask_mode() {
                MaskMode::PerArch { .. } => soft,
                // One label covers both arches, and so does their evidence.
                MaskMode::Combined => soft.into_iter().map(|[u, l]| [u.max(l); 2]).collect(),
            }),
            width: w,
            height: h,
            // As the tracker reads a written mask back: the mouth only when declared.
            data: values
                .iter()
                .map(|&v| capture.mask_mode().label_of(v, capture.mouth()))
                .collect(),
        };
        Ok((Some(mask.reduced(capture.mask_reduce())), lesson))
    }
}

impl MaskSource for Segmenter<'_> {
    fn frame_masks(&mut self, frame: u32, expected: &[ArchPoses]) -> Result<FrameMasks> {
        let started = std::time::Instant::now();
        match &self.before {
            Some((f, models, counts)) if *f == frame => {
                self.models = models.clone();
                self.counts = counts.clone();
            }
            _ => self.before = Some((frame, self.models.clone(), self.counts.clone())),
        }
        let mut models = std::mem::take(&mut self.models);
        let mut counts = std::mem::take(&mut self.counts);
        let this = &*self;
        let made: Vec<Result<(Option<LabelMask>, Option<Lesson>)>> = models
            .par_iter_mut()
            .zip(counts.par_iter_mut())
            .enumerate()
            .map(|(k, (m, c))| this.camera_mask(k, frame, expected, m, c))
            .collect();
        self.models = models;
        self.counts = counts;
        let (masks, lessons) = made.into_iter().collect::<Result<(Vec<_>, Vec<_>)>>()?;
        self.lessons = lessons;
        self.seconds += started.elapsed().as_secs_f64();
        Ok(FrameMasks { frame, masks })
    }

    fn follows_expected(&self) -> bool {
        true
    }

    /// The colour models follow the frame's pictures, the teeth's where the arches drawn at
    /// the tracked poses cover them ([`Lesson::follow`]); a frame tracked `low-confidence`
    /// teaches nothing (its arches may be lost, and its labels with them).
    fn tracked(&mut self, frame: u32, poses: &ArchPoses, status: Status) -> Result<()> {
        let started = std::time::Instant::now();
        if status == Status::Ok {
            self.motion.tracked(frame, poses);
        }
        let lessons = std::mem::replace(&mut self.lessons, vec![None; self.cameras.len()]);
        if status == Status::Ok {
            let (capture, settings) = (self.capture, &self.settings);
            self.models
                .par_iter_mut()
                .zip(&self.cameras)
                .zip(lessons)
                .for_each(|((models, cam), lesson)| {
                    let (Some(m), Some(lesson)) = (models.as_mut(), lesson) else {
                        return;
                    };
                    let drawn = render_labels(
                        cam,
                        &[
                            (capture.upper(), &poses.upper, UPPER_BIT, UPPER_BIT),
                            (capture.lower(), &poses.lower, LOWER_BIT, LOWER_BIT),
                        ],
                    );
                    lesson.follow(&drawn, cam.width as usize, m, settings);
                });
        }
        self.seconds += started.elapsed().as_secs_f64();
        Ok(())
    }
}

/// A frame that gives no mask now must not keep one from an earlier run.
fn remove_stale(path: &Path) -> Result<()> {
    match std::fs::remove_file(path) {
        Ok(()) => Ok(()),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(()),
        Err(error) => Err(Error::Write {
            path: path.to_path_buf(),
            error,
        }),
    }
}

/// Label bits to the capture's mask values (capture.json `masks`).
pub fn encode_values(labels: &[u8], mode: MaskMode, mouth: Option<u8>) -> Vec<u8> {
    labels
        .iter()
        .map(|&l| match mode {
            MaskMode::PerArch { upper, .. } if l & UPPER_BIT != 0 => upper,
            MaskMode::PerArch { lower, .. } if l & LOWER_BIT != 0 => lower,
            MaskMode::Combined if l & (UPPER_BIT | LOWER_BIT) != 0 => 255,
            _ if l & MOUTH_BIT != 0 => mouth.unwrap_or(0),
            _ => 0,
        })
        .collect()
}
