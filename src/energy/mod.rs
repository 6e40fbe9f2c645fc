//! The paper's energy E = E_SP + λ·E_BND (Eq. 7-9), per arch and candidate pose, summed over
//! cameras. Every backend implements [`EnergyEngine`]: a batch of candidate poses in, one
//! [`Energy`] (six counts per camera) out for each.

pub mod backend;
pub mod cpu;
pub mod gpu;
pub mod raster;

use crate::capture::{Arch, ArchPoses, Capture, FrameMasks, MaskMode, Mesh};
use crate::error::Result;
use crate::geometry::Camera;

pub use backend::{Backend, OpenedEngine, open_engine};
pub use cpu::CpuEnergy;

/// The paper's weight of the boundary term.
pub const DEFAULT_LAMBDA: f64 = 0.4;

/// Which part of each mask an evaluation renders and counts. Both give the same counts:
/// outside the model's footprint every pixel is class none, so those bins follow from the
/// mask's totals.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, clap::ValueEnum)]
pub enum Region {
    /// Only the pixels the arch (and, in combined mode, the other arch) can cover.
    #[default]
    Footprint,
    /// Every pixel of the mask (for comparison).
    FullFrame,
}

/// The six bins of a camera from the bins counted inside a rendered region, adding the
/// pixels outside it (all class none) from the mask's per-arch totals (upper, lower).
pub fn counts_with_outside(inside: [u64; 6], cam: &Camera, totals: [u64; 2], arch: Arch) -> Counts {
    let mask_total = totals[(arch == Arch::Lower) as usize];
    let inside_on: u64 = inside[3..].iter().sum();
    let inside_off: u64 = inside[..3].iter().sum();
    let all = cam.width as u64 * cam.height as u64;
    let mut bins = inside;
    bins[3] += mask_total - inside_on;
    bins[0] += (all - mask_total) - inside_off;
    Counts { bins }
}

/// One camera's six counts: mask (off, on) x class (none, body, BOI), at `mask * 3 + class`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Counts {
    pub bins: [u64; 6],
}

impl Counts {
    pub fn bin(&self, on_mask: bool, class: u8) -> u64 {
        self.bins[on_mask as usize * 3 + class as usize]
    }
    /// The paper's #Pixel_White: mask pixels the model leaves uncovered.
    pub fn uncovered(&self) -> u64 {
        self.bins[3]
    }
    /// The paper's #Pixel_DGreen: visible BOI pixels outside the mask.
    pub fn boi_outside(&self) -> u64 {
        self.bins[2]
    }
    pub fn mask_pixels(&self) -> u64 {
        self.bins[3] + self.bins[4] + self.bins[5]
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
    /// E = uncovered + λ·boi_outside.
    pub fn total(&self, lambda: f64) -> f64 {
        self.uncovered() as f64 + lambda * self.boi_outside() as f64
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
