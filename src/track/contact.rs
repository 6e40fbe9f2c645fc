//! The arches cannot pass through each other. When the mouth closes, a lower arch turned a
//! few degrees too far hides its incisors behind the upper ones and fits the masks about as
//! well as the true pose while reaching millimetres into the upper arch, which a true pose
//! never does (docs/tracking.md), so the search adds a penalty for jaw poses that put the
//! lower crowns into the upper ones.
//!
//! The test is a height map: along the occlusal axis (the upper arch's thinnest direction,
//! pointing away from the lower arch), the lowest point of the upper arch in each 0.5 mm
//! column; a lower-arch point above it has passed through. Depth is that overshoot for the
//! deepest few points (a single stray vertex does not count).

use nalgebra::Vector3;

use crate::geometry::Pose;
use crate::mesh::Mesh;

/// Column width of the height map (mm), and the most columns along a side (a mesh with stray
/// vertices far away gets wider columns, not a huge map).
const CELL_MM: f64 = 0.5;
const MAX_COLUMNS: f64 = 2000.0;
/// Lower-arch points tested per evaluation, at most (a stride through the vertices).
const MAX_POINTS: usize = 4000;
/// Depth is that of the `DEEPEST`-th deepest point.
const DEEPEST: usize = 5;

/// What the penalty costs: `weight` objective units (pixels) per mm of depth beyond
/// `tolerance_mm`.
#[derive(Debug, Clone, Copy)]
pub struct ContactSettings {
    pub weight: f64,
    pub tolerance_mm: f64,
}

/// The upper arch's height map and the lower arch's test points, both in model frames.
#[derive(Debug, Clone)]
pub struct Contact {
    /// Occlusal axis (unit, upper model frame, pointing away from the lower arch) and two
    /// axes across it.
    axis: Vector3<f64>,
    across: [Vector3<f64>; 2],
    /// Grid origin (in `across` coordinates), column width and size.
    origin: [f64; 2],
    cell_mm: f64,
    size: [usize; 2],
    /// Lowest height along `axis` per column; +inf where the upper arch has no point.
    lowest: Vec<f64>,
    points: Vec<Vector3<f64>>,
    weight: f64,
    tolerance_mm: f64,
}

impl Contact {
    /// `jaw` (upper_from_lower) is any pose the capture shows, to tell which side of the upper
    /// arch the lower one is on; the tolerance is raised to its depth plus 0.5 mm when that
    /// is deeper (meshes that already overlap there, e.g. a scan's bite registration).
    pub fn new(upper: &Mesh, lower: &Mesh, jaw: &Pose, settings: ContactSettings) -> Contact {
        let (upper_mean, axes) = upper.principal_axes();
        let (lower_mean, _) = lower.principal_axes();
        let mut axis = axes[0];
        if axis.dot(&(upper_mean - jaw.transform_point(&lower_mean))) < 0.0 {
            axis = -axis;
        }
        let across = [axes[1], axes[2]];

        let plane = |p: &Vector3<f64>| [p.dot(&across[0]), p.dot(&across[1])];
        let mut lo = [f64::INFINITY; 2];
        let mut hi = [f64::NEG_INFINITY; 2];
        for p in upper.points() {
            let q = plane(&p);
            for k in 0..2 {
                lo[k] = lo[k].min(q[k]);
                hi[k] = hi[k].max(q[k]);
            }
        }
        let cell_mm = CELL_MM.max((hi[0] - lo[0]).max(hi[1] - lo[1]) / MAX_COLUMNS);
        let size = if lo[0].is_finite() {
            [0, 1].map(|k| ((hi[k] - lo[k]) / cell_mm) as usize + 1)
        } else {
            [0, 0]
        };
        let mut contact = Contact {
            axis,
            across,
            origin: lo,
            cell_mm,
            size,
            lowest: vec![f64::INFINITY; size[0] * size[1]],
            points: Vec::new(),
            weight: settings.weight,
            tolerance_mm: settings.tolerance_mm,
        };
        for p in upper.points() {
            if let Some(i) = contact.cell(&p) {
                contact.lowest[i] = contact.lowest[i].min(p.dot(&axis));
            }
        }
        let stride = lower.positions.len().div_ceil(MAX_POINTS).max(1);
        contact.points = lower.points().step_by(stride).collect();
        let start = contact.depth(jaw);
        if start + 0.5 > contact.tolerance_mm {
            contact.tolerance_mm = start + 0.5;
        }
        contact
    }

    /// The column of a point in the upper model frame, if over the grid.
    fn cell(&self, p: &Vector3<f64>) -> Option<usize> {
        self.column([p.dot(&self.across[0]), p.dot(&self.across[1])])
    }

    /// The column at `plane` (a point's coordinates along `across`), if over the grid.
    fn column(&self, plane: [f64; 2]) -> Option<usize> {
        let index = |k: usize| {
            // Truncation is the floor from zero up, and below zero is off the grid.
            let c = (plane[k] - self.origin[k]) / self.cell_mm;
            (c >= 0.0 && c < self.size[k] as f64).then_some(c as usize)
        };
        Some(index(0)? * self.size[1] + index(1)?)
    }

