//! The paper's energy E = E_SP + λ·E_BND (Eq. 7-9), per arch and candidate pose, summed over
//! cameras, and the terms of our own beside it (cross-label, over the mouth). Every backend
//! implements [`EnergyEngine`]: a batch of candidate poses in, one [`Energy`] (twelve counts
//! per camera: mask none/own/other/mouth x class) out for each.

pub mod backend;
pub mod backfaces;
pub mod clusters;
pub mod contour;
pub mod cpu;
pub mod edge_terms;
pub mod gpu;
#[doc(hidden)]
pub mod hand_counted;
pub mod histogram;
pub mod lens;
pub mod pyramid;
pub mod raster;
pub mod relevance;
pub mod smooth;
pub mod target;

use crate::arch::{Arch, ArchPoses, PerArch};
use crate::capture::masks::MOUTH_BIT;
use crate::capture::{Capture, FrameMasks, MaskMode};
use crate::error::Result;
use crate::geometry::Camera;
use crate::mesh::Mesh;

pub use backend::{Backend, OpenedEngine, open_engine};
pub use cpu::CpuEnergy;

/// The paper's weight of the boundary term.
pub const DEFAULT_LAMBDA: f64 = 0.4;

/// Which part of each mask an evaluation renders and counts. `Footprint` and `FullFrame` give
/// the same counts: outside the model's footprint every pixel is class none, so those bins
/// follow from the mask's totals. `Relevant` gives the same energy, cross, over-mouth and area
/// error.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum Region {
    /// Only the pixels the arch (and, in combined mode, the other arch) can cover.
    #[default]
    Footprint,
    /// Every pixel of the mask (for comparison).
    FullFrame,
    /// The footprint, drawing only the faces relevant to the energy (the CPU reference; the
    /// GPU engine draws the footprint): body faces off the labelled pixels and away from the
    /// boundary of interest are skipped (`relevance`, by cluster then by face: `clusters`),
    /// and so are the faces of closed meshes turned away from the camera (`backfaces`). The
    /// bins of body pixels off the labels come out low; uncovered, BOI outside, cross,
    /// over-mouth and area error are those of `Footprint`.
    Relevant,
}

impl Region {
    /// The name the command line and logs use.
    pub fn name(self) -> &'static str {
        match self {
            Region::Footprint => "footprint",
            Region::FullFrame => "full frame",
            Region::Relevant => "relevant faces",
        }
    }
}

/// Mask states of a pixel for the scored arch.
pub const MASK_NONE: usize = 0;
/// The pixel shows the scored arch (with combined masks: any teeth).
pub const MASK_OWN: usize = 1;
/// The pixel shows the other arch (per-arch masks only).
pub const MASK_OTHER: usize = 2;
/// The pixel shows the visible mouth interior: no tooth there (`masks.mouth`).
pub const MASK_MOUTH: usize = 3;
/// Bins per camera: mask state (`MASK_*`) x class (none, body, BOI).
pub const BINS: usize = 12;

/// A mask's pixel totals for a scored arch: its own pixels, the other arch's and the mouth's
/// (the rest show none of them).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct MaskTotals {
    pub own: u64,
    pub other: u64,
    pub mouth: u64,
}

/// The mask state of a label for the scored arch: own, else other, else mouth, else none
/// (combined masks carry both arches' bits: own). The GPU's is in shaders/histogram.wgsl.
pub fn mask_state(label: u8, arch: Arch) -> usize {
    if label & arch.mask_bit() != 0 {
        MASK_OWN
    } else if label & arch.other().mask_bit() != 0 {
        MASK_OTHER
    } else if label & MOUTH_BIT != 0 {
        MASK_MOUTH
    } else {
        MASK_NONE
    }
}

/// The totals of `mask` for the scored `arch`.
pub fn mask_totals(mask: &crate::capture::LabelMask, arch: Arch) -> MaskTotals {
    let mut t = MaskTotals::default();
    for &m in &mask.data {
        match mask_state(m, arch) {
            MASK_OWN => t.own += 1,
            MASK_OTHER => t.other += 1,
            MASK_MOUTH => t.mouth += 1,
            _ => {}
        }
    }
    t
}

/// The totals of `mask` for each scored arch.
pub fn frame_totals(mask: &crate::capture::LabelMask) -> PerArch<MaskTotals> {
    PerArch::from_fn(|arch| mask_totals(mask, arch))
}

/// A camera's bins from the bins counted inside a rendered region, adding the pixels
/// outside it (all class none) from the mask's totals.
pub fn counts_with_outside(inside: [u64; BINS], cam: &Camera, totals: MaskTotals) -> Counts {
    let row = |m: usize| inside[m * 3..m * 3 + 3].iter().sum::<u64>();
    let all = cam.width as u64 * cam.height as u64;
    let mut bins = inside;
    bins[MASK_OWN * 3] += totals.own - row(MASK_OWN);
    bins[MASK_OTHER * 3] += totals.other - row(MASK_OTHER);
    bins[MASK_MOUTH * 3] += totals.mouth - row(MASK_MOUTH);
    bins[MASK_NONE * 3] += (all - totals.own - totals.other - totals.mouth) - row(MASK_NONE);
    Counts { bins }
}

