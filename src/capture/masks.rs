//! Segmentation masks: decoded per frame into label masks (bit 0: upper arch, bit 1: lower
//! arch) at the mask resolution, with lens distortion removed once per camera.

use std::path::Path;

use crate::error::{Error, Result};
use crate::geometry::Camera;
use nalgebra::Vector2;

pub const UPPER_BIT: u8 = 1;
pub const LOWER_BIT: u8 = 2;

/// How mask pixel values map to arches (capture.json `masks.mode`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MaskMode {
    /// A pixel equal to `upper` is upper arch, equal to `lower` lower arch.
    PerArch { upper: u8, lower: u8 },
    /// One teeth mask: a pixel is teeth (both arches) when its value is 128 or more.
    Combined,
}

impl MaskMode {
    pub fn label_of(&self, value: u8) -> u8 {
        match *self {
            MaskMode::PerArch { upper, lower } => {
                if value == upper {
                    UPPER_BIT
                } else if value == lower {
                    LOWER_BIT
                } else {
                    0
                }
            }
            MaskMode::Combined => {
                if value >= 128 {
                    UPPER_BIT | LOWER_BIT
                } else {
                    0
                }
            }
        }
    }
}

/// A decoded mask: one label byte per pixel, row-major.
#[derive(Debug, Clone, PartialEq)]
pub struct LabelMask {
    pub width: u32,
    pub height: u32,
    pub data: Vec<u8>,
}

impl LabelMask {
    pub fn count(&self, bit: u8) -> u64 {
        self.data.iter().filter(|&&v| v & bit != 0).count() as u64
    }
}

fn open_image(path: &Path) -> Result<image::ImageReader<std::io::BufReader<std::fs::File>>> {
    image::ImageReader::open(path)
        .map_err(|e| Error::read(path, "mask", e))?
        .with_guessed_format()
        .map_err(|e| Error::read(path, "mask", e))
}

/// Read a mask PNG's size from its header only.
pub fn mask_dimensions(path: &Path) -> Result<(u32, u32)> {
    open_image(path)?
        .into_dimensions()
        .map_err(|e| Error::Image {
            path: path.to_path_buf(),
            problem: e.to_string(),
        })
}

/// Decode a mask PNG into labels. Per-arch masks must be 8-bit single-channel (labels are
/// exact values); combined masks may be any format and are converted to grey.
pub fn decode_mask(path: &Path, mode: MaskMode) -> Result<LabelMask> {
    let img = open_image(path)?.decode().map_err(|e| Error::Image {
        path: path.to_path_buf(),
        problem: e.to_string(),
    })?;
    let (width, height) = (img.width(), img.height());
    let grey = match (img, mode) {
        (image::DynamicImage::ImageLuma8(g), _) => g.into_raw(),
        (image::DynamicImage::ImageLumaA8(g), _) => g.pixels().map(|p| p.0[0]).collect(),
        (other, MaskMode::Combined) => other.to_luma8().into_raw(),
        (other, MaskMode::PerArch { .. }) => {
            return Err(Error::invalid(
                path,
                "pixel format",
                format!(
                    "per-arch masks must be 8-bit single-channel PNGs, found {:?}",
                    other.color()
                ),
            ));
        }
    };
    Ok(LabelMask {
        width,
        height,
        data: grey.into_iter().map(|v| mode.label_of(v)).collect(),
    })
}

/// For each pixel of the undistorted mask, the index of the distorted source pixel it takes
/// its label from (nearest neighbour, so labels stay exact), or `u32::MAX` for outside.
/// `camera` is the calibrated camera scaled to the mask size, distortion included.
pub fn undistortion_map(camera: &Camera) -> Vec<u32> {
    let (w, h) = (camera.width, camera.height);
    let mut map = Vec::with_capacity((w * h) as usize);
    for v in 0..h {
        for u in 0..w {
            let n = Vector2::new(
                (u as f64 - camera.cx) / camera.fx,
                (v as f64 - camera.cy) / camera.fy,
            );
            let src = camera.normalised_to_pixel(n);
            let (su, sv) = (src.x.round(), src.y.round());
            map.push(
                if su >= 0.0 && sv >= 0.0 && su < w as f64 && sv < h as f64 {
                    sv as u32 * w + su as u32
                } else {
                    u32::MAX
                },
            );
        }
    }
    map
}

pub fn apply_map(mask: &LabelMask, map: &[u32]) -> LabelMask {
    LabelMask {
        width: mask.width,
        height: mask.height,
        data: map
            .iter()
            .map(|&i| {
                if i == u32::MAX {
                    0
                } else {
                    mask.data[i as usize]
                }
            })
            .collect(),
    }
}
