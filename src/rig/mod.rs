//! The jaw rig (Yang et al., Sections 3 and 5): jaw poses relative to the upper arch, mapped
//! to se(3) (the coordinates and PCA are `anatomy`'s), hierarchical NLPCA, the three-parameter rig with alpha-shape ranges, IK and
//! keyframe animation.

pub mod additive;
pub mod animate;
pub mod coupled;
pub mod eval;
mod file;
pub mod ik;
mod lbfgs;
pub mod model;
mod network;
pub mod nlpca;
pub mod plot;
pub mod ranges;
pub mod three;
pub mod units;

pub use model::{JawRig, RigError, RigSettings};
pub use nlpca::{Nlpca, NlpcaSettings};
pub use three::ThreeParameterRig;
pub use units::AnimatorParams;

/// Told, now and then, how far a long step (learning a rig) is.
pub type Progress<'a> = dyn Fn(&str) + Sync + 'a;
