//! What `jawtrack segment` can be told (`--segment-settings`, JSON; docs/footage.md).

use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};

#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct SegmentSettings {
    /// How far from the models' projection teeth may still be found, as a share of the
    /// picture's width (the prior falls off as exp(-d / reach)): how far the arches may move
    /// beyond the constant-velocity prediction in a frame.
    pub reach: f64,
    /// The graph cuts' smoothness: what a label change costs between two pixels of the same
    /// colour, in nats (less between pixels of different colours).
    pub smoothness: f64,
    /// How fast the colour models follow each frame (0: learned once, 1: relearned each frame).
    pub learning_rate: f32,
    /// Rounds of segmenting and relearning on the first picture of each camera.
    pub learning_rounds: usize,
    /// A picture whose region around the mouth is darker than this share of what it was
    /// when the models were learned is taken as lights-off: no mask.
    pub dark_ratio: f64,
    /// The fewest pixels a class needs to learn its colours from.
    pub min_pixels: usize,
    /// Track from the soft evidence (how much of each edge pixel the teeth hold, from its
    /// colour) rather than from the labels alone; the masks written are the labels either way.
    pub soft_evidence: bool,
    /// How long the shutter is open, as a share of the time between frames (0.5: a
    /// 180-degree shutter; 0: no motion blur): a moving arch's edges are then read as the
    /// ramps its motion over that time sweeps (`segment/smear.rs`).
    pub shutter: f64,
    /// Give the lip pixels beside the teeth that hold at least this share of the crowns'
    /// chromaticity to the teeth (0.5-1; `None`: off): a crown shaded by a lip is as dark as
    /// the lip (`segment/shaded_crowns.rs`). Off by default: the masks come closer to the
    /// truth, the tracked jaw only on some takes (docs/footage.md, "Crowns shaded by the lips").
    pub shaded_crowns: Option<f32>,
}

impl Default for SegmentSettings {
    fn default() -> Self {
        SegmentSettings {
            reach: 0.008,
            smoothness: 3.0,
            learning_rate: 0.25,
            learning_rounds: 4,
            dark_ratio: 0.5,
            min_pixels: 20,
            soft_evidence: false,
            shutter: 0.5,
            shaded_crowns: None,
        }
    }
}

impl SegmentSettings {
    /// Every field in its range; `source` names where they came from.
    pub fn validate(&self, source: &std::path::Path) -> Result<()> {
        let bad = |field: &str, why: &str| Err(Error::invalid(source, field, why.to_string()));
        if !(self.reach.is_finite() && self.reach > 0.0 && self.reach <= 0.5) {
            return bad(
                "reach",
                "must be above 0 and at most 0.5 (a share of the width)",
            );
        }
        if !(self.smoothness.is_finite() && (0.0..=100.0).contains(&self.smoothness)) {
            return bad("smoothness", "must be 0..100 (nats)");
        }
        if !(self.learning_rate.is_finite() && (0.0..=1.0).contains(&self.learning_rate)) {
            return bad("learning_rate", "must be 0..1");
        }
        if !(1..=20).contains(&self.learning_rounds) {
            return bad("learning_rounds", "must be 1..20");
        }
        if !(self.dark_ratio.is_finite() && (0.0..1.0).contains(&self.dark_ratio)) {
            return bad("dark_ratio", "must be 0 or more and below 1");
        }
        if self.min_pixels == 0 || self.min_pixels > 1_000_000 {
            return bad("min_pixels", "must be 1..1000000");
        }
        if !(self.shutter.is_finite() && (0.0..=1.0).contains(&self.shutter)) {
            return bad(
                "shutter",
                "must be 0..1 (a share of the time between frames)",
            );
        }
        if let Some(share) = self.shaded_crowns
            && !(share.is_finite() && (0.5..=1.0).contains(&share))
        {
            return bad(
                "shaded_crowns",
                "must be 0.5..1 (a share of the crowns' chromaticity) or null",
            );
        }
        Ok(())
    }
}
