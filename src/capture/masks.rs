//! Segmentation masks: decoded per frame into label masks (bit 0: upper arch, bit 1: lower
//! arch, bit 2: visible mouth interior) at the mask resolution (or 1/k of it,
//! [`LabelMask::reduced`]), as the cameras saw them: with lens distortion, the energy draws
//! the models through the lens.

use std::collections::BTreeSet;
use std::path::Path;

use rayon::prelude::*;

use crate::error::{Error, Result};

pub use crate::arch::{LOWER_BIT, UPPER_BIT};
/// The visible mouth interior (`masks.mouth`): the camera sees no tooth there.
pub const MOUTH_BIT: u8 = 4;
/// Every label bit.
const LABEL_BITS: u8 = UPPER_BIT | LOWER_BIT | MOUTH_BIT;

/// How mask pixel values map to arches (capture.json `masks.mode`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MaskMode {
    /// A pixel equal to `upper` is upper arch, equal to `lower` lower arch.
    PerArch { upper: u8, lower: u8 },
    /// One teeth mask: a pixel is teeth (both arches) when its value is 128 or more.
    Combined,
}

impl std::fmt::Display for MaskMode {
    /// In plain words, as `validate` and `synth` print it.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            MaskMode::PerArch { upper, lower } => {
                write!(f, "per arch (upper {upper}, lower {lower})")
            }
            MaskMode::Combined => write!(f, "combined (teeth at 128 or more)"),
        }
    }
}

impl MaskMode {
    /// `masks.mouth` of `capture_json` checked against this mode: a byte, not an arch's
    /// label, and below 128 with combined masks (where 128 and above are teeth).
    pub fn mouth_label(&self, value: Option<i64>, capture_json: &Path) -> Result<Option<u8>> {
        let Some(v) = value else {
            return Ok(None);
        };
        let why = match u8::try_from(v) {
            Err(_) => Some(format!("a mask value must be 0..255, found {v}")),
            Ok(v) => match *self {
                MaskMode::PerArch { upper, lower } => {
                    (v == upper || v == lower).then(|| format!("it is an arch's label ({v})"))
                }
                MaskMode::Combined => {
                    (v >= 128).then(|| format!("{v} would count as teeth: it must be below 128"))
                }
            },
        };
        match why {
            Some(why) => Err(Error::invalid(capture_json, "masks.mouth", why)),
            None => Ok(Some(v as u8)),
        }
    }

    /// The label bits of a mask pixel's value; `mouth` is the value of the visible mouth
    /// interior, when the masks label it (checked at open not to be an arch's value).
    pub fn label_of(&self, value: u8, mouth: Option<u8>) -> u8 {
        if mouth == Some(value) {
            return MOUTH_BIT;
        }
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
    /// Per pixel, how much of it each arch's teeth hold (upper, lower; 255 all of it): the
    /// evidence a segmentation weighed its labels from, which the smooth energy reads in
    /// their place (`segment`'s masks, never a file's). `None`: the labels alone.
    pub soft: Option<Vec<[u8; 2]>>,
}

impl LabelMask {
    pub fn count(&self, bit: u8) -> u64 {
        self.data.iter().filter(|&&v| v & bit != 0).count() as u64
    }

