//! The paper's figures as numbers: reconstruction error per pose (Fig. 12) for PCA and NLPCA
//! with 1..6 components and for the three-parameter rig; the distance from random rig poses
//! to the nearest captured pose, with and without the d1-dependent ranges (Fig. 13).

use std::time::Instant;

use nalgebra::Vector6;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use serde::Serialize;

use super::model::JawRig;
use super::nlpca::{Nlpca, NlpcaError};
use crate::anatomy::Coordinates;
use crate::anatomy::MeshMetric;
use crate::anatomy::Pca;
use crate::geometry::Pose;

pub use crate::stats::Stats;

/// One named series of per-pose errors (mm).
#[derive(Debug, Clone, Serialize)]
pub struct Series {
    pub name: String,
    pub stats: Stats,
    pub errors_mm: Vec<f64>,
}

impl Series {
    pub fn new(name: impl Into<String>, errors_mm: Vec<f64>) -> Series {
        Series {
            name: name.into(),
            stats: Stats::of(&errors_mm),
            errors_mm,
        }
    }
}

/// Fig. 12: reconstruction errors of the captured poses.
#[derive(Debug, Clone, Serialize)]
pub struct Reconstruction {
    /// PCA with 1..6 components.
    pub pca: Vec<Series>,
    /// PCA with 3 components on the paper's plain se(3) vectors (log of the pose in the
    /// scan's frame, radians and millimetres mixed), for comparison with [`Coordinates`].
    pub pca3_plain: Series,
    /// NLPCA with 1..5 components (the paper's network, where the rig has it), and 6 when a
    /// six-component network is given.
    pub nlpca: Vec<Series>,
    /// The three-parameter rig: encode, decode.
    pub rig: Series,
    /// Encode, clamp to the valid ranges, decode (what `rig reconstruct` writes).
    pub rig_clamped: Series,
    /// The paper's construction (Φ2, Φ3 from D23, D45; extraction functions), where the rig
    /// has its networks.
    pub paper_rig: Option<Series>,
    /// Share of the poses whose parameters are inside the valid ranges.
    pub valid_share: f64,
}

fn errors(poses: &[Pose], metric: &MeshMetric, rebuild: impl Fn(&Pose) -> Pose + Sync) -> Vec<f64> {
    poses
        .par_iter()
        .map(|p| metric.max_distance(p, &rebuild(p)))
        .collect()
}

pub fn reconstruction(
    rig: &JawRig,
    poses: &[Pose],
    metric: &MeshMetric,
    nlpca6: Option<&Nlpca>,
) -> Reconstruction {
    let coords = &rig.coords;
    let pca = (1..=6)
        .map(|k| {
            Series::new(
                format!("PCA-{k}"),
                errors(poses, metric, |p| {
                    coords.pose(&rig.pca.reconstruct(&coords.vector(p), k))
                }),
            )
        })
        .collect();
    let plain = Coordinates {
        centre_mm: [0.0; 3],
        radius_mm: 1.0,
    };
    let plain_pca = Pca::fit(&poses.iter().map(|p| plain.vector(p)).collect::<Vec<_>>());
    let pca3_plain = Series::new(
        "PCA-3, plain se(3)",
        errors(poses, metric, |p| {
            plain.pose(&plain_pca.reconstruct(&plain.vector(p), 3))
        }),
    );
    let by_network = |net: &Nlpca, k: usize| {
        Series::new(
            format!("NLPCA-{k}"),
            errors(poses, metric, |p| {
                let v = net.reconstruct(coords.vector(p).as_slice(), k);
                coords.pose(&Vector6::from_column_slice(&v))
            }),
        )
    };
    let mut nlpca: Vec<Series> = rig
        .network
        .iter()
        .flat_map(|net| (1..=net.components).map(|k| by_network(net, k)))
        .collect();
    if let Some(net) = nlpca6 {
        nlpca.push(by_network(net, net.components));
    }
    let params: Vec<[f64; 3]> = poses.par_iter().map(|p| rig.encode(p)).collect();
    let valid = params.iter().filter(|d| rig.is_valid(d)).count();
    let rebuilt = |clamp: bool| -> Vec<f64> {
        poses
            .par_iter()
            .zip(&params)
            .map(|(p, d)| {
                let d = if clamp { rig.clamp(d) } else { *d };
                metric.max_distance(p, &rig.pose(&d))
            })
            .collect()
    };
    Reconstruction {
        pca,
        pca3_plain,
        nlpca,
        rig: Series::new(format!("rig ({})", rig.model_name()), rebuilt(false)),
        rig_clamped: Series::new(
            format!("rig ({}), clamped", rig.model_name()),
            rebuilt(true),
        ),
        paper_rig: rig.paper.is_some().then(|| {
            Series::new(
                "paper's D23/D45",
                poses
                    .par_iter()
                    .filter_map(|p| Some(metric.max_distance(p, &rig.paper_reconstruct(p)?)))
                    .collect(),
            )
        }),
        valid_share: valid as f64 / poses.len().max(1) as f64,
    }
}

