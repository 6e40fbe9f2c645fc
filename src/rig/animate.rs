//! Keyframe animation: key parameter vectors at times, linearly interpolated (the paper's
//! Fig. 16), each frame clamped into the valid ranges.

use serde::{Deserialize, Serialize};

use super::model::JawRig;
use super::three::{ThreeParameterRig, nearest_animator};
use crate::geometry::Pose;

#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq)]
pub struct Key {
    /// Seconds.
    pub time: f64,
    pub params: [f64; 3],
}

/// Why keys cannot be played.
#[derive(Debug, Clone, thiserror::Error, PartialEq)]
pub enum KeyError {
    #[error("at least one key is needed")]
    NoKeys,
    #[error("key {0}: time and parameters must be finite numbers")]
    NotFinite(usize),
    #[error("key {0}: times must increase (key {0} is not after key {prev})", prev = .0 - 1)]
    NotIncreasing(usize),
    #[error("frames per second must be a positive number")]
    BadRate,
    #[error("the rig file has no jaw frame (learned before animator units): learn it again")]
    NoAnatomy,
    #[error("frame {0}: the rig reaches no pose with these degrees and millimetres")]
    Unreachable(u32),
}

/// Parameters at time `t` (held before the first key and after the last).
pub fn params_at(keys: &[Key], t: f64) -> [f64; 3] {
    let Some(first) = keys.first() else {
        return [0.0; 3];
    };
    if t <= first.time {
        return first.params;
    }
    for w in keys.windows(2) {
        let (a, b) = (w[0], w[1]);
        if t <= b.time {
            let f = (t - a.time) / (b.time - a.time);
            return std::array::from_fn(|k| a.params[k] + (b.params[k] - a.params[k]) * f);
        }
    }
    keys[keys.len() - 1].params
}

pub fn check_keys(keys: &[Key], fps: f64) -> Result<(), KeyError> {
    if keys.is_empty() {
        return Err(KeyError::NoKeys);
    }
    if !(fps.is_finite() && fps > 0.0) {
        return Err(KeyError::BadRate);
    }
    for (i, k) in keys.iter().enumerate() {
        if !k.time.is_finite() || k.params.iter().any(|v| !v.is_finite()) {
            return Err(KeyError::NotFinite(i));
        }
        if i > 0 && k.time <= keys[i - 1].time {
            return Err(KeyError::NotIncreasing(i));
        }
    }
    Ok(())
}

/// One frame of the animation.
#[derive(Debug, Clone, Serialize)]
pub struct AnimatedFrame {
    pub frame: u32,
    pub time: f64,
    pub params: [f64; 3],
    /// Whether the interpolated parameters had to be clamped.
    pub clamped: bool,
    #[serde(skip)]
    pub pose: Pose,
}

/// Frames at `fps` from the first key's time to the last's.
pub fn animate(rig: &JawRig, keys: &[Key], fps: f64) -> Result<Vec<AnimatedFrame>, KeyError> {
    check_keys(keys, fps)?;
    let (t0, t1) = (keys[0].time, keys[keys.len() - 1].time);
    let count = ((t1 - t0) * fps).floor() as u32 + 1;
    Ok((0..count)
        .map(|i| {
            let time = t0 + i as f64 / fps;
            let raw = params_at(keys, time);
            let params = rig.clamp(&raw);
            AnimatedFrame {
                frame: i,
                time,
                params,
                clamped: params != raw,
                pose: rig.pose(&params),
            }
        })
        .collect())
}

/// The same with keys in animator units (opening °, lateral mm, protrusion mm): those are
/// interpolated, and each frame's parameters solved for them (from the previous frame's),
/// then clamped. Any three-parameter rig.
pub fn animate_animator<R: ThreeParameterRig + ?Sized>(
    rig: &R,
    keys: &[Key],
    fps: f64,
) -> Result<Vec<AnimatedFrame>, KeyError> {
    check_keys(keys, fps)?;
    let Some(motion) = rig.motion_frame() else {
        return Err(KeyError::NoAnatomy);
    };
    let (t0, t1) = (keys[0].time, keys[keys.len() - 1].time);
    let count = ((t1 - t0) * fps).floor() as u32 + 1;
    let mut previous = None;
    (0..count)
        .map(|i| {
            let time = t0 + i as f64 / fps;
            let target = params_at(keys, time);
            let start = previous.unwrap_or_else(|| rig.rest_params());
            // A rig that poses only valid parameters (the envelope's cube) comes as near as
            // it can: that frame is clamped. Otherwise values it cannot reach are an error.
            let (raw, miss) =
                nearest_animator(rig, &motion, &target, start).ok_or(KeyError::Unreachable(i))?;
            let reached = miss < 1e-3;
            if !reached && !rig.is_valid(&raw) {
                return Err(KeyError::Unreachable(i));
            }
            previous = Some(raw);
            let params = rig.clamp(&raw);
            Ok(AnimatedFrame {
                frame: i,
                time,
                params,
                clamped: params != raw || !reached,
                pose: rig.pose(&params),
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn interpolates_linearly_and_holds_the_ends() {
        let keys = [
            Key {
                time: 1.0,
                params: [0.0, 0.0, 0.0],
            },
            Key {
                time: 2.0,
                params: [0.2, -0.1, 0.0],
            },
            Key {
                time: 4.0,
                params: [0.0, 0.1, 0.04],
            },
        ];
        assert_eq!(params_at(&keys, 0.0), [0.0; 3]);
        let mid = params_at(&keys, 1.5);
        assert!((mid[0] - 0.1).abs() < 1e-12 && (mid[1] + 0.05).abs() < 1e-12);
        let later = params_at(&keys, 3.0);
        assert!(
            (later[0] - 0.1).abs() < 1e-12
                && later[1].abs() < 1e-12
                && (later[2] - 0.02).abs() < 1e-12
        );
        assert_eq!(params_at(&keys, 9.0), [0.0, 0.1, 0.04]);
        assert_eq!(check_keys(&keys, 24.0), Ok(()));
        assert_eq!(
            check_keys(&[keys[1], keys[0]], 24.0),
            Err(KeyError::NotIncreasing(1))
        );
        assert_eq!(check_keys(&[], 24.0), Err(KeyError::NoKeys));
    }
}
