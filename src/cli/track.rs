use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, bail};
use jawtrack::capture::json::FrameRecordJson;
use jawtrack::capture::{ArchPoses, Capture};
use jawtrack::energy::{Region, Scene, open_engine};
use jawtrack::track::output::{TracksWriter, record_poses};
use jawtrack::track::score::{ScoreReport, Stats, score};
use jawtrack::track::{Status, TrackSettings, TrackState, overlay, track_frames};

#[derive(clap::Args)]
pub struct Args {
    /// The capture folder.
    pub capture: PathBuf,
    /// Where to write tracks.json.
    #[arg(short, long)]
    pub output: PathBuf,
    /// Frames to track: `A..B` (B excluded) or `A..=B`; default all.
    #[arg(long)]
    pub frames: Option<String>,
    #[command(flatten)]
    pub engine: super::energy::EngineArgs,
    /// Write the paper's overlay pictures (mask white, model red at alpha 0.5, BOI green) per
    /// camera and frame into this folder.
    #[arg(long)]
    pub overlays: Option<PathBuf>,
    /// Continue an interrupted run after its last complete frame.
    #[arg(long)]
    pub resume: bool,
    /// Start over when the output exists.
    #[arg(long)]
    pub force: bool,
    #[command(flatten)]
    pub load: super::energy::LoadArgs,
    /// Tracking settings as JSON (the fields of `TrackSettings`; see README; missing ones take
    /// their defaults, unknown ones are an error): a file, or the JSON itself when it starts
    /// with `{`, e.g. '{"search": {"lambda": 1.0}}'.
    #[arg(long)]
    pub settings: Option<PathBuf>,
}

/// What a tracking run did.
pub struct Summary {
    pub records: Vec<FrameRecordJson>,
    pub tracked_now: usize,
    pub seconds: f64,
    pub evaluations: usize,
    pub backend: String,
}

fn parse_range(s: &str, capture: &Capture) -> anyhow::Result<std::ops::Range<u32>> {
    let all = capture.frames();
    let (a, b, inclusive) = if let Some((a, b)) = s.split_once("..=") {
        (a, b, true)
    } else if let Some((a, b)) = s.split_once("..") {
        (a, b, false)
    } else {
        bail!("--frames {s:?}: expected A..B or A..=B");
    };
    let num = |x: &str, default: u32| -> anyhow::Result<u32> {
        if x.is_empty() {
            Ok(default)
        } else {
            x.trim()
                .parse()
                .with_context(|| format!("--frames {s:?}: `{x}` is not a frame number"))
        }
    };
    let start = num(a, all.start)?;
    let end = num(b, all.end)? + if inclusive { 1 } else { 0 };
    if start < all.start || end > all.end || start >= end {
        bail!(
            "--frames {s:?}: the capture has frames {}..{}",
            all.start,
            all.end
        );
    }
    Ok(start..end)
}

pub fn run(a: Args) -> anyhow::Result<()> {
    let capture = Capture::open_with(&a.capture, a.load.open_options())
        .with_context(|| format!("invalid capture {}", a.capture.display()))?;
    let summary = track(&capture, &a)?;
    print_summary(&a.output, &summary);
    if let Some(report) = score_records(&capture, &a.output, &summary.records)? {
        println!();
        print_score(&report);
    }
    Ok(())
}

