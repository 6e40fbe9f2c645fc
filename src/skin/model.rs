//! A jaw-from-skin model: which skin points it reads, the mapping Φ, and the subject it
//! predicts for (its rest pose, bone points and, once retargeted, the per-feature transforms).
//! Learning one from a subject (Section 5), from several (Section 6.2), and retargeting one
//! to a new subject (Section 6.1).

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use super::features::{FeatureSettings, SkinPoint, choose_skin_points};
use super::regress::{RegressSettings, Regressor};
use super::retarget::{FeatureTransform, RetargetReport, RetargetSettings, align_globally, apply};
use super::subject::{Subject, jaw_from_bone};
use crate::error::{Error, Result};
use crate::formats::PoseJson;
use crate::geometry::Pose;

/// A subject's rows of skin features and of bone features.
type FramesXY = (Vec<Vec<f64>>, Vec<Vec<f64>>);

pub const MODEL_FORMAT: &str = "jawtrack-skin-model/2";

/// The earlier format, still read: one mapping, carried by one set of transforms.
pub const MODEL_FORMAT_1: &str = "jawtrack-skin-model/1";

/// Everything learning and retargeting can be told (`--settings FILE`, JSON; absent fields
/// keep their defaults).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SkinSettings {
    pub features: FeatureSettings,
    pub regress: RegressSettings,
    pub retarget: RetargetSettings,
}

/// The subject a model predicts for.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct SubjectFit {
    pub name: String,
    pub rest: PoseJson,
    pub bone_points: [[f64; 3]; 5],
    /// Per skin feature (or one for all), applied before Φ; empty: none. Used where `blend`
    /// is empty.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub transforms: Vec<FeatureTransform>,
    /// The mapping as carried to this subject: the weighted mean of the bone features each
    /// term predicts (its mapping after its transforms). Empty: `regressor` after
    /// `transforms`.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub blend: Vec<BlendTerm>,
}

/// One mapping of a model carried one way, and its weight.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct BlendTerm {
    /// 0: the model's `regressor`; k: its `sources[k - 1]`.
    pub mapping: usize,
    /// The rung of the retargeting ladder ("none", "global", …).
    pub carry: String,
    pub weight: f64,
    /// Per skin feature, one for all, or none.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub transforms: Vec<FeatureTransform>,
}

/// A further mapping of a multi-subject model: one source subject's own, on the same skin
/// points.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct SourceMapping {
    pub name: String,
    pub regressor: Regressor,
}

#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct SkinModel {
    pub format: String,
    /// The topology the skin points refer to.
    pub skin_vertices: usize,
    pub skin_triangles: usize,
    pub skin_points: Vec<SkinPoint>,
    pub settings: SkinSettings,
    pub trained_on: Vec<String>,
    /// Φ: the one subject's mapping, or the paper's pooled multi-subject mapping.
    pub regressor: Regressor,
    /// A multi-subject model's sources, each its own subject's mapping; retargeting weighs
    /// them with `regressor` by how well each predicts the new subject's calibration poses.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub sources: Vec<SourceMapping>,
    pub subject: SubjectFit,
}

impl SubjectFit {
    pub(crate) fn of(s: &Subject, rest: &Pose) -> SubjectFit {
        SubjectFit {
            name: s.name.clone(),
            rest: PoseJson::from(rest),
            bone_points: s.bone.map(|p| [p.x, p.y, p.z]),
            transforms: Vec::new(),
            blend: Vec::new(),
        }
    }

    fn rest_pose(&self) -> Pose {
        // Written by this program from a checked pose; the reader checks it again.
        self.rest
            .to_pose(std::path::Path::new("model"), "subject.rest")
            .unwrap_or_default()
    }

    fn bone(&self) -> [Vector3<f64>; 5] {
        self.bone_points.map(Vector3::from)
    }
}

impl SkinModel {
    /// The jaw pose for a frame's skin features (the model's own skin points).
    pub fn predict(&self, features: &[f64]) -> Pose {
        self.jaw_from_bone(&self.predict_bone(features))
    }

