use std::path::PathBuf;

use jawtrack::synth::SynthOptions;

use super::args::{CameraRigArgs, JointArg, MaskKindArg, PhotosArg, PresetArg};

#[derive(clap::Args)]
pub struct Args {
    /// Folder to write the capture to (must not exist, unless --force); with --face, the
    /// set of subjects (default `faces`).
    pub out: Option<PathBuf>,
    /// Write face sequences (the jaw from the skin) instead of a capture: a set of subjects,
    /// each a folder in the face-sequence format.
    #[arg(long)]
    pub face: bool,
    /// With --face: how many subjects.
    #[arg(long, default_value_t = 4, value_parser = clap::value_parser!(u32).range(1..=64), requires = "face")]
    pub subjects: u32,
    /// With --face: the face tracker's noise per vertex and coordinate (mm).
    #[arg(long, default_value_t = 0.1, requires = "face")]
    pub noise_mm: f64,
    /// Number of frames (24 per second); default 48, with --face 600.
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..=100_000))]
    pub frames: Option<u32>,
    /// Random seed: the same seed writes the same capture.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// How much the masks are degraded.
    #[arg(long, value_enum, default_value_t = PresetArg::Realistic)]
    pub preset: PresetArg,
    /// One mask per arch, or one teeth mask for both.
    #[arg(long, value_enum, default_value_t = MaskKindArg::PerArch)]
    pub masks: MaskKindArg,
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
    #[arg(long, value_enum, default_value_t = JointArg::Average)]
    pub joint: JointArg,
    /// The movements' pace: frames each segment of the exercise (e.g. rest to wide open)
    /// takes at least; 20 (0.83 s at the synthetic 24 fps) is an unhurried human pace.
    #[arg(long, default_value_t = jawtrack::synth::exercise::FRAMES_PER_SEGMENT)]
    pub frames_per_segment: u32,
    #[command(flatten)]
    pub rig: CameraRigArgs,
    /// Masks label the teeth alone: no visible mouth interior (`masks.mouth`), as before it
    /// was in the format.
    #[arg(long)]
    pub no_mouth: bool,
    /// Segmentation errors that persist from frame to frame (as a tracked roto mask's do)
    /// rather than being drawn afresh each frame.
    #[arg(long)]
    pub persistent_noise: bool,
    /// Also film it in colour: images/<camera>/<frame>.png at the masks' resolution, and the
    /// labels they truly show in gt/masks/ (to score `jawtrack segment` against).
    #[arg(long)]
    pub images: bool,
    /// With --images: frames `A..B` during which the light is off (the sync event).
    #[arg(long, requires = "images")]
    pub light_off: Option<String>,
    /// With --images: `hard` films what a real mouth shows besides teeth (gums, the tongue,
    /// wet highlights, lips shading the crowns, motion blur, drifting exposure and white
    /// balance).
    #[arg(long, value_enum, default_value_t = PhotosArg::Clean, requires = "images")]
    pub photos: PhotosArg,
    /// Print the report as JSON.
    #[arg(long)]
    pub json: bool,
}

pub fn run(a: Args) -> anyhow::Result<()> {
    if a.face {
        return faces(a);
    }
    let Some(out) = a.out.clone() else {
        anyhow::bail!(
            "synth: give the folder to write the capture to (OUT), or --face for face sequences"
        );
    };
    let opts = SynthOptions {
        frames: a.frames.unwrap_or(48),
        seed: a.seed,
        preset: a.preset.into(),
        masks: a.masks.into(),
        meshes: a.meshes,
        force: a.force,
        no_masks: a.no_masks,
        joint: a.joint.into(),
        frames_per_segment: a.frames_per_segment,
        rig: a.rig.rig.clone(),
        distortion: a.rig.distortion()?,
        mouth: !a.no_mouth,
        persistent_noise: a.persistent_noise,
        images: a.images,
        light_off: a.light_off.as_deref().map(light_off).transpose()?,
        photos: a.photos.into(),
    };
    let report = super::run::synthesise(&out, &opts)?;
    if a.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        super::report::synth(&out, &report);
    }
    Ok(())
}

/// `A..B`: the frames the light is off.
fn light_off(s: &str) -> anyhow::Result<std::ops::Range<u32>> {
    let parse = |t: &str| {
        t.trim()
            .parse::<u32>()
            .map_err(|_| anyhow::anyhow!("--light-off {s:?}: expected A..B (frame numbers)"))
    };
    let (a, b) = s
        .split_once("..")
        .ok_or_else(|| anyhow::anyhow!("--light-off {s:?}: expected A..B (frame numbers)"))?;
    let (a, b) = (parse(a)?, parse(b)?);
    anyhow::ensure!(
        a < b,
        "--light-off {s:?}: the first frame must come before the last"
    );
    Ok(a..b)
}

fn faces(a: Args) -> anyhow::Result<()> {
    use anyhow::Context;
    let out = a.out.clone().unwrap_or_else(|| PathBuf::from("faces"));
    let opts = jawtrack::synth::face::FaceSynthOptions {
        subjects: a.subjects,
        frames: a.frames.unwrap_or(600),
        seed: a.seed,
        noise_mm: a.noise_mm,
        force: a.force,
    };
    let bar = super::progress_bar(opts.subjects as u64 * opts.frames as u64, "synth --face");
    let report = jawtrack::synth::face::generate_faces(&out, &opts, &|| bar.inc(1))
        .with_context(|| format!("writing face sequences to {}", out.display()))?;
    bar.finish_and_clear();
    if a.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
        return Ok(());
    }
    println!(
        "wrote {} subjects to {} in {:.1} s",
        report.subjects.len(),
        out.display(),
        report.seconds
    );
    for s in &report.subjects {
        println!(
            "  {}: {} frames, {} skin vertices, chin tissue {:.1} mm, sliding {:.2}, opening up to {:.1} mm, skin moves up to {:.1} mm",
            s.name,
            s.frames,
            s.skin_vertices,
            s.chin_tissue_mm,
            s.sliding,
            s.max_opening_mm,
            s.max_skin_mm
        );
    }
    println!("evaluate them with: jawtrack skin eval {}", out.display());
    Ok(())
}
