//! `jawtrack bench energy` / `track` (`rig`: bench_rig.rs): evaluations per second of every energy backend, for performance
//! engineers; one synthetic capture per mesh case, three cameras, half-resolution masks.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::Context;
use jawtrack::capture::{Arch, ArchPoses, Capture, OpenOptions};
use jawtrack::energy::gpu::GpuEnergy;
use jawtrack::energy::{CpuEnergy, EnergyEngine, Region, Scene};
use jawtrack::synth::{Preset, SynthOptions, generate};

#[derive(clap::Subcommand)]
pub enum Command {
    /// Time the energy: CPU reference, GPU histogram and the readback baseline, single and
    /// batched, footprint and full frame, on a procedural arch and the real scans.
    Energy(EnergyArgs),
    /// Track synthetic captures and compare with the energy's floor (the minimum of E found
    /// by a long, fine search from the truth), per preset: accuracy, speed, ratio to floor.
    Track(TrackArgs),
    /// Learn a rig from synthetic TMJ motion and report the paper's figures, learning time and
    /// IK speed.
    Rig(super::bench_rig::RigArgs),
}

#[derive(clap::Args)]
pub struct EnergyArgs {
    /// Print JSON instead of a table.
    #[arg(long)]
    json: bool,
    /// Seconds to spend on each measurement (at least two runs each).
    #[arg(long, default_value_t = 1.0)]
    seconds: f64,
    /// Folder with the real scans (upper.obj, lower.obj); skipped when absent.
    #[arg(long, default_value = "../shared/data/scan-tag0")]
    scans: PathBuf,
    /// Triangles per arch of the simplified scan.
    #[arg(long, default_value_t = 10_000)]
    simplified: usize,
    /// Candidates per batch.
    #[arg(long, default_value_t = 64)]
    batch: usize,
    /// Which backends to time.
    #[arg(long, value_delimiter = ',', default_value = "cpu,gpu,readback", value_parser = ["cpu", "gpu", "readback"])]
    backends: Vec<String>,
}

#[derive(serde::Serialize)]
struct Row {
    mesh: String,
    triangles: usize,
    backend: String,
    region: String,
    batch: usize,
    ms_per_evaluation: f64,
    evaluations_per_second: f64,
}

#[derive(serde::Serialize)]
struct Report {
    machine: String,
    adapter: Option<String>,
    rows: Vec<Row>,
}

pub fn run(c: Command) -> anyhow::Result<()> {
    match c {
        Command::Energy(a) => energy(a),
        Command::Track(a) => track(a),
        Command::Rig(a) => super::bench_rig::rig(a),
    }
}

/// Candidates around the truth: small moves of the lower arch, as a search makes them.
fn candidates(truth: &ArchPoses, n: usize) -> Vec<ArchPoses> {
    (0..n)
        .map(|k| {
            let mut d = [0.0; 6];
            d[k % 6] = (k as f64 / n as f64 - 0.5) * if k % 6 < 3 { 0.02 } else { 1.0 };
            truth.with(Arch::Lower, truth.lower.with_euler_offset(&d))
        })
        .collect()
}

/// Mean time per evaluation of `batch` candidates, over at least two runs and `seconds`.
fn time(engine: &dyn EnergyEngine, batch: &[ArchPoses], seconds: f64) -> anyhow::Result<f64> {
    engine.evaluate(Arch::Lower, batch)?; // warm-up
    let budget = Duration::from_secs_f64(seconds);
    let started = Instant::now();
    let mut runs = 0;
    while runs < 2 || started.elapsed() < budget {
        engine.evaluate(Arch::Lower, batch)?;
        runs += 1;
    }
    Ok(started.elapsed().as_secs_f64() / (runs * batch.len()) as f64)
}

