//! The paper's energy E = E_SP + λ·E_BND (Eq. 7-9), per arch and candidate pose, summed over
//! cameras. Every backend implements [`EnergyEngine`]: a batch of candidate poses in, one
//! [`Energy`] (nine counts per camera: mask none/own/other x class) out for each.

pub mod backend;
pub mod backfaces;
pub mod clusters;
pub mod cpu;
pub mod gpu;
#[doc(hidden)]
pub mod hand_counted;
pub mod histogram;
pub mod lens;
pub mod raster;
pub mod relevance;
pub mod target;

use crate::capture::{Arch, ArchPoses, Capture, FrameMasks, MaskMode, Mesh, PerArch};
use crate::error::Result;
use crate::geometry::Camera;

pub use backend::{Backend, OpenedEngine, open_engine};
pub use cpu::CpuEnergy;

/// The paper's weight of the boundary term.
pub const DEFAULT_LAMBDA: f64 = 0.4;

/// Which part of each mask an evaluation renders and counts. `Footprint` and `FullFrame` give
/// the same counts: outside the model's footprint every pixel is class none, so those bins
/// follow from the mask's totals. `Relevant` gives the same energy, cross and area error.
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
    /// bins of body pixels off the mask come out low; uncovered, BOI outside, cross and area
    /// error are those of `Footprint`.
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

/// A mask's pixel totals for a scored arch: its own pixels and the other arch's (the rest
/// show neither).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct MaskTotals {
    pub own: u64,
    pub other: u64,
}

/// The totals of `mask` for the scored `arch`.
pub fn mask_totals(mask: &crate::capture::LabelMask, arch: Arch) -> MaskTotals {
    let (own, other) = (arch.mask_bit(), arch.other().mask_bit());
    let mut t = MaskTotals::default();
    for &m in &mask.data {
        if m & own != 0 {
            t.own += 1;
        } else if m & other != 0 {
            t.other += 1;
        }
    }
    t
}

/// The totals of `mask` for each scored arch.
pub fn frame_totals(mask: &crate::capture::LabelMask) -> PerArch<MaskTotals> {
    PerArch::from_fn(|arch| mask_totals(mask, arch))
}

/// The nine bins of a camera from the bins counted inside a rendered region, adding the
/// pixels outside it (all class none) from the mask's totals.
pub fn counts_with_outside(inside: [u64; 9], cam: &Camera, totals: MaskTotals) -> Counts {
    let row = |m: usize| inside[m * 3..m * 3 + 3].iter().sum::<u64>();
    let all = cam.width as u64 * cam.height as u64;
    let mut bins = inside;
    bins[MASK_OWN * 3] += totals.own - row(MASK_OWN);
    bins[MASK_OTHER * 3] += totals.other - row(MASK_OTHER);
    bins[MASK_NONE * 3] += (all - totals.own - totals.other) - row(MASK_NONE);
    Counts { bins }
}

/// One camera's counts: mask state (none, own, other: `MASK_*`) x class (none, body, BOI), at
/// `mask * 3 + class`. The paper's six bins fold "other" into "none" ([`Counts::paper_bins`]).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Counts {
    pub bins: [u64; 9],
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
        self.bins[MASK_NONE * 3 + 2] + self.bins[MASK_OTHER * 3 + 2]
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
    /// The paper's six bins, mask (off, on) x class: the other arch's pixels count as off.
    pub fn paper_bins(&self) -> [u64; 6] {
        let b = &self.bins;
        [b[0] + b[6], b[1] + b[7], b[2] + b[8], b[3], b[4], b[5]]
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
    /// The paper's E = uncovered + λ·boi_outside.
    pub fn total(&self, lambda: f64) -> f64 {
        self.uncovered() as f64 + lambda * self.boi_outside() as f64
    }
    /// What the search minimises: the paper's E plus `cross_weight`·cross (per-arch masks).
    pub fn objective(&self, lambda: f64, cross_weight: f64) -> f64 {
        self.total(lambda) + cross_weight * self.cross() as f64
    }
    /// The paper's accuracy proxy: uncovered / mask pixels (0 without mask pixels).
    pub fn area_error(&self) -> f64 {
        match self.mask_pixels() {
            0 => 0.0,
            m => self.uncovered() as f64 / m as f64,
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
            cameras: capture.cameras.iter().map(|c| c.mask_camera()).collect(),
            upper: capture.upper.clone(),
            lower: capture.lower.clone(),
            mode: capture.mask_mode,
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
}
