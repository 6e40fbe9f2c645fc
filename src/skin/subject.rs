//! A face sequence read into memory: every frame's skin, the jaw poses it has, the rest pose
//! and the five bone points. Features are computed from it for any choice of skin points.

use nalgebra::Vector3;
use rayon::prelude::*;

use super::features::{SkinPoint, bone_features, bone_points, skin_features};
use super::format::{CalibrationJson, FaceSequence};
use crate::anatomy::MeshMetric;
use crate::error::{Error, Result};
use crate::geometry::Pose;
use crate::mesh::Mesh;

/// The mean skin displacement (mm) below which a frame counts as the neutral. The rest pose of
/// a subject is the jaw pose of the frame nearest the neutral; one farther than this is used
/// all the same, and the commands say so (the bone features are then measured from a pose
/// that is not quite the rest).
pub const REST_MAX_MM: f64 = 1.5;

#[derive(Debug, Clone)]
pub struct Subject {
    pub name: String,
    pub frames: Vec<u32>,
    pub skin: Vec<Vec<[f32; 3]>>,
    pub neutral: Mesh,
    pub mandible: Mesh,
    /// The jaw pose per frame (index as `frames`), where known.
    pub jaw: Vec<Option<Pose>>,
    pub calibration: Option<CalibrationJson>,
    pub bone: [Vector3<f64>; 5],
    /// The mandible's vertices, on which a jaw pose's error is measured.
    pub metric: MeshMetric,
}

impl Subject {
    /// Read every frame of `seq` (in parallel); `progress` is called once a frame.
    pub fn load(seq: &FaceSequence, name: &str, progress: &(dyn Fn() + Sync)) -> Result<Subject> {
        let frames: Vec<u32> = seq.frames().collect();
        let skin = frames
            .par_iter()
            .map(|&f| {
                let v = seq.read_frame(f);
                progress();
                v
            })
            .collect::<Result<Vec<_>>>()?;
        Ok(Subject {
            name: name.into(),
            jaw: frames.iter().map(|f| seq.jaw.get(f).copied()).collect(),
            frames,
            skin,
            bone: bone_points(&seq.mandible),
            metric: MeshMetric::new(&seq.mandible),
            neutral: seq.neutral.clone(),
            mandible: seq.mandible.clone(),
            calibration: seq.calibration,
        })
    }

    /// The mean vertex error (mm) of `poses` (one per frame) against the jaw poses the
    /// sequence has, frame by frame where it has one.
    pub fn errors_against_jaw(&self, poses: &[Pose]) -> Vec<f64> {
        self.jaw
            .iter()
            .zip(poses)
            .filter_map(|(truth, p)| truth.map(|t| self.metric.mean_distance(p, &t)))
            .collect()
    }

    /// The index in `frames` of frame number `f`.
    pub fn index_of(&self, f: u32) -> Option<usize> {
        f.checked_sub(*self.frames.first()?)
            .map(|i| i as usize)
            .filter(|&i| i < self.frames.len())
    }

    /// The rest pose: the jaw pose of the frame whose skin is nearest the neutral, that frame,
    /// and its mean distance from the neutral (mm; see [`REST_MAX_MM`]).
    pub fn rest(&self) -> Result<(Pose, u32, f64)> {
        let mut best: Option<(f64, usize)> = None;
        for (i, jaw) in self.jaw.iter().enumerate() {
            if jaw.is_none() {
                continue;
            }
            let d = mean_displacement(&self.neutral.positions, &self.skin[i]);
            if best.is_none_or(|b| d < b.0) {
                best = Some((d, i));
            }
        }
        let Some((d, i)) = best else {
            return Err(Error::invalid(
                self.dir_file(),
                "jaw",
                "no jaw poses: the subject can only be predicted for, with a model made for it (`skin retarget`)",
            ));
        };
        Ok((
            self.jaw[i].expect("chosen among frames with a pose"),
            self.frames[i],
            d,
        ))
    }

    /// A note for the user when the rest pose comes from a frame far from the neutral.
    pub fn rest_note(&self) -> Option<String> {
        let (_, frame, d) = self.rest().ok()?;
        (d > REST_MAX_MM).then(|| {
            format!(
                "{}: the frame with a jaw pose nearest the neutral skin (frame {frame}) is {d:.2} mm from it on average (more than {REST_MAX_MM} mm); its pose is taken as the rest pose. Give jaw.json the pose of a frame at rest (mouth closed, relaxed) for a true one",
                self.name
            )
        })
    }

    fn dir_file(&self) -> std::path::PathBuf {
        std::path::PathBuf::from(&self.name).join("face.json")
    }

    /// Skin features of frame index `i` for `points`.
    pub fn skin_features(&self, points: &[SkinPoint], i: usize) -> Vec<f64> {
        skin_features(
            points,
            &self.neutral.triangles,
            &self.neutral.positions,
            &self.skin[i],
        )
    }

    /// Bone features of frame index `i` (which must have a jaw pose) from `rest`.
    pub fn bone_features(&self, rest: &Pose, i: usize) -> Option<Vec<f64>> {
        self.jaw[i].map(|j| bone_features(&self.bone, rest, &j))
    }

    /// The calibration frames as indices, named.
    pub fn calibration_indices(&self) -> Result<Vec<(&'static str, usize)>> {
        let cal = self.calibration.ok_or_else(|| {
            Error::invalid(
                self.dir_file(),
                "calibration",
                "missing: retargeting to a subject needs the frames of its five calibration poses",
            )
        })?;
        cal.frames()
            .into_iter()
            .map(|(name, f)| {
                let i = self
                    .index_of(f)
                    .filter(|&i| self.jaw[i].is_some())
                    .ok_or_else(|| {
                        Error::invalid(
                            self.dir_file(),
                            format!("calibration.{name}"),
                            format!("frame {f} has no jaw pose in jaw.json"),
                        )
                    })?;
                Ok((name, i))
            })
            .collect()
    }
}

fn mean_displacement(a: &[[f32; 3]], b: &[[f32; 3]]) -> f64 {
    let s: f64 = a
        .iter()
        .zip(b)
        .map(|(p, q)| {
            let d = [p[0] - q[0], p[1] - q[1], p[2] - q[2]];
            ((d[0] * d[0] + d[1] * d[1] + d[2] * d[2]) as f64).sqrt()
        })
        .sum();
    s / a.len().max(1) as f64
}

/// The jaw pose (`upper_from_lower`) that best places the bone points, rest-posed, at their
/// predicted displacements (the paper's Eq. 1, solved in closed form).
pub fn jaw_from_bone(bone: &[Vector3<f64>; 5], rest: &Pose, b: &[f64]) -> Pose {
    let at_rest: Vec<Vector3<f64>> = bone.iter().map(|m| rest.transform_point(m)).collect();
    let moved: Vec<Vector3<f64>> = at_rest
        .iter()
        .enumerate()
        .map(|(i, p)| p + Vector3::new(b[3 * i], b[3 * i + 1], b[3 * i + 2]))
        .collect();
    // Five points spread over a mandible are never collinear; if a mapping predicts them so,
    // the rest pose is the honest answer.
    crate::geometry::fit_rigid(&at_rest, &moved)
        .map(|t| t.compose(rest))
        .unwrap_or(*rest)
}

/// Mean distance (mm) over the bone points: the paper's own measure.
pub fn bone_point_error(bone: &[Vector3<f64>; 5], a: &Pose, b: &Pose) -> f64 {
    bone.iter()
        .map(|p| (a.transform_point(p) - b.transform_point(p)).norm())
        .sum::<f64>()
        / 5.0
}