pub fn track(capture: &Capture, a: &Args) -> anyhow::Result<Summary> {
    let settings: TrackSettings = match &a.settings {
        Some(p) => super::read_settings(p, "settings file")?,
        None => TrackSettings::default(),
    };
    let range = match &a.frames {
        Some(s) => parse_range(s, capture)?,
        None => capture.frames(),
    };
    let (mut writer, done) = TracksWriter::open(&a.output, a.resume, a.force)?;
    // Where to start: after the frames already written, from the last good one.
    let (mut state, start) = match done
        .iter()
        .rev()
        .find(|r| r.status.as_deref() == Some("ok"))
    {
        Some(last_ok) if a.resume => {
            let (last, _) = record_poses(&a.output, last_ok)?;
            let mut state = TrackState::new(last);
            let before = done
                .iter()
                .rev()
                .find(|r| r.frame + 1 == last_ok.frame && r.status.as_deref() == Some("ok"));
            state.before = before
                .map(|r| record_poses(&a.output, r))
                .transpose()?
                .map(|(p, _)| p);
            let next = done
                .last()
                .map_or(range.start, |r| r.frame + 1)
                .max(range.start);
            (state, next)
        }
        _ => {
            let first = capture.initial_poses().context(
                "tracking needs the first frame's poses: init.json with poses, or the paper's bootstrap points",
            )?;
            let next = done
                .last()
                .map_or(range.start, |r| r.frame + 1)
                .max(range.start);
            (TrackState::new(first), next)
        }
    };
    let todo = start..range.end;
    let opened = open_engine(
        a.engine.backend,
        Scene::from_capture(capture),
        a.engine.region.unwrap_or(Region::Energy),
    )?;
    eprintln!("energy backend: {}", opened.choice);
    let mut engine = opened.engine;
    let bar = super::progress_bar(todo.len() as u64, "tracking");
    let started = Instant::now();
    let mut evaluations = 0;
    let mut tracked_now = 0;
    track_frames(
        capture,
        engine.as_mut(),
        &settings,
        todo,
        &mut state,
        &mut |r, masks| {
            writer.push(r)?;
            if let Some(dir) = &a.overlays {
                overlay::write_overlays(dir, capture, masks, &r.poses)?;
            }
            evaluations += r.evaluations;
            tracked_now += 1;
            let e = r.energies.as_ref().map_or(0.0, |[u, l]| {
                u.total(settings.search.lambda) + l.total(settings.search.lambda)
            });
            bar.set_message(format!("tracking (E = {e:.0}, {})", r.status.as_str()));
            bar.inc(1);
            Ok(())
        },
    )?;
    bar.finish_and_clear();
    let records = writer.finish()?;
    Ok(Summary {
        records,
        tracked_now,
        seconds: started.elapsed().as_secs_f64(),
        evaluations,
        backend: opened.choice,
    })
}

pub fn print_summary(output: &Path, s: &Summary) {
    let count = |st: &str| {
        s.records
            .iter()
            .filter(|r| r.status.as_deref() == Some(st))
            .count()
    };
    println!(
        "tracked {} frames ({} now) -> {}: {} ok, {} low-confidence, {} no-data",
        s.records.len(),
        s.tracked_now,
        output.display(),
        count(Status::Ok.as_str()),
        count(Status::LowConfidence.as_str()),
        count(Status::NoData.as_str())
    );
    if s.tracked_now > 0 {
        println!(
            "time {:.2} s per frame ({} energy evaluations per frame, {:.2} ms each), backend {}",
            s.seconds / s.tracked_now as f64,
            s.evaluations / s.tracked_now,
            s.seconds * 1e3 / s.evaluations.max(1) as f64,
            s.backend
        );
    }
}

/// Score written records against the capture's ground truth, if it has any.
pub fn score_records(
    capture: &Capture,
    path: &Path,
    records: &[FrameRecordJson],
) -> anyhow::Result<Option<ScoreReport>> {
    let tracked: Vec<(FrameRecordJson, ArchPoses)> = records
        .iter()
        .map(|r| Ok((r.clone(), record_poses(path, r)?.0)))
        .collect::<anyhow::Result<_>>()?;
    Ok(score(capture, &tracked))
}

pub fn print_score(r: &ScoreReport) {
    println!(
        "against ground truth, {} frames ({} ok, {} low-confidence, {} no-data): median / 95th percentile / max",
        r.frames, r.frames_ok, r.frames_low_confidence, r.frames_no_data
    );
    let line = |name: &str, what: &str, s: &Stats| {
        println!(
            "  {name:<6} {what:<22} {:>8.3} {:>8.3} {:>8.3}",
            s.median, s.p95, s.max
        );
    };
    for (name, e) in [("upper", &r.upper), ("lower", &r.lower), ("jaw", &r.jaw)] {
        line(name, "mean vertex error (mm)", &e.mean_vertex_mm);
        line(name, "rotation error (deg)", &e.rotation_deg);
        line(name, "translation error (mm)", &e.translation_mm);
    }
    line("upper", "area error (%)", &r.area_error_percent[0]);
    line("lower", "area error (%)", &r.area_error_percent[1]);
}
