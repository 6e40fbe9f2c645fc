//! The tracker's settings (`track --settings`): the search's, and what the frame loop adds
//! around it (passes, confidence, the jaw prior, the penalties), each checked against its
//! range (docs/settings.md).

use std::sync::Arc;

use super::search::SearchSettings;
use super::window::WindowSettings;
use crate::capture::{Capture, MaskMode};
use crate::error::Result;
use crate::geometry::Pose;
use crate::io::Fnv;
use crate::settings::Rules;

#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TrackSettings {
    pub search: SearchSettings,
    /// Passes over the two arches per frame (upper, then lower with the new upper). With
    /// combined masks the arches compete for the same pixels and alternate until neither moves
    /// more than `settle_mm`, at most `combined_passes` times; per-arch masks need one pass.
    pub per_arch_passes: usize,
    pub combined_passes: usize,
    pub settle_mm: f64,
    /// A frame is `low-confidence` when an arch's area error (uncovered / mask pixels) exceeds
    /// `low_confidence_area_error`, or both `low_confidence_floor` and `low_confidence_ratio`
    /// times the median area error of the last `confidence_window` good frames (a sudden
    /// jump; the floor keeps clean data, whose area error is near zero, from tripping it).
    pub low_confidence_area_error: f64,
    /// A frame where an arch's area error exceeds this after its search, and the arch leaves
    /// at least 40 of its mask pixels uncovered (fewer are a small mask the lips close over),
    /// is taken as lost (at 0.1, frames of hard captures where the lips close trip it, and the
    /// fresh look finds poses the energy prefers that are further from the truth):
    /// both arches are looked for afresh from its masks alone (`locate`, as for a capture
    /// without init.json) and kept where they fit better. 1 turns it off. (Left out of the
    /// output's fingerprint at its default, so runs from before it resume.)
    #[serde(skip_serializing_if = "is_default_relocate")]
    pub relocate_area_error: f64,
    pub low_confidence_floor: f64,
    pub low_confidence_ratio: f64,
    pub confidence_window: usize,
    /// A frame where either arch's incisal band (its BOI, as drawn at the poses found) shows
    /// in the masks for less than this share of its pixels is written `low-confidence` with
    /// `teeth_hidden`: the lips hide the teeth, and the pose is what the frames before and the
    /// priors left it at. Tracking goes on from it as from an `ok` frame. 0 turns it off.
    /// (Left out of the output's fingerprint at its default, so runs from before it resume.)
    #[serde(skip_serializing_if = "is_default_hidden")]
    pub hidden_teeth_share: f64,
    /// Extra starts for the lower arch from an average temporomandibular joint fitted to the
    /// capture's meshes (the jaw moves on a low-dimensional manifold): a grid of this many
    /// openings, lateral excursions and protrusions, each placed on the frame's upper arch;
    /// the energy picks among them and the usual starts. Both mask modes. [0, 0, 0] turns
    /// it off.
    pub jaw_prior_grid: [usize; 3],
    /// And the `jaw_prior_nearest` poses of a finer grid (`jaw_prior_fine_grid`) nearest to the
    /// frame's starts.
    pub jaw_prior_fine_grid: [usize; 3],
    pub jaw_prior_nearest: usize,
    /// Each arch is searched from this many of its best starts (at least 1 mm apart) and
    /// keeps the best result: the energy has many shallow minima, and the best start is not
    /// always in the deepest one's basin.
    pub restarts: usize,
    /// The arches cannot pass through each other (`contact`): every candidate whose lower
    /// crowns reach more than `contact_tolerance_mm` into the upper ones (along the occlusal
    /// axis) costs `contact_weight` objective units (pixels) per mm beyond. 0 turns it off.
    pub contact_weight: f64,
    pub contact_tolerance_mm: f64,
    /// The jaw moves on a low-dimensional manifold (`manifold`): every candidate whose jaw
    /// pose lies more than `jaw_manifold_tolerance_mm` from the average joint's (the three
    /// principal directions of the jaw prior's fine grid, in the rig's se(3) coordinates)
    /// costs `jaw_manifold_weight` objective units per mm beyond. It steers both arches
    /// along the directions the energy cannot tell apart (a tilt about the incisal edge).
    /// Per-arch masks only: a combined mask's one label cannot tell the arches apart, so the
    /// manifold would pull the jaw toward the average joint against evidence it cannot
    /// weigh. Built from the fine grid, so off with it too; 0 turns it off.
    pub jaw_manifold_weight: f64,
    pub jaw_manifold_tolerance_mm: f64,
    /// The last 13 frames tracked ok with the jaw farther than this (mm) from the manifold, by
    /// their median, say the subject's joint is not the one it describes, and it is let go for
    /// the rest of the take (`state::ManifoldFit`). 0: never. Only where the masks label the
    /// mouth: the paper's one-sided energy leaves the jaw to the manifold along directions it
    /// cannot see.
    pub jaw_manifold_release_mm: f64,
    /// What replaces the fields above when the masks label the mouth (`masks.mouth`) and
    /// `search.mouth_weight` is above 0.
    pub labelled: LabelledSettings,
    /// The window over frames (a fixed-lag smoother of the tracked frames).
    /// Left out of the output's fingerprint at its defaults.
    #[serde(skip_serializing_if = "WindowSettings::is_default")]
    pub window: WindowSettings,
    /// The subject's own jaw (`track --rig`): the jaw prior's candidates and the manifold the
    /// jaw is held to, in place of the average joint's. Not a field of a settings file; the
    /// output's fingerprint records its digest.
    #[serde(
        skip_deserializing,
        skip_serializing_if = "Option::is_none",
        serialize_with = "digest_of"
    )]
    pub jaw_space: Option<Arc<JawSpace>>,
}