/// The weights of the objective the search minimises: the paper's E (λ) and the terms of
/// our own (cross-label, over the mouth).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Weights {
    pub lambda: f64,
    pub cross: f64,
    pub mouth: f64,
}

impl Weights {
    /// The paper's objective: E alone.
    pub fn paper(lambda: f64) -> Weights {
        Weights {
            lambda,
            cross: 0.0,
            mouth: 0.0,
        }
    }
}

/// One camera's counts: mask state (none, own, other, mouth: `MASK_*`) x class (none, body,
/// BOI), at `mask * 3 + class`. The paper's six bins fold "other" and "mouth" into "none"
/// ([`Counts::paper_bins`]).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Counts {
    pub bins: [u64; BINS],
}

impl Counts {
    pub fn bin(&self, mask: usize, class: u8) -> u64 {
        self.bins[mask * 3 + class as usize]
    }
    /// The paper's #Pixel_White: the arch's mask pixels the model leaves uncovered.
    pub fn uncovered(&self) -> u64 {
        self.bins[MASK_OWN * 3]
    }
    /// The paper's #Pixel_DGreen: visible BOI pixels outside the arch's mask.
    pub fn boi_outside(&self) -> u64 {
        self.bins[MASK_NONE * 3 + 2] + self.bins[MASK_OTHER * 3 + 2] + self.bins[MASK_MOUTH * 3 + 2]
    }
    /// Pixels labelled visible mouth interior where the model is drawn (the scored arch's;
    /// with combined masks either arch's): a tooth drawn where the camera sees none. The
    /// paper's energy is blind to it, so a pose may slide into the region the lips hide.
    pub fn over_mouth(&self) -> u64 {
        self.bins[MASK_MOUTH * 3 + 1] + self.bins[MASK_MOUTH * 3 + 2]
    }
    /// Pixels the segmentation gives to the other arch where this arch's model is visible in
    /// front of it: a contradiction that a single teeth mask (the paper's) cannot show. Zero
    /// with combined masks.
    pub fn cross(&self) -> u64 {
        self.bins[MASK_OTHER * 3 + 1] + self.bins[MASK_OTHER * 3 + 2]
    }
    pub fn mask_pixels(&self) -> u64 {
        self.bins[MASK_OWN * 3..MASK_OWN * 3 + 3].iter().sum()
    }
    /// The visible BOI pixels (the incisal band) the masks give to the arch, and all of them.
    pub fn boi_in_mask(&self) -> (u64, u64) {
        let all = (0..BINS / 3).map(|m| self.bins[m * 3 + 2]).sum();
        (self.bins[MASK_OWN * 3 + 2], all)
    }
    /// The paper's six bins, mask (off, on) x class: the other arch's and the mouth's pixels
    /// count as off.
    pub fn paper_bins(&self) -> [u64; 6] {
        let b = &self.bins;
        [
            b[0] + b[6] + b[9],
            b[1] + b[7] + b[10],
            b[2] + b[8] + b[11],
            b[3],
            b[4],
            b[5],
        ]
    }
    pub fn total(&self, lambda: f64) -> f64 {
        self.uncovered() as f64 + lambda * self.boi_outside() as f64
    }
}

/// The energy of one candidate: counts per camera (zero for a camera without a mask).
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Energy {
    pub cameras: Vec<Counts>,
}

