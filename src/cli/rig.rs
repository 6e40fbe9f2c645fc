//! `jawtrack rig ...`: learn the three-parameter jaw rig and use it.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, bail};
use jawtrack::anatomy::MeshMetric;
use jawtrack::capture::{BoiSource, Mesh};
use jawtrack::geometry::Pose;
use jawtrack::rig::eval::{self, Reconstruction, Sampled, Series};
use jawtrack::rig::model::NETWORK_COMPONENTS;
use jawtrack::rig::{JawPoses, JawRig, Nlpca, RigSettings, read_jaw_poses};
use serde::Serialize;

#[derive(clap::Subcommand)]
pub enum Command {
    /// Learn a rig from jaw poses (a tracks.json, gt/poses.json or jawtrack-jaw/1 file).
    #[command(allow_negative_numbers = true)]
    Learn(LearnArgs),
    /// The paper's figures for a rig on a set of poses: reconstruction error of PCA, NLPCA and
    /// the rig (Fig. 12) and random rig poses against the captured ones (Fig. 13).
    Eval(EvalArgs),
    /// The jaw pose for parameters d1 (opening), d2 (lateral), d3 (protrusion), and whether
    /// they are valid (JSON on stdout).
    #[command(allow_negative_numbers = true)]
    Pose(PoseArgs),
    /// The parameters of every pose of a file.
    Encode(EncodeArgs),
    /// Each pose through the rig: encode, clamp into the valid ranges, decode (a jaw-pose file).
    Reconstruct(ReconstructArgs),
    /// Inverse kinematics: the valid parameters that bring a mesh point closest to a target.
    #[command(allow_negative_numbers = true)]
    Ik(IkArgs),
    /// Keyframe animation: key parameters at times, linearly interpolated, as jaw poses (and
    /// optionally posed meshes).
    #[command(allow_negative_numbers = true)]
    Animate(AnimateArgs),
    /// Random valid rig poses (the d1-dependent ranges, or the fixed ones).
    Sample(SampleArgs),
    /// Every rig on the same poses: traditional 1/3/5-DOF, PCA-3, the NLPCA rig, the envelope
    /// rig.
    Compare(CompareArgs),
}

#[derive(clap::Args)]
pub struct CompareArgs {
    pub input: PathBuf,
    /// The mandible mesh (lower frame): jaw frame landmarks and the error metric.
    #[arg(long)]
    pub mesh: PathBuf,
    #[command(flatten)]
    pub landmarks: super::envelope::Landmarks,
    #[arg(long)]
    pub json: bool,
}

#[derive(clap::Args)]
pub struct PoseArgs {
    pub rig: PathBuf,
    pub d1: f64,
    pub d2: f64,
    pub d3: f64,
    /// Clamp the parameters into the valid ranges before posing.
    #[arg(long)]
    pub clamp: bool,
}

#[derive(clap::Args)]
pub struct EncodeArgs {
    pub rig: PathBuf,
    /// Jaw poses: tracks.json, gt/poses.json or a jawtrack-jaw/1 file.
    pub input: PathBuf,
    /// Where to write the parameters (JSON).
    #[arg(short, long)]
    pub out: PathBuf,
}

#[derive(clap::Args)]
pub struct ReconstructArgs {
    pub rig: PathBuf,
    pub input: PathBuf,
    /// Where to write the reconstructed jaw poses (jawtrack-jaw/1).
    #[arg(short, long)]
    pub out: PathBuf,
}

#[derive(clap::Args)]
pub struct IkArgs {
    pub rig: PathBuf,
    /// The point to move, lower frame (mm): X,Y,Z.
    #[arg(long, value_parser = parse_vec3, conflicts_with = "vertex")]
    pub point: Option<[f64; 3]>,
    /// Or a vertex of --mesh.
    #[arg(long, requires = "mesh")]
    pub vertex: Option<usize>,
    /// The mesh --vertex refers to (lower frame).
    #[arg(long)]
    pub mesh: Option<PathBuf>,
    /// Where the point should go, upper frame (mm): X,Y,Z.
    #[arg(long, value_parser = parse_vec3)]
    pub target: [f64; 3],
    /// The current parameters: D1,D2,D3.
    #[arg(long, value_parser = parse_vec3, default_value = "0,0,0")]
    pub from: [f64; 3],
}