    /// How far (mm) the lower arch reaches past the upper arch's surface at this jaw pose
    /// (upper_from_lower); negative: that far apart.
    pub fn depth(&self, jaw: &Pose) -> f64 {
        // The DEEPEST deepest so far, deepest first (no allocation: this runs per candidate).
        let mut deepest = [f64::NEG_INFINITY; DEEPEST];
        let mut seen = 0;
        // Only the moved points' coordinates along the map's three axes are read: each is
        // the point's own along the axis carried back by the jaw, plus the jaw's shift.
        let along =
            |axis: &Vector3<f64>| (jaw.rotation.transpose() * axis, axis.dot(&jaw.translation));
        let (height, across) = (along(&self.axis), self.across.each_ref().map(along));
        for p in &self.points {
            let plane = across.map(|(a, shift)| a.dot(p) + shift);
            let Some(lowest) = self.column(plane).map(|i| self.lowest[i]) else {
                continue;
            };
            if !lowest.is_finite() {
                continue;
            }
            seen += 1;
            let d = height.0.dot(p) + height.1 - lowest;
            if d > deepest[DEEPEST - 1] {
                let at = deepest.partition_point(|&x| x >= d);
                deepest.copy_within(at..DEEPEST - 1, at + 1);
                deepest[at] = d;
            }
        }
        match seen {
            0 => f64::NEG_INFINITY,
            n => deepest[n.min(DEEPEST) - 1],
        }
    }

    /// The objective's penalty for this jaw pose (upper_from_lower): `weight` per mm of depth
    /// past the tolerance.
    pub fn penalty(&self, jaw: &Pose) -> f64 {
        if self.weight == 0.0 {
            return 0.0;
        }
        self.weight * (self.depth(jaw) - self.tolerance_mm).max(0.0)
    }

    /// The tolerance in force (the setting, or more: see [`Contact::new`]).
    pub fn tolerance_mm(&self) -> f64 {
        self.tolerance_mm
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::anatomy::{procedural_arch, rest_bite};
    use crate::arch::ArchPoses;

    const SETTINGS: ContactSettings = ContactSettings {
        weight: 100.0,
        tolerance_mm: 1.0,
    };

    fn setup() -> (Contact, Pose) {
        let (upper, lower) = (procedural_arch(true), procedural_arch(false));
        let rest = rest_bite(&upper, &lower);
        (Contact::new(&upper, &lower, &rest, SETTINGS), rest)
    }

    /// The jaw moved `mm` along the occlusal axis, towards the upper arch.
    fn raised(contact: &Contact, rest: &Pose, mm: f64) -> Pose {
        Pose::from_translation(contact.axis * mm).compose(rest)
    }

    #[test]
    fn the_occlusal_axis_points_from_the_lower_arch_to_the_upper() {
        // The procedural arches are built with y up (a 3 degree curve tilts the thinnest axis).
        let (contact, _) = setup();
        assert!(contact.axis.y > 0.99, "{:?}", contact.axis);
    }

    #[test]
    fn depth_grows_as_the_lower_arch_rises_into_the_upper() {
        let (contact, rest) = setup();
        let at_rest = contact.depth(&rest);
        // The rest bite interdigitates by 1 mm on a 1 mm grid; on 0.5 mm columns a little less.
        assert!(at_rest > 0.0 && at_rest < 1.0, "{at_rest}");
        for mm in [1.0, 2.5, 4.0, -6.0] {
            let d = contact.depth(&raised(&contact, &rest, mm));
            assert!((d - (at_rest + mm)).abs() < 1e-6, "{mm}: {d}");
        }
        // Beside the upper arch (no column above): nothing to pass through.
        let aside = Pose::from_translation(Vector3::new(200.0, 0.0, 0.0)).compose(&rest);
        assert_eq!(contact.depth(&aside), f64::NEG_INFINITY);
    }

    #[test]
    fn the_penalty_starts_past_the_tolerance() {
        let (contact, rest) = setup();
        assert_eq!(contact.penalty(&rest), 0.0);
        let at_rest = contact.depth(&rest);
        let p = contact.penalty(&raised(&contact, &rest, 3.0));
        assert!((p - 100.0 * (at_rest + 3.0 - 1.0)).abs() < 1e-6, "{p}");
        // The jaw is what counts: both arches moved together change nothing.
        let shift = Pose::from_translation(Vector3::new(5.0, -3.0, 2.0));
        let moved = ArchPoses {
            upper: shift,
            lower: shift.compose(&raised(&contact, &rest, 3.0)),
        };
        let penalties = super::super::penalties::Penalties {
            contact: Some(contact),
            manifold: None,
        };
        assert!((penalties.of(&moved) - p).abs() < 1e-6);
    }

    #[test]
    fn a_stray_vertex_far_away_widens_the_columns_instead_of_the_map() {
        let (mut upper, lower) = (procedural_arch(true), procedural_arch(false));
        let rest = rest_bite(&upper, &lower);
        upper.positions.push([100_000.0, 0.0, 0.0]);
        let contact = Contact::new(&upper, &lower, &rest, SETTINGS);
        assert!(
            contact.size.iter().all(|&n| n <= 2001),
            "{:?}",
            contact.size
        );
        assert!(contact.cell_mm > 40.0);
        assert!(contact.depth(&rest).is_finite());
    }

    #[test]
    fn a_start_deeper_than_the_tolerance_raises_it() {
        let (upper, lower) = (procedural_arch(true), procedural_arch(false));
        let (contact, rest) = setup();
        let deep = raised(&contact, &rest, 2.0);
        let from_deep = Contact::new(&upper, &lower, &deep, SETTINGS);
        let d = from_deep.depth(&deep);
        assert!(d > 2.0, "{d}");
        assert!((from_deep.tolerance_mm() - (d + 0.5)).abs() < 1e-9);
        assert_eq!(contact.tolerance_mm(), 1.0);
    }
}
