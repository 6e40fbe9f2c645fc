use std::path::PathBuf;
use std::time::Instant;

use jawtrack::capture::{Arch, ArchPoses};
use jawtrack::energy::{DEFAULT_LAMBDA, Scene, open_engine};
use jawtrack::synth::{MaskKind, Preset, SynthOptions};

#[derive(clap::Args)]
pub struct Args {
    /// Where to write the demo capture (default: jawtrack-demo in the system's temporary folder,
    /// replaced on each run). A folder you name must not exist, unless --force.
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
    #[command(flatten)]
    pub engine: super::energy::EngineArgs,
}

pub fn run(a: Args) -> anyhow::Result<()> {
    let (out, force) = match a.out {
        Some(o) => (o, a.force),
        None => (std::env::temp_dir().join("jawtrack-demo"), true),
    };
    let opts = SynthOptions {
        frames: a.frames,
        seed: a.seed,
        preset: Preset::Realistic,
        masks: MaskKind::PerArch,
        meshes: None,
        force,
    };
    println!(
        "== 1. synthesise a realistic capture (three cameras, half-resolution masks, lips, noise)"
    );
    let report = super::synth::generate(&out, &opts)?;
    super::synth::print_report(&out, &report);

    println!("\n== 2. read it back through the capture reader");
    let capture = super::validate::open_and_check(&out, true)?;
    super::validate::print_summary(&capture);

    let frame = capture.first_frame + capture.frame_count / 2;
    println!("\n== 3. the energy E = uncovered + {DEFAULT_LAMBDA}·boi_outside at frame {frame}");
    let truth = super::energy::default_poses(&capture, frame)
        .ok_or_else(|| anyhow::anyhow!("the demo capture has no ground truth"))?;
    let opened = open_engine(
        a.engine.backend,
        Scene::from_capture(&capture),
        a.engine.region,
    )?;
    eprintln!("energy backend: {}", opened.choice);
    let mut engine = opened.engine;
    engine.set_frame(&capture.load_masks(frame)?)?;
    println!("at the true poses:");
    println!("{}", super::energy::TABLE_HEADER);
    for arch in Arch::BOTH {
        let e = engine.evaluate(arch, &[truth])?.remove(0);
        super::energy::print_energy(arch, &capture.camera_names(), &e, DEFAULT_LAMBDA);
    }
    println!(
        "\neach of the 6 pose parameters moved by ±0.5 mm or ±0.5° (12 candidates per arch, one batch):"
    );
    println!("arch   E(truth)  lowest E moved  highest E moved");
    for arch in Arch::BOTH {
        let candidates: Vec<ArchPoses> = (0..12)
            .map(|k| {
                let mut d = [0.0; 6];
                let step = if k / 2 < 3 { 0.5f64.to_radians() } else { 0.5 };
                d[k / 2] = if k % 2 == 0 { step } else { -step };
                truth.with(arch, truth.get(arch).with_euler_offset(&d))
            })
            .collect();
        let at_truth = engine.evaluate(arch, &[truth])?[0].total(DEFAULT_LAMBDA);
        let started = Instant::now();
        let moved: Vec<f64> = engine
            .evaluate(arch, &candidates)?
            .iter()
            .map(|e| e.total(DEFAULT_LAMBDA))
            .collect();
        let per_eval_ms = started.elapsed().as_secs_f64() * 1e3 / candidates.len() as f64;
        let lo = moved.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = moved.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        println!(
            "{:<6} {:>8.1}  {:>14.1}  {:>15.1}   ({per_eval_ms:.2} ms per evaluation)",
            arch.name(),
            at_truth,
            lo,
            hi
        );
    }
    println!("\nthe capture is in {}", out.display());
    println!("not built yet: tracking (`jawtrack track`) and the jaw rig.");
    Ok(())
}
