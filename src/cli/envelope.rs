//! `jawtrack envelope ...`: the empirical jaw rig on Posselt's envelope (Zoss et al. 2018).

use std::path::PathBuf;

use anyhow::bail;
use jawtrack::envelope::adapt::EXTREMES;

use super::args::{AdaptationArg, Landmarks};
use jawtrack::envelope::{EnvelopeRig, model::bijectivity};
use jawtrack::geometry::Pose;
use jawtrack::rig::eval::Series;
use nalgebra::Vector3;
use serde::Serialize;

#[derive(clap::Subcommand)]
pub enum Command {
    /// Learn an envelope rig from jaw poses (tracks.json, gt/poses.json or jawtrack-jaw/1).
    Learn(LearnArgs),
    /// The jaw pose for a reference-point position (direct manipulation; projected onto the
    /// envelope when outside) or for unit-cube sliders (JSON on stdout).
    #[command(allow_negative_numbers = true)]
    Pose(PoseArgs),
    /// Each pose through the rig: its reference point, projected, back to a pose.
    Reconstruct(ReconstructArgs),
    /// Reconstruction error and bijectivity (Eq. 15) on a set of poses.
    Eval(EvalArgs),
    /// Adapt a rig to a new subject from five measured extremal poses.
    Adapt(AdaptArgs),
}

#[derive(clap::Args)]
pub struct AdaptArgs {
    /// The source subject's envelope rig.
    pub envelope: PathBuf,
    /// The new subject's five extremal poses, in this order: open, left, right, front, back
    /// (tracks.json, gt/poses.json or jawtrack-jaw/1).
    #[arg(long)]
    pub poses: PathBuf,
    /// The new subject's mandible (lower frame).
    #[arg(long)]
    pub mesh: PathBuf,
    /// Reduced (only the reference points of the poses) or full (the whole poses).
    #[arg(long, value_enum, default_value_t = AdaptationArg::Full)]
    pub mode: AdaptationArg,
    #[arg(short, long)]
    pub out: PathBuf,
}

#[derive(clap::Args)]
pub struct LearnArgs {
    pub input: PathBuf,
    /// The mandible mesh (lower frame): its landmarks define the jaw frame, and errors are
    /// measured on it.
    #[arg(long)]
    pub mesh: PathBuf,
    #[arg(short, long)]
    pub out: PathBuf,
    #[command(flatten)]
    pub landmarks: Landmarks,
    /// Also write the envelope's surface (OBJ, upper frame at the neutral pose).
    #[arg(long)]
    pub surface: Option<PathBuf>,
}

#[derive(clap::Args)]
pub struct PoseArgs {
    pub envelope: PathBuf,
    /// Where the reference point should go, upper frame (mm): X,Y,Z.
    #[arg(long, value_parser = super::args::parse_vec3, conflicts_with = "cube", required_unless_present = "cube")]
    pub point: Option<[f64; 3]>,
    /// Unit-cube sliders: SX (left→right), SY (top→bottom), SZ (back→front), each in [0, 1].
    #[arg(long, value_parser = super::args::parse_vec3)]
    pub cube: Option<[f64; 3]>,
}

#[derive(clap::Args)]
pub struct ReconstructArgs {
    pub envelope: PathBuf,
    pub input: PathBuf,
    #[arg(short, long)]
    pub out: PathBuf,
}

#[derive(clap::Args)]
pub struct EvalArgs {
    pub envelope: PathBuf,
    pub input: PathBuf,
    #[arg(long)]
    pub mesh: PathBuf,
    /// Write histograms (SVG) and the data (JSON) here.
    #[arg(long)]
    pub plots: Option<PathBuf>,
    #[arg(long)]
    pub json: bool,
}

pub fn run(c: Command) -> anyhow::Result<()> {
    match c {
        Command::Learn(a) => learn(a),
        Command::Pose(a) => pose(a),
        Command::Reconstruct(a) => reconstruct(a),
        Command::Eval(a) => evaluate(a),
        Command::Adapt(a) => adapt(a),
    }
}

fn learn(a: LearnArgs) -> anyhow::Result<()> {
    let poses = jawtrack::formats::read_jaw_poses(&a.input)?;
    let (mesh, metric) = super::args::load_mesh(&a.mesh)?;
    let frame = a.landmarks.frame(&a.mesh, &mesh)?;
    let rig = EnvelopeRig::learn(&poses.poses, &frame, &metric)?;
    rig.save(&a.out)?;
    let s = &rig.shield;
    println!(
        "learned {} from {} jaw poses in {:.2} s: envelope {:.1} mm high, {:.1} mm wide at the top; {} RBF kernels",
        a.out.display(),
        rig.poses,
        rig.seconds,
        s.y_top - s.y_bottom,
        s.left[0] - s.right[0],
        rig.rbf.centres.len()
    );
    println!(
        "jaw frame: condyles {:?} / {:?}, reference point {:?} (lower frame, mm)",
        frame.condyle_left.map(|v| (v * 10.0).round() / 10.0),
        frame.condyle_right.map(|v| (v * 10.0).round() / 10.0),
        frame.reference.map(|v| (v * 10.0).round() / 10.0)
    );
    if let Some(path) = &a.surface {
        let mut surface = rig.shield.surface(16);
        for p in &mut surface.positions {
            let q = rig.to_upper(&Vector3::new(p[0] as f64, p[1] as f64, p[2] as f64));
            *p = [q.x as f32, q.y as f32, q.z as f32];
        }
        jawtrack::mesh::write_obj(&surface, path)?;
        println!("envelope surface: {}", path.display());
    }
    Ok(())
}