/// The profile for masks that label the visible mouth interior: the energy is then two-sided
/// and has fewer false minima, so a coarser jaw prior and one sampling round suffice
/// (docs/tracking.md, "The two-sided energy", has the figures). Without the label (or with
/// the term off) the settings above apply as they are.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LabelledSettings {
    pub jaw_prior_grid: [usize; 3],
    pub jaw_prior_nearest: usize,
    pub sample_rounds: usize,
}

impl Default for LabelledSettings {
    fn default() -> Self {
        LabelledSettings {
            jaw_prior_grid: [5, 3, 3],
            jaw_prior_nearest: 20,
            sample_rounds: 1,
        }
    }
}

/// A subject's own jaw poses (upper_from_lower, in the capture's model frames): a rig's,
/// sampled over its valid range.
#[derive(Debug, Clone)]
pub struct JawSpace {
    pub poses: Vec<Pose>,
    /// Where they come from and a digest of them.
    pub digest: String,
}

impl JawSpace {
    /// `source` names where the poses come from (a rig file).
    pub fn new(poses: Vec<Pose>, source: &str) -> JawSpace {
        let mut hash = Fnv::default();
        for p in &poses {
            for row in p.rotation_rows() {
                for v in row {
                    hash.write(&v.to_le_bytes());
                }
            }
            for v in p.translation.iter() {
                hash.write(&v.to_le_bytes());
            }
        }
        let digest = format!("{source}: {} poses, {:016x}", poses.len(), hash.0);
        JawSpace { poses, digest }
    }
}

fn digest_of<S: serde::Serializer>(
    space: &Option<Arc<JawSpace>>,
    s: S,
) -> std::result::Result<S::Ok, S::Error> {
    s.serialize_str(space.as_ref().map_or("", |j| j.digest.as_str()))
}

const DEFAULT_RELOCATE: f64 = 0.2;

const DEFAULT_HIDDEN: f64 = 0.1;

fn is_default_hidden(v: &f64) -> bool {
    *v == DEFAULT_HIDDEN
}

fn is_default_relocate(v: &f64) -> bool {
    *v == DEFAULT_RELOCATE
}

impl Default for TrackSettings {
    fn default() -> Self {
        TrackSettings {
            search: SearchSettings::default(),
            per_arch_passes: 1,
            combined_passes: 3,
            settle_mm: 0.02,
            low_confidence_area_error: 0.25,
            relocate_area_error: DEFAULT_RELOCATE,
            low_confidence_floor: 0.03,
            low_confidence_ratio: 2.5,
            confidence_window: 15,
            hidden_teeth_share: DEFAULT_HIDDEN,
            jaw_prior_grid: [7, 5, 3],
            jaw_prior_fine_grid: [31, 11, 6],
            jaw_prior_nearest: 60,
            restarts: 1,
            contact_weight: 100.0,
            contact_tolerance_mm: 1.0,
            jaw_manifold_weight: 60.0,
            jaw_manifold_tolerance_mm: 0.3,
            jaw_manifold_release_mm: 0.8,
            labelled: LabelledSettings::default(),
            window: WindowSettings::default(),
            jaw_space: None,
        }
    }
}