#[derive(clap::Args)]
pub struct AnimateArgs {
    pub rig: PathBuf,
    /// A key: TIME:D1,D2,D3 (seconds, parameters); repeat for each key.
    #[arg(long = "key", value_parser = parse_key)]
    pub keys: Vec<jawtrack::rig::animate::Key>,
    /// Or a JSON file: [{"time": 0.0, "params": [d1, d2, d3]}, ...].
    #[arg(long, conflicts_with = "keys")]
    pub keys_file: Option<PathBuf>,
    /// Frames per second.
    #[arg(long, default_value_t = 24.0)]
    pub fps: f64,
    /// Where to write the jaw poses (jawtrack-jaw/1).
    #[arg(short, long)]
    pub out: PathBuf,
    /// Also write the posed mesh of every frame here (OBJ, upper frame), from --mesh.
    #[arg(long, requires = "mesh")]
    pub obj_dir: Option<PathBuf>,
    /// The mesh to pose (lower frame).
    #[arg(long)]
    pub mesh: Option<PathBuf>,
}

#[derive(clap::Args)]
pub struct SampleArgs {
    pub rig: PathBuf,
    /// How many poses.
    #[arg(short = 'n', long, default_value_t = 1000)]
    pub count: usize,
    /// Draw each parameter over its own fixed range instead of the d1-dependent ones.
    #[arg(long)]
    pub fixed_ranges: bool,
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Where to write the poses (jawtrack-jaw/1); their parameters go beside it
    /// (`.params.json`).
    #[arg(short, long)]
    pub out: PathBuf,
}

pub(crate) fn parse_vec3(s: &str) -> Result<[f64; 3], String> {
    let v: Vec<f64> = s
        .split(',')
        .map(|p| p.trim().parse::<f64>().map_err(|e| format!("{p:?}: {e}")))
        .collect::<Result<_, _>>()?;
    match v.as_slice() {
        [a, b, c] if v.iter().all(|x| x.is_finite()) => Ok([*a, *b, *c]),
        _ => Err(format!("expected three finite numbers X,Y,Z, found {s:?}")),
    }
}

fn parse_key(s: &str) -> Result<jawtrack::rig::animate::Key, String> {
    let (t, d) = s
        .split_once(':')
        .ok_or_else(|| format!("expected TIME:D1,D2,D3, found {s:?}"))?;
    Ok(jawtrack::rig::animate::Key {
        time: t.trim().parse().map_err(|e| format!("time {t:?}: {e}"))?,
        params: parse_vec3(d)?,
    })
}

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
    #[arg(long, default_value_t = RigSettings::default().alpha)]
    pub alpha: f64,
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
    #[arg(long, default_value_t = 1000)]
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

pub fn run(c: Command) -> anyhow::Result<()> {
    match c {
        Command::Learn(a) => learn(a),
        Command::Eval(a) => evaluate(a),
        Command::Pose(a) => pose(a),
        Command::Encode(a) => encode(a),
        Command::Reconstruct(a) => reconstruct(a),
        Command::Ik(a) => ik(a),
        Command::Animate(a) => animate(a),
        Command::Sample(a) => sample(a),
        Command::Compare(a) => compare(a),
    }
}

pub(crate) fn load_mesh(path: &Path) -> anyhow::Result<(Mesh, MeshMetric)> {
    let mesh = Mesh::load(path, BoiSource::None)
        .with_context(|| format!("reading the mesh {}", path.display()))?;
    let metric = MeshMetric::new(&mesh);
    Ok((mesh, metric))
}

fn load_poses(path: &Path) -> anyhow::Result<(JawPoses, f64)> {
    let started = Instant::now();
    let poses = read_jaw_poses(path)?;
    Ok((poses, started.elapsed().as_secs_f64()))
}

#[derive(Serialize)]
struct LearnSummary<'a> {
    rig: String,
    poses: usize,
    skipped: usize,
    read_seconds: f64,
    learn_seconds: f64,
    singular_values_mm: &'a [f64],
    network_unexplained: &'a [f64],
    iterations: [u64; 3],
    d1_range: [f64; 2],
    bounds: [[f64; 2]; 3],
}

/// Learn a rig from poses and a mesh metric; shared with the demo.
pub(crate) fn learn_rig(
    poses: &JawPoses,
    metric: &MeshMetric,
    settings: &RigSettings,
) -> anyhow::Result<JawRig> {
    Ok(JawRig::learn(&poses.poses, metric, settings)?)
}