    /// The bone features (the five bone points' displacements from rest, mm) for a frame's
    /// skin features.
    pub fn predict_bone(&self, features: &[f64]) -> Vec<f64> {
        if self.subject.blend.is_empty() {
            return self
                .regressor
                .predict(&apply(&self.subject.transforms, features));
        }
        let mut b = vec![0.0; 15];
        for t in &self.subject.blend {
            let p = self
                .mapping(t.mapping)
                .predict(&apply(&t.transforms, features));
            for (acc, v) in b.iter_mut().zip(p) {
                *acc += t.weight * v;
            }
        }
        b
    }

    /// Mapping `k`: 0 the model's `regressor`, k its `sources[k - 1]`.
    fn mapping(&self, k: usize) -> &Regressor {
        match k {
            0 => &self.regressor,
            k => &self.sources[k - 1].regressor,
        }
    }

    /// Every mapping with its name: the model's own (named for what it was trained on), then
    /// its sources'.
    pub fn mappings(&self) -> Vec<(String, &Regressor)> {
        let own = if self.sources.is_empty() {
            self.trained_on.join("+")
        } else {
            "pooled".to_string()
        };
        std::iter::once((own, &self.regressor))
            .chain(self.sources.iter().map(|s| (s.name.clone(), &s.regressor)))
            .collect()
    }

    /// This (multi-subject) model with each source subject's own mapping beside the pooled
    /// one, for retargeting to weigh. Each must be on this model's skin points.
    pub fn with_sources(mut self, sources: Vec<(String, &SkinModel)>) -> SkinModel {
        self.sources = sources
            .into_iter()
            .map(|(name, m)| SourceMapping {
                name,
                regressor: m.regressor.clone(),
            })
            .collect();
        self
    }

    /// The jaw pose of the model's subject whose bone points moved by `b`.
    pub fn jaw_from_bone(&self, b: &[f64]) -> Pose {
        jaw_from_bone(&self.subject.bone(), &self.subject.rest_pose(), b)
    }

    /// The jaw in every frame of `s`, in its frames' order.
    pub fn predict_sequence(&self, s: &Subject) -> Vec<Pose> {
        (0..s.frames.len())
            .map(|i| self.predict(&s.skin_features(&self.skin_points, i)))
            .collect()
    }

    /// Check that `s` has the topology the skin points refer to.
    pub fn check_topology(&self, s: &Subject, path: &std::path::Path) -> Result<()> {
        if s.neutral.positions.len() != self.skin_vertices
            || s.neutral.triangles.len() != self.skin_triangles
        {
            return Err(Error::invalid(
                path,
                "neutral",
                format!(
                    "has {} vertices and {} triangles; the model was learned on a topology of {} and {} (every subject shares one topology)",
                    s.neutral.positions.len(),
                    s.neutral.triangles.len(),
                    self.skin_vertices,
                    self.skin_triangles
                ),
            ));
        }
        Ok(())
    }

    /// Read and check a model file (this format or the earlier one).
    pub fn read(path: &std::path::Path) -> Result<SkinModel> {
        let mut m: SkinModel = crate::io::read_json(path, "skin model")?;
        if m.format != MODEL_FORMAT && m.format != MODEL_FORMAT_1 {
            return Err(Error::invalid(
                path,
                "format",
                format!(
                    "is `{}`, expected `{MODEL_FORMAT}` (or `{MODEL_FORMAT_1}`)",
                    m.format
                ),
            ));
        }
        m.format = MODEL_FORMAT.into();
        m.subject.rest.to_pose(path, "subject.rest")?;
        let damaged = |field: String, what: &str| {
            Error::invalid(
                path,
                &field,
                format!("{what} (a damaged or hand-edited model)"),
            )
        };
        if m.skin_points
            .iter()
            .any(|p| p.triangle as usize >= m.skin_triangles)
        {
            return Err(damaged(
                "skin_points".into(),
                "names a triangle the topology does not have",
            ));
        }
        let dim = m.skin_points.len() * 3;
        let fields = std::iter::once("regressor".to_string())
            .chain((0..m.sources.len()).map(|k| format!("sources[{k}].regressor")));
        for ((_, r), field) in m.mappings().into_iter().zip(fields) {
            if !regressor_fits(r, dim) {
                return Err(damaged(field, "its sizes do not agree with one another"));
            }
            if !regressor_numbers(r).all(f64::is_finite) {
                return Err(damaged(field, "holds a number that is not finite"));
            }
        }
        let numbers = m
            .skin_points
            .iter()
            .flat_map(|p| p.barycentric.iter())
            .chain(m.subject.bone_points.iter().flatten())
            .copied();
        if !numbers.into_iter().all(f64::is_finite) {
            return Err(damaged(
                "subject".into(),
                "holds a number that is not finite",
            ));
        }
        let n = m.skin_points.len();
        check_transforms(path, "subject.transforms", &m.subject.transforms, n)?;
        for (k, t) in m.subject.blend.iter().enumerate() {
            let field = format!("subject.blend[{k}]");
            if t.mapping > m.sources.len() {
                return Err(damaged(
                    field,
                    &format!(
                        "names mapping {} of {} (0 the pooled one, then the sources)",
                        t.mapping,
                        m.sources.len() + 1
                    ),
                ));
            }
            if !(t.weight.is_finite() && (0.0..=1.0).contains(&t.weight)) {
                return Err(damaged(field, "has a weight outside 0..1"));
            }
            check_transforms(path, &format!("{field}.transforms"), &t.transforms, n)?;
        }
        let total: f64 = m.subject.blend.iter().map(|t| t.weight).sum();
        if !m.subject.blend.is_empty() && (total - 1.0).abs() > 1e-6 {
            return Err(damaged(
                "subject.blend".into(),
                &format!("has weights that sum to {total}, not 1"),
            ));
        }
        Ok(m)
    }
}

