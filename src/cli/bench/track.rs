//! `jawtrack bench track`: synthetic captures tracked and compared with the energy's floor.

use std::path::{Path, PathBuf};

use anyhow::Context;
use jawtrack::arch::ArchPoses;
use jawtrack::capture::Capture;
use jawtrack::energy::{Region, Scene};
use jawtrack::synth::{SynthOptions, generate};
use jawtrack::track::floor::{FloorCheck, FloorSummary, FloorTally};
use jawtrack::track::prior_and_penalties;
use jawtrack::track::{SessionOptions, Summary, TrackSettings};

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
    /// How the poses are found (`search.solver` of the settings; this wins).
    #[arg(long, value_enum)]
    search: Option<crate::cli::args::SearchArg>,
    /// Track each capture with its masks' mouth label, without it (the label ignored: the
    /// same masks as teeth masks), or both, one row each.
    #[arg(long, value_delimiter = ',', default_value = "with,without")]
    mouth: Vec<MouthLabel>,
    /// Segmentation errors that persist from frame to frame (see `synth --persistent-noise`).
    #[arg(long)]
    persistent_noise: bool,
    /// Track as if the captures had no init.json: the first frame's poses found from its
    /// masks alone.
    #[arg(long)]
    no_init: bool,
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
    #[serde(flatten)]
    summary: FloorSummary,
}

/// What every capture of the bench is tracked and measured with.
struct Bench<'a> {
    args: &'a TrackArgs,
    tmp: &'a Path,
    settings: &'a TrackSettings,
}

pub fn track(a: TrackArgs) -> anyhow::Result<()> {
    let tmp = tempfile::tempdir()?;
    let settings = crate::cli::args::track_settings(a.settings.as_deref(), a.energy, a.search)?;
    let bench = Bench {
        args: &a,
        tmp: tmp.path(),
        settings: &settings,
    };
    let mut rows = Vec::new();
    for (preset, label) in a
        .presets
        .iter()
        .flat_map(|p| a.mouth.iter().map(move |m| (p, *m)))
    {
        rows.push(measure_row(&bench, preset, label)?);
    }
    if a.json {
        println!("{}", serde_json::to_string_pretty(&rows)?);
    } else {
        print_table(&rows);
    }
    Ok(())
}

/// One row of the table: every seed's capture of a preset, tracked with or without its label.
fn measure_row(b: &Bench, preset: &PresetArg, label: MouthLabel) -> anyhow::Result<TrackRow> {
    let mut labelled = false;
    let mut tally = FloorTally::default();
    for &seed in &b.args.seeds {
        labelled |= measure_capture(b, preset, label, seed, &mut tally)?;
    }
    Ok(TrackRow {
        preset: name_of(preset),
        masks: name_of(&b.args.masks),
        mouth_label: labelled,
        summary: tally.summary(),
    })
}

/// Tracks one seed's capture and adds its speed, errors and floor to `tally`; whether the
/// capture has a mouth label.
fn measure_capture(
    b: &Bench,
    preset: &PresetArg,
    label: MouthLabel,
    seed: u64,
    tally: &mut FloorTally,
) -> anyhow::Result<bool> {
    let a = b.args;
    let dir = b.tmp.join(format!("{}-{seed}", name_of(preset)));
    let capture = open_capture(a, &dir, preset, label, seed)?;
    let out = dir.join("tracks.json");
    let summary = track_capture(b, &capture, &out, tally)?;
    let report = jawtrack::track::score_records(&capture, &out, &summary.records)?
        .context("ground truth")?;
    let opened = jawtrack::energy::open_engine(
        a.engine.backend.into(),
        Scene::from_capture(&capture),
        a.engine.region.map_or(Region::Relevant, Into::into),
    )?;
    let mut engine = opened.engine;
    let tracked: std::collections::HashMap<u32, ArchPoses> = summary
        .records
        .iter()
        .map(|r| Ok((r.frame, r.poses(&out)?)))
        .collect::<anyhow::Result<_>>()?;
    // The run's prior and penalties, for the smooth energy's floor, fitted around where the
    // run started: init.json's poses, or (with `--no-init`) its first tracked frame's.
    let settings = b.settings.for_capture(&capture);
    let start = match capture.initial_poses() {
        Ok(poses) => poses,
        Err(_) => *summary
            .records
            .first()
            .and_then(|r| tracked.get(&r.frame))
            .context("no tracked frame to start the floor's penalties from")?,
    };
    let (_, penalties) = prior_and_penalties(&capture, &settings, &start);
    for (frame, err) in &report.per_frame {
        let truth = capture.gt_poses(*frame).context("ground truth")?;
        let masks = capture.load_masks(*frame)?;
        if masks.masks.iter().all(Option::is_none) {
            continue;
        }
        if a.no_floor {
            tally.frame(*err, None);
            continue;
        }
        engine.set_frame(&masks)?;
        let f = FloorCheck::of(
            &capture,
            engine.as_ref(),
            &masks,
            (&truth, &tracked[frame]),
            (&settings.search, &penalties),
        )?;
        tally.frame(*err, Some(f));
        eprintln!(
            "{} {} seed {seed} frame {frame}: jaw {:.3} mm, floor {:.3} mm (smooth {:.3}); E tracked {:.0}, at the floor {:.0}",
            name_of(preset),
            if capture.mouth().is_some() {
                "labelled"
            } else {
                "unlabelled"
            },
            err[2],
            f.jaw_mm,
            f.smooth_jaw_mm,
            f.tracked,
            f.floor
        );
    }
    tally.capture_area_errors(report.area_error_percent.each_ref().map(|s| s.median));
    tally.capture_flags(&report.flags, report.frames_teeth_hidden);
    Ok(capture.mouth().is_some())
}

