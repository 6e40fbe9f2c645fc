use std::path::{Path, PathBuf};

use anyhow::Context;
use jawtrack::synth::{self, Joint, MaskKind, Preset, SynthOptions, SynthReport};

#[derive(clap::Args)]
pub struct Args {
    /// Folder to write the capture to (must not exist, unless --force).
    pub out: PathBuf,
    /// Number of frames (24 per second).
    #[arg(long, default_value_t = 48)]
    pub frames: u32,
    /// Random seed: the same seed writes the same capture.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// How much the masks are degraded.
    #[arg(long, value_enum, default_value_t = Preset::Realistic)]
    pub preset: Preset,
    /// One mask per arch, or one teeth mask for both.
    #[arg(long, value_enum, default_value_t = MaskKind::PerArch)]
    pub masks: MaskKind,
    /// Folder with upper.{obj,stl,ply} and lower.{obj,stl,ply} (scan frame: y up, +z anterior)
    /// to use instead of procedural arches.
    #[arg(long)]
    pub meshes: Option<PathBuf>,
    /// Replace OUT if it exists.
    #[arg(long)]
    pub force: bool,
    /// Write no masks (meshes, cameras, init and gt/poses.json only): ground-truth motion for
    /// `jawtrack rig`, quickly.
    #[arg(long)]
    pub no_masks: bool,
    /// The subject's temporomandibular joint.
    #[arg(long, value_enum, default_value_t = Joint::Average)]
    pub joint: Joint,
    /// The movements' pace: frames each segment of the exercise (e.g. rest to wide open)
    /// takes at least; 20 (0.83 s at the synthetic 24 fps) is an unhurried human pace.
    #[arg(long, default_value_t = jawtrack::synth::exercise::FRAMES_PER_SEGMENT)]
    pub frames_per_segment: u32,
    #[command(flatten)]
    pub rig: RigArgs,
    /// Print the report as JSON.
    #[arg(long)]
    pub json: bool,
}

/// The cameras a synthetic capture is filmed with (`synth`, `bench track`).
#[derive(clap::Args, Clone, Debug)]
pub struct RigArgs {
    /// A folder of camera files (`<name>.json`, as in a capture's cameras/) to film with
    /// instead of the rig of calib/ (three cameras); masks are written at half each camera's
    /// resolution.
    #[arg(long)]
    pub rig: Option<PathBuf>,
    /// Lens distortion for every camera, OpenCV's k1,k2,p1,p2[,k3] (e.g. -0.25,0.08,0,0, a
    /// moderate barrel), replacing the camera files': written to the capture's camera files,
    /// and the masks are drawn through it. Default: the cameras' own (calib/ has none).
    #[arg(long, value_delimiter = ',', allow_hyphen_values = true)]
    pub distortion: Option<Vec<f64>>,
}

impl RigArgs {
    pub fn distortion(&self) -> anyhow::Result<Option<[f64; 5]>> {
        let Some(d) = &self.distortion else {
            return Ok(None);
        };
        anyhow::ensure!(
            (4..=5).contains(&d.len()) && d.iter().all(|x| x.is_finite()),
            "--distortion: expected 4 or 5 finite numbers (k1,k2,p1,p2[,k3]), found {d:?}"
        );
        let mut k = [0.0; 5];
        k[..d.len()].copy_from_slice(d);
        Ok(Some(k))
    }
}

pub fn run(a: Args) -> anyhow::Result<()> {
    let opts = SynthOptions {
        frames: a.frames,
        seed: a.seed,
        preset: a.preset,
        masks: a.masks,
        meshes: a.meshes,
        force: a.force,
        no_masks: a.no_masks,
        joint: a.joint,
        frames_per_segment: a.frames_per_segment,
        rig: a.rig.rig.clone(),
        distortion: a.rig.distortion()?,
    };
    let report = generate(&a.out, &opts)?;
    if a.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        print_report(&a.out, &report);
    }
    Ok(())
}

pub fn generate(out: &Path, opts: &SynthOptions) -> anyhow::Result<SynthReport> {
    let bar = super::progress_bar(opts.frames as u64, "synth");
    let report = synth::generate(out, opts, &|| bar.inc(1))
        .with_context(|| format!("writing a synthetic capture to {}", out.display()))?;
    bar.finish_and_clear();
    Ok(report)
}

pub fn print_report(out: &Path, r: &SynthReport) {
    println!(
        "wrote {} ({} frames in {:.2} s)",
        out.display(),
        r.frames,
        r.seconds
    );
    println!(
        "meshes: upper {} triangles ({} BOI), lower {} ({} BOI)",
        r.triangles[0], r.boi_triangles[0], r.triangles[1], r.boi_triangles[1]
    );
    println!(
        "motion: opening up to {:.1} mm, lateral {:.1} to {:.1} mm, protrusion up to {:.1} mm, condylar travel up to {:.1} mm",
        r.max_opening_mm,
        r.lateral_mm[0],
        r.lateral_mm[1],
        r.max_protrusion_mm,
        r.max_condylar_travel_mm
    );
    println!(
        "camera  mask size  frames with mask  mean mask px (upper, lower)  visible share (upper, lower)"
    );
    for c in &r.cameras {
        println!(
            "{:<6}  {}x{}    {:>5}             {:>7.0} {:>7.0}             {:>5.1}% {:>5.1}%",
            c.name,
            c.mask_size[0],
            c.mask_size[1],
            c.frames_with_mask,
            c.mean_mask_pixels[0],
            c.mean_mask_pixels[1],
            100.0 * c.visible_share[0],
            100.0 * c.visible_share[1]
        );
    }
}
