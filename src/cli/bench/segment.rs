//! `jawtrack bench segment`: masks made from colour pictures while tracking (`segment`),
//! scored against the true labels and poses, on pictures of our own (`synth --images`) and on
//! captures other programs wrote. Each capture is segmented in a scratch copy: the masks a
//! run writes never touch the folder given.

use std::path::{Path, PathBuf};

use anyhow::Context;
use jawtrack::capture::json::CaptureJson;
use jawtrack::capture::{Capture, OpenOptions};
use jawtrack::io::read_json;
use jawtrack::segment::SegmentSettings;
use jawtrack::segment::score::{MaskScore, score_masks};
use jawtrack::synth::{SynthOptions, generate};
use jawtrack::track::score::FlagScore;
use jawtrack::track::{SessionOptions, score_records};

use crate::cli::args::{PhotosArg, PresetArg, name_of};
use crate::cli::segment::{
    gauss_newton_unless_asked, prepared, segment_and_track, segment_settings,
};
use crate::cli::track::TrackingArgs;

#[derive(clap::Args)]
pub struct SegmentArgs {
    /// Print JSON instead of a table.
    #[arg(long)]
    json: bool,
    /// Our own pictures to film (`synth --images --photos`), each with every preset and seed.
    #[arg(long, value_delimiter = ',', default_value = "clean,hard")]
    photos: Vec<PhotosArg>,
    /// Presets of our own captures (`hard`: faster motion, and the exercise starting again
    /// halfway).
    #[arg(long, value_delimiter = ',', default_value = "realistic")]
    presets: Vec<PresetArg>,
    /// Seeds of our own captures (one capture each).
    #[arg(long, value_delimiter = ',', default_value = "0,3")]
    seeds: Vec<u64>,
    /// Frames per capture of our own.
    #[arg(long, default_value_t = 24, value_parser = clap::value_parser!(u32).range(1..=100_000))]
    frames: u32,
    /// A folder with upper.* and lower.* to film instead of procedural arches (e.g. the real
    /// scans, ../shared/data/scan-tag0).
    #[arg(long)]
    meshes: Option<PathBuf>,
    /// A capture another program wrote, with its pictures (images/), init.json and its truth
    /// (gt/poses.json, and gt/masks/ for the IoU): copied to a scratch folder and segmented
    /// there. Repeat for more.
    #[arg(long = "capture", value_name = "DIR")]
    captures: Vec<PathBuf>,
    /// Only the --capture folders: no pictures of our own.
    #[arg(long, requires = "captures")]
    captures_only: bool,
    /// Segmentation settings as JSON (the fields of `SegmentSettings`): a file, or the JSON
    /// itself when it starts with `{`.
    #[arg(long)]
    segment_settings: Option<PathBuf>,
    #[command(flatten)]
    how: TrackingArgs,
}

#[derive(serde::Serialize)]
struct SegmentRow {
    set: String,
    frames: usize,
    /// Segmentation and tracking together, a frame.
    seconds_per_frame: f64,
    /// Of that, segmentation (all cameras).
    segmentation_seconds_per_frame: f64,
    evaluations_per_frame: f64,
    /// Against gt/masks, where the capture has them.
    masks: Option<MaskScore>,
    /// Mean vertex error (mm), median and 95th percentile: the jaw, the upper, the lower arch.
    jaw_mm: [f64; 2],
    upper_mm: [f64; 2],
    lower_mm: [f64; 2],
    flags: FlagScore,
    /// The jaw's manifold was let go (another subject's joint).
    manifold_released: bool,
}

pub fn segment(mut a: SegmentArgs) -> anyhow::Result<()> {
    gauss_newton_unless_asked(&mut a.how);
    let settings = segment_settings(a.segment_settings.as_deref())?;
    let tmp = tempfile::tempdir()?;
    let mut sets: Vec<(String, PathBuf)> = Vec::new();
    if !a.captures_only {
        let mut ours = Vec::new();
        for &photos in &a.photos {
            for &preset in &a.presets {
                ours.extend(a.seeds.iter().map(|&seed| (photos, preset, seed)));
            }
        }
        for (photos, preset, seed) in ours {
            let name = format!("{} {} seed {seed}", name_of(&photos), name_of(&preset));
            let dir = tmp.path().join(name.replace(' ', "-"));
            film(&a, &dir, photos, preset, seed)?;
            sets.push((name, dir));
        }
    }
    for (k, source) in a.captures.iter().enumerate() {
        let dir = tmp.path().join(format!("capture-{k}"));
        copy_without_masks(source, &dir)?;
        sets.push((source.display().to_string(), dir));
    }
    let mut rows = Vec::new();
    for (name, dir) in &sets {
        eprintln!("{name}");
        rows.push(measure(&a, name, dir, settings.clone())?);
    }
    if a.json {
        println!("{}", serde_json::to_string_pretty(&rows)?);
    } else {
        print_table(&rows);
    }
    Ok(())
}