fn energy(a: EnergyArgs) -> anyhow::Result<()> {
    let tmp = tempfile::tempdir()?;
    // (name, scan folder, how the arches are simplified at load, lens)
    let full = OpenOptions {
        simplify_mm: 0.0,
        ..OpenOptions::default()
    };
    let lens = Some(jawtrack::synth::BARREL_LENS);
    type Case<'a> = (String, Option<&'a Path>, OpenOptions, Option<[f64; 5]>);
    let mut cases: Vec<Case> = vec![
        ("procedural".into(), None, full, None),
        ("procedural, barrel lens".into(), None, full, lens),
    ];
    if a.scans.join("upper.obj").exists() {
        let scans = Some(a.scans.as_path());
        cases.push(("scan-tag0".into(), scans, full, None));
        cases.push((
            format!("scan-tag0 {} mm", jawtrack::capture::DEFAULT_SIMPLIFY_MM),
            scans,
            OpenOptions::default(),
            None,
        ));
        cases.push((
            "scan-tag0 simplified".to_string(),
            scans,
            OpenOptions {
                max_triangles: Some(a.simplified),
                ..full
            },
            None,
        ));
    } else {
        eprintln!("no scans at {}: procedural arch only", a.scans.display());
    }
    let mut report = Report {
        machine: format!("{} CPU threads", rayon::current_num_threads()),
        adapter: None,
        rows: Vec::new(),
    };
    for (name, meshes, open, distortion) in cases {
        let dir = tmp
            .path()
            .join(match (meshes.is_some(), distortion.is_some()) {
                (true, _) => "scan",
                (false, false) => "procedural",
                (false, true) => "procedural-lens",
            });
        if !dir.exists() {
            let opts = SynthOptions {
                frames: 6,
                preset: Preset::Realistic,
                meshes: meshes.map(Path::to_path_buf),
                distortion,
                ..SynthOptions::default()
            };
            generate(&dir, &opts, &|| {}).context("synthesising the benchmark capture")?;
        }
        let capture = Capture::open_with(&dir, open)?;
        let masks = capture.load_masks(3)?;
        let truth = capture
            .gt_poses(3)
            .context("benchmark capture without ground truth")?;
        let batch = candidates(&truth, a.batch);
        let scene = Scene::from_capture(&capture);
        let triangles = capture.lower.triangles.len();
        let mut engines: Vec<(String, Region, Box<dyn EnergyEngine>)> = Vec::new();
        let want = |b: &str| a.backends.iter().any(|x| x == b);
        for region in [Region::Energy, Region::Footprint, Region::FullFrame] {
            if want("cpu") {
                engines.push((
                    "cpu".into(),
                    region,
                    Box::new(CpuEnergy::with_region(scene.clone(), region)),
                ));
            }
            // The GPU engine draws the footprint for `Energy`.
            if want("gpu") && region != Region::Energy {
                match GpuEnergy::new(scene.clone(), region) {
                    Ok(g) => {
                        report.adapter = Some(g.context().describe());
                        engines.push(("gpu".into(), region, Box::new(g)));
                    }
                    Err(e) => eprintln!("gpu: {e}"),
                }
            }
        }
        if want("readback") {
            match GpuEnergy::readback_baseline(scene.clone()) {
                Ok(g) => engines.push(("readback".into(), Region::FullFrame, Box::new(g))),
                Err(e) => eprintln!("readback: {e}"),
            }
        }
        anyhow::ensure!(!engines.is_empty(), "no backend to time");
        // Every backend must agree with the first before it is timed (within a few pixels:
        // see tests/gpu_energy.rs).
        let reference = engines[0].2.as_mut();
        reference.set_frame(&masks)?;
        let expected = reference.evaluate(Arch::Lower, &batch[..1])?[0].total(0.4);
        for (label, region, engine) in &mut engines {
            engine.set_frame(&masks)?;
            let got = engine.evaluate(Arch::Lower, &batch[..1])?[0].total(0.4);
            anyhow::ensure!(
                (got - expected).abs() <= 5.0,
                "{label} {region:?} energy {got} differs from the CPU reference's {expected}"
            );
        }
        for (label, region, engine) in &engines {
            for n in [1, a.batch] {
                let s = time(engine.as_ref(), &batch[..n], a.seconds)?;
                eprintln!("{name}: {label} {region:?} batch {n}: {:.3} ms", s * 1e3);
                report.rows.push(Row {
                    mesh: name.clone(),
                    triangles,
                    backend: label.clone(),
                    region: format!("{region:?}"),
                    batch: n,
                    ms_per_evaluation: s * 1e3,
                    evaluations_per_second: 1.0 / s,
                });
            }
        }
    }
    if a.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        println!(
            "energy of one arch, three cameras, 960x540 masks; {}; adapter: {}",
            report.machine,
            report.adapter.as_deref().unwrap_or("none")
        );
        println!(
            "{:<22} {:>9} {:<9} {:<10} {:>5} {:>11} {:>10}",
            "mesh", "triangles", "backend", "region", "batch", "ms/eval", "evals/s"
        );
        for r in &report.rows {
            println!(
                "{:<22} {:>9} {:<9} {:<10} {:>5} {:>11.3} {:>10.1}",
                r.mesh,
                r.triangles,
                r.backend,
                r.region,
                r.batch,
                r.ms_per_evaluation,
                r.evaluations_per_second
            );
        }
    }
    Ok(())
}

