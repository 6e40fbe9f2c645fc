//! The motion of a synthetic face sequence: the five calibration poses first (each held, then
//! released), then a random mixture of opening, excursions and protrusion, with expressions
//! (smile, lips pressed, pucker) keyed independently of the jaw. Deterministic per seed.

use rand::RngExt;
use rand_chacha::ChaCha8Rng;

use crate::anatomy::JawControls;
use crate::skin::format::CalibrationJson;

/// The jaw's controls and the expressions' strengths over the sequence: the five calibration
/// poses (wide open, left, right, forward, backward) in the first 200 frames with a relaxed
/// face, then random keys eased into one another.
pub(super) fn script(
    frames: u32,
    rng: &mut ChaCha8Rng,
) -> (Vec<(JawControls, [f64; 3])>, CalibrationJson) {
    let calibration = CalibrationJson {
        open: 20,
        left: 60,
        right: 100,
        forward: 140,
        backward: 180,
    };
    let mut jaw_keys: Vec<(u32, JawControls)> = calibration_keys().to_vec();
    push_random_jaw_keys(&mut jaw_keys, frames, rng);
    let expr_keys = random_expression_keys(frames, rng);
    let eased = |keys: &[(u32, f64)], f: u32| -> f64 { ease(keys, f, |a, b, e| a + (b - a) * e) };
    let out = (0..frames)
        .map(|f| {
            let c = eased_controls(&jaw_keys, f);
            let e = [
                eased(&expr_keys[0], f),
                eased(&expr_keys[1], f),
                eased(&expr_keys[2], f),
            ];
            (c, e)
        })
        .collect();
    (out, calibration)
}

/// The jaw's keys over the first 200 frames: each calibration pose (at the frames
/// that `script`'s calibration names) between rests.
fn calibration_keys() -> [(u32, JawControls); 12] {
    [
        (0, JawControls::default()),
        (
            20,
            JawControls {
                open: 1.0,
                lateral: 0.0,
                protrusion: 0.0,
            },
        ),
        (40, JawControls::default()),
        (
            60,
            JawControls {
                open: 0.08,
                lateral: 1.0,
                protrusion: 0.0,
            },
        ),
        (80, JawControls::default()),
        (
            100,
            JawControls {
                open: 0.08,
                lateral: -1.0,
                protrusion: 0.0,
            },
        ),
        (120, JawControls::default()),
        (
            140,
            JawControls {
                open: 0.03,
                lateral: 0.0,
                protrusion: 1.0,
            },
        ),
        (160, JawControls::default()),
        // "Backward": the jaw held retruded, the teeth apart (the joint model does not
        // retrude past the rest bite).
        (
            180,
            JawControls {
                open: 0.15,
                lateral: 0.0,
                protrusion: 0.0,
            },
        ),
        (195, JawControls::default()),
        (200, JawControls::default()),
    ]
}

/// Random jaw keys after frame 200 up to `frames`, appended to `keys`.
fn push_random_jaw_keys(keys: &mut Vec<(u32, JawControls)>, frames: u32, rng: &mut ChaCha8Rng) {
    let mut t = 200;
    while t < frames {
        t += rng.random_range(8..30);
        let open = rng.random_range(0.0f64..1.0).powf(1.6);
        let lateral = rng.random_range(-0.8..0.8) * (1.0 - open * 0.7);
        let protrusion = rng.random_range(0.0f64..0.8).powi(2);
        keys.push((
            t,
            JawControls {
                open,
                lateral,
                protrusion,
            },
        ));
    }
}

/// Each expression's keys: relaxed over the first 200 frames, then randomly on (at a random
/// strength) or off up to `frames`.
fn random_expression_keys(frames: u32, rng: &mut ChaCha8Rng) -> [Vec<(u32, f64)>; 3] {
    let mut expr_keys: [Vec<(u32, f64)>; 3] = Default::default();
    for keys in &mut expr_keys {
        keys.push((0, 0.0));
        keys.push((200, 0.0));
        let mut t = 200;
        while t < frames {
            t += rng.random_range(15..60);
            let on = rng.random_range(0.0..1.0) < 0.45;
            keys.push((t, if on { rng.random_range(0.3..1.0) } else { 0.0 }));
        }
    }
    expr_keys
}

/// The jaw's controls at frame `f`, eased between `keys`.
fn eased_controls(keys: &[(u32, JawControls)], f: u32) -> JawControls {
    ease(keys, f, |a: JawControls, b: JawControls, e| JawControls {
        open: a.open + (b.open - a.open) * e,
        lateral: a.lateral + (b.lateral - a.lateral) * e,
        protrusion: a.protrusion + (b.protrusion - a.protrusion) * e,
    })
}

/// The value at frame `f` of keys eased (cosine) from one to the next.
fn ease<T: Copy>(keys: &[(u32, T)], f: u32, lerp: impl Fn(T, T, f64) -> T) -> T {
    let i = keys.iter().rposition(|k| k.0 <= f).unwrap_or(0);
    let Some(next) = keys.get(i + 1) else {
        return keys[i].1;
    };
    let x = (f - keys[i].0) as f64 / (next.0 - keys[i].0).max(1) as f64;
    lerp(
        keys[i].1,
        next.1,
        0.5 - 0.5 * (std::f64::consts::PI * x).cos(),
    )
}
