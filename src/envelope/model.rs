//! The envelope rig: a jaw pose from a point of Posselt's envelope (direct manipulation) or
//! from unit-cube sliders, through the RBF map to the 6-DOF rig's parameters (Eq. 2).

use std::path::Path;

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use super::rbf::Rbf;
use super::shield::{Shield, ShieldError};
use super::traditional::{Dofs, TraditionalRig};
use crate::anatomy::MeshMetric;
use crate::anatomy::jaw_frame::{FrameError, JawFrame};
use crate::error::{Error, Result};
use crate::geometry::Pose;
use crate::io::read_json;
use crate::io::write_json_atomic;

pub const ENVELOPE_FORMAT: &str = "jawtrack-envelope/1";

/// (The inner errors are part of the message, not `#[source]`s, so anyhow does not print them
/// twice.)
#[derive(Debug, thiserror::Error)]
pub enum EnvelopeError {
    #[error("the jaw frame: {0}")]
    Frame(FrameError),
    #[error("Posselt's envelope: {0}")]
    Shield(ShieldError),
}

impl From<FrameError> for EnvelopeError {
    fn from(e: FrameError) -> Self {
        EnvelopeError::Frame(e)
    }
}

impl From<ShieldError> for EnvelopeError {
    fn from(e: ShieldError) -> Self {
        EnvelopeError::Shield(e)
    }
}

#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct EnvelopeRig {
    pub format: String,
    /// The 6-DOF traditional rig whose parameters the map predicts (no per-pose parameters).
    pub six: TraditionalRig,
    pub shield: Shield,
    pub rbf: Rbf,
    pub poses: usize,
    pub seconds: f64,
}

impl EnvelopeRig {
    pub fn learn(
        poses: &[Pose],
        frame: &JawFrame,
        metric: &MeshMetric,
    ) -> Result<EnvelopeRig, EnvelopeError> {
        let started = std::time::Instant::now();
        frame.axes()?;
        let mut six = TraditionalRig::fit(poses, frame, metric.probes(), Dofs::Six);
        let params = std::mem::take(&mut six.params);
        let points: Vec<Vector3<f64>> = poses.iter().map(|p| point_in(&six, p)).collect();
        let shield = Shield::fit(&points)?;
        let rbf = Rbf::fit(&shield, &points, &params);
        Ok(EnvelopeRig {
            format: ENVELOPE_FORMAT.into(),
            six,
            shield,
            rbf,
            poses: poses.len(),
            seconds: started.elapsed().as_secs_f64(),
        })
    }

    /// The reference point of a jaw pose, in the jaw frame.
    pub fn point_of(&self, pose: &Pose) -> Vector3<f64> {
        point_in(&self.six, pose)
    }

    /// Upper-frame coordinates (mm) to the jaw frame, and back.
    pub fn from_upper(&self, x: &Vector3<f64>) -> Vector3<f64> {
        c_upper(&self.six).inverse().transform_point(x)
    }

    pub fn to_upper(&self, p: &Vector3<f64>) -> Vector3<f64> {
        c_upper(&self.six).transform_point(p)
    }

    /// The jaw pose whose reference point is at `p` (jaw frame), `p` projected into the
    /// envelope first. The map gives the rotation; the translation is then solved so the
    /// reference point lands exactly on `p` (the rig's premise, Sec. 5.2): with the rig's
    /// motion e = R·(q + t), t = Rᵀ·e − q, where q is the reference point at the neutral pose.
    pub fn pose_at(&self, p: &Vector3<f64>) -> Pose {
        let e = self.shield.project(p);
        let mut theta = self.rbf.eval(&e);
        let r = super::traditional::local_motion(&[theta[0], theta[1], theta[2], 0.0, 0.0, 0.0])
            .rotation;
        let q = point_in(&self.six, &self.six.neutral);
        let t = r.inverse() * e - q;
        theta[3..].copy_from_slice(t.as_slice());
        self.six.pose(&theta)
    }

    /// The jaw pose for unit-cube sliders (s_x left→right, s_y top→bottom, s_z back→front).
    pub fn pose_at_cube(&self, s: &[f64; 3]) -> Pose {
        self.pose_at(&self.shield.point(s))
    }

    /// A pose through the rig: its reference point, projected, mapped back to a pose.
    pub fn reconstruct(&self, pose: &Pose) -> Pose {
        self.pose_at(&self.point_of(pose))
    }

    pub fn save(&self, path: &Path) -> Result<()> {
        write_json_atomic(path, self)
    }

