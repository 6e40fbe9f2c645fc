//! `jawtrack bench track`: synthetic captures tracked and compared with the energy's floor.

use std::path::PathBuf;

use anyhow::Context;
use jawtrack::arch::{Arch, ArchPoses};
use jawtrack::capture::Capture;
use jawtrack::energy::{EnergyEngine, Region, Scene, Weights};
use jawtrack::synth::{SynthOptions, generate};
use jawtrack::track::SessionOptions;

use crate::cli::args::{EnergyArg, JointArg, MaskKindArg, PresetArg, name_of};

#[derive(clap::Args)]
pub struct TrackArgs {
    /// Print JSON instead of a table.
    #[arg(long)]
    json: bool,
    /// Presets to measure.
    #[arg(long, value_delimiter = ',', default_value = "realistic")]
    presets: Vec<PresetArg>,
    /// Seeds (one capture each).
    #[arg(long, value_delimiter = ',', default_value = "1,2,3")]
    seeds: Vec<u64>,
    /// Frames per capture.
    #[arg(long, default_value_t = 34, value_parser = clap::value_parser!(u32).range(1..=100_000))]
    frames: u32,
    /// Mask kind.
    #[arg(long, value_enum, default_value_t = MaskKindArg::PerArch)]
    masks: MaskKindArg,
    /// The synthetic subject's joint (the tracker's jaw prior assumes an average one).
    #[arg(long, value_enum, default_value_t = JointArg::Average)]
    joint: JointArg,
    /// The movements' pace (see `synth --frames-per-segment`); 4 is about the pace this
    /// bench's 34-frame captures had before the option (4.25: the exercise's core squeezed in).
    #[arg(long, default_value_t = jawtrack::synth::exercise::FRAMES_PER_SEGMENT)]
    frames_per_segment: u32,
    /// A folder with upper.* and lower.* to use instead of procedural arches (e.g. the real
    /// scans, ../shared/data/scan-tag0).
    #[arg(long)]
    meshes: Option<PathBuf>,
    #[command(flatten)]
    rig: crate::cli::args::CameraRigArgs,
    /// Tracking settings (JSON, fields of TrackSettings), e.g. to turn the jaw prior off: a
    /// file, or the JSON itself when it starts with `{`.
    #[arg(long)]
    settings: Option<PathBuf>,
    /// The objective: the paper's E with the terms of our own, or the paper's E alone (for
    /// tracking and the floor alike).
    #[arg(long, value_enum, default_value_t = EnergyArg::Full)]
    energy: EnergyArg,
    /// Track each capture with its masks' mouth label, without it (the label ignored: the
    /// same masks as teeth masks), or both, one row each.
    #[arg(long, value_delimiter = ',', default_value = "with,without")]
    mouth: Vec<MouthLabel>,
    /// Segmentation errors that persist from frame to frame (see `synth --persistent-noise`).
    #[arg(long)]
    persistent_noise: bool,
    /// Skip the energy's floor (its columns print as NaN): for comparing search settings,
    /// which do not change it, in half the time.
    #[arg(long)]
    no_floor: bool,
    /// How the meshes are simplified and the masks read at load (for tracking, the floor and
    /// the score alike).
    #[command(flatten)]
    load: crate::cli::args::LoadArgs,
    #[command(flatten)]
    engine: crate::cli::args::EngineArgs,
}

/// Whether a capture is tracked with its masks' mouth label.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
enum MouthLabel {
    With,
    Without,
}

