use std::path::PathBuf;

use jawtrack::capture::Capture;
use jawtrack::synth::{MaskKind, Preset, SynthOptions};

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
    #[arg(long, default_value_t = 48)]
    pub frames: u32,
    /// Random seed.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Synthetic preset.
    #[arg(long, value_enum, default_value_t = Preset::Realistic)]
    pub preset: Preset,
    #[command(flatten)]
    pub engine: super::energy::EngineArgs,
}

/// The main job on a built-in default: synthesise, track, score.
pub fn run(a: Args) -> anyhow::Result<()> {
    let (out, force) = match a.out {
        Some(o) => (o, a.force),
        None => (std::env::temp_dir().join("jawtrack-demo"), true),
    };
    let opts = SynthOptions {
        frames: a.frames,
        seed: a.seed,
        preset: a.preset,
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
    };
    println!(
        "== 1. synthesise a {:?} capture: three cameras, half-resolution masks",
        a.preset
    );
    let report = super::synth::generate(&out, &opts)?;
    super::synth::print_report(&out, &report);

    println!("\n== 2. read it back");
    let capture = super::validate::open_and_check(&out, true)?;
    println!(
        "{} cameras, frames {}..{}, meshes {} + {} triangles",
        capture.cameras.len(),
        capture.first_frame,
        capture.first_frame + capture.frame_count,
        capture.upper.triangles.len(),
        capture.lower.triangles.len()
    );

    println!("\n== 3. track both arches from init.json, frame after frame");
    let tracks = out.join("tracks.json");
    let overlays = out.join("overlays");
    let args = super::track::Args {
        capture: out.clone(),
        output: tracks.clone(),
        frames: None,
        engine: a.engine,
        overlays: Some(overlays.clone()),
        resume: false,
        force: true,
        load: Default::default(),
        settings: None,
    };
    let summary = super::track::track(&capture, &args)?;
    super::track::print_summary(&tracks, &summary);

    println!("\n== 4. score against the ground truth");
    let reopened = Capture::open(&out)?;
    if let Some(r) = super::track::score_records(&reopened, &tracks, &summary.records)? {
        super::track::print_score(&r);
    }

    println!("\n== 5. learn a jaw rig from the tracked poses (frames with status ok)");
    let rig_path = out.join("rig.json");
    let poses = jawtrack::rig::read_jaw_poses(&tracks)?;
    // The error is measured on the mandible when the capture has one.
    let metric =
        jawtrack::anatomy::MeshMetric::new(reopened.mandible.as_ref().unwrap_or(&reopened.lower));
    let rig = super::rig::learn_rig(&poses, &metric, &Default::default())?;
    rig.save(&rig_path)?;
    let report = super::rig::evaluate_rig(&rig, &poses.poses, &metric, 0, 0, false)?;
    let rec = &report.reconstruction;
    println!(
        "{} poses, learned in {:.2} s; reconstruction error on the mandible (largest vertex distance, mm): rig mean {:.3}, max {:.3}; PCA-3 mean {:.3}; NLPCA-5 mean {:.3}",
        poses.len(),
        rig.training.seconds,
        rec.rig.stats.mean,
        rec.rig.stats.max,
        rec.pca[2].stats.mean,
        rec.nlpca[4].stats.mean
    );
    if let Some(mandible) = &reopened.mandible {
        let frame = jawtrack::envelope::JawFrame::from_mesh(mandible, None, None)?;
        let envelope = jawtrack::envelope::EnvelopeRig::learn(&poses.poses, &frame, &metric)?;
        let errors: Vec<f64> = poses
            .poses
            .iter()
            .map(|p| metric.max_distance(p, &envelope.reconstruct(p)))
            .collect();
        let s = jawtrack::stats::Stats::of(&errors);
        envelope.save(&out.join("envelope.json"))?;
        println!(
            "envelope rig (Zoss et al.) on the same poses: mean {:.3}, max {:.3} mm",
            s.mean, s.max
        );
    }
    println!(
        "(rigs learned from {} tracked frames of a short exercise; `jawtrack bench rig` learns them from 833 poses of ground truth and compares every rig)",
        poses.len()
    );

    println!("\ntracks: {}", tracks.display());
    println!(
        "overlays (mask white, model red at alpha 0.5, BOI green): {}",
        overlays.display()
    );
    println!("rigs: {} and envelope.json beside it", rig_path.display());
    Ok(())
}
