//! The rest bite: where the lower arch sits against the upper one with the teeth closed.

use nalgebra::Vector3;

use crate::geometry::Pose;
use crate::mesh::Mesh;

/// The rest bite of two arches given each in its own frame: `upper_from_lower` at rest.
/// Midlines aligned in x; the lower incisors 2.5 mm behind the upper ones (overjet); then the
/// lower arch raised until its crowns first touch the upper crowns (found on a 1 mm grid in
/// the occlusal plane), less 1 mm of cusp interdigitation.
pub fn rest_bite(upper: &Mesh, lower: &Mesh) -> Pose {
    const OVERJET_MM: f64 = 2.5;
    const INTERDIGITATION_MM: f64 = 1.0;
    let (ulo, uhi) = upper.bounds();
    let (llo, lhi) = lower.bounds();
    let dx = ((ulo[0] + uhi[0]) - (llo[0] + lhi[0])) as f64 * 0.5;
    let dz = (uhi[2] - lhi[2]) as f64 - OVERJET_MM;
    let cell = |x: f64, z: f64| ((x.floor() as i64), (z.floor() as i64));
    let mut upper_low = std::collections::HashMap::new();
    for p in &upper.positions {
        let e = upper_low
            .entry(cell(p[0] as f64, p[2] as f64))
            .or_insert(f64::INFINITY);
        *e = f64::min(*e, p[1] as f64);
    }
    let mut gap = f64::INFINITY;
    for p in &lower.positions {
        if let Some(&u) = upper_low.get(&cell(p[0] as f64 + dx, p[2] as f64 + dz)) {
            gap = gap.min(u - p[1] as f64);
        }
    }
    if !gap.is_finite() {
        // No overlap in plan view: put the tips level.
        gap = (ulo[1] - lhi[1]) as f64;
    }
    Pose::from_translation(Vector3::new(dx, gap + INTERDIGITATION_MM, dz))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::anatomy::procedural_arch;

    #[test]
    fn rest_bite_puts_the_lower_arch_below_and_behind() {
        let (u, l) = (procedural_arch(true), procedural_arch(false));
        let rest = rest_bite(&u, &l);
        let t = rest.translation;
        assert!(t.y < -5.0 && t.y > -12.0, "{t:?}");
        let (_, uhi) = u.bounds();
        let (_, lhi) = l.bounds();
        assert!((lhi[2] as f64 + t.z - (uhi[2] as f64 - 2.5)).abs() < 1e-6);
    }
}