fn learn(a: LearnArgs) -> anyhow::Result<()> {
    let (poses, read_seconds) = load_poses(&a.input)?;
    let (_, metric) = load_mesh(&a.mesh)?;
    let mut settings: RigSettings = match &a.settings {
        Some(p) => super::read_settings(p, "rig settings")?,
        None => RigSettings::default(),
    };
    settings.alpha = a.alpha;
    settings.network.seed = a.seed;
    settings.mode.seed = a.seed;
    settings.modes.seed = a.seed;
    if !(settings.alpha.is_finite() && settings.alpha > 0.0) {
        bail!(
            "--alpha must be a positive number, found {}",
            settings.alpha
        );
    }
    let rig = learn_rig(&poses, &metric, &settings)?;
    rig.save(&a.out)?;
    let summary = LearnSummary {
        rig: a.out.display().to_string(),
        poses: poses.len(),
        skipped: poses.skipped,
        read_seconds,
        learn_seconds: rig.training.seconds,
        singular_values_mm: &rig.pca.singular_values,
        network_unexplained: &rig.training.network.unexplained,
        iterations: [
            rig.training.network.iterations,
            rig.training.lateral.iterations,
            rig.training.protrusion.iterations,
        ],
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
        "NLPCA-{NETWORK_COMPONENTS}: share of variance unexplained with 1..{NETWORK_COMPONENTS} components: {}",
        fmt_list(&rig.training.network.unexplained, 6)
    );
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

#[derive(Serialize)]
pub(crate) struct EvalReport {
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

/// The figures for `rig` on `poses`; shared with the demo and the benchmark.
pub(crate) fn evaluate_rig(
    rig: &JawRig,
    poses: &[Pose],
    metric: &MeshMetric,
    samples: usize,
    seed: u64,
    nlpca6: bool,
) -> anyhow::Result<EvalReport> {
    let started = Instant::now();
    let six = if nlpca6 {
        let samples: Vec<Vec<f64>> = poses
            .iter()
            .map(|p| rig.coords.vector(p).as_slice().to_vec())
            .collect();
        Some(
            Nlpca::train(&samples, 6, &rig.settings.network)
                .context("training the six-component NLPCA")?
                .0,
        )
    } else {
        None
    };
    let reconstruction = eval::reconstruction(rig, poses, metric, six.as_ref());
    let sampled = (samples > 0).then(|| eval::sampled(rig, poses, metric, samples, seed));
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

pub(crate) fn print_eval(r: &EvalReport) {
    println!(
        "reconstruction error of {} poses: largest vertex distance on a mesh of {} vertices (mm)",
        r.poses, r.mesh_vertices
    );
    println!("model            mean   median      p95      max");
    let row = |s: &Series| {
        println!(
            "{:<14} {:>6.3} {:>8.3} {:>8.3} {:>8.3}",
            s.name, s.stats.mean, s.stats.median, s.stats.p95, s.stats.max
        )
    };
    let rec = &r.reconstruction;
    rec.pca.iter().for_each(row);
    row(&rec.pca3_plain);
    rec.nlpca.iter().for_each(row);
    row(&rec.rig);
    row(&rec.rig_clamped);
    row(&rec.paper_rig);
    println!(
        "{:.1}% of the poses encode inside the valid ranges; encoding {:.3} ms a pose, decoding {:.2} µs",
        100.0 * rec.valid_share,
        r.encode_ms,
        r.decode_us
    );
    if let Some(s) = &r.sampled {
        println!(
            "{} random rig poses, distance to the nearest captured pose (mm):",
            s.dynamic_ranges.errors_mm.len()
        );
        row(&s.dynamic_ranges);
        row(&s.static_ranges);
    }
}

fn evaluate(a: EvalArgs) -> anyhow::Result<()> {
    let rig = JawRig::load(&a.rig)?;
    let (poses, _) = load_poses(&a.input)?;
    let (_, metric) = load_mesh(&a.mesh)?;
    let report = evaluate_rig(&rig, &poses.poses, &metric, a.samples, a.seed, !a.no_nlpca6)?;
    if let Some(dir) = &a.plots {
        jawtrack::rig::plot::write_figures(dir, &report.reconstruction, report.sampled.as_ref())
            .with_context(|| format!("writing the figures to {}", dir.display()))?;
    }
    if a.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        print_eval(&report);
        if let Some(dir) = &a.plots {
            println!("figures: {}", dir.display());
        }
    }
    Ok(())
}

#[derive(Serialize)]
struct PoseReport {
    params: [f64; 3],
    valid: bool,
    /// The nearest valid parameters (equal to `params` when they are valid).
    valid_params: [f64; 3],
    /// upper_from_lower for `params` (or `valid_params` with --clamp).
    pose: jawtrack::capture::json::PoseJson,
}

fn pose(a: PoseArgs) -> anyhow::Result<()> {
    let rig = JawRig::load(&a.rig)?;
    let d = [a.d1, a.d2, a.d3];
    if d.iter().any(|v| !v.is_finite()) {
        bail!("the parameters must be finite numbers");
    }
    let valid_params = rig.clamp(&d);
    let used = if a.clamp { valid_params } else { d };
    let report = PoseReport {
        params: d,
        valid: rig.is_valid(&d),
        valid_params,
        pose: (&rig.pose(&used)).into(),
    };
    println!("{}", serde_json::to_string_pretty(&report)?);
    Ok(())
}

#[derive(Serialize)]
struct EncodedFrame {
    frame: u32,
    params: [f64; 3],
    valid: bool,
    /// Largest distance of the rig's probe points (extreme mesh vertices) between the pose
    /// and the rig's pose for `params` (mm).
    probe_error_mm: f64,
}

#[derive(Serialize)]
struct EncodedFile {
    format: &'static str,
    rig: String,
    frames: Vec<EncodedFrame>,
}

fn probe_metric(rig: &JawRig) -> MeshMetric {
    MeshMetric::from_points(
        rig.probes_mm
            .iter()
            .map(|p| nalgebra::Vector3::from(*p))
            .collect(),
    )
}

fn encode(a: EncodeArgs) -> anyhow::Result<()> {
    let rig = JawRig::load(&a.rig)?;
    let (poses, _) = load_poses(&a.input)?;
    let probes = probe_metric(&rig);
    let frames: Vec<EncodedFrame> = poses
        .frames
        .iter()
        .zip(&poses.poses)
        .map(|(&frame, p)| {
            let params = rig.encode(p);
            EncodedFrame {
                frame,
                params,
                valid: rig.is_valid(&params),
                probe_error_mm: probes.max_distance(p, &rig.pose(&params)),
            }
        })
        .collect();
    let valid = frames.iter().filter(|f| f.valid).count();
    let mean = frames.iter().map(|f| f.probe_error_mm).sum::<f64>() / frames.len().max(1) as f64;
    jawtrack::capture::write_json_atomic(
        &a.out,
        &EncodedFile {
            format: "jawtrack-rig-params/1",
            rig: a.rig.display().to_string(),
            frames,
        },
    )?;
    println!(
        "encoded {} poses into {} ({} valid; mean probe error {:.3} mm)",
        poses.len(),
        a.out.display(),
        valid,
        mean
    );
    Ok(())
}

fn reconstruct(a: ReconstructArgs) -> anyhow::Result<()> {
    let rig = JawRig::load(&a.rig)?;
    let (poses, _) = load_poses(&a.input)?;
    let probes = probe_metric(&rig);
    let mut clamped = 0;
    let mut worst: f64 = 0.0;
    let out: Vec<Pose> = poses
        .poses
        .iter()
        .map(|p| {
            let d = rig.encode(p);
            let c = rig.clamp(&d);
            clamped += (c != d) as usize;
            let q = rig.pose(&c);
            worst = worst.max(probes.max_distance(p, &q));
            q
        })
        .collect();
    jawtrack::rig::write_jaw_poses(&a.out, &poses.frames, &out)?;
    println!(
        "wrote {} reconstructed poses to {} ({} clamped into the valid ranges; largest probe error {:.3} mm)",
        out.len(),
        a.out.display(),
        clamped,
        worst
    );
    Ok(())
}

#[derive(Serialize)]
struct IkReport {
    #[serde(flatten)]
    result: jawtrack::rig::ik::IkResult,
    valid: bool,
    milliseconds: f64,
    pose: jawtrack::capture::json::PoseJson,
}

fn ik(a: IkArgs) -> anyhow::Result<()> {
    let rig = JawRig::load(&a.rig)?;
    let point = match (a.point, a.vertex, &a.mesh) {
        (Some(p), _, _) => nalgebra::Vector3::from(p),
        (None, Some(v), Some(mesh)) => {
            let (m, _) = load_mesh(mesh)?;
            let p = m.positions.get(v).with_context(|| {
                format!(
                    "{}: --vertex {v}: the mesh has {} vertices",
                    mesh.display(),
                    m.positions.len()
                )
            })?;
            nalgebra::Vector3::new(p[0] as f64, p[1] as f64, p[2] as f64)
        }
        _ => bail!("give the point to move: --point X,Y,Z or --vertex I --mesh MESH"),
    };
    let started = Instant::now();
    let result = jawtrack::rig::ik::solve(
        &rig,
        &point,
        &nalgebra::Vector3::from(a.target),
        &a.from,
        &Default::default(),
    );
    let milliseconds = started.elapsed().as_secs_f64() * 1e3;
    let report = IkReport {
        valid: rig.is_valid(&result.params),
        pose: (&rig.pose(&result.params)).into(),
        result,
        milliseconds,
    };
    println!("{}", serde_json::to_string_pretty(&report)?);
    Ok(())
}

fn animate(a: AnimateArgs) -> anyhow::Result<()> {
    use jawtrack::rig::animate::{Key, animate};
    let rig = JawRig::load(&a.rig)?;
    let keys: Vec<Key> = match &a.keys_file {
        Some(p) => jawtrack::capture::json::read_json(p, "keys file")?,
        None => a.keys.clone(),
    };
    let frames = animate(&rig, &keys, a.fps).map_err(|e| match &a.keys_file {
        Some(p) => anyhow::anyhow!("{}: {e}", p.display()),
        None => anyhow::anyhow!("--key: {e}"),
    })?;
    let numbers: Vec<u32> = frames.iter().map(|f| f.frame).collect();
    let poses: Vec<Pose> = frames.iter().map(|f| f.pose).collect();
    jawtrack::rig::write_jaw_poses(&a.out, &numbers, &poses)?;
    if let (Some(dir), Some(mesh)) = (&a.obj_dir, &a.mesh) {
        let (m, _) = load_mesh(mesh)?;
        for f in &frames {
            let mut posed = m.clone();
            for p in &mut posed.positions {
                let q = f.pose.transform_point(&nalgebra::Vector3::new(
                    p[0] as f64,
                    p[1] as f64,
                    p[2] as f64,
                ));
                *p = [q.x as f32, q.y as f32, q.z as f32];
            }
            jawtrack::capture::mesh::write_obj(&posed, &dir.join(format!("{:06}.obj", f.frame)))?;
        }
    }
    let clamped = frames.iter().filter(|f| f.clamped).count();
    println!(
        "wrote {} frames ({:.2} s at {} fps) to {}{}; {} frames clamped into the valid ranges",
        frames.len(),
        frames.len() as f64 / a.fps,
        a.fps,
        a.out.display(),
        a.obj_dir
            .as_ref()
            .map(|d| format!(" and posed meshes to {}", d.display()))
            .unwrap_or_default(),
        clamped
    );
    Ok(())
}

fn sample(a: SampleArgs) -> anyhow::Result<()> {
    use rand::SeedableRng;
    let rig = JawRig::load(&a.rig)?;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(a.seed);
    let params: Vec<[f64; 3]> = (0..a.count)
        .map(|_| {
            if a.fixed_ranges {
                rig.ranges.sample_static(&mut rng)
            } else {
                rig.ranges.sample_dynamic(&mut rng)
            }
        })
        .collect();
    let poses: Vec<Pose> = params.iter().map(|d| rig.pose(d)).collect();
    let frames: Vec<u32> = (0..a.count as u32).collect();
    jawtrack::rig::write_jaw_poses(&a.out, &frames, &poses)?;
    let side = a.out.with_extension("params.json");
    jawtrack::capture::write_json_atomic(&side, &params)?;
    println!(
        "wrote {} random rig poses ({} ranges) to {} and their parameters to {}",
        a.count,
        if a.fixed_ranges {
            "fixed"
        } else {
            "d1-dependent"
        },
        a.out.display(),
        side.display()
    );
    Ok(())
}

fn compare(a: CompareArgs) -> anyhow::Result<()> {
    let poses = read_jaw_poses(&a.input)?;
    let (mesh, metric) = load_mesh(&a.mesh)?;
    let frame = a.landmarks.frame(&a.mesh, &mesh)?;
    let rows = jawtrack::envelope::compare::compare(&poses.poses, &frame, &metric)?;
    if a.json {
        println!("{}", serde_json::to_string_pretty(&rows)?);
        return Ok(());
    }
    print_compare(poses.len(), metric.vertex_count(), &rows);
    Ok(())
}

pub(crate) fn print_compare(
    poses: usize,
    vertices: usize,
    rows: &[jawtrack::envelope::compare::Row],
) {
    println!(
        "{poses} poses; errors on a mesh of {vertices} vertices (mm): largest vertex distance per pose, and the front-weighted mean distance"
    );
    println!(
        "rig                           params   max: mean      p95      max   front-weighted: mean      max   learn (s)"
    );
    for r in rows {
        println!(
            "{:<30} {:>5} {:>10.3} {:>8.3} {:>8.3} {:>22.3} {:>8.3} {:>11.2}",
            r.name,
            r.parameters,
            r.max_vertex_mm.mean,
            r.max_vertex_mm.p95,
            r.max_vertex_mm.max,
            r.front_weighted_mm.mean,
            r.front_weighted_mm.max,
            r.learn_seconds
        );
    }
}
