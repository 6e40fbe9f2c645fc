//! The exercise a synthetic subject performs: keyed controls of the joint model
//! ([`crate::anatomy::JawModel`]) played smoothly over the capture.

use crate::anatomy::JawControls;

/// The exercise a subject is asked to perform, as keyed controls (open, lateral, protrusion),
/// played smoothly (cosine easing between keys). The first `CORE_SEGMENTS` segments reach the
/// whole range (wide opening, left, right, protrusion); the rest combine them.
const EXERCISE: [(f64, f64, f64); 18] = [
    (0.0, 0.0, 0.0),
    (1.0, 0.0, 0.0), // open wide
    (0.0, 0.0, 0.0),
    (0.08, 1.0, 0.0), // left excursion
    (0.0, 0.0, 0.0),
    (0.08, -1.0, 0.0), // right excursion
    (0.0, 0.0, 0.0),
    (0.03, 0.0, 1.0), // protrusion
    (0.0, 0.0, 0.0),  // end of the core exercise
    (0.45, 0.0, 0.6), // open while protruded
    (0.0, 0.0, 0.0),
    (0.6, 0.6, 0.0), // open to the left
    (0.3, 0.0, 0.0),
    (0.6, -0.6, 0.0), // open to the right
    (0.0, 0.0, 0.0),
    (0.5, 0.0, 0.0), // half open, chewing-like
    (0.15, 0.3, 0.2),
    (0.0, 0.0, 0.0),
];

/// Segments of the core exercise, and of the whole one.
pub const CORE_SEGMENTS: usize = 8;
pub const ALL_SEGMENTS: usize = EXERCISE.len() - 1;
/// The default pace: frames a segment takes at least (see `SynthOptions::frames_per_segment`).
pub const FRAMES_PER_SEGMENT: u32 = 20;

/// Controls at time `tau` in [0, 1] over the capture, playing the first `segments` segments
/// (a fraction ends within one; at most the whole exercise) `repeats` times. `gain` scales
/// each control's amplitude per subject (e.g. 0.95..1.0 so that seeds differ).
pub fn exercise_controls(tau: f64, segments: f64, repeats: u32, gain: &[f64; 3]) -> JawControls {
    let keys = segments.clamp(0.0, ALL_SEGMENTS as f64);
    let x =
        (tau.clamp(0.0, 1.0) * repeats.max(1) as f64).fract() + if tau >= 1.0 { 1.0 } else { 0.0 };
    let pos = (x * keys).min(keys);
    let i = (pos.floor() as usize).min(ALL_SEGMENTS - 1);
    let f = pos - i as f64;
    let ease = 0.5 - 0.5 * (std::f64::consts::PI * f).cos();
    let (a, b) = (EXERCISE[i], EXERCISE[i + 1]);
    let lerp = |p: f64, q: f64| p + (q - p) * ease;
    JawControls {
        open: lerp(a.0, b.0) * gain[0],
        lateral: lerp(a.1, b.1) * gain[1],
        protrusion: lerp(a.2, b.2) * gain[2],
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_exercise_starts_and_ends_at_rest_and_is_smooth() {
        let g = [1.0; 3];
        for segments in [CORE_SEGMENTS, ALL_SEGMENTS] {
            assert_eq!(
                exercise_controls(0.0, segments as f64, 1, &g),
                JawControls::default()
            );
            assert_eq!(
                exercise_controls(1.0, segments as f64, 1, &g),
                JawControls::default()
            );
        }
        // The core reaches the whole range: wide open, both sides, protrusion.
        let core: Vec<JawControls> = (0..=800)
            .map(|k| exercise_controls(k as f64 / 800.0, CORE_SEGMENTS as f64, 1, &g))
            .collect();
        assert!(core.iter().any(|c| c.open > 0.99) && core.iter().any(|c| c.protrusion > 0.99));
        assert!(core.iter().any(|c| c.lateral > 0.99) && core.iter().any(|c| c.lateral < -0.99));
        let mut prev = exercise_controls(0.0, ALL_SEGMENTS as f64, 1, &g);
        for k in 1..=2000 {
            let c = exercise_controls(k as f64 / 2000.0, ALL_SEGMENTS as f64, 1, &g);
            assert!((c.open - prev.open).abs() < 0.03 && (c.lateral - prev.lateral).abs() < 0.05);
            prev = c;
        }
    }
}
