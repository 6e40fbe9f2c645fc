//! `jawtrack bench rig`: the rig's accuracy and speed goals on synthetic TMJ motion.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Context;
use jawtrack::anatomy::MeshMetric;
use jawtrack::formats::{JawPoses, read_jaw_poses};
use jawtrack::rig::{JawRig, RigSettings};
use jawtrack::synth::{SynthOptions, generate};
use rand::SeedableRng;
use serde::Serialize;

#[derive(clap::Args)]
pub struct RigArgs {
    /// Poses of synthetic motion (the whole exercise is played once).
    #[arg(long, default_value_t = 833)]
    frames: u32,
    /// Seed of the synthetic subject and of the networks.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Folder with upper.* and lower.* to build the subject from (default: procedural arches).
    #[arg(long)]
    meshes: Option<PathBuf>,
    /// Jaw poses to learn from instead of synthetic motion (tracks.json, gt/poses.json or a
    /// jawtrack-jaw/1 file, e.g. from `benches/other_joint.py`), with `--mesh`; the
    /// adaptation to a second subject is then left out.
    #[arg(long, requires = "mesh")]
    poses: Option<PathBuf>,
    /// The mandible mesh of `--poses` (lower frame).
    #[arg(long, requires = "poses")]
    mesh: Option<PathBuf>,
    /// Random rig poses for Fig. 13.
    #[arg(long, default_value_t = 1000)]
    samples: usize,
    /// IK queries to time.
    #[arg(long, default_value_t = 1000)]
    ik_queries: usize,
    /// Write the figures (SVG, JSON) here.
    #[arg(long)]
    plots: Option<PathBuf>,
    /// Print JSON instead of a table.
    #[arg(long)]
    json: bool,
}

#[derive(Serialize)]
struct RigBench {
    poses: usize,
    /// Reading the poses file, jaw poses from upper/lower (Eq. 1-3) and the se(3) log of each.
    extraction_ms: f64,
    /// Learning the rig (its modes and, coupled, their couplings).
    learn_seconds: f64,
    /// Learning the paper's five-component NLPCA and D23/D45 as well (for the figures).
    paper_seconds: f64,
    ik_ms_per_query: f64,
    ik_mean_residual_mm: f64,
    eval: jawtrack::rig::eval::EvalReport,
    /// Every rig on the same poses (`rig compare`).
    compare: Vec<jawtrack::envelope::compare::Row>,
    /// The envelope rig adapted to a second subject (another joint) from five of its poses,
    /// scored over all of its motion.
    adaptation: Vec<AdaptRow>,
}

#[derive(Serialize)]
struct AdaptRow {
    name: &'static str,
    max_vertex_mm: jawtrack::stats::Stats,
    front_weighted_mm: jawtrack::stats::Stats,
}

pub fn rig(a: RigArgs) -> anyhow::Result<()> {
    let dir = tempfile::tempdir().context("creating a temporary folder")?;
    let (poses_path, mesh_path) = motion_files(&a, dir.path())?;
    let (mandible, metric) = crate::cli::args::load_mesh(&mesh_path)?;
    let (poses, extraction_ms) = extract_poses(&poses_path, &metric)?;
    let rig = learn_rig(&poses.poses, &metric, a.seed)?;
    let (ik_ms, ik_residual) = time_ik(&rig, &metric, a.ik_queries, a.seed);
    let eval = jawtrack::rig::eval::report(&rig, &poses.poses, &metric, a.samples, a.seed, true)?;
    if let Some(p) = &a.plots {
        jawtrack::rig::plot::write_figures(p, &eval.reconstruction, eval.sampled.as_ref())?;
    }
    let frame = jawtrack::envelope::JawFrame::from_mesh(&mandible, None, None)?;
    let compare = jawtrack::envelope::compare::compare(&poses.poses, &frame, &metric)?;
    let adaptation = if a.poses.is_none() {
        adapt_to_variant(&poses.poses, &frame, &metric, &a, dir.path())?
    } else {
        Vec::new()
    };
    let report = RigBench {
        poses: poses.len(),
        extraction_ms,
        learn_seconds: rig.training.modes.seconds
            + rig.training.couplings.as_ref().map_or(0.0, |c| c.seconds),
        paper_seconds: [
            &rig.training.network,
            &rig.training.lateral,
            &rig.training.protrusion,
        ]
        .iter()
        .filter_map(|r| r.as_ref().map(|r| r.seconds))
        .sum(),
        ik_ms_per_query: ik_ms,
        ik_mean_residual_mm: ik_residual,
        eval,
        compare,
        adaptation,
    };
    if a.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
        return Ok(());
    }
    print_report(&a, &report, &metric);
    Ok(())
}

