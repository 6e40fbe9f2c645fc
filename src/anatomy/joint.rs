//! A model of the temporomandibular joint (in the upper arch's frame: y up,
//! +z anterior, +x the subject's left). Each condyle slides along a curved articular eminence;
//! the mandible rotates about the hinge axis through the two condyles wherever they are.
//! Lateral excursion comes from the balancing-side condyle advancing while the working-side
//! one stays; opening past the first degrees (pure hinge rotation) forces condylar travel.

use nalgebra::{Rotation3, Unit, Vector3};

use crate::geometry::Pose;
use crate::mesh::Mesh;

/// The three intuitive controls: opening in [0, 1], lateral excursion in [−1, 1]
/// (+1: the chin to the subject's left), protrusion in [0, 1].
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct JawControls {
    pub open: f64,
    pub lateral: f64,
    pub protrusion: f64,
}

/// A joint's shape, placed relative to the upper arch's incisal edge and midline.
struct JointSpec {
    half_width_mm: f64,
    above_mm: f64,
    behind_mm: f64,
    eminence_height_mm: f64,
    eminence_length_mm: f64,
    max_opening_deg: f64,
    hinge_only_deg: f64,
    opening_travel_mm: f64,
    protrusion_travel_mm: f64,
    lateral_travel_mm: f64,
}

const AVERAGE: JointSpec = JointSpec {
    half_width_mm: 50.0,
    above_mm: 25.0,
    behind_mm: 88.0,
    eminence_height_mm: 7.0,
    eminence_length_mm: 20.0,
    max_opening_deg: 30.0,
    hinge_only_deg: 6.0,
    opening_travel_mm: 16.0,
    protrusion_travel_mm: 11.0,
    lateral_travel_mm: 11.5,
};

const VARIANT: JointSpec = JointSpec {
    half_width_mm: 47.0,
    above_mm: 21.0,
    behind_mm: 82.0,
    eminence_height_mm: 9.0,
    eminence_length_mm: 16.0,
    max_opening_deg: 26.0,
    hinge_only_deg: 9.0,
    opening_travel_mm: 13.0,
    protrusion_travel_mm: 9.0,
    lateral_travel_mm: 10.0,
};

#[derive(Debug, Clone)]
pub struct JawModel {
    /// Condyle centres at rest, upper-arch frame; left is +x.
    pub condyle_left: Vector3<f64>,
    pub condyle_right: Vector3<f64>,
    /// The articular eminence: height of the descent and its forward length (mm).
    pub eminence_height_mm: f64,
    pub eminence_length_mm: f64,
    /// Hinge rotation at full opening, and the part of it with no condylar travel (rad).
    pub max_opening_rad: f64,
    pub hinge_only_rad: f64,
    /// Condylar travel (mm, forward) at full opening, full protrusion and, for the balancing
    /// condyle, full lateral excursion.
    pub opening_travel_mm: f64,
    pub protrusion_travel_mm: f64,
    pub lateral_travel_mm: f64,
    /// `upper_from_lower` in the rest bite.
    pub rest: Pose,
}

impl JawModel {
    /// An average adult joint placed from the upper arch: condyles 100 mm apart, 88 mm behind
    /// and 25 mm above the upper incisal edge; a 7 mm high, 20 mm long eminence.
    pub fn for_arches(upper: &Mesh, rest: Pose) -> JawModel {
        Self::from_spec(upper, rest, &AVERAGE)
    }

    /// A second subject whose joint differs: condyles closer together (94 mm), further forward
    /// and lower; a steeper, shorter eminence (9 mm over 16 mm); less opening (26°) with more
    /// hinge-only rotation, shorter travels.
    pub fn variant_for_arches(upper: &Mesh, rest: Pose) -> JawModel {
        Self::from_spec(upper, rest, &VARIANT)
    }

    fn from_spec(upper: &Mesh, rest: Pose, j: &JointSpec) -> JawModel {
        let (lo, hi) = upper.bounds();
        let mid_x = (lo[0] + hi[0]) as f64 * 0.5;
        let y = lo[1] as f64 + j.above_mm;
        let z = hi[2] as f64 - j.behind_mm;
        JawModel {
            condyle_left: Vector3::new(mid_x + j.half_width_mm, y, z),
            condyle_right: Vector3::new(mid_x - j.half_width_mm, y, z),
            eminence_height_mm: j.eminence_height_mm,
            eminence_length_mm: j.eminence_length_mm,
            max_opening_rad: j.max_opening_deg.to_radians(),
            hinge_only_rad: j.hinge_only_deg.to_radians(),
            opening_travel_mm: j.opening_travel_mm,
            protrusion_travel_mm: j.protrusion_travel_mm,
            lateral_travel_mm: j.lateral_travel_mm,
            rest,
        }
    }

    /// A condyle `s` mm forward along the eminence from `rest`: down by
    /// H·(1 − cos(π s / L)) / 2, an S-shaped slope steepest half-way.
    pub fn condyle_on_path(&self, rest: &Vector3<f64>, s: f64) -> Vector3<f64> {
        let s = s.clamp(0.0, self.eminence_length_mm);
        let drop = self.eminence_height_mm
            * (1.0 - (std::f64::consts::PI * s / self.eminence_length_mm).cos())
            * 0.5;
        rest + Vector3::new(0.0, -drop, s)
    }