impl TrackSettings {
    /// Every field in its range (see [`crate::settings`]); errors name `settings` as the
    /// source. Use [`TrackSettings::validate_from`] to name a file.
    pub fn validate(&self) -> Result<()> {
        self.validate_from(std::path::Path::new("settings"))
    }

    pub fn validate_from(&self, source: &std::path::Path) -> Result<()> {
        let rules = Rules::new(source);
        self.search.validate(&rules.within("search"))?;
        self.window.validate(&rules.within("window"))?;
        // A search's seed packs the pass in 4 bits and the restart in 7 (see `track_frame`).
        rules.count("per_arch_passes", self.per_arch_passes as u64, 1, 16)?;
        rules.count("combined_passes", self.combined_passes as u64, 1, 16)?;
        rules.number("settle_mm", self.settle_mm, 0.0, 100.0)?;
        rules.number(
            "low_confidence_area_error",
            self.low_confidence_area_error,
            0.0,
            1.0,
        )?;
        rules.number("relocate_area_error", self.relocate_area_error, 0.0, 1.0)?;
        rules.number("low_confidence_floor", self.low_confidence_floor, 0.0, 1.0)?;
        rules.number("low_confidence_ratio", self.low_confidence_ratio, 0.0, 1e6)?;
        rules.number("hidden_teeth_share", self.hidden_teeth_share, 0.0, 1.0)?;
        rules.count(
            "confidence_window",
            self.confidence_window as u64,
            1,
            10_000,
        )?;
        rules.grid("jaw_prior_grid", &self.jaw_prior_grid, 100, 10_000)?;
        rules.grid(
            "jaw_prior_fine_grid",
            &self.jaw_prior_fine_grid,
            200,
            100_000,
        )?;
        rules.count(
            "jaw_prior_nearest",
            self.jaw_prior_nearest as u64,
            0,
            10_000,
        )?;
        rules.count("restarts", self.restarts as u64, 1, 100)?;
        rules.number("contact_weight", self.contact_weight, 0.0, 1e6)?;
        rules.number(
            "contact_tolerance_mm",
            self.contact_tolerance_mm,
            0.0,
            100.0,
        )?;
        rules.number("jaw_manifold_weight", self.jaw_manifold_weight, 0.0, 1e6)?;
        rules.number(
            "jaw_manifold_tolerance_mm",
            self.jaw_manifold_tolerance_mm,
            0.0,
            100.0,
        )?;
        rules.number(
            "jaw_manifold_release_mm",
            self.jaw_manifold_release_mm,
            0.0,
            100.0,
        )?;
        let labelled = rules.within("labelled");
        labelled.grid("jaw_prior_grid", &self.labelled.jaw_prior_grid, 100, 10_000)?;
        labelled.count(
            "jaw_prior_nearest",
            self.labelled.jaw_prior_nearest as u64,
            0,
            10_000,
        )?;
        labelled.count("sample_rounds", self.labelled.sample_rounds as u64, 0, 100)?;
        Ok(())
    }

    /// The settings a capture is tracked with: `labelled`'s in place of the fields they
    /// replace when its masks label the mouth and the over-mouth term is on (else the jaw's
    /// manifold is never let go), and the solver `auto` stands for.
    pub fn for_capture(&self, capture: &Capture) -> TrackSettings {
        let mut s = self.clone();
        let two_sided = capture.mouth().is_some() && self.search.mouth_weight > 0.0;
        if two_sided {
            s.jaw_prior_grid = self.labelled.jaw_prior_grid;
            s.jaw_prior_nearest = self.labelled.jaw_prior_nearest;
            s.search.sample_rounds = self.labelled.sample_rounds;
        } else {
            // The one-sided energy is blind along directions that only the manifold holds,
            // and even another joint's holds them better than nothing (docs/tracking.md).
            s.jaw_manifold_release_mm = 0.0;
        }
        let combined = capture.mask_mode() == MaskMode::Combined;
        s.search.solver = self.search.solver.for_masks(two_sided, combined);
        s
    }
}