#[derive(clap::Args)]
pub struct TrackArgs {
    /// Print JSON instead of a table.
    #[arg(long)]
    json: bool,
    /// Presets to measure.
    #[arg(long, value_delimiter = ',', default_value = "realistic")]
    presets: Vec<Preset>,
    /// Seeds (one capture each).
    #[arg(long, value_delimiter = ',', default_value = "1,2,3")]
    seeds: Vec<u64>,
    /// Frames per capture.
    #[arg(long, default_value_t = 34)]
    frames: u32,
    /// Mask kind.
    #[arg(long, value_enum, default_value_t = jawtrack::synth::MaskKind::PerArch)]
    masks: jawtrack::synth::MaskKind,
    /// The synthetic subject's joint (the tracker's jaw prior assumes an average one).
    #[arg(long, value_enum, default_value_t = jawtrack::synth::Joint::Average)]
    joint: jawtrack::synth::Joint,
    /// The movements' pace (see `synth --frames-per-segment`); 4 is about the pace this
    /// bench's 34-frame captures had before the option (4.25: the exercise's core squeezed in).
    #[arg(long, default_value_t = jawtrack::synth::exercise::FRAMES_PER_SEGMENT)]
    frames_per_segment: u32,
    /// A folder with upper.* and lower.* to use instead of procedural arches (e.g. the real
    /// scans, ../shared/data/scan-tag0).
    #[arg(long)]
    meshes: Option<PathBuf>,
    #[command(flatten)]
    rig: super::synth::RigArgs,
    /// Tracking settings (JSON, fields of TrackSettings), e.g. to turn the jaw prior off: a
    /// file, or the JSON itself when it starts with `{`.
    #[arg(long)]
    settings: Option<PathBuf>,
    /// How the meshes are simplified and the masks read at load (for tracking, the floor and
    /// the score alike).
    #[command(flatten)]
    load: super::energy::LoadArgs,
    #[command(flatten)]
    engine: super::energy::EngineArgs,
}

#[derive(serde::Serialize)]
struct TrackRow {
    preset: String,
    masks: String,
    frames: usize,
    seconds_per_frame: f64,
    evaluations_per_frame: f64,
    /// Jaw and per-arch mean vertex error (mm): median, 95th percentile.
    jaw_error_mm: [f64; 2],
    upper_error_mm: [f64; 2],
    lower_error_mm: [f64; 2],
    /// The energy's floor: the error of E's minimum found by a long, fine search from the
    /// truth (jaw, median and 95th percentile).
    jaw_floor_mm: [f64; 2],
    /// Median over frames of tracked error / floor (jaw mean vertex error; floors under
    /// 0.01 mm count as 0.01 mm).
    median_ratio_to_floor: f64,
    /// Share of frames whose tracked poses have a higher objective (both arches) than the
    /// floor's: there the search stopped short; elsewhere the energy cannot tell them apart.
    search_shortfall: f64,
    area_error_percent_median: [f64; 2],
}