    /// Condylar travel (left, right) and hinge rotation for the controls.
    pub fn joint_state(&self, c: &JawControls) -> (f64, f64, f64) {
        let open = c.open.clamp(0.0, 1.0);
        let prot = c.protrusion.clamp(0.0, 1.0);
        let lat = c.lateral.clamp(-1.0, 1.0);
        let hinge = open * self.max_opening_rad;
        let translating =
            ((hinge - self.hinge_only_rad) / (self.max_opening_rad - self.hinge_only_rad)).max(0.0);
        let s_open = self.opening_travel_mm * translating;
        let s_common = s_open + prot * self.protrusion_travel_mm;
        // Moving the chin to the left (+x) advances the right (balancing) condyle.
        let s_left = s_common + (-lat).max(0.0) * self.lateral_travel_mm;
        let s_right = s_common + lat.max(0.0) * self.lateral_travel_mm;
        // A little extra opening keeps the teeth apart in excursions (incisal guidance).
        let angle = hinge + (prot * 3.0 + lat.abs() * 1.5).to_radians();
        (s_left, s_right, angle)
    }

    /// The motion of the mandible (points in the upper frame at rest → now).
    pub fn mandible_motion(&self, c: &JawControls) -> Pose {
        let (s_left, s_right, angle) = self.joint_state(c);
        let p_left = self.condyle_on_path(&self.condyle_left, s_left);
        let p_right = self.condyle_on_path(&self.condyle_right, s_right);
        let axis0 = (self.condyle_left - self.condyle_right).normalize();
        let axis = (p_left - p_right).normalize();
        let align = Rotation3::rotation_between(&axis0, &axis).unwrap_or_else(Rotation3::identity);
        // Opening turns the chin down: a positive rotation about the left-pointing (+x) axis
        // takes +z (anterior) towards −y.
        let open = Rotation3::from_axis_angle(&Unit::new_normalize(axis), angle);
        let rotation = open * align;
        let mid0 = (self.condyle_left + self.condyle_right) * 0.5;
        let mid = (p_left + p_right) * 0.5;
        Pose::new(rotation, mid - rotation * mid0)
    }

    /// The jaw pose `upper_from_lower` for the controls.
    pub fn jaw_pose(&self, c: &JawControls) -> Pose {
        self.mandible_motion(c).compose(&self.rest)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::anatomy::{procedural_arch, rest_bite};

    fn model_and_incisor() -> (JawModel, Vector3<f64>) {
        let (u, l) = (procedural_arch(true), procedural_arch(false));
        let rest = rest_bite(&u, &l);
        let (llo, lhi) = l.bounds();
        let incisor = Vector3::new((llo[0] + lhi[0]) as f64 * 0.5, lhi[1] as f64, lhi[2] as f64);
        (JawModel::for_arches(&u, rest), incisor)
    }

    /// Displacement of the lower incisal point from rest, upper frame.
    fn incisal_motion(m: &JawModel, inc: &Vector3<f64>, c: JawControls) -> Vector3<f64> {
        m.jaw_pose(&c).transform_point(inc) - m.rest.transform_point(inc)
    }

    #[test]
    fn ranges_match_the_literature() {
        let (m, inc) = model_and_incisor();
        let open = incisal_motion(
            &m,
            &inc,
            JawControls {
                open: 1.0,
                ..Default::default()
            },
        );
        // Maximum incisal opening ~45-50 mm.
        assert!(-open.y > 42.0 && -open.y < 53.0, "opening {open:?}");
        let left = incisal_motion(
            &m,
            &inc,
            JawControls {
                lateral: 1.0,
                ..Default::default()
            },
        );
        assert!(left.x > 8.0 && left.x < 12.0, "lateral {left:?}");
        let prot = incisal_motion(
            &m,
            &inc,
            JawControls {
                protrusion: 1.0,
                ..Default::default()
            },
        );
        assert!(prot.z > 7.0 && prot.z < 11.0, "protrusion {prot:?}");
        let (sl, sr, _) = m.joint_state(&JawControls {
            open: 1.0,
            ..Default::default()
        });
        assert!(
            (15.0..=20.0).contains(&sl.max(sr)),
            "condylar travel {sl} {sr}"
        );
    }

    #[test]
    fn first_degrees_of_opening_are_pure_hinge_rotation() {
        let (m, _) = model_and_incisor();
        let small = JawControls {
            open: 0.2,
            ..Default::default()
        };
        let (sl, sr, angle) = m.joint_state(&small);
        assert!(angle < m.hinge_only_rad && sl == 0.0 && sr == 0.0);
        // The condyles stay put: the motion fixes both condyle centres.
        let mm = m.mandible_motion(&small);
        assert!((mm.transform_point(&m.condyle_left) - m.condyle_left).norm() < 1e-9);
    }
}
