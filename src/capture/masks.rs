//! Segmentation masks: decoded per frame into label masks (bit 0: upper arch, bit 1: lower
//! arch) at the mask resolution, with lens distortion removed once per camera.

use std::path::Path;

use crate::error::{Error, Result};

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
