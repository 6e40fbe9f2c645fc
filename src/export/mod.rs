//! Motion out: the tracked motion checked and measured from its rest bite ([`motion`]), as
//! glTF for animation packages ([`gltf`]) and, in anatomical units
//! ([`crate::anatomy::motion`]), as CSV for analysis ([`csv`]).

pub mod csv;
pub mod gltf;
pub mod motion;

pub use motion::{MotionKey, MotionRanges, TrackedMotion, tracked_motion};
