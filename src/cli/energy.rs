use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, anyhow};
use jawtrack::capture::{Arch, ArchPoses, Capture, OpenOptions, read_pose_file};
use jawtrack::energy::{Backend, DEFAULT_LAMBDA, Energy, Region, Scene, open_engine};

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
    /// Weight of the boundary term.
    #[arg(long, default_value_t = DEFAULT_LAMBDA)]
    pub lambda: f64,
    #[command(flatten)]
    pub load: LoadArgs,
    #[command(flatten)]
    pub engine: EngineArgs,
}

/// How a capture is loaded: the arches' simplification and the masks' resolution (shared by
/// the commands that evaluate energies).
#[derive(clap::Args, Clone, Copy)]
pub struct LoadArgs {
    /// Simplify each arch to at most this many triangles at load (instead of --simplify-mm).
    #[arg(long)]
    pub max_triangles: Option<usize>,
    /// Simplify each arch as far as its surface stays within this distance (mm) of the
    /// scan's; 0 keeps every triangle (a silhouette needs far fewer than a scan has).
    #[arg(long, default_value_t = jawtrack::capture::DEFAULT_SIMPLIFY_MM)]
    pub simplify_mm: f64,
    /// Read the masks at 1/K of their resolution (each K x K block's most common label; K
    /// must divide the masks' sides): for masks larger than the time per frame allows, e.g.
    /// 4K video's. Drawing and counting cost about K² times less (setting up each triangle
    /// costs the same), and the pixels are K times coarser.
    #[arg(long, default_value_t = 1, value_name = "K", value_parser = clap::value_parser!(u32).range(1..=16))]
    pub mask_reduce: u32,
}

impl LoadArgs {
    pub fn open_options(&self) -> OpenOptions {
        OpenOptions {
            max_triangles: self.max_triangles,
            simplify_mm: self.simplify_mm,
            mask_reduce: self.mask_reduce,
        }
    }
}

impl Default for LoadArgs {
    fn default() -> Self {
        let o = OpenOptions::default();
        LoadArgs {
            max_triangles: o.max_triangles,
            simplify_mm: o.simplify_mm,
            mask_reduce: o.mask_reduce,
        }
    }
}

/// How energies are evaluated (shared by every command that evaluates them).
#[derive(clap::Args, Clone, Copy)]
pub struct EngineArgs {
    /// Energy backend: `auto` takes a hardware GPU adapter when there is one and the CPU
    /// reference otherwise; `JAWTRACK_ADAPTER=substring` picks an adapter by name.
    #[arg(long, value_enum, default_value_t = Backend::Auto)]
    pub backend: Backend,
    /// What to render and count: only where the arch can be (`footprint`), every pixel
    /// (`full-frame`), or only what can change the energy (`energy`: the CPU reference skips
    /// body faces off the mask; the other counts are then low). Default: `energy` where
    /// only the energy is read (track, bench track), `footprint` for the energy command.
    #[arg(long, value_enum)]
    pub region: Option<Region>,
}

pub fn run(a: Args) -> anyhow::Result<()> {
    let capture = Capture::open_with(&a.capture, a.load.open_options())
        .with_context(|| format!("invalid capture {}", a.capture.display()))?;
    if !capture.frames().contains(&a.frame) {
        return Err(anyhow!(
            "--frame {}: the capture has frames {}..{}",
            a.frame,
            capture.first_frame,
            capture.first_frame + capture.frame_count
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
                    if a.frame == capture.first_frame { " and no init.json" } else { "" }
                )
            }),
        }
    };
    let poses = ArchPoses {
        upper: pick(&a.upper, Arch::Upper)?,
        lower: pick(&a.lower, Arch::Lower)?,
    };
    let opened = open_engine(
        a.engine.backend,
        Scene::from_capture(&capture),
        a.engine.region.unwrap_or(Region::Footprint),
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
        (frame == capture.first_frame)
            .then(|| capture.initial_poses().ok())
            .flatten()
    })
}

/// The header of `print_energy`'s table: the paper's terms, the cross-label count (pixels of
/// the other arch covered by this one), and the paper's six bins (mask off/on x class).
pub const TABLE_HEADER: &str = "arch   camera  mask_px  uncovered  boi_outside  total      cross  off/none off/body off/boi on/none on/body on/boi";

pub fn print_energy(arch: Arch, cameras: &[&str], e: &Energy, lambda: f64) {
    for (name, c) in cameras.iter().zip(&e.cameras) {
        let b = c.paper_bins();
        println!(
            "{:<6} {:<7} {:>7}  {:>9}  {:>11}  {:>9.1}  {:>5}  {:>8} {:>8} {:>7} {:>7} {:>7} {:>6}",
            arch.name(),
            name,
            c.mask_pixels(),
            c.uncovered(),
            c.boi_outside(),
            c.total(lambda),
            c.cross(),
            b[0],
            b[1],
            b[2],
            b[3],
            b[4],
            b[5]
        );
    }
    println!(
        "{:<6} {:<7} {:>7}  {:>9}  {:>11}  {:>9.1}  {:>5}  area error {:.3}%",
        arch.name(),
        "all",
        e.mask_pixels(),
        e.uncovered(),
        e.boi_outside(),
        e.total(lambda),
        e.cross(),
        100.0 * e.area_error()
    );
}
