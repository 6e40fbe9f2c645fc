//! The tracked motion an export writes: the frames with a pose (their jaw checked against
//! their arches and the capture), the rest bite they are measured from, and the anatomical
//! ranges they span.

use std::path::Path;

use crate::anatomy::motion::{Anatomical, MotionFrame};
use crate::capture::Capture;
use crate::envelope::JawFrame;
use crate::error::{Error, Result};
use crate::formats::{Status, TracksJson};
use crate::geometry::Pose;

/// One exported frame: its number, its status and its jaw pose (`upper_from_lower`).
#[derive(Debug, Clone, Copy)]
pub struct MotionKey {
    pub frame: u32,
    pub status: Status,
    pub jaw: Pose,
}

/// What an export writes.
#[derive(Debug, Clone)]
pub struct TrackedMotion {
    /// By frame number; no-data frames left out.
    pub keys: Vec<MotionKey>,
    /// The index in `keys` of the rest bite.
    pub rest: usize,
    /// The jaw frame at the rest bite: what the anatomical units are measured in.
    pub motion: MotionFrame,
}

/// The motion of `tracks` (read from `tracks_path`) in `capture`. The rest bite is
/// `rest_frame`, or else the `ok` frame (any frame, if none is `ok`) with the lower incisal
/// point highest.
pub fn tracked_motion(
    capture: &Capture,
    tracks: &TracksJson,
    tracks_path: &Path,
    rest_frame: Option<u32>,
) -> Result<TrackedMotion> {
    let mut keys = Vec::new();
    let last = capture.first_frame() as u64 + capture.frame_count() as u64;
    for f in &tracks.frames {
        if f.status() == Status::NoData {
            continue;
        }
        let jaw = f.checked_jaw(tracks_path)?;
        if (f.frame as u64) < capture.first_frame() as u64 || f.frame as u64 >= last {
            return Err(Error::invalid(
                tracks_path,
                format!("frame {}", f.frame),
                format!(
                    "the capture has frames {} to {}",
                    capture.first_frame(),
                    last.saturating_sub(1)
                ),
            ));
        }
        keys.push(MotionKey {
            frame: f.frame,
            status: f.status(),
            jaw,
        });
    }
    keys.sort_by_key(|k| k.frame);
    if keys.is_empty() {
        return Err(Error::invalid(
            tracks_path,
            "frames",
            "no frame with a pose (all no-data)",
        ));
    }
    // The jaw frame from the mandible's condyles when the capture has one; else the lower
    // arch's last molars stand in for them (the axes, all that is used, come out the same).
    let landmarks_on = capture.mandible().unwrap_or(capture.lower());
    let landmarks = JawFrame::from_mesh(landmarks_on, None, None).map_err(|e| {
        Error::invalid(
            capture.dir().join("capture.json"),
            "meshes",
            format!("the jaw frame's landmarks: {e}"),
        )
    })?;
    let rest = match rest_frame {
        Some(n) => keys.iter().position(|k| k.frame == n).ok_or_else(|| {
            Error::invalid(
                tracks_path,
                "frames",
                format!("--rest-frame {n}: no such frame with a pose"),
            )
        })?,
        None => {
            let ok: Vec<usize> = (0..keys.len())
                .filter(|&i| keys[i].status == Status::Ok)
                .collect();
            let pool = if ok.is_empty() {
                (0..keys.len()).collect()
            } else {
                ok
            };
            let jaws: Vec<Pose> = pool.iter().map(|&i| keys[i].jaw).collect();
            pool[MotionFrame::most_closed(&landmarks, &jaws).expect("keys is not empty")]
        }
    };
    let motion = MotionFrame::new(&landmarks, keys[rest].jaw);
    Ok(TrackedMotion { keys, rest, motion })
}

/// The least and the largest value of each anatomical measure over the motion.
#[derive(Debug, Clone, Copy)]
pub struct MotionRanges {
    pub opening_deg: (f64, f64),
    pub incisal_opening_mm: (f64, f64),
    pub lateral_mm: (f64, f64),
    pub protrusion_mm: (f64, f64),
}

impl TrackedMotion {
    /// Seconds from the first key at `fps`.
    pub fn time_s(&self, frame: u32, fps: f64) -> f64 {
        (frame - self.keys[0].frame) as f64 / fps
    }

    pub fn ranges(&self) -> MotionRanges {
        let measured: Vec<Anatomical> = self
            .keys
            .iter()
            .map(|k| self.motion.measure(&k.jaw))
            .collect();
        let range = |f: fn(&Anatomical) -> f64| {
            measured
                .iter()
                .map(f)
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
                    (lo.min(v), hi.max(v))
                })
        };
        MotionRanges {
            opening_deg: range(|a| a.opening_deg),
            incisal_opening_mm: range(|a| a.incisal_opening_mm),
            lateral_mm: range(|a| a.lateral_mm),
            protrusion_mm: range(|a| a.protrusion_mm),
        }
    }
}
