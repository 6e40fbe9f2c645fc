//! `rig learn`, `rig eval`, `rig compare`.

use std::path::PathBuf;

use anyhow::Context;
use jawtrack::formats::read_jaw_poses;
use jawtrack::rig::model::{NETWORK_COMPONENTS, RigModel};
use jawtrack::rig::{JawRig, RigSettings};
use serde::Serialize;

use crate::cli::args::load_mesh;

use super::load_poses;

#[derive(clap::Args)]
pub struct LearnArgs {
    /// Jaw poses: tracks.json (frames with status `ok`), gt/poses.json or a jawtrack-jaw/1 file.
    pub input: PathBuf,
    /// The mesh the error is measured on, in the lower arch's frame: a mandible (best: it
    /// includes the condyles) or the lower arch.
    #[arg(long)]
    pub mesh: PathBuf,
    /// Where to write the rig.
    #[arg(short, long)]
    pub out: PathBuf,
    /// Alpha radius of the valid-range shapes, in parameter units.
    #[arg(long, default_value_t = RigSettings::default().alpha, value_parser = crate::cli::args::number_in(1e-6, 100.0))]
    pub alpha: f64,
    /// The three-parameter model: the modes and their couplings, or the paper's sum (Eq. 5).
    #[arg(long, value_enum, default_value_t = Model::Coupled)]
    pub model: Model,
    /// Also learn the paper's five-component NLPCA and its D23/D45 construction (for the
    /// figures of `rig eval`; the rig does not need them, and they take most of the time).
    #[arg(long)]
    pub paper: bool,
    /// Seed of the networks' initial weights.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Training settings as JSON (fields of RigSettings; missing ones take their defaults):
    /// a file, or the JSON itself when it starts with `{`.
    #[arg(long)]
    pub settings: Option<PathBuf>,
    /// Print the summary as JSON.
    #[arg(long)]
    pub json: bool,
}

#[derive(clap::Args)]
pub struct EvalArgs {
    /// The rig file.
    pub rig: PathBuf,
    /// Jaw poses to reconstruct (usually the ones the rig was learned from).
    pub input: PathBuf,
    /// The mesh the error is measured on (lower arch frame).
    #[arg(long)]
    pub mesh: PathBuf,
    /// Write histograms (SVG) and their data (JSON) here.
    #[arg(long)]
    pub plots: Option<PathBuf>,
    /// Random rig poses for Fig. 13.
    #[arg(long, default_value_t = 1000, value_parser = crate::cli::args::count_in(1, 10_000_000))]
    pub samples: usize,
    /// Seed of the random rig poses.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Leave out the six-component NLPCA (trained here only for the figure).
    #[arg(long)]
    pub no_nlpca6: bool,
    /// Print the report as JSON.
    #[arg(long)]
    pub json: bool,
}

#[derive(clap::Args)]
pub struct CompareArgs {
    pub input: PathBuf,
    /// The mandible mesh (lower frame): jaw frame landmarks and the error metric.
    #[arg(long)]
    pub mesh: PathBuf,
    #[command(flatten)]
    pub landmarks: crate::cli::args::Landmarks,
    #[arg(long)]
    pub json: bool,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Model {
    Coupled,
    Additive,
}

#[derive(Serialize)]
struct LearnSummary<'a> {
    rig: String,
    model: &'static str,
    poses: usize,
    skipped: usize,
    read_seconds: f64,
    learn_seconds: f64,
    singular_values_mm: &'a [f64],
    /// The paper's network (`--paper`).
    network_unexplained: Option<&'a [f64]>,
    /// Share of the variance the rig leaves unexplained.
    unexplained: f64,
    d1_range: [f64; 2],
    bounds: [[f64; 2]; 3],
}

