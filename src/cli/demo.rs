use std::path::{Path, PathBuf};

use jawtrack::anatomy::MeshMetric;
use jawtrack::capture::Capture;
use jawtrack::energy::Region;
use jawtrack::geometry::Pose;
use jawtrack::mesh::Mesh;
use jawtrack::synth::{MaskKind, SynthOptions};
use jawtrack::track::Summary;

use super::args::PresetArg;

#[derive(clap::Args)]
pub struct Args {
    /// Where to write the demo capture, tracks.json and overlays (default: jawtrack-demo in
    /// the system's temporary folder, replaced on each run). A folder you name must not exist,
    /// unless --force.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Replace --out if it exists.
    #[arg(long)]
    pub force: bool,
    /// Number of frames.
    #[arg(long, default_value_t = 48, value_parser = clap::value_parser!(u32).range(1..=100_000))]
    pub frames: u32,
    /// Random seed.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Synthetic preset.
    #[arg(long, value_enum, default_value_t = PresetArg::Realistic)]
    pub preset: PresetArg,
    #[command(flatten)]
    pub engine: super::args::EngineArgs,
}

/// The main job on a built-in default: synthesise, track, score.
pub fn run(a: Args) -> anyhow::Result<()> {
    let (out, force) = match &a.out {
        Some(o) => (o.clone(), a.force),
        None => (std::env::temp_dir().join("jawtrack-demo"), true),
    };
    synthesise(&a, &out, force)?;
    let capture = read_back(&out)?;
    let tracks = out.join("tracks.json");
    let overlays = out.join("overlays");
    let summary = track(&a, &capture, &tracks, &overlays)?;
    let reopened = score(&out, &tracks, &summary)?;
    let rig_path = out.join("rig.json");
    learn_rigs(&out, &reopened, &tracks, &rig_path)?;

    println!("\ntracks: {}", tracks.display());
    println!(
        "overlays (mask white, model red at alpha 0.5, BOI green): {}",
        overlays.display()
    );
    println!("rigs: {} and envelope.json beside it", rig_path.display());
    Ok(())
}

/// Step 1: writes the synthetic capture of the demo to `out`.
fn synthesise(a: &Args, out: &Path, force: bool) -> anyhow::Result<()> {
    let opts = SynthOptions {
        frames: a.frames,
        seed: a.seed,
        preset: a.preset.into(),
        masks: MaskKind::PerArch,
        meshes: None,
        force,
        no_masks: false,
        joint: Default::default(),
        // The exercise's core (open, left, right, protrude) squeezed into 48 frames, 6 a
        // movement, faster than people move: the rig learnt at the end sees the whole range.
        frames_per_segment: 6,
        rig: None,
        distortion: None,
        mouth: true,
        persistent_noise: false,
        images: false,
        light_off: None,
        photos: Default::default(),
    };
    println!(
        "== 1. synthesise a {} capture: three cameras, half-resolution masks",
        super::args::name_of(&a.preset)
    );
    let report = super::run::synthesise(out, &opts)?;
    super::report::synth(out, &report);
    Ok(())
}

/// Step 2: opens the capture and checks it, printing what it holds.
fn read_back(out: &Path) -> anyhow::Result<Capture> {
    println!("\n== 2. read it back");
    let (capture, _) = super::run::open_and_check(out, Default::default(), true)?;
    println!(
        "{} cameras, frames {}..{}, meshes {} + {} triangles, {}",
        capture.cameras().len(),
        capture.first_frame(),
        capture.first_frame() + capture.frame_count(),
        capture.upper().triangles.len(),
        capture.lower().triangles.len(),
        match capture.mouth() {
            Some(_) => "masks label the visible mouth interior",
            None => "teeth masks alone",
        }
    );
    Ok(capture)
}

/// Step 3: tracks both arches into `tracks`, with overlays in `overlays`.
fn track(a: &Args, capture: &Capture, tracks: &Path, overlays: &Path) -> anyhow::Result<Summary> {
    println!("\n== 3. track both arches from init.json, frame after frame");
    let options = jawtrack::track::SessionOptions {
        backend: a.engine.backend.into(),
        region: a.engine.region.map_or(Region::Relevant, Into::into),
        overlays: Some(overlays.to_path_buf()),
        force: true,
        ..jawtrack::track::SessionOptions::new(tracks)
    };
    let summary = super::run::track(capture, options)?;
    super::report::track_summary(tracks, &summary);
    Ok(summary)
}

/// Step 4: reopens the capture and scores the tracked poses against its ground truth.
fn score(out: &Path, tracks: &Path, summary: &Summary) -> anyhow::Result<Capture> {
    println!("\n== 4. score against the ground truth");
    let reopened = Capture::open(out)?;
    if let Some(r) = jawtrack::track::score_records(&reopened, tracks, &summary.records)? {
        super::report::score(&r);
    }
    Ok(reopened)
}

/// Step 5: learns a jaw rig (saved to `rig_path`) and, with a mandible, an envelope rig from
/// the tracked poses, printing their reconstruction errors.
fn learn_rigs(
    out: &Path,
    reopened: &Capture,
    tracks: &Path,
    rig_path: &Path,
) -> anyhow::Result<()> {
    println!("\n== 5. learn a jaw rig from the tracked poses (frames with status ok)");
    let poses = jawtrack::formats::read_jaw_poses(tracks)?;
    // The error is measured on the mandible when the capture has one.
    let metric = MeshMetric::new(reopened.mandible().unwrap_or(reopened.lower()));
    let rig = super::run::with_spinner("learning the rig", || {
        jawtrack::rig::JawRig::learn(&poses.poses, &metric, &Default::default(), &|_| {})
    })?;
    rig.save(rig_path)?;
    let report = jawtrack::rig::eval::report(&rig, &poses.poses, &metric, 0, 0, false)?;
    let rec = &report.reconstruction;
    println!(
        "{} poses, learned in {:.2} s; reconstruction error on the mandible (largest vertex distance, mm): rig mean {:.3}, max {:.3}; PCA-3 mean {:.3}",
        poses.len(),
        rig.training.seconds,
        rec.rig.stats.mean,
        rec.rig.stats.max,
        rec.pca[2].stats.mean,
    );
    if let Some(mandible) = &reopened.mandible() {
        envelope_rig(out, mandible, &poses.poses, &metric)?;
    }
    println!(
        "(rigs learned from {} tracked frames of a short exercise; `jawtrack bench rig` learns them from 833 poses of ground truth and compares every rig)",
        poses.len()
    );
    Ok(())
}

/// Learns the envelope rig (Zoss et al.) from the poses, saves it in `out` and prints its
/// reconstruction error.
fn envelope_rig(
    out: &Path,
    mandible: &Mesh,
    poses: &[Pose],
    metric: &MeshMetric,
) -> anyhow::Result<()> {
    let frame = jawtrack::envelope::JawFrame::from_mesh(mandible, None, None)?;
    let envelope = jawtrack::envelope::EnvelopeRig::learn(poses, &frame, metric)?;
    let errors: Vec<f64> = poses
        .iter()
        .map(|p| metric.max_distance(p, &envelope.reconstruct(p)))
        .collect();
    let s = jawtrack::stats::Stats::of(&errors);
    envelope.save(&out.join("envelope.json"))?;
    println!(
        "envelope rig (Zoss et al.) on the same poses: mean {:.3}, max {:.3} mm",
        s.mean, s.max
    );
    Ok(())
}
