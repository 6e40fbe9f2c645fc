//! The jaw's anatomy, shared by the synthetic subjects, the tracker and the rigs: an average
//! dentition (`arches`), the rest bite (`bite`), a model of the temporomandibular joint
//! (`joint`) and that joint placed on any pair of arches (`joint_grid`, through the scan
//! convention of `scan_frame`), and the measures of jaw poses: se(3) coordinates
//! (`coords`), the vertex metric (`metric`), their principal components (`pca`), the jaw frame
//! of condyles and incisal point (`jaw_frame`) and the animator's units on it (`motion`).

pub mod arches;
pub mod bite;
pub mod coords;
pub mod jaw_frame;
pub mod joint;
pub mod joint_grid;
pub mod metric;
pub mod motion;
pub mod pca;
mod rings;
pub mod scan_frame;

pub use arches::procedural_arch;
pub use bite::rest_bite;
pub use coords::Coordinates;
pub use jaw_frame::JawFrame;
pub use joint::{JawControls, JawModel};
pub use joint_grid::joint_grid;
pub use metric::MeshMetric;
pub use pca::Pca;
pub(crate) use rings::stitch_rings;