fn model(
    points: Vec<SkinPoint>,
    on: &Subject,
    regressor: Regressor,
    trained_on: Vec<String>,
    settings: &SkinSettings,
    subject: SubjectFit,
) -> SkinModel {
    SkinModel {
        format: MODEL_FORMAT.into(),
        skin_vertices: on.neutral.positions.len(),
        skin_triangles: on.neutral.triangles.len(),
        skin_points: points,
        settings: settings.clone(),
        trained_on,
        regressor,
        sources: Vec::new(),
        subject,
    }
}

/// Whether a regressor's sizes agree with each other and with `dim` skin features.
fn regressor_fits(r: &Regressor, dim: usize) -> bool {
    r.mean.len() == dim
        && r.basis.iter().all(|b| b.len() == dim)
        && r.support.iter().all(|s| s.len() == r.basis.len())
        && r.outputs.len() == 15
        && r.outputs.iter().all(|o| o.alpha.len() == r.support.len())
        && r.width > 0.0
}

fn regressor_numbers(r: &Regressor) -> impl Iterator<Item = f64> + '_ {
    r.mean
        .iter()
        .chain(r.basis.iter().flatten())
        .chain(r.support.iter().flatten())
        .chain(
            r.outputs
                .iter()
                .flat_map(|o| o.alpha.iter().chain([&o.rho, &o.mean, &o.scale])),
        )
        .chain([&r.width])
        .copied()
}

/// Transforms are one per skin point, one for all, or none, and finite.
fn check_transforms(
    path: &std::path::Path,
    field: &str,
    t: &[FeatureTransform],
    points: usize,
) -> Result<()> {
    if !t.is_empty() && t.len() != 1 && t.len() != points {
        return Err(Error::invalid(
            path,
            field,
            format!(
                "{} transforms for {points} skin points (one each, or one for all)",
                t.len()
            ),
        ));
    }
    if !t
        .iter()
        .flat_map(|t| t.rotation.iter().chain(&t.translation))
        .all(|v| v.is_finite())
    {
        return Err(Error::invalid(
            path,
            field,
            "holds a number that is not finite (a damaged or hand-edited model)",
        ));
    }
    Ok(())
}

fn regress_error(s: &Subject, e: impl std::fmt::Display) -> Error {
    Error::invalid(
        std::path::PathBuf::from(&s.name).join("face.json"),
        "frames",
        format!("cannot learn a mapping: {e}"),
    )
}

/// The skin points for a set whose first subject is `s`.
pub fn skin_points(s: &Subject, settings: &SkinSettings) -> Result<Vec<SkinPoint>> {
    let (rest, ..) = s.rest()?;
    choose_skin_points(&s.neutral, &s.mandible, &rest, &settings.features)
        .map_err(|e| regress_error(s, e))
}