/// The search's objective (E plus the cross-label term, default weights) of both arches.
fn objective_sum(engine: &dyn EnergyEngine, poses: &ArchPoses) -> anyhow::Result<f64> {
    let s = jawtrack::track::SearchSettings::default();
    let mut sum = 0.0;
    for arch in Arch::BOTH {
        sum += engine.evaluate(arch, std::slice::from_ref(poses))?[0]
            .objective(s.lambda, s.cross_weight);
    }
    Ok(sum)
}

/// The floor: E minimised by a long, fine search from the true poses (upper, then lower).
fn floor_poses(
    capture: &Capture,
    engine: &dyn EnergyEngine,
    truth: &ArchPoses,
    frame: u32,
) -> anyhow::Result<ArchPoses> {
    use jawtrack::track::SearchSettings;
    let fine = SearchSettings {
        max_rounds: 40,
        min_gain: 0.1,
        sample_rounds: 4,
        samples: 64,
        scales: vec![1.0, 0.25, 0.06],
        ..SearchSettings::default()
    };
    let mut poses = *truth;
    for arch in Arch::BOTH {
        let centre = jawtrack::track::sequence::centre(capture, arch);
        let found = jawtrack::track::search(
            engine,
            arch,
            &poses,
            *poses.get(arch),
            &centre,
            &jawtrack::track::penalties::Penalties::NONE,
            &fine,
            frame as u64,
        )?;
        poses = poses.with(arch, found.pose);
    }
    Ok(poses)
}

