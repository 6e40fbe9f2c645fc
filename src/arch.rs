//! The two arches, a value per arch, and both arches' poses.

use crate::geometry::Pose;

/// The bit of a label mask that marks the upper arch's pixels (the masks' bitfield).
pub const UPPER_BIT: u8 = 1;
/// The bit of a label mask that marks the lower arch's pixels.
pub const LOWER_BIT: u8 = 2;

/// The two arches.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Arch {
    Upper,
    Lower,
}

impl Arch {
    pub const BOTH: [Arch; 2] = [Arch::Upper, Arch::Lower];
    pub fn name(self) -> &'static str {
        match self {
            Arch::Upper => "upper",
            Arch::Lower => "lower",
        }
    }
    pub fn mask_bit(self) -> u8 {
        match self {
            Arch::Upper => UPPER_BIT,
            Arch::Lower => LOWER_BIT,
        }
    }
    pub fn other(self) -> Arch {
        match self {
            Arch::Upper => Arch::Lower,
            Arch::Lower => Arch::Upper,
        }
    }
    /// 0 for the upper arch, 1 for the lower: the order of [`Arch::BOTH`].
    pub fn index(self) -> usize {
        match self {
            Arch::Upper => 0,
            Arch::Lower => 1,
        }
    }
}

/// One value per arch.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct PerArch<T> {
    pub upper: T,
    pub lower: T,
}

impl<T> PerArch<T> {
    /// The value of each arch from `f`.
    pub fn from_fn(mut f: impl FnMut(Arch) -> T) -> PerArch<T> {
        PerArch {
            upper: f(Arch::Upper),
            lower: f(Arch::Lower),
        }
    }
    pub fn get(&self, arch: Arch) -> &T {
        match arch {
            Arch::Upper => &self.upper,
            Arch::Lower => &self.lower,
        }
    }
}

/// Both arches' poses in the world (`world_from_upper`, `world_from_lower`).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ArchPoses {
    pub upper: Pose,
    pub lower: Pose,
}

impl ArchPoses {
    pub fn get(&self, arch: Arch) -> &Pose {
        match arch {
            Arch::Upper => &self.upper,
            Arch::Lower => &self.lower,
        }
    }
    pub fn with(mut self, arch: Arch, pose: Pose) -> Self {
        match arch {
            Arch::Upper => self.upper = pose,
            Arch::Lower => self.lower = pose,
        }
        self
    }
    /// The jaw pose, `upper_from_lower` (Eq. 1-3).
    pub fn jaw(&self) -> Pose {
        crate::geometry::jaw_pose(&self.upper, &self.lower)
    }
}