    pub fn load(path: &Path) -> Result<EnvelopeRig> {
        let rig: EnvelopeRig = read_json(path, "envelope rig file")?;
        if rig.format != ENVELOPE_FORMAT {
            return Err(Error::invalid(
                path,
                "format",
                format!("expected {ENVELOPE_FORMAT:?}, found {:?}", rig.format),
            ));
        }
        let s = &rig.shield;
        if s.rows < 2 || s.cols < 2 || s.left.len() != s.rows || s.right.len() != s.rows {
            return Err(Error::invalid(
                path,
                "shield",
                "rows, cols and the limit tables do not match",
            ));
        }
        if s.back.len() != s.rows * s.cols
            || s.front.len() != s.rows * s.cols
            || s.y_top <= s.y_bottom
        {
            return Err(Error::invalid(
                path,
                "shield",
                "the limit tables do not match rows × cols, or y_top ≤ y_bottom",
            ));
        }
        let r = &rig.rbf;
        if r.centres.is_empty()
            || r.sigmas.len() != r.centres.len()
            || r.weights.len() != r.centres.len()
        {
            return Err(Error::invalid(
                path,
                "rbf",
                "centres, sigmas and weights must have one entry per kernel",
            ));
        }
        if r.sigmas.iter().any(|s| !(s.is_finite() && *s > 0.0)) {
            return Err(Error::invalid(
                path,
                "rbf.sigmas",
                "must be positive numbers",
            ));
        }
        rig.six
            .frame
            .axes()
            .map_err(|e| Error::invalid(path, "six.frame", e.to_string()))?;
        Ok(rig)
    }
}

/// C in the upper frame: the neutral pose times the jaw frame at the rig's origin.
fn c_upper(six: &TraditionalRig) -> Pose {
    six.neutral
        .compose(&six.frame.matrix(&Vector3::from(six.origin)))
}

fn point_in(six: &TraditionalRig, pose: &Pose) -> Vector3<f64> {
    c_upper(six)
        .inverse()
        .transform_point(&pose.transform_point(&Vector3::from(six.frame.reference)))
}

/// Eq. 15: for every pose, among the k poses whose reference points are nearest, the largest
/// pose difference (the largest displacement of the metric's probe points, mm) weighted by a
/// Gaussian of the points' distance (σ in mm). Zero where nearby points mean nearby poses.
pub fn bijectivity(
    rig: &EnvelopeRig,
    poses: &[Pose],
    metric: &MeshMetric,
    k: usize,
    sigma_mm: f64,
) -> Vec<f64> {
    use rayon::prelude::*;
    let points: Vec<Vector3<f64>> = poses.iter().map(|p| rig.point_of(p)).collect();
    (0..poses.len())
        .into_par_iter()
        .map(|i| {
            let mut near: Vec<(f64, usize)> = points
                .iter()
                .enumerate()
                .filter(|(j, _)| *j != i)
                .map(|(j, q)| ((q - points[i]).norm(), j))
                .collect();
            near.sort_by(|a, b| a.0.total_cmp(&b.0));
            near.iter()
                .take(k)
                .map(|&(d, j)| {
                    (-0.5 * d * d / (sigma_mm * sigma_mm)).exp()
                        * metric.probe_distance(&poses[i], &poses[j])
                })
                .fold(0.0, f64::max)
        })
        .collect()
}

/// The unit-cube sliders as the three parameters: inside the cube is inside Posselt's
/// envelope, the valid poses.
impl crate::rig::ThreeParameterRig for EnvelopeRig {
    fn kind(&self) -> &'static str {
        "envelope rig"
    }

    fn pose(&self, d: &[f64; 3]) -> Pose {
        self.pose_at_cube(d)
    }

    fn is_valid(&self, d: &[f64; 3]) -> bool {
        d.iter().all(|v| (-1e-9..=1.0 + 1e-9).contains(v))
    }

    fn clamp(&self, d: &[f64; 3]) -> [f64; 3] {
        d.map(|v| if v.is_nan() { 0.0 } else { v.clamp(0.0, 1.0) })
    }

    fn band(&self, _d: &[f64; 3], _k: usize) -> Option<[f64; 2]> {
        Some([0.0, 1.0])
    }

    fn motion_frame(&self) -> Option<crate::anatomy::motion::MotionFrame> {
        Some(crate::anatomy::motion::MotionFrame::new(
            &self.six.frame,
            self.six.neutral,
        ))
    }

    fn spread(&self) -> Vec<[f64; 3]> {
        let at = |i: usize| i as f64 / 4.0;
        (0..125)
            .map(|i| [at(i % 5), at(i / 5 % 5), at(i / 25)])
            .collect()
    }

    fn rest_params(&self) -> [f64; 3] {
        let rest = self.point_of(&self.six.neutral);
        self.shield.cube(&rest).map(|v| v.clamp(0.0, 1.0))
    }

    fn clamp_for_search(&self, d: &[f64; 3]) -> [f64; 3] {
        d.map(|v| if v.is_nan() { 0.0 } else { v.clamp(0.0, 1.0) })
    }
}
