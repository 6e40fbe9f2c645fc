//! `rig pose`, `rig encode`, `rig reconstruct`, `rig ik`.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, bail};
use jawtrack::anatomy::MeshMetric;
use jawtrack::geometry::Pose;
use jawtrack::rig::JawRig;
use serde::Serialize;

use super::load_poses;
use crate::cli::args::{load_mesh, number_in, parse_vec3};

#[derive(clap::Args)]
pub struct PoseArgs {
    pub rig: PathBuf,
    /// The network's parameters d1 d2 d3 (or give the animator's, below).
    #[arg(allow_hyphen_values = true, value_parser = number_in(-1e6, 1e6), num_args = 3,
          value_names = ["D1", "D2", "D3"], required_unless_present = "opening_deg")]
    pub d: Option<Vec<f64>>,
    /// Opening in degrees about the condylar axis (0 at the rest bite); with --lateral-mm and
    /// --protrusion-mm instead of D1 D2 D3.
    #[arg(long, allow_hyphen_values = true, value_parser = number_in(-90.0, 90.0),
          requires_all = ["lateral_mm", "protrusion_mm"], conflicts_with = "d")]
    pub opening_deg: Option<f64>,
    /// Lateral excursion of the lower incisal point, mm (to the subject's left positive).
    #[arg(long, allow_hyphen_values = true, value_parser = number_in(-100.0, 100.0), requires = "opening_deg")]
    pub lateral_mm: Option<f64>,
    /// Protrusion of the lower incisal point, mm (forwards positive).
    #[arg(long, allow_hyphen_values = true, value_parser = number_in(-100.0, 100.0), requires = "opening_deg")]
    pub protrusion_mm: Option<f64>,
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
    /// The current parameters: D1,D2,D3 (default: the rest bite).
    #[arg(long, value_parser = parse_vec3, conflicts_with = "from_animator")]
    pub from: Option<[f64; 3]>,
    /// Or the current pose in animator units: OPENING_DEG,LATERAL_MM,PROTRUSION_MM.
    #[arg(long, value_parser = parse_vec3)]
    pub from_animator: Option<[f64; 3]>,
}

/// A pose in the animator's units (degrees; mm at the lower incisal point, from the rest bite).
#[derive(Serialize)]
struct AnimatorReport {
    opening_deg: f64,
    incisal_opening_mm: f64,
    lateral_mm: f64,
    protrusion_mm: f64,
}

/// The pose of `d` in animator units (`None` for a rig file without its anatomy).
fn animator_of(rig: &JawRig, d: &[f64; 3]) -> Option<AnimatorReport> {
    rig.anatomical(d).map(|u| AnimatorReport {
        opening_deg: u.opening_deg,
        incisal_opening_mm: u.incisal_opening_mm,
        lateral_mm: u.lateral_mm,
        protrusion_mm: u.protrusion_mm,
    })
}

#[derive(Serialize)]
struct PoseReport {
    params: [f64; 3],
    /// The posed jaw in animator units (absent for rig files learned before they existed).
    #[serde(skip_serializing_if = "Option::is_none")]
    animator: Option<AnimatorReport>,
    valid: bool,
    /// The nearest valid parameters (equal to `params` when they are valid).
    valid_params: [f64; 3],
    /// upper_from_lower for `params` (or `valid_params` with --clamp).
    pose: jawtrack::formats::PoseJson,
}

pub fn pose(a: PoseArgs) -> anyhow::Result<()> {
    let rig = JawRig::load(&a.rig)?;
    let d = match (&a.d, a.opening_deg, a.lateral_mm, a.protrusion_mm) {
        (Some(d), ..) => [d[0], d[1], d[2]],
        (None, Some(o), Some(l), Some(p)) => {
            if rig.anatomy.is_none() {
                bail!(
                    "{}: this rig file has no jaw frame (learned before animator units): learn it again to pose it in degrees and mm",
                    a.rig.display()
                );
            }
            rig.params_for(&[o, l, p]).with_context(|| {
                format!(
                    "the rig reaches no pose opened {o}° with {l} mm lateral and {p} mm protrusion"
                )
            })?
        }
        _ => bail!("give D1 D2 D3, or --opening-deg, --lateral-mm and --protrusion-mm"),
    };
    if d.iter().any(|v| !v.is_finite()) {
        bail!("the parameters must be finite numbers");
    }
    let valid_params = rig.clamp(&d);
    let used = if a.clamp { valid_params } else { d };
    let animator = animator_of(&rig, &used);
    let report = PoseReport {
        params: d,
        animator,
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

pub(super) fn probe_metric(rig: &JawRig) -> MeshMetric {
    MeshMetric::from_points(
        rig.probes_mm
            .iter()
            .map(|p| nalgebra::Vector3::from(*p))
            .collect(),
    )
}

pub fn encode(a: EncodeArgs) -> anyhow::Result<()> {
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
    jawtrack::io::write_json_atomic(
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

pub fn reconstruct(a: ReconstructArgs) -> anyhow::Result<()> {
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
    jawtrack::formats::write_jaw_poses(&a.out, &poses.frames, &out)?;
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
    /// The solved pose in animator units (absent for rig files learned before them).
    #[serde(skip_serializing_if = "Option::is_none")]
    animator: Option<AnimatorReport>,
    valid: bool,
    milliseconds: f64,
    pose: jawtrack::formats::PoseJson,
}

pub fn ik(a: IkArgs) -> anyhow::Result<()> {
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
    let from = match (a.from, a.from_animator) {
        (Some(d), _) => d,
        (None, Some(u)) => rig.params_for(&u).with_context(|| {
            format!(
                "--from-animator {},{},{}: the rig reaches no such pose (or its file has no jaw frame)",
                u[0], u[1], u[2]
            )
        })?,
        (None, None) => rig.params_for(&[0.0; 3]).unwrap_or([0.0; 3]),
    };
    let started = Instant::now();
    let result = jawtrack::rig::ik::solve(
        &rig,
        &point,
        &nalgebra::Vector3::from(a.target),
        &from,
        &Default::default(),
    )
    .context("rig ik")?;
    let milliseconds = started.elapsed().as_secs_f64() * 1e3;
    let report = IkReport {
        animator: animator_of(&rig, &result.params),
        valid: rig.is_valid(&result.params),
        pose: (&rig.pose(&result.params)).into(),
        result,
        milliseconds,
    };
    println!("{}", serde_json::to_string_pretty(&report)?);
    Ok(())
}