pub fn learn(a: LearnArgs) -> anyhow::Result<()> {
    let (poses, read_seconds) = load_poses(&a.input)?;
    let (mesh, metric) = load_mesh(&a.mesh)?;
    let mut settings = crate::cli::args::rig_settings(a.settings.as_deref())?;
    settings.alpha = a.alpha;
    settings.network.seed = a.seed;
    settings.mode.seed = a.seed;
    settings.modes.seed = a.seed;
    settings.couplings.seed = a.seed;
    settings.model = match a.model {
        Model::Coupled => RigModel::Coupled,
        Model::Additive => RigModel::Additive,
    };
    settings.paper |= a.paper;
    settings.validate(std::path::Path::new("--alpha"))?;
    let rig = crate::cli::run::with_progress("learning the rig", |progress| {
        JawRig::learn(&poses.poses, &metric, &settings, progress)
    })?
    .with_anatomy(&mesh, &poses.poses);
    rig.save(&a.out)?;
    let summary = LearnSummary {
        rig: a.out.display().to_string(),
        poses: poses.len(),
        skipped: poses.skipped,
        read_seconds,
        learn_seconds: rig.training.seconds,
        singular_values_mm: &rig.pca.singular_values,
        model: rig.model_name(),
        network_unexplained: rig
            .training
            .network
            .as_ref()
            .map(|n| n.unexplained.as_slice()),
        unexplained: rig
            .training
            .couplings
            .as_ref()
            .unwrap_or(&rig.training.modes)
            .unexplained,
        d1_range: rig.ranges.d1_range(),
        bounds: rig.ranges.bounds,
    };
    if a.json {
        println!("{}", serde_json::to_string_pretty(&summary)?);
        return Ok(());
    }
    println!(
        "learned {} from {} jaw poses ({} frames skipped: status not ok) in {:.2} s (poses read and mapped to se(3) in {:.1} ms)",
        a.out.display(),
        poses.len(),
        poses.skipped,
        rig.training.seconds,
        read_seconds * 1e3
    );
    println!(
        "PCA singular values (RMS mm-equivalent along each component): {}",
        fmt_list(&rig.pca.singular_values, 3)
    );
    println!(
        "the {} rig leaves {:.6} of the variance unexplained",
        summary.model, summary.unexplained
    );
    if let Some(u) = summary.network_unexplained {
        println!(
            "NLPCA-{NETWORK_COMPONENTS}: share of variance unexplained with 1..{NETWORK_COMPONENTS} components: {}",
            fmt_list(u, 6)
        );
    }
    let r = rig.ranges.d1_range();
    println!(
        "parameters: d1 (opening) {:.3}..{:.3}, d2 (lateral) {:.3}..{:.3}, d3 (protrusion) {:.3}..{:.3}; valid d1 {:.3}..{:.3} (alpha {})",
        rig.ranges.bounds[0][0],
        rig.ranges.bounds[0][1],
        rig.ranges.bounds[1][0],
        rig.ranges.bounds[1][1],
        rig.ranges.bounds[2][0],
        rig.ranges.bounds[2][1],
        r[0],
        r[1],
        rig.settings.alpha
    );
    Ok(())
}

fn fmt_list(v: &[f64], digits: usize) -> String {
    v.iter()
        .map(|x| format!("{x:.digits$}"))
        .collect::<Vec<_>>()
        .join(", ")
}

pub fn evaluate(a: EvalArgs) -> anyhow::Result<()> {
    let rig = JawRig::load(&a.rig)?;
    let (poses, _) = load_poses(&a.input)?;
    let (_, metric) = load_mesh(&a.mesh)?;
    let report = crate::cli::run::with_spinner("evaluating the rig", || {
        jawtrack::rig::eval::report(&rig, &poses.poses, &metric, a.samples, a.seed, !a.no_nlpca6)
    })?;
    if let Some(dir) = &a.plots {
        jawtrack::rig::plot::write_figures(dir, &report.reconstruction, report.sampled.as_ref())
            .with_context(|| format!("writing the figures to {}", dir.display()))?;
    }
    if a.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        crate::cli::report::rig_eval(&report);
        if let Some(dir) = &a.plots {
            println!("figures: {}", dir.display());
        }
    }
    Ok(())
}

pub fn compare(a: CompareArgs) -> anyhow::Result<()> {
    let poses = read_jaw_poses(&a.input)?;
    let (mesh, metric) = load_mesh(&a.mesh)?;
    let frame = a.landmarks.frame(&a.mesh, &mesh)?;
    let rows = jawtrack::envelope::compare::compare(&poses.poses, &frame, &metric)?;
    if a.json {
        println!("{}", serde_json::to_string_pretty(&rows)?);
        return Ok(());
    }
    crate::cli::report::rig_compare(poses.len(), metric.vertex_count(), &rows);
    Ok(())
}
