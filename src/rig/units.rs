//! The rig's parameters in the units animators use: zero at the rest bite, opening in degrees
//! about the condylar axis, lateral excursion and protrusion in mm at the lower incisal point
//! ([`crate::anatomy::motion`]). The network's own coordinates (d1, d2, d3) stay inside the
//! rig; these are measured on the poses it produces, and solved for when given.

use serde::{Deserialize, Serialize};

use super::JawRig;
use super::three::{ThreeParameterRig, solve_animator};
use crate::anatomy::JawFrame;
use crate::anatomy::motion::{Anatomical, MotionFrame};
use crate::formats::PoseJson;
use crate::geometry::Pose;
use crate::mesh::Mesh;

/// What the rig file keeps to speak anatomical units: the jaw frame's landmarks (lower frame)
/// and the rest bite (`upper_from_lower`, the most closed training pose).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct RigAnatomy {
    pub frame: JawFrame,
    pub rest: PoseJson,
}

/// Opening (degrees), lateral (mm) and protrusion (mm): the three animator parameters.
pub type AnimatorParams = [f64; 3];

impl JawRig {
    /// Attach the anatomy: landmarks found on `mesh` (the mandible or lower arch the rig was
    /// learned with), the rest bite the most closed of `poses`. `None` when the landmarks are
    /// degenerate.
    pub fn with_anatomy(mut self, mesh: &Mesh, poses: &[Pose]) -> JawRig {
        self.anatomy = JawFrame::from_mesh(mesh, None, None)
            .ok()
            .and_then(|frame| {
                let rest = poses[MotionFrame::most_closed(&frame, poses)?];
                Some(RigAnatomy {
                    frame,
                    rest: (&rest).into(),
                })
            });
        self
    }

    /// The rest bite and jaw axes the animator units are measured on (`None` without the
    /// anatomy).
    pub fn motion_frame(&self) -> Option<MotionFrame> {
        let a = self.anatomy.as_ref()?;
        let rest = a
            .rest
            .to_pose(std::path::Path::new("rig"), "anatomy.rest")
            .ok()?;
        Some(MotionFrame::new(&a.frame, rest))
    }

    /// The pose for `d` in anatomical units (`None` for a rig file without its anatomy).
    pub fn anatomical(&self, d: &[f64; 3]) -> Option<Anatomical> {
        Some(self.motion_frame()?.measure(&self.pose(d)))
    }

    /// The network parameters whose pose has these animator parameters, by Newton's method
    /// from the rest bite's parameters (the Jacobian by central differences). `None` without
    /// the anatomy, or when the rig cannot reach them (its modes do not span that pose).
    pub fn params_for(&self, target: &AnimatorParams) -> Option<[f64; 3]> {
        let m = self.motion_frame()?;
        solve_animator(self, &m, target, self.encode(m.rest()))
    }
}

impl ThreeParameterRig for JawRig {
    fn kind(&self) -> &'static str {
        "NLPCA rig"
    }

    fn pose(&self, d: &[f64; 3]) -> Pose {
        JawRig::pose(self, d)
    }

    fn is_valid(&self, d: &[f64; 3]) -> bool {
        JawRig::is_valid(self, d)
    }

    fn clamp(&self, d: &[f64; 3]) -> [f64; 3] {
        JawRig::clamp(self, d)
    }

    fn band(&self, d: &[f64; 3], k: usize) -> Option<[f64; 2]> {
        let (lateral, protrusion) = self.ranges.at(d[0]);
        let intervals = if k == 1 { lateral } else { protrusion };
        let lo = intervals.iter().map(|i| i[0]).reduce(f64::min)?;
        let hi = intervals.iter().map(|i| i[1]).reduce(f64::max)?;
        Some([lo, hi])
    }

    fn motion_frame(&self) -> Option<MotionFrame> {
        JawRig::motion_frame(self)
    }

    fn spread(&self) -> Vec<[f64; 3]> {
        self.training_params.clone()
    }

    fn rest_params(&self) -> [f64; 3] {
        self.motion_frame()
            .map_or([0.0; 3], |m| self.encode(m.rest()))
    }
}
