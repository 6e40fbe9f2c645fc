//! Overlays, the paper's Fig. 9/10: per camera and frame, the segmentation in white (and the
//! visible mouth interior, when the masks label it, in blue), the models in red at alpha 0.5
//! (so overlap is pink) and the boundary of interest in green, at the masks' resolution; on
//! top of the video frame when the capture has images/.

use std::path::Path;

use crate::arch::ArchPoses;
use crate::capture::masks::{LabelMask, MOUTH_BIT};
use crate::capture::{Capture, FrameMasks, LOWER_BIT, UPPER_BIT};
use crate::energy::raster::{CLASS_BODY, CLASS_BOI, render_labels};
use crate::error::{Error, Result};
use crate::io::write_atomic;

/// The models' colours: the paper's overlay draws both arches red; a viewer telling the arches
/// apart draws the lower one in yellow.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ArchColours {
    Paper,
    Distinct,
}

/// Write `dir/<camera>/<frame:06>.png` for every camera with a mask in this frame.
pub fn write_overlays(
    dir: &Path,
    capture: &Capture,
    masks: &FrameMasks,
    poses: &ArchPoses,
) -> Result<()> {
    for (k, cam_info) in capture.cameras().iter().enumerate() {
        let Some(mask) = &masks.masks[k] else {
            continue;
        };
        let Some((rgb, _)) = picture(
            capture,
            k,
            masks.frame,
            Some(mask),
            Some(poses),
            ArchColours::Paper,
        )?
        else {
            continue;
        };
        write_atomic(
            &dir.join(&cam_info.calibrated.name)
                .join(format!("{:06}.png", masks.frame)),
            &png(&rgb),
        )?;
    }
    Ok(())
}

/// An RGB picture as PNG bytes.
pub fn png(rgb: &image::RgbImage) -> Vec<u8> {
    let mut png = Vec::new();
    rgb.write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
        .expect("encoding into memory cannot fail");
    png
}

/// Camera `k`'s overlay of `frame` at the masks' resolution: its video frame (black without
/// images/), the mask when given, the models at `poses` when given; with the box the models cover
/// (x0, y0, x1, y1, exclusive; `None` when out of view). `None` when the camera's mask size
/// is not known.
pub fn picture(
    capture: &Capture,
    k: usize,
    frame: u32,
    mask: Option<&LabelMask>,
    poses: Option<&ArchPoses>,
    colours: ArchColours,
) -> Result<Option<(image::RgbImage, Option<[u32; 4]>)>> {
    let Some(cam) = capture.cameras()[k].mask_camera() else {
        return Ok(None);
    };
    let lower_body = match colours {
        ArchColours::Paper => CLASS_BODY,
        ArchColours::Distinct => CLASS_LOWER_BODY,
    };
    let classes = match poses {
        Some(poses) => render_labels(
            &cam,
            &[
                (capture.upper(), &poses.upper, CLASS_BODY, CLASS_BOI),
                (capture.lower(), &poses.lower, lower_body, CLASS_BOI),
            ],
        ),
        None => vec![0; cam.width as usize * cam.height as usize],
    };
    let (w, h) = (cam.width, cam.height);
    let mut rgb = match capture.image_path(k, frame) {
        Some(path) => image::open(&path)
            .map_err(|e| Error::Image {
                path: path.clone(),
                problem: e.to_string(),
            })?
            .resize_exact(w, h, image::imageops::FilterType::Triangle)
            .to_rgb8(),
        None => image::RgbImage::new(w, h),
    };
    let blend = |a: [u8; 3], b: [u8; 3], alpha: f32| -> [u8; 3] {
        std::array::from_fn(|i| (a[i] as f32 * (1.0 - alpha) + b[i] as f32 * alpha).round() as u8)
    };
    let mut models: Option<[u32; 4]> = None;
    for (i, px) in rgb.pixels_mut().enumerate() {
        let mut c = px.0;
        if classes[i] != 0 {
            let (x, y) = (i as u32 % w, i as u32 / w);
            let b = models.get_or_insert([x, y, x + 1, y + 1]);
            *b = [b[0].min(x), b[1].min(y), b[2].max(x + 1), b[3].max(y + 1)];
        }
        if let Some(mask) = mask {
            let label = mask.data[i];
            if label & (UPPER_BIT | LOWER_BIT) != 0 {
                c = blend(c, [255, 255, 255], 0.85);
            } else if label & MOUTH_BIT != 0 {
                c = blend(c, [0, 0, 255], 0.6);
            }
        }
        c = match classes[i] {
            CLASS_BODY => blend(c, [255, 0, 0], 0.5),
            CLASS_LOWER_BODY => blend(c, [255, 220, 0], 0.5),
            CLASS_BOI => blend(c, [0, 255, 0], 0.5),
            _ => c,
        };
        px.0 = c;
    }
    Ok(Some((rgb, models)))
}

/// A class value the rasteriser passes through untouched, for the lower arch's body when the
/// arches are told apart.
const CLASS_LOWER_BODY: u8 = 200;