/// The poses file and mandible mesh to learn from: `--poses` and `--mesh`, or synthetic TMJ
/// motion written to `dir`.
fn motion_files(a: &RigArgs, dir: &Path) -> anyhow::Result<(PathBuf, PathBuf)> {
    let capture = dir.join("motion");
    let opts = SynthOptions {
        frames: a.frames,
        seed: a.seed,
        meshes: a.meshes.clone(),
        no_masks: true,
        ..Default::default()
    };
    Ok(match (&a.poses, &a.mesh) {
        (Some(p), Some(m)) => (p.clone(), m.clone()),
        _ => {
            generate(&capture, &opts, &|| {}).context("synthesising the motion")?;
            (
                capture.join("gt/poses.json"),
                capture.join("meshes/mandible.obj"),
            )
        }
    })
}

/// Reads the jaw poses and takes the se(3) log of each: the poses and the time it took (ms).
fn extract_poses(path: &Path, metric: &MeshMetric) -> anyhow::Result<(JawPoses, f64)> {
    let t = Instant::now();
    let poses = read_jaw_poses(path)?;
    let coords = jawtrack::anatomy::Coordinates::for_mesh(metric);
    let vectors: Vec<_> = poses.poses.iter().map(|p| coords.vector(p)).collect();
    let extraction_ms = t.elapsed().as_secs_f64() * 1e3;
    std::hint::black_box(vectors);
    Ok((poses, extraction_ms))
}

/// Learns the rig from the poses, the paper's networks included, every network seeded with
/// `seed`.
fn learn_rig(
    poses: &[jawtrack::geometry::Pose],
    metric: &MeshMetric,
    seed: u64,
) -> anyhow::Result<JawRig> {
    let mut settings = RigSettings::default();
    settings.network.seed = seed;
    settings.mode.seed = seed;
    settings.modes.seed = seed;
    settings.couplings.seed = seed;
    settings.paper = true;
    let rig = crate::cli::run::with_progress("learning the rig", |progress| {
        JawRig::learn(poses, metric, &settings, progress)
    })?;
    Ok(rig)
}

/// Prints the bench's figures: timings, the rig's evaluation, the comparison of rigs and the
/// adaptation to a second subject when there is one.
fn print_report(a: &RigArgs, report: &RigBench, metric: &MeshMetric) {
    let source = match &a.poses {
        Some(p) => p.display().to_string(),
        None => format!("synthetic TMJ motion (seed {})", a.seed),
    };
    println!(
        "{source}: {} poses, mandible of {} vertices; machine: {} cores",
        report.poses,
        metric.vertex_count(),
        std::thread::available_parallelism().map_or(1, |n| n.get())
    );
    println!(
        "relative poses + se(3) for all poses: {:.1} ms; learning the rig: {:.2} s (the paper's networks, for the figures: {:.2} s more); IK: {:.3} ms a query (mean residual {:.3} mm over {} reachable targets)",
        report.extraction_ms,
        report.learn_seconds,
        report.paper_seconds,
        report.ik_ms_per_query,
        report.ik_mean_residual_mm,
        a.ik_queries
    );
    crate::cli::report::rig_eval(&report.eval);
    println!();
    crate::cli::report::rig_compare(report.poses, metric.vertex_count(), &report.compare);
    if report.adaptation.is_empty() {
        return;
    }
    println!();
    println!(
        "adaptation to a second subject (`synth --joint variant`, same teeth), from its five extremal poses; error over its whole motion ({} poses):",
        a.frames
    );
    println!(
        "rig                                   max: mean      p95      max   front-weighted: mean"
    );
    for r in &report.adaptation {
        println!(
            "{:<36} {:>10.3} {:>8.3} {:>8.3} {:>22.3}",
            r.name,
            r.max_vertex_mm.mean,
            r.max_vertex_mm.p95,
            r.max_vertex_mm.max,
            r.front_weighted_mm.mean
        );
    }
}

