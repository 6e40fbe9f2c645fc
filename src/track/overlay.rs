//! Overlays, the paper's Fig. 9/10: per camera and frame, the segmentation in white (and the
//! visible mouth interior, when the masks label it, in blue), the models in red at alpha 0.5
//! (so overlap is pink) and the boundary of interest in green, at the masks' resolution; on
//! top of the video frame when the capture has images/.

use std::path::Path;

use crate::capture::masks::MOUTH_BIT;
use crate::capture::{ArchPoses, Capture, FrameMasks, LOWER_BIT, UPPER_BIT, write_atomic};
use crate::energy::raster::{CLASS_BODY, CLASS_BOI, render_labels};
use crate::error::{Error, Result};

/// Write `dir/<camera>/<frame:06>.png` for every camera with a mask in this frame.
pub fn write_overlays(
    dir: &Path,
    capture: &Capture,
    masks: &FrameMasks,
    poses: &ArchPoses,
) -> Result<()> {
    for (k, cam_info) in capture.cameras.iter().enumerate() {
        let (Some(mask), Some(cam)) = (&masks.masks[k], cam_info.mask_camera()) else {
            continue;
        };
        let name = &cam_info.calibrated.name;
        let classes = render_labels(
            &cam,
            &[
                (&capture.upper, &poses.upper, CLASS_BODY, CLASS_BOI),
                (&capture.lower, &poses.lower, CLASS_BODY, CLASS_BOI),
            ],
        );
        let (w, h) = (cam.width, cam.height);
        let mut rgb = match capture.image_path(k, masks.frame) {
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
            std::array::from_fn(|i| {
                (a[i] as f32 * (1.0 - alpha) + b[i] as f32 * alpha).round() as u8
            })
        };
        for (i, px) in rgb.pixels_mut().enumerate() {
            let mut c = px.0;
            let label = mask.data[i];
            if label & (UPPER_BIT | LOWER_BIT) != 0 {
                c = blend(c, [255, 255, 255], 0.85);
            } else if label & MOUTH_BIT != 0 {
                c = blend(c, [0, 0, 255], 0.6);
            }
            c = match classes[i] {
                CLASS_BODY => blend(c, [255, 0, 0], 0.5),
                CLASS_BOI => blend(c, [0, 255, 0], 0.5),
                _ => c,
            };
            px.0 = c;
        }
        let mut png = Vec::new();
        image::DynamicImage::ImageRgb8(rgb)
            .write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
            .expect("encoding into memory cannot fail");
        write_atomic(
            &dir.join(name).join(format!("{:06}.png", masks.frame)),
            &png,
        )?;
    }
    Ok(())
}
