//! The jaw rig (Yang et al., Sections 3 and 5): jaw poses relative to the upper arch, mapped
//! to se(3), PCA, hierarchical NLPCA, the three-parameter rig with alpha-shape ranges, IK and
//! keyframe animation.

pub mod additive;
pub mod animate;
pub mod coords;
pub mod eval;
pub mod ik;
pub mod input;
mod lbfgs;
pub mod metric;
pub mod model;
pub mod nlpca;
pub mod pca;
pub mod plot;
pub mod ranges;

pub use coords::Coordinates;
pub use input::{JawPoses, read_jaw_poses, write_jaw_poses};
pub use metric::MeshMetric;
pub use model::{JawRig, RigError, RigSettings};
pub use nlpca::{Nlpca, NlpcaSettings};
pub use pca::Pca;
