//! Jaw motion in the units animators and biomechanists use: zero at the rest bite, opening in
//! degrees about the condylar (lateral) axis, and the lower incisal point's travel in mm:
//! downwards (opening), to the subject's left (lateral) and forwards (protrusion).
//!
//! The axes are the jaw frame's (Zoss et al. 2018: x from the right to the left condyle, z
//! towards the lower incisal point, y up) at the rest bite; the network coordinates of the
//! rigs stay inside the rigs.

use nalgebra::{Matrix3, Vector3};

use super::JawFrame;
use crate::geometry::Pose;

/// One jaw pose in anatomical units.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Anatomical {
    /// Rotation about the lateral axis, chin down positive (degrees).
    pub opening_deg: f64,
    /// The incisal point's travel from the rest bite (mm): down, to the left, forwards.
    pub incisal_opening_mm: f64,
    pub lateral_mm: f64,
    pub protrusion_mm: f64,
}

/// The reference a motion is measured from: the jaw frame's landmarks (lower frame) and the
/// rest bite (`upper_from_lower`).
#[derive(Debug, Clone)]
pub struct MotionFrame {
    incisal: Vector3<f64>,
    /// The jaw frame's axes at rest, in the upper frame (columns x, y, z).
    axes: Matrix3<f64>,
    rest: Pose,
}

impl MotionFrame {
    pub fn new(frame: &JawFrame, rest: Pose) -> MotionFrame {
        let local = frame
            .axes()
            .map(|r| *r.matrix())
            .unwrap_or_else(|_| Matrix3::identity());
        MotionFrame {
            incisal: Vector3::from(frame.reference),
            axes: rest.rotation.matrix() * local,
            rest,
        }
    }

    /// The rest bite: of `jaws`, the one whose incisal point sits highest along the jaw
    /// frame's up axis (the most closed), measured in the first pose's frame.
    pub fn most_closed(frame: &JawFrame, jaws: &[Pose]) -> Option<usize> {
        let first = MotionFrame::new(frame, *jaws.first()?);
        let up = first.axes.column(1).into_owned();
        let height = |j: &Pose| j.transform_point(&first.incisal).dot(&up);
        // The first of equals: the earliest frame at the bite.
        let mut best = (0, height(&jaws[0]));
        for (i, j) in jaws.iter().enumerate().skip(1) {
            if height(j) > best.1 {
                best = (i, height(j));
            }
        }
        Some(best.0)
    }

    pub fn rest(&self) -> &Pose {
        &self.rest
    }

    /// The incisal point (lower frame), the jaw frame's reference point.
    pub fn incisal_point(&self) -> Vector3<f64> {
        self.incisal
    }

    /// `upper_from_lower` in anatomical units.
    pub fn measure(&self, jaw: &Pose) -> Anatomical {
        let d = jaw.transform_point(&self.incisal) - self.rest.transform_point(&self.incisal);
        let [x, y, z] = [0, 1, 2].map(|k| self.axes.column(k).into_owned());
        let relative = jaw.rotation.matrix() * self.rest.rotation.matrix().transpose();
        let m = self.axes.transpose() * relative * self.axes;
        Anatomical {
            opening_deg: m[(2, 1)].atan2(m[(1, 1)]).to_degrees(),
            incisal_opening_mm: -d.dot(&y),
            lateral_mm: d.dot(&x),
            protrusion_mm: d.dot(&z),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Rotation3;

    fn frame() -> JawFrame {
        JawFrame {
            condyle_left: [50.0, 20.0, -80.0],
            condyle_right: [-50.0, 20.0, -80.0],
            reference: [0.0, 0.0, 0.0],
        }
    }

    #[test]
    fn a_hinge_rotation_reads_as_opening() {
        let rest = Pose::from_translation(Vector3::new(0.0, -2.0, -1.0));
        let m = MotionFrame::new(&frame(), rest);
        assert_eq!(m.measure(&rest).opening_deg, 0.0);
        // 10° about the condyle axis, chin down: the incisal point goes down and back.
        let origin = Vector3::new(0.0, 20.0, -80.0);
        let hinge = Rotation3::from_axis_angle(&Vector3::x_axis(), 10f64.to_radians());
        let about = Pose::new(hinge, origin - hinge * origin);
        let open = about.compose(&rest);
        let a = m.measure(&open);
        assert!((a.opening_deg - 10.0).abs() < 1e-9, "{a:?}");
        assert!(
            a.incisal_opening_mm > 10.0 && a.protrusion_mm < 0.0,
            "{a:?}"
        );
        assert!(a.lateral_mm.abs() < 1e-9);
        // A 3 mm slide to the subject's left.
        let left = Pose::from_translation(Vector3::new(3.0, 0.0, 0.0)).compose(&rest);
        assert!((m.measure(&left).lateral_mm - 3.0).abs() < 1e-12);
        let picked = MotionFrame::most_closed(&frame(), &[open, rest, left]);
        assert_eq!(picked, Some(1));
    }
}