    /// The mask at 1/`k` of its resolution (`k` divides both sides): each k x k block takes its
    /// most common label. Ties (half the block teeth, along every edge when k = 2) go by a
    /// checkerboard over the blocks, so that an edge moves neither in nor out on average.
    pub fn reduced(self, k: u32) -> LabelMask {
        if k <= 1 {
            return self;
        }
        let (w, h) = ((self.width / k) as usize, (self.height / k) as usize);
        let (k, width) = (k as usize, self.width as usize);
        let mut data = vec![0u8; w * h];
        data.par_chunks_mut(w.max(1))
            .enumerate()
            .for_each(|(by, out)| {
                let rows = &self.data[by * k * width..(by + 1) * k * width];
                for (bx, label) in out.iter_mut().enumerate() {
                    let block = || rows.chunks(width).flat_map(|r| &r[bx * k..(bx + 1) * k]);
                    let first = rows[bx * k] & LABEL_BITS;
                    // Most blocks hold one label (off the mask's edges).
                    if block().all(|&v| v & LABEL_BITS == first) {
                        *label = first;
                        continue;
                    }
                    let mut votes = [0u32; LABEL_BITS as usize + 1];
                    for &v in block() {
                        votes[(v & LABEL_BITS) as usize] += 1;
                    }
                    let most = *votes.iter().max().expect("labels");
                    let tied = votes.iter().filter(|&&v| v == most).count();
                    *label = (0..=LABEL_BITS)
                        .filter(|&l| votes[l as usize] == most)
                        .nth((bx + by) % tied)
                        .expect("a tied label");
                }
            });
        // How much of a block each arch's teeth hold is the mean of its pixels'.
        let soft = self.soft.as_ref().map(|soft| {
            (0..w * h)
                .map(|i| {
                    let (bx, by) = (i % w, i / w);
                    let mut sum = [0u32; 2];
                    for y in by * k..(by + 1) * k {
                        for s in &soft[y * width + bx * k..y * width + (bx + 1) * k] {
                            sum[0] += s[0] as u32;
                            sum[1] += s[1] as u32;
                        }
                    }
                    let n = (k * k) as u32;
                    sum.map(|v| ((v + n / 2) / n) as u8)
                })
                .collect()
        });
        LabelMask {
            soft,
            width: w as u32,
            height: h as u32,
            data,
        }
    }
}

fn open_image(path: &Path) -> Result<image::ImageReader<std::io::BufReader<std::fs::File>>> {
    let (file, _) = crate::io::read::open_input(path, "mask")?;
    image::ImageReader::new(std::io::BufReader::new(file))
        .with_guessed_format()
        .map_err(|e| Error::read(path, "mask", e))
}

/// Read a mask PNG's size from its header only, and check there that its pixel format is one
/// [`decode_mask`] takes for `mode`.
pub fn mask_header(path: &Path, mode: MaskMode) -> Result<(u32, u32)> {
    use image::ImageDecoder;
    let image_error = |e: image::ImageError| Error::Image {
        path: path.to_path_buf(),
        problem: e.to_string(),
    };
    let decoder = open_image(path)?.into_decoder().map_err(image_error)?;
    let colour = decoder.color_type();
    let single_channel = colour == image::ColorType::L8;
    let png = png_ends(path)?;
    if matches!(mode, MaskMode::PerArch { .. }) && !single_channel {
        return Err(per_arch_format_error(path, colour, png.palette));
    }
    if png.is_png && !png.complete {
        return Err(Error::invalid(
            path,
            "file",
            "truncated: the PNG does not end with its IEND chunk",
        ));
    }
    Ok(decoder.dimensions())
}

/// What a PNG's two ends say: whether it is one, whether its colour type is a palette, whether
/// it ends with its IEND chunk (a file cut short does not), read without decoding it.
struct PngEnds {
    is_png: bool,
    palette: bool,
    complete: bool,
}

fn png_ends(path: &Path) -> Result<PngEnds> {
    use std::io::{Read, Seek, SeekFrom};
    const SIGNATURE: [u8; 8] = [0x89, b'P', b'N', b'G', b'\r', b'\n', 0x1a, b'\n'];
    const IEND: [u8; 12] = [0, 0, 0, 0, b'I', b'E', b'N', b'D', 0xae, 0x42, 0x60, 0x82];
    let (mut file, len) = crate::io::read::open_input(path, "mask")?;
    let io = |e| Error::read(path, "mask", e);
    let mut head = [0u8; 26];
    if len < 26 + 12 || file.read_exact(&mut head).is_err() || head[..8] != SIGNATURE {
        return Ok(PngEnds {
            is_png: len >= 8 && head[..8] == SIGNATURE,
            palette: false,
            complete: false,
        });
    }
    let mut tail = [0u8; 12];
    file.seek(SeekFrom::End(-12)).map_err(io)?;
    file.read_exact(&mut tail).map_err(io)?;
    Ok(PngEnds {
        is_png: true,
        // IHDR comes first: signature, length, "IHDR", width, height, bit depth, colour type.
        palette: head[25] == 3,
        complete: tail == IEND,
    })
}

fn per_arch_format_error(path: &Path, colour: image::ColorType, palette: bool) -> Error {
    let found = if palette {
        "a palette (indexed-colour) PNG".to_string()
    } else {
        format!("{colour:?}")
    };
    Error::invalid(
        path,
        "pixel format",
        format!("per-arch masks must be 8-bit single-channel (greyscale) PNGs, found {found}"),
    )
}

/// Decode a mask PNG into labels. Per-arch masks must be 8-bit single-channel (labels are
/// exact values); combined masks may be any format and are converted to grey. `mouth` is
/// `masks.mouth`.
pub fn decode_mask(path: &Path, mode: MaskMode, mouth: Option<u8>) -> Result<LabelMask> {
    let img = open_image(path)?.decode().map_err(|e| Error::Image {
        path: path.to_path_buf(),
        problem: e.to_string(),
    })?;
    let (width, height) = (img.width(), img.height());
    let grey = match (img, mode) {
        (image::DynamicImage::ImageLuma8(g), _) => g.into_raw(),
        (other, MaskMode::Combined) => other.to_luma8().into_raw(),
        (other, MaskMode::PerArch { .. }) => {
            let palette = png_ends(path)?.palette;
            return Err(per_arch_format_error(path, other.color(), palette));
        }
    };
    Ok(LabelMask {
        soft: None,
        width,
        height,
        data: grey.into_iter().map(|v| mode.label_of(v, mouth)).collect(),
    })
}

/// What a camera's mask folder holds: the masks' common size and the frames present.
pub(super) type MaskScan = (Option<(u32, u32)>, BTreeSet<u32>);

/// A camera's mask size read at 1/`k` of its resolution; `k` must divide both sides (so that
/// the scaled intrinsics stay exact).
pub(super) fn reduced_size((w, h): (u32, u32), k: u32, cam_dir: &Path) -> Result<(u32, u32)> {
    if k <= 1 {
        return Ok((w, h));
    }
    if w % k != 0 || h % k != 0 {
        return Err(Error::invalid(
            cam_dir,
            "size",
            format!(
                "masks of {w}x{h} cannot be read at 1/{k} of their resolution: {k} must divide both sides"
            ),
        ));
    }
    Ok((w / k, h / k))
}

/// List a camera's mask files and check that they share one size (headers only). `root`: the
/// capture folder, which the mask files may not link out of (`None`: they may).
pub(super) fn scan_masks(cam_dir: &Path, mode: MaskMode, root: Option<&Path>) -> Result<MaskScan> {
    let mut frames = BTreeSet::new();
    let entries = match std::fs::read_dir(cam_dir) {
        Ok(e) => e,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok((None, frames)),
        Err(e) => return Err(Error::read(cam_dir, "mask folder", e)),
    };
    for entry in entries {
        let entry = entry.map_err(|e| Error::read(cam_dir, "mask folder", e))?;
        let name = entry.file_name();
        let Some(name) = name.to_str() else { continue };
        if let Some(stem) = name.strip_suffix(".png")
            && stem.len() == 6
            && stem.bytes().all(|b| b.is_ascii_digit())
        {
            frames.insert(stem.parse::<u32>().expect("six digits"));
        }
    }
    let mut size: Option<((u32, u32), u32)> = None;
    for &f in &frames {
        let path = cam_dir.join(format!("{f:06}.png"));
        super::paths::listed_file_inside(super::Folder::Capture, &path, root)?;
        let dims = mask_header(&path, mode)?;
        match size {
            None => size = Some((dims, f)),
            Some((s, f0)) if s != dims => {
                return Err(Error::invalid(
                    &path,
                    "size",
                    format!(
                        "{}x{} differs from {:06}.png ({}x{}): all masks of a camera must have one size",
                        dims.0, dims.1, f0, s.0, s.1
                    ),
                ));
            }
            _ => {}
        }
    }
    Ok((size.map(|(s, _)| s), frames))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn mask(width: u32, rows: &[&[u8]]) -> LabelMask {
        LabelMask {
            soft: None,
            width,
            height: rows.len() as u32,
            data: rows.concat(),
        }
    }

    #[test]
    fn a_reduced_mask_takes_each_blocks_most_common_label() {
        let m = mask(
            6,
            &[
                &[1, 1, 2, 2, 0, 0],
                &[1, 0, 2, 1, 0, 1],
                &[0, 0, 1, 1, 2, 2],
                &[0, 0, 0, 0, 0, 0],
            ],
        );
        let r = m.clone().reduced(2);
        assert_eq!((r.width, r.height), (3, 2));
        // Blocks: 3 upper of 4; 3 lower of 4; 3 none of 4; all none; then ties: 2 upper
        // against 2 none at (1, 1), 2 lower against 2 none at (2, 1).
        let tie = |bx: u32, by: u32, labels: &[u8]| labels[((bx + by) % 2) as usize];
        assert_eq!(
            r.data,
            vec![1, 2, 0, 0, tie(1, 1, &[0, 1]), tie(2, 1, &[0, 2]),]
        );
        assert_eq!(m.clone().reduced(1), m);
    }

    /// A block's share of each arch's teeth is the mean of its pixels' shares.
    #[test]
    fn a_reduced_mask_s_evidence_is_each_blocks_mean() {
        let mut m = mask(4, &[&[1, 1, 0, 0], &[1, 1, 0, 2]]);
        m.soft = Some(vec![
            [255, 0],
            [200, 0],
            [100, 0],
            [0, 0],
            [255, 0],
            [255, 10],
            [0, 0],
            [0, 90],
        ]);
        let r = m.reduced(2);
        assert_eq!(r.soft, Some(vec![[241, 3], [25, 23]]));
    }

    #[test]
    fn the_mouth_value_reads_as_its_own_label_and_survives_reduction() {
        let per_arch = MaskMode::PerArch {
            upper: 85,
            lower: 170,
        };
        assert_eq!(per_arch.label_of(40, Some(40)), MOUTH_BIT);
        assert_eq!(per_arch.label_of(40, None), 0);
        assert_eq!(per_arch.label_of(85, Some(40)), UPPER_BIT);
        assert_eq!(MaskMode::Combined.label_of(40, Some(40)), MOUTH_BIT);
        assert_eq!(
            MaskMode::Combined.label_of(200, Some(40)),
            UPPER_BIT | LOWER_BIT
        );
        let m = mask(4, &[&[4, 4, 1, 0], &[4, 0, 1, 1]]);
        assert_eq!(m.reduced(2).data, vec![MOUTH_BIT, UPPER_BIT]);
    }

    #[test]
    fn ties_alternate_so_an_edge_keeps_its_place_on_average() {
        // A vertical edge through the middle of every 2 x 2 block: half the blocks keep the
        // teeth, half do not.
        let rows: Vec<Vec<u8>> = (0..8)
            .map(|_| (0..16).map(|x| u8::from(x % 2 == 0)).collect())
            .collect();
        let refs: Vec<&[u8]> = rows.iter().map(Vec::as_slice).collect();
        let m = mask(16, &refs);
        let r = m.clone().reduced(2);
        assert_eq!(r.count(UPPER_BIT) * 4, m.count(UPPER_BIT));
    }
}