/// Opens one seed's synthetic capture in `dir`, writing it the first time, without its mouth
/// label when `label` says so.
fn open_capture(
    a: &TrackArgs,
    dir: &Path,
    preset: &PresetArg,
    label: MouthLabel,
    seed: u64,
) -> anyhow::Result<Capture> {
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
        generate(dir, &opts, &|| {}).context("synthesising")?;
    }
    let mut capture = Capture::open_with(dir, a.load.open_options())?;
    if label == MouthLabel::Without {
        capture = capture.without_mouth_label();
    }
    if a.no_init {
        capture = capture.without_init();
    }
    Ok(capture)
}

/// Tracks the capture into `out` and adds the time, evaluations and frames to `tally`.
fn track_capture(
    b: &Bench,
    capture: &Capture,
    out: &Path,
    tally: &mut FloorTally,
) -> anyhow::Result<Summary> {
    let options = SessionOptions {
        backend: b.args.engine.backend.into(),
        region: b.args.engine.region.map_or(Region::Relevant, Into::into),
        force: true,
        settings: b.settings.clone(),
        ..SessionOptions::new(out)
    };
    let summary = crate::cli::run::track(capture, options)?;
    tally.seconds += summary.seconds;
    tally.evaluations += summary.evaluations;
    tally.steps += summary.steps;
    tally.frames += summary.tracked_now;
    Ok(summary)
}

/// Prints the rows as a table: errors as median / 95th percentile, against the energy's floor.
fn print_table(rows: &[TrackRow]) {
    println!(
        "mean vertex error in mm (median / 95th percentile); floor = error of E's lowest minimum found from the truth and from the tracked poses, smooth = of the smooth energy's (Gauss-Newton's); flags: flagged of the frames with the jaw off by more than 1 mm, flagged of the others, of those with the teeth hidden"
    );
    println!(
        "{:<10} {:<8} {:<5} {:>6} {:>8} {:>7} {:>6} {:>13} {:>13} {:>13} {:>13} {:>13} {:>11} {:>9} {:>13} {:>16}",
        "preset",
        "masks",
        "mouth",
        "frames",
        "s/frame",
        "evals",
        "steps",
        "jaw",
        "upper",
        "lower",
        "jaw floor",
        "smooth floor",
        "ratio",
        "shortfall",
        "area err %",
        "flags"
    );
    for row in rows {
        let r = &row.summary;
        println!(
            "{:<10} {:<8} {:<5} {:>6} {:>8.2} {:>7.0} {:>6.1} {:>6.3}/{:<6.3} {:>6.3}/{:<6.3} {:>6.3}/{:<6.3} {:>6.3}/{:<6.3} {:>6.3}/{:<6.3} {:>11.2} {:>9.2} {:>6.2}/{:<6.2} {:>3}/{:<3} {:>3}/{:<3} {:>2}",
            row.preset,
            row.masks,
            if row.mouth_label { "yes" } else { "no" },
            r.frames,
            r.seconds_per_frame,
            r.evaluations_per_frame,
            r.steps_per_frame,
            r.jaw_error_mm[0],
            r.jaw_error_mm[1],
            r.upper_error_mm[0],
            r.upper_error_mm[1],
            r.lower_error_mm[0],
            r.lower_error_mm[1],
            r.jaw_floor_mm[0],
            r.jaw_floor_mm[1],
            r.jaw_smooth_floor_mm[0],
            r.jaw_smooth_floor_mm[1],
            r.median_ratio_to_floor,
            r.search_shortfall,
            r.area_error_percent_median[0],
            r.area_error_percent_median[1],
            r.flags.wrong_flagged,
            r.flags.wrong,
            r.flags.right_flagged,
            r.flags.right,
            r.flags.teeth_hidden,
        );
    }
}