#[derive(Serialize)]
struct PoseReport {
    /// The reference point used (upper frame, mm), after projection.
    point: [f64; 3],
    /// Its unit-cube coordinates.
    cube: [f64; 3],
    /// Whether the requested point was inside the envelope.
    inside: bool,
    pose: jawtrack::formats::PoseJson,
}

fn pose(a: PoseArgs) -> anyhow::Result<()> {
    let rig = EnvelopeRig::load(&a.envelope)?;
    let (requested, inside) = match (a.point, a.cube) {
        (Some(x), _) => {
            let p = rig.from_upper(&Vector3::from(x));
            (p, rig.shield.contains(&p))
        }
        (None, Some(s)) => {
            if s.iter().any(|v| !(0.0..=1.0).contains(v)) {
                bail!("--cube: each slider must be in [0, 1], found {s:?}");
            }
            (rig.shield.point(&s), true)
        }
        _ => bail!("give --point X,Y,Z or --cube SX,SY,SZ"),
    };
    let p = rig.shield.project(&requested);
    let report = PoseReport {
        point: rig.to_upper(&p).into(),
        cube: rig.shield.cube(&p),
        inside,
        pose: (&rig.pose_at(&p)).into(),
    };
    println!("{}", serde_json::to_string_pretty(&report)?);
    Ok(())
}

fn reconstruct(a: ReconstructArgs) -> anyhow::Result<()> {
    let rig = EnvelopeRig::load(&a.envelope)?;
    let poses = jawtrack::formats::read_jaw_poses(&a.input)?;
    let out: Vec<Pose> = poses.poses.iter().map(|p| rig.reconstruct(p)).collect();
    let outside = poses
        .poses
        .iter()
        .filter(|p| !rig.shield.contains(&rig.point_of(p)))
        .count();
    jawtrack::formats::write_jaw_poses(&a.out, &poses.frames, &out)?;
    println!(
        "wrote {} reconstructed poses to {} ({} reference points were outside the envelope and projected)",
        out.len(),
        a.out.display(),
        outside
    );
    Ok(())
}

#[derive(Serialize)]
struct EvalReport {
    poses: usize,
    reconstruction: Series,
    front_weighted: Series,
    /// Eq. 15 per pose (k = 10, σ = 1 mm).
    bijectivity: Series,
}

fn evaluate(a: EvalArgs) -> anyhow::Result<()> {
    let rig = EnvelopeRig::load(&a.envelope)?;
    let poses = jawtrack::formats::read_jaw_poses(&a.input)?;
    let (_, metric) = super::args::load_mesh(&a.mesh)?;
    let weights = jawtrack::envelope::compare::front_weights(&metric, &rig.six.frame);
    let rebuilt: Vec<Pose> = poses.poses.iter().map(|p| rig.reconstruct(p)).collect();
    let report = EvalReport {
        poses: poses.len(),
        reconstruction: Series::new(
            "largest vertex distance",
            poses
                .poses
                .iter()
                .zip(&rebuilt)
                .map(|(p, q)| metric.max_distance(p, q))
                .collect(),
        ),
        front_weighted: Series::new(
            "front-weighted mean distance",
            poses
                .poses
                .iter()
                .zip(&rebuilt)
                .map(|(p, q)| metric.weighted_mean_distance(p, q, &weights))
                .collect(),
        ),
        bijectivity: Series::new(
            "bijectivity d_i (Eq. 15)",
            bijectivity(&rig, &poses.poses, &metric, 10, 1.0),
        ),
    };
    if let Some(dir) = &a.plots {
        jawtrack::rig::plot::histograms(
            &dir.join("envelope.svg"),
            "Envelope rig: reconstruction error and bijectivity",
            &[&report.reconstruction, &report.bijectivity],
        )?;
        jawtrack::io::write_json_atomic(&dir.join("envelope.json"), &report)?;
    }
    if a.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
        return Ok(());
    }
    println!("{} poses through the envelope rig (mm):", report.poses);
    println!("measure                               mean   median      p95      max");
    for s in [
        &report.reconstruction,
        &report.front_weighted,
        &report.bijectivity,
    ] {
        println!(
            "{:<34} {:>7.3} {:>8.3} {:>8.3} {:>8.3}",
            s.name, s.stats.mean, s.stats.median, s.stats.p95, s.stats.max
        );
    }
    Ok(())
}

fn adapt(a: AdaptArgs) -> anyhow::Result<()> {
    let source = EnvelopeRig::load(&a.envelope)?;
    let poses = jawtrack::formats::read_jaw_poses(&a.poses)?;
    let measured: [Pose; 5] = poses.poses.as_slice().try_into().map_err(|_| {
        anyhow::anyhow!(
            "{}: expected exactly five poses ({}), found {}",
            a.poses.display(),
            EXTREMES.join(", "),
            poses.len()
        )
    })?;
    let (mesh, metric) = super::args::load_mesh(&a.mesh)?;
    let frame = Landmarks::default().frame(&a.mesh, &mesh)?;
    let rig = jawtrack::envelope::adapt::adapt(&source, &measured, &frame, &metric, a.mode.into())?;
    rig.save(&a.out)?;
    println!(
        "adapted {} to the new subject ({} adaptation, five poses: {}) in {:.2} s: {}",
        a.envelope.display(),
        crate::cli::args::name_of(&a.mode),
        EXTREMES.join(", "),
        rig.seconds,
        a.out.display()
    );
    Ok(())
}