/// Fig. 13: random rig poses, each scored by its distance to the nearest captured pose.
#[derive(Debug, Clone, Serialize)]
pub struct Sampled {
    pub dynamic_ranges: Series,
    pub static_ranges: Series,
}

pub fn sampled(
    rig: &JawRig,
    poses: &[Pose],
    metric: &MeshMetric,
    count: usize,
    seed: u64,
) -> Sampled {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let dynamic: Vec<[f64; 3]> = (0..count)
        .map(|_| rig.ranges.sample_dynamic(&mut rng))
        .collect();
    let fixed: Vec<[f64; 3]> = (0..count)
        .map(|_| rig.ranges.sample_static(&mut rng))
        .collect();
    let nearest = |ds: &[[f64; 3]]| -> Vec<f64> {
        ds.par_iter()
            .map(|d| {
                metric
                    .nearest(&rig.pose(d), poses)
                    .map_or(f64::NAN, |(_, e)| e)
            })
            .collect()
    };
    Sampled {
        dynamic_ranges: Series::new("with d1-dependent ranges", nearest(&dynamic)),
        static_ranges: Series::new("with fixed ranges", nearest(&fixed)),
    }
}
#[derive(Serialize)]
pub struct EvalReport {
    pub poses: usize,
    pub mesh_vertices: usize,
    pub singular_values_mm: Vec<f64>,
    pub reconstruction: Reconstruction,
    pub sampled: Option<Sampled>,
    /// Time to encode one pose (extraction + Gauss-Newton), ms.
    pub encode_ms: f64,
    /// Time to decode one parameter vector into a pose, µs.
    pub decode_us: f64,
    pub seconds: f64,
}

/// The figures for `rig` on `poses` (`rig eval`, the demo and `bench rig`): reconstruction
/// errors, optionally random rig poses (`samples`) and a six-component NLPCA, and timings.
pub fn report(
    rig: &JawRig,
    poses: &[Pose],
    metric: &MeshMetric,
    samples: usize,
    seed: u64,
    nlpca6: bool,
) -> Result<EvalReport, NlpcaError> {
    let started = Instant::now();
    let six = if nlpca6 {
        let samples: Vec<Vec<f64>> = poses
            .iter()
            .map(|p| rig.coords.vector(p).as_slice().to_vec())
            .collect();
        Some(Nlpca::train(&samples, 6, &rig.settings.network)?.0)
    } else {
        None
    };
    let reconstruction = reconstruction(rig, poses, metric, six.as_ref());
    let sampled = (samples > 0).then(|| sampled(rig, poses, metric, samples, seed));
    let t = Instant::now();
    let reps = poses.len().min(200);
    let mut sink = 0.0;
    for p in &poses[..reps] {
        sink += rig.encode(p)[0];
    }
    let encode_ms = t.elapsed().as_secs_f64() * 1e3 / reps.max(1) as f64;
    let t = Instant::now();
    for k in 0..1000 {
        sink += rig.pose(&[k as f64 * 1e-4, 0.0, 0.0]).translation.x;
    }
    let decode_us = t.elapsed().as_secs_f64() * 1e3;
    std::hint::black_box(sink);
    Ok(EvalReport {
        poses: poses.len(),
        mesh_vertices: metric.vertex_count(),
        singular_values_mm: rig.pca.singular_values.clone(),
        reconstruction,
        sampled,
        encode_ms,
        decode_us,
        seconds: started.elapsed().as_secs_f64(),
    })
}