/// Learn a mapping from frame indices `frames` of one subject (with jaw poses).
pub fn learn_single(
    s: &Subject,
    points: Option<Vec<SkinPoint>>,
    frames: &[usize],
    settings: &SkinSettings,
) -> Result<SkinModel> {
    let (rest, ..) = s.rest()?;
    let points = match points {
        Some(p) => p,
        None => skin_points(s, settings)?,
    };
    let (x, y) = training_rows(s, &points, &rest, frames);
    let cut = held_out_cut(x.len(), settings.regress.held_out);
    let regressor =
        Regressor::learn(&x, &y, cut, &settings.regress).map_err(|e| regress_error(s, e))?;
    Ok(model(
        points,
        s,
        regressor,
        vec![s.name.clone()],
        settings,
        SubjectFit::of(s, &rest),
    ))
}

/// Skin and bone features of those of frame indices `frames` that have a jaw pose.
fn training_rows(s: &Subject, points: &[SkinPoint], rest: &Pose, frames: &[usize]) -> FramesXY {
    frames
        .iter()
        .filter_map(|&i| Some((s.skin_features(points, i), s.bone_features(rest, i)?)))
        .unzip()
}

fn held_out_cut(n: usize, share: f64) -> usize {
    ((n as f64 * (1.0 - share)).round() as usize).clamp(n.min(4), n.saturating_sub(2).max(n.min(4)))
}

/// Up to `most` indices spread evenly over `0..n`.
pub fn spaced(n: usize, most: usize) -> Vec<usize> {
    if n <= most.max(1) {
        return (0..n).collect();
    }
    (0..most).map(|i| i * n / most).collect()
}

/// The multi-subject mapping (Section 6.2): the first subject is the primary; every other is
/// aligned to it by one rigid transform of all its skin features, then one mapping is learned
/// from all of them. Every subject needs jaw poses.
///
/// `primary_model`, when given, is the primary's own mapping on all its frames with the same
/// skin points (saves learning it again).
pub fn learn_multi(
    subjects: &[&Subject],
    points: Option<Vec<SkinPoint>>,
    primary_model: Option<&SkinModel>,
    settings: &SkinSettings,
) -> Result<(SkinModel, Vec<RetargetReport>)> {
    let primary = subjects[0];
    let points = match points {
        Some(p) => p,
        None => skin_points(primary, settings)?,
    };
    let all: Vec<usize> = (0..primary.frames.len()).collect();
    let learned;
    let single = match primary_model {
        Some(m) => m,
        None => {
            learned = learn_single(primary, Some(points.clone()), &all, settings)?;
            &learned
        }
    };
    // Per subject: its skin features (aligned) and bone features, frame by frame.
    let mut parts: Vec<FramesXY> = Vec::new();
    let mut reports = Vec::new();
    for (k, s) in subjects.iter().enumerate() {
        let (rest, ..) = s.rest()?;
        let every: Vec<usize> = (0..s.frames.len()).collect();
        let (x, y) = training_rows(s, &points, &rest, &every);
        let x = if k == 0 {
            x
        } else {
            let sample = spaced(x.len(), 150);
            let pairs: Vec<(Vec<f64>, Vec<f64>)> = sample
                .iter()
                .map(|&i| (x[i].clone(), y[i].clone()))
                .collect();
            let (t, report) = align_globally(&single.regressor, &pairs, &settings.retarget);
            reports.push(report);
            x.iter().map(|f| apply(&[t], f)).collect()
        };
        parts.push((x, y));
    }
    // Every subject's first frames learn, its last ones are held out to choose the
    // hyperparameters: the rows are ordered so that one cut does both.
    let (mut x, mut y, mut held_x, mut held_y) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    for (px, py) in parts {
        let cut = held_out_cut(px.len(), settings.regress.held_out);
        for (i, (f, b)) in px.into_iter().zip(py).enumerate() {
            if i < cut {
                x.push(f);
                y.push(b);
            } else {
                held_x.push(f);
                held_y.push(b);
            }
        }
    }
    let cut = x.len();
    x.extend(held_x);
    y.extend(held_y);
    let regressor =
        Regressor::learn(&x, &y, cut, &settings.regress).map_err(|e| regress_error(primary, e))?;
    let names = subjects.iter().map(|s| s.name.clone()).collect();
    let (rest, ..) = primary.rest()?;
    let fit = SubjectFit::of(primary, &rest);
    Ok((
        model(points, primary, regressor, names, settings, fit),
        reports,
    ))
}
