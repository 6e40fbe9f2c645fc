//! Masks scored against true ones (gt/masks/<camera>/<frame:06>.png, numbered and valued as
//! the capture's masks: what `jawtrack synth --images` writes): intersection over union of
//! teeth, each arch and the mouth interior, pooled over cameras and frames.

use std::ops::Range;

use crate::capture::masks::{MOUTH_BIT, decode_mask};
use crate::capture::{Capture, LOWER_BIT, MaskMode, UPPER_BIT};
use crate::error::Result;

#[derive(Debug, Clone, Default, serde::Serialize)]
pub struct MaskScore {
    /// Pictures (camera and frame) with a true mask.
    pub pictures: usize,
    pub teeth_iou: f64,
    /// Per arch, with per-arch masks.
    pub upper_iou: Option<f64>,
    pub lower_iou: Option<f64>,
    /// When the masks label the mouth interior.
    pub mouth_iou: Option<f64>,
    /// The worst picture's teeth IoU.
    pub worst_teeth_iou: f64,
}

#[derive(Default, Clone, Copy)]
struct Tally {
    inter: u64,
    union: u64,
}

impl Tally {
    fn add(&mut self, a: bool, b: bool) {
        self.inter += (a && b) as u64;
        self.union += (a || b) as u64;
    }
    fn iou(&self) -> f64 {
        if self.union == 0 {
            1.0
        } else {
            self.inter as f64 / self.union as f64
        }
    }
}

/// The capture's masks of `frames` against gt/masks/; `None` when it has no true masks.
pub fn score_masks(capture: &Capture, frames: Range<u32>) -> Result<Option<MaskScore>> {
    let truth_dir = capture.dir().join("gt").join("masks");
    if !truth_dir.is_dir() {
        return Ok(None);
    }
    // Teeth, upper, lower, mouth.
    let mut tallies = [Tally::default(); 4];
    let mut score = MaskScore {
        worst_teeth_iou: 1.0,
        ..Default::default()
    };
    for frame in frames {
        for (k, cam) in capture.cameras().iter().enumerate() {
            let Some(file) = cam.file_frame(frame) else {
                continue;
            };
            let truth_path = truth_dir
                .join(&cam.calibrated.name)
                .join(format!("{file:06}.png"));
            if !truth_path.exists() {
                continue;
            }
            let truth = decode_mask(&truth_path, capture.mask_mode(), capture.mouth())?;
            let mask_path = capture.mask_path(k, frame);
            let made = if mask_path.exists() {
                decode_mask(&mask_path, capture.mask_mode(), capture.mouth())?.data
            } else {
                vec![0; truth.data.len()]
            };
            if made.len() != truth.data.len() {
                return Err(crate::error::Error::invalid(
                    &mask_path,
                    "size",
                    format!("differs from the true mask {}", truth_path.display()),
                ));
            }
            score.pictures += 1;
            let mut this = Tally::default();
            for (&m, &t) in made.iter().zip(&truth.data) {
                let teeth_bits = UPPER_BIT | LOWER_BIT;
                this.add(m & teeth_bits != 0, t & teeth_bits != 0);
                tallies[1].add(m & UPPER_BIT != 0, t & UPPER_BIT != 0);
                tallies[2].add(m & LOWER_BIT != 0, t & LOWER_BIT != 0);
                tallies[3].add(m & MOUTH_BIT != 0, t & MOUTH_BIT != 0);
            }
            tallies[0].inter += this.inter;
            tallies[0].union += this.union;
            score.worst_teeth_iou = score.worst_teeth_iou.min(this.iou());
        }
    }
    if score.pictures == 0 {
        return Ok(None);
    }
    let per_arch = matches!(capture.mask_mode(), MaskMode::PerArch { .. });
    score.teeth_iou = tallies[0].iou();
    score.upper_iou = per_arch.then(|| tallies[1].iou());
    score.lower_iou = per_arch.then(|| tallies[2].iou());
    score.mouth_iou = capture.mouth().map(|_| tallies[3].iou());
    Ok(Some(score))
}