/// Films one of our own captures into `dir`, without masks (segment makes them).
fn film(
    a: &SegmentArgs,
    dir: &Path,
    photos: PhotosArg,
    preset: PresetArg,
    seed: u64,
) -> anyhow::Result<()> {
    let opts = SynthOptions {
        frames: a.frames,
        seed,
        preset: preset.into(),
        meshes: a.meshes.clone(),
        images: true,
        photos: photos.into(),
        ..SynthOptions::default()
    };
    generate(dir, &opts, &|| {}).context("synthesising")?;
    let capture = Capture::open_with(dir, OpenOptions::default())?;
    std::fs::remove_dir_all(capture.mask_dir())
        .with_context(|| format!("removing {}", capture.mask_dir().display()))?;
    Ok(())
}

/// Copies the capture folder `from` into `to`, all but its masks folder (which is not read:
/// the copy is checked when it is opened).
fn copy_without_masks(from: &Path, to: &Path) -> anyhow::Result<()> {
    let cj: CaptureJson = read_json(&from.join("capture.json"), "capture.json")?;
    copy_tree(from, to, &from.join(&cj.masks.dir))
}

/// Copies the tree at `from` into `to`, leaving out `skip`. Links are followed: the capture
/// format keeps every path inside the folder.
fn copy_tree(from: &Path, to: &Path, skip: &Path) -> anyhow::Result<()> {
    std::fs::create_dir_all(to).with_context(|| format!("creating {}", to.display()))?;
    for entry in std::fs::read_dir(from).with_context(|| format!("reading {}", from.display()))? {
        let path = entry?.path();
        if path == skip {
            continue;
        }
        let target = to.join(path.file_name().context("a file without a name")?);
        if path.is_dir() {
            copy_tree(&path, &target, skip)?;
        } else {
            std::fs::copy(&path, &target).with_context(|| format!("copying {}", path.display()))?;
        }
    }
    Ok(())
}

/// Segments and tracks the capture at `dir`, and scores masks and poses against its truth.
fn measure(
    a: &SegmentArgs,
    name: &str,
    dir: &Path,
    settings: SegmentSettings,
) -> anyhow::Result<SegmentRow> {
    let options = OpenOptions {
        masks_to_come: true,
        ..a.how.load.open_options()
    };
    let capture =
        Capture::open_with(dir, options).with_context(|| format!("invalid capture {name}"))?;
    let (capture, sizes) = prepared(capture, options)?;
    let out = dir.join("tracks.json");
    let session = SessionOptions {
        backend: a.how.backend(),
        region: a.how.region(),
        force: true,
        settings: a.how.settings()?,
        ..SessionOptions::new(&out)
    };
    let run = segment_and_track(&capture, &sizes, session, settings, None)?;
    let frames = run.summary.tracked_now.max(1) as f64;
    let report = score_records(&capture, &out, &run.summary.records)?
        .with_context(|| format!("{name}: no ground truth (gt/poses.json) to score against"))?;
    let pair =
        |e: &jawtrack::track::score::PoseErrors| [e.mean_vertex_mm.median, e.mean_vertex_mm.p95];
    Ok(SegmentRow {
        set: name.to_string(),
        frames: run.summary.tracked_now,
        seconds_per_frame: run.summary.seconds / frames,
        segmentation_seconds_per_frame: run.segmenter.seconds / frames,
        evaluations_per_frame: run.summary.evaluations as f64 / frames,
        masks: score_masks(&capture, run.todo)?,
        jaw_mm: pair(&report.jaw),
        upper_mm: pair(&report.upper),
        lower_mm: pair(&report.lower),
        flags: report.flags,
        manifold_released: run.summary.manifold_released,
    })
}

fn print_table(rows: &[SegmentRow]) {
    println!(
        "IoU against gt/masks: teeth (worst picture), mouth interior; mean vertex error in mm (median / 95th percentile); s/frame: segmentation and tracking together (of that, segmentation); flags: flagged of the frames with the jaw off by more than 1 mm, flagged of the others"
    );
    println!(
        "{:<28} {:>6} {:>15} {:>6} {:>13} {:>13} {:>13} {:>12} {:>6} {:>9}",
        "set", "frames", "IoU teeth", "mouth", "jaw", "upper", "lower", "s/frame", "evals", "flags"
    );
    for r in rows {
        let (teeth, mouth) = r.masks.as_ref().map_or(("-".into(), "-".into()), |m| {
            (
                format!("{:.3} ({:.3})", m.teeth_iou, m.worst_teeth_iou),
                m.mouth_iou.map_or("-".into(), |v| format!("{v:.3}")),
            )
        });
        println!(
            "{:<28} {:>6} {:>15} {:>6} {:>6.3}/{:<6.3} {:>6.3}/{:<6.3} {:>6.3}/{:<6.3} {:>5.2} ({:.2}) {:>6.0} {:>3}/{:<3} {:>2}/{:<3}",
            r.set,
            r.frames,
            teeth,
            mouth,
            r.jaw_mm[0],
            r.jaw_mm[1],
            r.upper_mm[0],
            r.upper_mm[1],
            r.lower_mm[0],
            r.lower_mm[1],
            r.seconds_per_frame,
            r.segmentation_seconds_per_frame,
            r.evaluations_per_frame,
            r.flags.wrong_flagged,
            r.flags.wrong,
            r.flags.right_flagged,
            r.flags.right,
        );
    }
}