#[derive(serde::Serialize)]
struct TrackRow {
    preset: String,
    masks: String,
    /// Whether the masks' mouth label was read (the capture has one).
    mouth_label: bool,
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

/// The search's objective (E plus the terms of our own, at `weights`) of both arches.
fn objective_sum(
    engine: &dyn EnergyEngine,
    poses: &ArchPoses,
    weights: &Weights,
) -> anyhow::Result<f64> {
    let mut sum = 0.0;
    for arch in Arch::BOTH {
        sum += engine.evaluate(arch, std::slice::from_ref(poses))?[0].objective(weights);
    }
    Ok(sum)
}

/// The floor: the objective (at the tracking's weights, without penalties) minimised by a
/// long, fine search from the true poses (upper, then lower).
fn floor_poses(
    capture: &Capture,
    engine: &dyn EnergyEngine,
    truth: &ArchPoses,
    frame: u32,
    weights: &Weights,
) -> anyhow::Result<ArchPoses> {
    use jawtrack::track::SearchSettings;
    let fine = SearchSettings {
        max_rounds: 40,
        min_gain: 0.1,
        sample_rounds: 4,
        samples: 64,
        scales: vec![1.0, 0.25, 0.06],
        lambda: weights.lambda,
        cross_weight: weights.cross,
        mouth_weight: weights.mouth,
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
    let settings = crate::cli::args::track_settings(a.settings.as_deref(), a.energy)?;
    let weights = settings.search.weights();
    let mut rows = Vec::new();
    for (preset, label) in a
        .presets
        .iter()
        .flat_map(|p| a.mouth.iter().map(move |m| (p, *m)))
    {
        let mut labelled = false;
        let mut jaw = Vec::new();
        let mut upper = Vec::new();
        let mut lower = Vec::new();
        let mut floor = Vec::new();
        let mut ratio = Vec::new();
        let mut area = [Vec::new(), Vec::new()];
        let (mut seconds, mut evaluations, mut frames) = (0.0, 0usize, 0usize);
        let mut shortfall = 0usize;
        for &seed in &a.seeds {
            let dir = tmp.path().join(format!("{}-{seed}", name_of(preset)));
            let opts = SynthOptions {
                frames: a.frames,
                seed,
                preset: (*preset).into(),
                masks: a.masks.into(),
                joint: a.joint.into(),
                frames_per_segment: a.frames_per_segment,
                meshes: a.meshes.clone(),
                rig: a.rig.rig.clone(),
                distortion: a.rig.distortion()?,
                persistent_noise: a.persistent_noise,
                ..SynthOptions::default()
            };
            // Each capture is written once and tracked with and without its label.
            if !dir.exists() {
                generate(&dir, &opts, &|| {}).context("synthesising")?;
            }
            let mut capture = Capture::open_with(&dir, a.load.open_options())?;
            if label == MouthLabel::Without {
                capture = capture.without_mouth_label();
            }
            labelled |= capture.mouth().is_some();
            let out = dir.join("tracks.json");
            let options = SessionOptions {
                backend: a.engine.backend.into(),
                region: a.engine.region.map_or(Region::Relevant, Into::into),
                force: true,
                settings: settings.clone(),
                ..SessionOptions::new(&out)
            };
            let summary = crate::cli::run::track(&capture, options)?;
            seconds += summary.seconds;
            evaluations += summary.evaluations;
            frames += summary.tracked_now;
            let report = jawtrack::track::score_records(&capture, &out, &summary.records)?
                .context("ground truth")?;
            let opened = jawtrack::energy::open_engine(
                a.engine.backend.into(),
                Scene::from_capture(&capture),
                a.engine.region.map_or(Region::Relevant, Into::into),
            )?;
            let mut engine = opened.engine;
            let lower_metric = jawtrack::anatomy::MeshMetric::new(capture.lower());
            let tracked: std::collections::HashMap<u32, ArchPoses> = summary
                .records
                .iter()
                .map(|r| Ok((r.frame, r.poses(&out)?)))
                .collect::<anyhow::Result<_>>()?;
            for (frame, err) in &report.per_frame {
                let truth = capture.gt_poses(*frame).context("ground truth")?;
                let masks = capture.load_masks(*frame)?;
                if masks.masks.iter().all(Option::is_none) {
                    continue;
                }
                upper.push(err[0]);
                lower.push(err[1]);
                jaw.push(err[2]);
                if a.no_floor {
                    continue;
                }
                engine.set_frame(&masks)?;
                let f = floor_poses(&capture, engine.as_ref(), &truth, *frame, &weights)?;
                let t = tracked[frame];
                let (et, ef) = (
                    objective_sum(engine.as_ref(), &t, &weights)?,
                    objective_sum(engine.as_ref(), &f, &weights)?,
                );
                if et > ef + 0.5 {
                    shortfall += 1;
                }
                let (fj, tj) = (f.jaw(), truth.jaw());
                let floor_jaw = lower_metric.mean_distance(&fj, &tj);
                floor.push(floor_jaw);
                ratio.push(err[2] / floor_jaw.max(0.01));
                eprintln!(
                    "{} {} seed {seed} frame {frame}: jaw {:.3} mm, floor {:.3} mm; E tracked {et:.0}, at the floor {ef:.0}",
                    name_of(preset),
                    if capture.mouth().is_some() {
                        "labelled"
                    } else {
                        "unlabelled"
                    },
                    err[2],
                    floor_jaw
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
        let skipped = |v: f64| if a.no_floor { f64::NAN } else { v };
        rows.push(TrackRow {
            preset: name_of(preset),
            masks: name_of(&a.masks),
            mouth_label: labelled,
            frames,
            seconds_per_frame: seconds / frames.max(1) as f64,
            evaluations_per_frame: evaluations as f64 / frames.max(1) as f64,
            jaw_error_mm: two(&jaw),
            upper_error_mm: two(&upper),
            lower_error_mm: two(&lower),
            jaw_floor_mm: two(&floor).map(skipped),
            median_ratio_to_floor: skipped(Stats::of(&ratio).median),
            search_shortfall: skipped(shortfall as f64 / jaw.len().max(1) as f64),
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
            "{:<10} {:<8} {:<5} {:>6} {:>8} {:>7} {:>13} {:>13} {:>13} {:>13} {:>11} {:>9} {:>13}",
            "preset",
            "masks",
            "mouth",
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
                "{:<10} {:<8} {:<5} {:>6} {:>8.2} {:>7.0} {:>6.3}/{:<6.3} {:>6.3}/{:<6.3} {:>6.3}/{:<6.3} {:>6.3}/{:<6.3} {:>11.2} {:>9.2} {:>6.2}/{:<6.2}",
                r.preset,
                r.masks,
                if r.mouth_label { "yes" } else { "no" },
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
