//! `rig animate` (keyframes) and `rig sample` (random poses within the valid ranges).

use std::path::PathBuf;

use jawtrack::geometry::Pose;
use jawtrack::rig::JawRig;

use crate::cli::args::{load_mesh, parse_vec3};

#[derive(clap::Args)]
pub struct AnimateArgs {
    pub rig: PathBuf,
    /// A key: TIME:D1,D2,D3 (seconds, parameters; with --animator TIME:OPENING_DEG,LATERAL_MM,
    /// PROTRUSION_MM); repeat for each key.
    #[arg(long = "key", value_parser = parse_key)]
    pub keys: Vec<jawtrack::rig::animate::Key>,
    /// Or a JSON file: [{"time": 0.0, "params": [d1, d2, d3]}, ...].
    #[arg(long, conflicts_with = "keys")]
    pub keys_file: Option<PathBuf>,
    /// Keys are in animator units (opening °, lateral and protrusion mm at the incisal point,
    /// from the rest bite), interpolated in those units.
    #[arg(long)]
    pub animator: bool,
    /// Frames per second (above 0, at most 10000).
    #[arg(long, default_value_t = 24.0, value_parser = crate::cli::args::number_in(1e-3, 10_000.0))]
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
    /// Also write the animation as glTF 2.0 (Blender, Maya): --mesh animated, --upper fixed.
    #[arg(long, requires = "mesh")]
    pub gltf: Option<PathBuf>,
    /// The upper arch (upper frame) to show, fixed, in the glTF file.
    #[arg(long, requires = "gltf")]
    pub upper: Option<PathBuf>,
}

#[derive(clap::Args)]
pub struct SampleArgs {
    pub rig: PathBuf,
    /// How many poses (at most 10 million).
    #[arg(short = 'n', long, default_value_t = 1000, value_parser = crate::cli::args::count_in(1, 10_000_000))]
    pub count: usize,
    /// Draw each parameter over its own fixed range instead of the d1-dependent ones.
    #[arg(long)]
    pub fixed_ranges: bool,
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Where to write the poses (jawtrack-jaw/1); their parameters go beside it
    /// (`.params.json`, the network's) and, in animator units, `.animator.json`
    /// ([opening °, lateral mm, protrusion mm] per pose).
    #[arg(short, long)]
    pub out: PathBuf,
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

pub fn animate(a: AnimateArgs) -> anyhow::Result<()> {
    use jawtrack::rig::animate::{Key, animate, animate_animator};
    let rig = JawRig::load(&a.rig)?;
    let keys: Vec<Key> = match &a.keys_file {
        Some(p) => jawtrack::io::read_json(p, "keys file")?,
        None => a.keys.clone(),
    };
    let play = if a.animator {
        animate_animator
    } else {
        animate
    };
    let frames = play(&rig, &keys, a.fps).map_err(|e| match (&e, &a.keys_file) {
        (jawtrack::rig::animate::KeyError::NoAnatomy, _) => {
            anyhow::anyhow!("{}: {e}", a.rig.display())
        }
        (_, Some(p)) => anyhow::anyhow!("{}: {e}", p.display()),
        (_, None) => anyhow::anyhow!("--key: {e}"),
    })?;
    let numbers: Vec<u32> = frames.iter().map(|f| f.frame).collect();
    let poses: Vec<Pose> = frames.iter().map(|f| f.pose).collect();
    jawtrack::formats::write_jaw_poses(&a.out, &numbers, &poses)?;
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
            jawtrack::mesh::write_obj(&posed, &dir.join(format!("{:06}.obj", f.frame)))?;
        }
    }
    if let (Some(out), Some(mesh)) = (&a.gltf, &a.mesh) {
        use jawtrack::export::gltf::{Part, keys_of, write_gltf};
        let (lower, _) = load_mesh(mesh)?;
        let upper = a.upper.as_deref().map(load_mesh).transpose()?;
        let keys = keys_of(&frames, a.fps);
        let part = |name, mesh| Part {
            name,
            mesh,
            colour: [0.9, 0.9, 0.88, 1.0],
        };
        let bytes = write_gltf(
            upper.as_ref().map(|(u, _)| part("upper", u)).as_ref(),
            &part("lower", &lower),
            None,
            &keys,
            "rig animation",
        );
        jawtrack::io::write_atomic(out, &bytes)?;
        println!("glTF: {} keys -> {}", keys.len(), out.display());
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

pub fn sample(a: SampleArgs) -> anyhow::Result<()> {
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
    jawtrack::formats::write_jaw_poses(&a.out, &frames, &poses)?;
    let side = a.out.with_extension("params.json");
    jawtrack::io::write_json_atomic(&side, &params)?;
    let animator: Option<Vec<[f64; 3]>> = params
        .iter()
        .map(|d| {
            rig.anatomical(d)
                .map(|u| [u.opening_deg, u.lateral_mm, u.protrusion_mm])
        })
        .collect();
    if let Some(units) = &animator {
        jawtrack::io::write_json_atomic(&a.out.with_extension("animator.json"), units)?;
    }
    println!(
        "wrote {} random rig poses ({} ranges) to {} and their parameters to {}{}",
        a.count,
        if a.fixed_ranges {
            "fixed"
        } else {
            "d1-dependent"
        },
        a.out.display(),
        side.display(),
        if animator.is_some() {
            " (in degrees and mm: .animator.json)"
        } else {
            ""
        }
    );
    Ok(())
}
