//! What a picture teaches its camera's colour models, learned once tracking has placed the
//! arches in it: the peer trackers' idea (RBOT, M3T) of colour statistics updated from each
//! frame's model projection. Learning from a picture's own labels alone feeds a segmentation's
//! mistakes back into the models it is made from (gums or a lip labelled teeth teach the
//! teeth's model pink, and the next picture labels more of them teeth); the tracked projection
//! is the three cameras' and the rigid scans' verdict on where the teeth are. A frame tracked
//! `low-confidence` teaches nothing (`Segmenter::tracked`).

use super::{Models, Roi, TEETH_SHADE_FALLOFF, eroded, learn_class, near_only};
use crate::segment::settings::SegmentSettings;

/// One picture's classes and colours over its region of interest, kept until the frame is
/// tracked.
#[derive(Debug, Clone)]
pub struct Lesson {
    pub(super) colours: Vec<[u8; 3]>,
    /// 0 teeth, 1 mouth interior, 2 lips and skin, after the cuts and the edges' refinement.
    pub(super) classes: Vec<u8>,
    /// Lips and skin too far from the projection to learn from.
    pub(super) far: Vec<bool>,
    pub(super) roi: Roi,
    pub(super) mean_luma: f32,
}

impl Lesson {
    /// The models follow this picture: teeth from the pixels labelled teeth that `tracked`,
    /// the arches drawn at the frame's tracked poses (label bits over the whole picture,
    /// `width` wide), covers; the mouth interior, lips and skin from their labels. The
    /// interior is not held to the projection: the dark gaps between and beside the crowns,
    /// which the drawn arches round over, are the interior's own colour (docs/footage.md).
    pub fn follow(&self, tracked: &[u8], width: usize, m: &mut Models, settings: &SegmentSettings) {
        let roi = self.roi;
        let agreed: Vec<u8> = self
            .classes
            .iter()
            .enumerate()
            .map(|(i, &c)| {
                let (x, y) = roi.at(i);
                match c {
                    0 if tracked[y * width + x] == 0 => 3,
                    c => c,
                }
            })
            .collect();
        follow_picture(
            &self.colours,
            &agreed,
            &self.far,
            roi,
            m,
            self.mean_luma,
            settings,
        );
    }
}

/// Each class's model follows what this picture showed of it (`classes`: 0 teeth, 1 mouth
/// interior, 2 lips and skin, 3 unused), when it showed enough; so does the lit luma.
pub(super) fn follow_picture(
    colours: &[[u8; 3]],
    classes: &[u8],
    far: &[bool],
    roi: Roi,
    m: &mut Models,
    mean_luma: f32,
    settings: &SegmentSettings,
) {
    let edges_out = eroded(classes, roi.w, roi.h);
    let rate = settings.learning_rate;
    let fresh = |k: u8| learn_class(colours, &edges_out, k, settings.min_pixels);
    if let Some(f) = fresh(0) {
        m.teeth.update(&f.shaded(TEETH_SHADE_FALLOFF), rate);
    }
    // Lips and skin also from the edges, as on the first picture (`learn`).
    if let Some(f) = learn_class(colours, &near_only(classes, far), 2, settings.min_pixels) {
        m.other.update(&f, rate);
    }
    if let (Some(mouth), Some(f)) = (&mut m.mouth, fresh(1)) {
        mouth.update(&f, rate);
    }
    m.lit_luma += rate * (mean_luma - m.lit_luma);
}