impl Energy {
    pub fn uncovered(&self) -> u64 {
        self.cameras.iter().map(Counts::uncovered).sum()
    }
    pub fn boi_outside(&self) -> u64 {
        self.cameras.iter().map(Counts::boi_outside).sum()
    }
    pub fn mask_pixels(&self) -> u64 {
        self.cameras.iter().map(Counts::mask_pixels).sum()
    }
    pub fn cross(&self) -> u64 {
        self.cameras.iter().map(Counts::cross).sum()
    }
    pub fn over_mouth(&self) -> u64 {
        self.cameras.iter().map(Counts::over_mouth).sum()
    }
    /// The paper's E = uncovered + λ·boi_outside.
    pub fn total(&self, lambda: f64) -> f64 {
        self.uncovered() as f64 + lambda * self.boi_outside() as f64
    }
    /// What the search minimises: the paper's E plus the cross-label term (per-arch masks)
    /// and the over-mouth term (masks that label the mouth), each at its weight.
    pub fn objective(&self, w: &Weights) -> f64 {
        self.total(w.lambda) + w.cross * self.cross() as f64 + w.mouth * self.over_mouth() as f64
    }
    /// The share of the arch's visible incisal band (its BOI) that the masks show as the arch,
    /// over the cameras; `None` where no BOI is drawn. Near 1 with the lips apart, near 0 where
    /// they close over the incisal edges.
    pub fn boi_shown(&self) -> Option<f64> {
        let (shown, all) = self
            .cameras
            .iter()
            .map(Counts::boi_in_mask)
            .fold((0, 0), |(s, a), (cs, ca)| (s + cs, a + ca));
        (all > 0).then(|| shown as f64 / all as f64)
    }
    /// The paper's accuracy proxy: uncovered / mask pixels (0 without mask pixels).
    pub fn area_error(&self) -> f64 {
        match self.mask_pixels() {
            0 => 0.0,
            m => self.uncovered() as f64 / m as f64,
        }
    }
    /// The model drawn where the masks say something else is seen (the other arch's label,
    /// the mouth interior; each where its term weighs in `w`), per mask pixel (0 without mask
    /// pixels): near zero at the true pose whatever the lips hide, where the area error cannot
    /// see an arch drawn over the open mouth.
    pub fn misdrawn_share(&self, w: &Weights) -> f64 {
        let counted = |on: f64, n: u64| if on > 0.0 { n } else { 0 };
        match self.mask_pixels() {
            0 => 0.0,
            m => {
                (counted(w.cross, self.cross()) + counted(w.mouth, self.over_mouth())) as f64
                    / m as f64
            }
        }
    }
}

/// What every backend renders: the cameras the masks are seen through (mask resolution,
/// undistorted; `None` for a camera without masks), both arch meshes and the mask mode.
#[derive(Debug, Clone)]
pub struct Scene {
    pub cameras: Vec<Option<Camera>>,
    pub upper: Mesh,
    pub lower: Mesh,
    pub mode: MaskMode,
}

impl Scene {
    pub fn from_capture(capture: &Capture) -> Scene {
        Scene {
            cameras: capture.cameras().iter().map(|c| c.mask_camera()).collect(),
            upper: capture.upper().clone(),
            lower: capture.lower().clone(),
            mode: capture.mask_mode(),
        }
    }

    /// The scene with unused vertices dropped from both meshes (what engines render).
    pub fn compacted(self) -> Scene {
        Scene {
            upper: self.upper.compacted(),
            lower: self.lower.compacted(),
            ..self
        }
    }

    pub fn mesh(&self, arch: Arch) -> &Mesh {
        match arch {
            Arch::Upper => &self.upper,
            Arch::Lower => &self.lower,
        }
    }

    /// The class the other arch is drawn with: in combined mode it covers the teeth mask
    /// (body); with per-arch masks it only hides what is behind it (depth, class none), so
    /// that only *visible* BOI pixels count.
    pub fn other_arch_class(&self) -> u8 {
        match self.mode {
            MaskMode::Combined => raster::CLASS_BODY,
            MaskMode::PerArch { .. } => raster::CLASS_NONE,
        }
    }
}

/// An energy backend. `set_frame` uploads a frame's masks once; `evaluate` scores a batch of
/// candidates for one arch (each candidate carries both arches' poses: the other arch is
/// drawn at its pose as described in [`Scene::other_arch_class`]).
pub trait EnergyEngine {
    /// The backend and adapter, for logs.
    fn name(&self) -> String;
    fn set_frame(&mut self, masks: &FrameMasks) -> Result<()>;
    fn evaluate(&self, arch: Arch, candidates: &[ArchPoses]) -> Result<Vec<Energy>>;
    /// The smooth energy's terms at a stage's samples over the frame's masks ([`smooth`]):
    /// the CPU reference by its twin ([`edge_terms`]), the GPU engine by
    /// shaders/edge_terms.wgsl. One per sample, in order.
    fn edge_terms(&self, q: &edge_terms::EdgeQuery) -> Result<Vec<Option<edge_terms::EdgeTerm>>>;
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_misdrawn_share_counts_the_weighed_terms_per_mask_pixel() {
        let mut c = Counts::default();
        c.bins[MASK_OWN * 3] = 60; // uncovered
        c.bins[MASK_OWN * 3 + 1] = 40; // covered: 100 mask pixels in all
        c.bins[MASK_OTHER * 3 + 1] = 5; // over the other arch's label
        c.bins[MASK_MOUTH * 3 + 2] = 10; // BOI over the mouth interior
        let two_cameras = Energy {
            cameras: vec![c, c],
        };
        let both = Weights {
            lambda: 0.4,
            cross: 1.0,
            mouth: 1.0,
        };
        assert!((two_cameras.misdrawn_share(&both) - 0.15).abs() < 1e-12);
        let mouth_only = Weights { cross: 0.0, ..both };
        assert!((two_cameras.misdrawn_share(&mouth_only) - 0.10).abs() < 1e-12);
        assert_eq!(two_cameras.misdrawn_share(&Weights::paper(0.4)), 0.0);
        assert_eq!(Energy::default().misdrawn_share(&both), 0.0);
    }
}