pub fn track(a: TrackArgs) -> anyhow::Result<()> {
    use jawtrack::track::score::Stats;
    let tmp = tempfile::tempdir()?;
    let mut rows = Vec::new();
    for preset in &a.presets {
        let mut jaw = Vec::new();
        let mut upper = Vec::new();
        let mut lower = Vec::new();
        let mut floor = Vec::new();
        let mut ratio = Vec::new();
        let mut area = [Vec::new(), Vec::new()];
        let (mut seconds, mut evaluations, mut frames) = (0.0, 0usize, 0usize);
        let mut shortfall = 0usize;
        for &seed in &a.seeds {
            let dir = tmp.path().join(format!("{preset:?}-{seed}"));
            let opts = SynthOptions {
                frames: a.frames,
                seed,
                preset: *preset,
                masks: a.masks,
                joint: a.joint,
                frames_per_segment: a.frames_per_segment,
                meshes: a.meshes.clone(),
                rig: a.rig.rig.clone(),
                distortion: a.rig.distortion()?,
                ..SynthOptions::default()
            };
            generate(&dir, &opts, &|| {}).context("synthesising")?;
            let capture = Capture::open_with(&dir, a.load.open_options())?;
            let out = dir.join("tracks.json");
            let args = super::track::Args {
                capture: dir.clone(),
                output: out.clone(),
                frames: None,
                engine: a.engine,
                overlays: None,
                resume: false,
                force: true,
                load: a.load,
                settings: a.settings.clone(),
            };
            let summary = super::track::track(&capture, &args)?;
            seconds += summary.seconds;
            evaluations += summary.evaluations;
            frames += summary.tracked_now;
            let report = super::track::score_records(&capture, &out, &summary.records)?
                .context("ground truth")?;
            let opened = jawtrack::energy::open_engine(
                a.engine.backend,
                Scene::from_capture(&capture),
                a.engine.region.unwrap_or(Region::Energy),
            )?;
            let mut engine = opened.engine;
            let vertices = jawtrack::track::score::sample_vertices(&capture.lower);
            let tracked: std::collections::HashMap<u32, ArchPoses> = summary
                .records
                .iter()
                .map(|r| Ok((r.frame, jawtrack::track::output::record_poses(&out, r)?.0)))
                .collect::<anyhow::Result<_>>()?;
            for (frame, err) in &report.per_frame {
                let truth = capture.gt_poses(*frame).context("ground truth")?;
                let masks = capture.load_masks(*frame)?;
                if masks.masks.iter().all(Option::is_none) {
                    continue;
                }
                engine.set_frame(&masks)?;
                let f = floor_poses(&capture, engine.as_ref(), &truth, *frame)?;
                let t = tracked[frame];
                let (et, ef) = (
                    objective_sum(engine.as_ref(), &t)?,
                    objective_sum(engine.as_ref(), &f)?,
                );
                if et > ef + 0.5 {
                    shortfall += 1;
                }
                let (fj, tj) = (f.jaw(), truth.jaw());
                let floor_jaw = jawtrack::track::score::mean_distance(&vertices, &fj, &tj);
                upper.push(err[0]);
                lower.push(err[1]);
                jaw.push(err[2]);
                floor.push(floor_jaw);
                ratio.push(err[2] / floor_jaw.max(0.01));
                eprintln!(
                    "{preset:?} seed {seed} frame {frame}: jaw {:.3} mm, floor {:.3} mm; E tracked {et:.0}, at the floor {ef:.0}",
                    err[2], floor_jaw
                );
            }
            for (k, s) in report.area_error_percent.iter().enumerate() {
                area[k].push(s.median);
            }
        }
        let two = |v: &[f64]| {
            let s = Stats::of(v);
            [s.median, s.p95]
        };
        rows.push(TrackRow {
            preset: format!("{preset:?}"),
            masks: format!("{:?}", a.masks),
            frames,
            seconds_per_frame: seconds / frames.max(1) as f64,
            evaluations_per_frame: evaluations as f64 / frames.max(1) as f64,
            jaw_error_mm: two(&jaw),
            upper_error_mm: two(&upper),
            lower_error_mm: two(&lower),
            jaw_floor_mm: two(&floor),
            median_ratio_to_floor: Stats::of(&ratio).median,
            search_shortfall: shortfall as f64 / jaw.len().max(1) as f64,
            area_error_percent_median: [Stats::of(&area[0]).median, Stats::of(&area[1]).median],
        });
    }
    if a.json {
        println!("{}", serde_json::to_string_pretty(&rows)?);
    } else {
        println!(
            "mean vertex error in mm (median / 95th percentile); floor = error of E's minimum found from the truth"
        );
        println!(
            "{:<10} {:<8} {:>6} {:>8} {:>7} {:>13} {:>13} {:>13} {:>13} {:>11} {:>9} {:>13}",
            "preset",
            "masks",
            "frames",
            "s/frame",
            "evals",
            "jaw",
            "upper",
            "lower",
            "jaw floor",
            "ratio",
            "shortfall",
            "area err %"
        );
        for r in &rows {
            println!(
                "{:<10} {:<8} {:>6} {:>8.2} {:>7.0} {:>6.3}/{:<6.3} {:>6.3}/{:<6.3} {:>6.3}/{:<6.3} {:>6.3}/{:<6.3} {:>11.2} {:>9.2} {:>6.2}/{:<6.2}",
                r.preset,
                r.masks,
                r.frames,
                r.seconds_per_frame,
                r.evaluations_per_frame,
                r.jaw_error_mm[0],
                r.jaw_error_mm[1],
                r.upper_error_mm[0],
                r.upper_error_mm[1],
                r.lower_error_mm[0],
                r.lower_error_mm[1],
                r.jaw_floor_mm[0],
                r.jaw_floor_mm[1],
                r.median_ratio_to_floor,
                r.search_shortfall,
                r.area_error_percent_median[0],
                r.area_error_percent_median[1]
            );
        }
    }
    Ok(())
}
