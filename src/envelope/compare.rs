//! One table comparing every rig on the same poses (Zoss et al. 2018, Fig. 8): traditional
//! 1/3/5-DOF rigs, linear PCA with three components, the NLPCA three-parameter rig and the
//! envelope rig; the largest vertex distance per pose (mean, 95th percentile, maximum), the
//! paper's front-weighted average vertex distance, and learning time.

use std::time::Instant;

use rayon::prelude::*;
use serde::Serialize;

use super::model::{EnvelopeError, EnvelopeRig};
use super::traditional::{Dofs, TraditionalRig};
use crate::anatomy::jaw_frame::JawFrame;
use crate::anatomy::{Coordinates, MeshMetric, Pca};
use crate::geometry::Pose;
use crate::rig::model::RigModel;
use crate::rig::{JawRig, RigError, RigSettings};
use crate::stats::Stats;

#[derive(Debug, Clone, Serialize)]
pub struct Row {
    pub name: String,
    pub parameters: usize,
    pub learn_seconds: f64,
    /// Largest vertex distance per pose (mm).
    pub max_vertex_mm: Stats,
    /// Front-weighted mean vertex distance per pose (mm).
    pub front_weighted_mm: Stats,
}

/// (The inner errors are part of the message, not `#[source]`s, so anyhow does not print them
/// twice.)
#[derive(Debug, thiserror::Error)]
pub enum CompareError {
    #[error("the NLPCA rig: {0}")]
    Rig(RigError),
    #[error("the envelope rig: {0}")]
    Envelope(EnvelopeError),
}

impl From<RigError> for CompareError {
    fn from(e: RigError) -> Self {
        CompareError::Rig(e)
    }
}

impl From<EnvelopeError> for CompareError {
    fn from(e: EnvelopeError) -> Self {
        CompareError::Envelope(e)
    }
}

/// Vertex weights growing from the back of the mandible to the front (the paper's weight map:
/// errors at the front show most): 0.1 at the most posterior vertex, 1 at the most anterior,
/// linear along the jaw frame's z axis.
pub fn front_weights(metric: &MeshMetric, frame: &JawFrame) -> Vec<f64> {
    let c = frame.matrix(&frame.origin()).inverse();
    let z: Vec<f64> = metric
        .points()
        .iter()
        .map(|p| c.transform_point(p).z)
        .collect();
    let (lo, hi) = z
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), v| {
            (l.min(*v), h.max(*v))
        });
    z.iter()
        .map(|v| 0.1 + 0.9 * if hi > lo { (v - lo) / (hi - lo) } else { 1.0 })
        .collect()
}

fn row(
    name: &str,
    parameters: usize,
    learn_seconds: f64,
    poses: &[Pose],
    metric: &MeshMetric,
    weights: &[f64],
    rebuild: impl Fn(usize, &Pose) -> Pose + Sync,
) -> Row {
    let (max, front): (Vec<f64>, Vec<f64>) = poses
        .par_iter()
        .enumerate()
        .map(|(i, p)| {
            let q = rebuild(i, p);
            (
                metric.max_distance(p, &q),
                metric.weighted_mean_distance(p, &q, weights),
            )
        })
        .unzip();
    Row {
        name: name.into(),
        parameters,
        learn_seconds,
        max_vertex_mm: Stats::of(&max),
        front_weighted_mm: Stats::of(&front),
    }
}

pub fn compare(
    poses: &[Pose],
    frame: &JawFrame,
    metric: &MeshMetric,
) -> Result<Vec<Row>, CompareError> {
    let weights = front_weights(metric, frame);
    let mut rows = Vec::new();
    for dofs in [Dofs::One, Dofs::Three, Dofs::Five] {
        let t = Instant::now();
        let rig = TraditionalRig::fit(poses, frame, metric.probes(), dofs);
        let s = t.elapsed().as_secs_f64();
        rows.push(row(
            &format!("traditional {}", dofs.name()),
            dofs.count(),
            s,
            poses,
            metric,
            &weights,
            |i, _| rig.pose(&rig.params[i]),
        ));
    }
    let t = Instant::now();
    let coords = Coordinates::for_mesh(metric);
    let pca = Pca::fit(&poses.iter().map(|p| coords.vector(p)).collect::<Vec<_>>());
    let s = t.elapsed().as_secs_f64();
    rows.push(row("PCA-3", 3, s, poses, metric, &weights, |_, p| {
        coords.pose(&pca.reconstruct(&coords.vector(p), 3))
    }));
    for (name, model) in [
        ("NLPCA rig, additive (Yang et al.)", RigModel::Additive),
        ("NLPCA rig, coupled modes", RigModel::Coupled),
    ] {
        let t = Instant::now();
        let settings = RigSettings {
            model,
            ..Default::default()
        };
        let rig = JawRig::learn(poses, metric, &settings, &|_| {})?;
        let s = t.elapsed().as_secs_f64();
        rows.push(row(name, 3, s, poses, metric, &weights, |_, p| {
            rig.pose(&rig.encode(p))
        }));
    }
    let t = Instant::now();
    let env = EnvelopeRig::learn(poses, frame, metric)?;
    let s = t.elapsed().as_secs_f64();
    rows.push(row(
        "envelope rig (Zoss et al.)",
        3,
        s,
        poses,
        metric,
        &weights,
        |_, p| env.reconstruct(p),
    ));
    Ok(rows)
}
