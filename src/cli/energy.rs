use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, anyhow};
use jawtrack::arch::{Arch, ArchPoses};
use jawtrack::capture::Capture;
use jawtrack::energy::{DEFAULT_LAMBDA, Energy, Region, Scene, open_engine};
use jawtrack::formats::read_pose_file;

use super::args::{EngineArgs, LoadArgs};

#[derive(clap::Args)]
pub struct Args {
    /// The capture folder.
    pub capture: PathBuf,
    /// The frame to evaluate.
    #[arg(long)]
    pub frame: u32,
    /// Upper arch pose (JSON: rotation, translation); default: ground truth, or init.json
    /// for the first frame.
    #[arg(long)]
    pub upper: Option<PathBuf>,
    /// Lower arch pose; default as for --upper.
    #[arg(long)]
    pub lower: Option<PathBuf>,
    /// Weight of the boundary term (0 to 1000).
    #[arg(long, default_value_t = DEFAULT_LAMBDA, value_parser = crate::cli::args::number_in(0.0, 1000.0))]
    pub lambda: f64,
    #[command(flatten)]
    pub load: LoadArgs,
    #[command(flatten)]
    pub engine: EngineArgs,
}

pub fn run(a: Args) -> anyhow::Result<()> {
    let capture = Capture::open_with(&a.capture, a.load.open_options())
        .with_context(|| format!("invalid capture {}", a.capture.display()))?;
    if !capture.frames().contains(&a.frame) {
        return Err(anyhow!(
            "--frame {}: the capture has frames {}..{}",
            a.frame,
            capture.first_frame(),
            capture.first_frame() + capture.frame_count()
        ));
    }
    let default = default_poses(&capture, a.frame);
    let pick = |arg: &Option<PathBuf>, arch: Arch| -> anyhow::Result<_> {
        match arg {
            Some(p) => Ok(read_pose_file(p)?),
            None => default.map(|d| *d.get(arch)).ok_or_else(|| {
                anyhow!(
                    "no pose for the {} arch: pass --{} POSE.json (the capture has no ground truth for frame {}{})",
                    arch.name(),
                    arch.name(),
                    a.frame,
                    if a.frame == capture.first_frame() { " and no init.json" } else { "" }
                )
            }),
        }
    };
    let poses = ArchPoses {
        upper: pick(&a.upper, Arch::Upper)?,
        lower: pick(&a.lower, Arch::Lower)?,
    };
    let opened = open_engine(
        a.engine.backend.into(),
        Scene::from_capture(&capture),
        a.engine.region.map_or(Region::Footprint, Into::into),
    )?;
    eprintln!("backend: {}", opened.choice);
    let mut engine = opened.engine;
    engine.set_frame(&capture.load_masks(a.frame)?)?;
    println!("frame {}  lambda {}", a.frame, a.lambda);
    println!("{}", TABLE_HEADER);
    for arch in Arch::BOTH {
        let started = Instant::now();
        let e = engine.evaluate(arch, &[poses])?.remove(0);
        eprintln!(
            "{} arch: evaluated in {:.2} ms",
            arch.name(),
            started.elapsed().as_secs_f64() * 1e3
        );
        print_energy(arch, &capture.camera_names(), &e, a.lambda);
    }
    Ok(())
}

/// Ground truth for the frame, else init.json's poses for the first frame.
pub fn default_poses(capture: &Capture, frame: u32) -> Option<ArchPoses> {
    capture.gt_poses(frame).or_else(|| {
        (frame == capture.first_frame())
            .then(|| capture.initial_poses().ok())
            .flatten()
    })
}

/// The header of `print_energy`'s table: the paper's terms, the cross-label count (pixels of
/// the other arch covered by this one), the over-mouth count (mouth-interior pixels under the
/// model) and the paper's six bins (mask off/on x class).
pub const TABLE_HEADER: &str = "arch   camera  mask_px  uncovered  boi_outside  total      cross  mouth  off/none off/body off/boi on/none on/body on/boi";

pub fn print_energy(arch: Arch, cameras: &[&str], e: &Energy, lambda: f64) {
    for (name, c) in cameras.iter().zip(&e.cameras) {
        let b = c.paper_bins();
        println!(
            "{:<6} {:<7} {:>7}  {:>9}  {:>11}  {:>9.1}  {:>5}  {:>5}  {:>8} {:>8} {:>7} {:>7} {:>7} {:>6}",
            arch.name(),
            name,
            c.mask_pixels(),
            c.uncovered(),
            c.boi_outside(),
            c.total(lambda),
            c.cross(),
            c.over_mouth(),
            b[0],
            b[1],
            b[2],
            b[3],
            b[4],
            b[5]
        );
    }
    println!(
        "{:<6} {:<7} {:>7}  {:>9}  {:>11}  {:>9.1}  {:>5}  {:>5}  area error {:.3}%",
        arch.name(),
        "all",
        e.mask_pixels(),
        e.uncovered(),
        e.boi_outside(),
        e.total(lambda),
        e.cross(),
        e.over_mouth(),
        100.0 * e.area_error()
    );
}