/// IK queries towards targets the rig can reach (a mesh vertex under a random valid pose),
/// each from the rest parameters: time per query and mean residual.
fn time_ik(rig: &JawRig, metric: &MeshMetric, queries: usize, seed: u64) -> (f64, f64) {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed ^ 0x1c);
    let point = metric.probes()[0];
    let targets: Vec<_> = (0..queries)
        .map(|_| {
            rig.pose(&rig.ranges.sample_dynamic(&mut rng))
                .transform_point(&point)
        })
        .collect();
    let t = Instant::now();
    let residual: f64 = targets
        .iter()
        .map(|target| {
            // The targets are the rig's own poses of a mesh point: finite, within reach.
            jawtrack::rig::ik::solve(rig, &point, target, &[0.0; 3], &Default::default())
                .map_or(f64::NAN, |r| r.residual_mm)
        })
        .sum();
    let n = queries.max(1) as f64;
    (t.elapsed().as_secs_f64() * 1e3 / n, residual / n)
}

/// Subject B: the same teeth, another joint. Adapt A's envelope rig to B from B's five extremal
/// poses (reduced and full) and score each over all of B's motion, with A's rig as it is and
/// B's own rig (learned from all its poses) for reference.
fn adapt_to_variant(
    poses_a: &[jawtrack::geometry::Pose],
    frame_a: &jawtrack::envelope::JawFrame,
    metric_a: &MeshMetric,
    a: &RigArgs,
    dir: &std::path::Path,
) -> anyhow::Result<Vec<AdaptRow>> {
    use jawtrack::envelope::adapt::{Adaptation, adapt, extremal_poses};
    use jawtrack::envelope::{EnvelopeRig, JawFrame, compare::front_weights};
    let capture = dir.join("variant");
    let opts = SynthOptions {
        frames: a.frames,
        seed: a.seed,
        meshes: a.meshes.clone(),
        no_masks: true,
        joint: jawtrack::synth::Joint::Variant,
        ..Default::default()
    };
    generate(&capture, &opts, &|| {}).context("synthesising the second subject")?;
    let (mesh_b, metric_b) = crate::cli::args::load_mesh(&capture.join("meshes/mandible.obj"))?;
    let frame_b = JawFrame::from_mesh(&mesh_b, None, None)?;
    let poses_b = read_jaw_poses(&capture.join("gt/poses.json"))?.poses;
    let measured = extremal_poses(&poses_b, &frame_b);
    let source = EnvelopeRig::learn(poses_a, frame_a, metric_a)?;
    let weights = front_weights(&metric_b, &frame_b);
    let score =
        |name: &'static str,
         rebuild: &dyn Fn(&jawtrack::geometry::Pose) -> jawtrack::geometry::Pose| {
            let (max, front): (Vec<f64>, Vec<f64>) = poses_b
                .iter()
                .map(|p| {
                    let q = rebuild(p);
                    (
                        metric_b.max_distance(p, &q),
                        metric_b.weighted_mean_distance(p, &q, &weights),
                    )
                })
                .unzip();
            AdaptRow {
                name,
                max_vertex_mm: jawtrack::stats::Stats::of(&max),
                front_weighted_mm: jawtrack::stats::Stats::of(&front),
            }
        };
    let reduced = adapt(&source, &measured, &frame_b, &metric_b, Adaptation::Reduced)?;
    let full = adapt(&source, &measured, &frame_b, &metric_b, Adaptation::Full)?;
    let own = EnvelopeRig::learn(&poses_b, &frame_b, &metric_b)?;
    Ok(vec![
        score("source rig, not adapted", &|p| source.reconstruct(p)),
        score("reduced adaptation (5 points)", &|p| reduced.reconstruct(p)),
        score("full adaptation (5 poses)", &|p| full.reconstruct(p)),
        score("rig learned from all its poses", &|p| own.reconstruct(p)),
    ])
}
