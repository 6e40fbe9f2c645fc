use std::path::{Path, PathBuf};
use std::sync::Arc;

use anyhow::Context;
use jawtrack::anatomy::MeshMetric;
use jawtrack::capture::Capture;
use jawtrack::energy::{Backend, Region};
use jawtrack::formats::read_jaw_poses;
use jawtrack::rig::{JawRig, RigSettings};
use jawtrack::track::{SessionOptions, TrackSettings, score_records};

use super::args::{
    EnergyArg, EngineArgs, LoadArgs, load_rig, parse_frames, rig_space, track_settings,
};

/// What `track` and `segment` share: the capture, the output, the frames, how they are
/// tracked, and how a run that exists is continued or started over.
#[derive(clap::Args)]
pub struct RunArgs {
    /// The capture folder.
    pub capture: PathBuf,
    /// Where to write tracks.json.
    #[arg(short, long)]
    pub output: PathBuf,
    /// Frames to track: `A..B` (B excluded) or `A..=B`; default all.
    #[arg(long)]
    pub frames: Option<String>,
    /// Write the paper's overlay pictures (mask white, model red at alpha 0.5, BOI green) per
    /// camera and frame into this folder.
    #[arg(long)]
    pub overlays: Option<PathBuf>,
    /// Continue an interrupted run after its last complete frame.
    #[arg(long)]
    pub resume: bool,
    /// Start over when the output exists (`segment`: also make the masks already in the masks
    /// folder again, which may be corrections made by hand).
    #[arg(long)]
    pub force: bool,
    /// Find the first frame's poses from its masks (per-arch masks), even where init.json
    /// gives them: for a run that starts later in a take (`--frames A..B`).
    #[arg(long)]
    pub locate: bool,
    #[command(flatten)]
    pub how: TrackingArgs,
}

/// How frames are tracked: what `track`, `segment` and `merge` (which re-tracks where chunks
/// disagree) share, and what a batch passes to each of its tasks.
#[derive(clap::Args)]
pub struct TrackingArgs {
    #[command(flatten)]
    pub engine: EngineArgs,
    #[command(flatten)]
    pub load: LoadArgs,
    /// Tracking settings as JSON (the fields of `TrackSettings`; see docs/settings.md; missing
    /// ones take their defaults, unknown ones are an error): a file, or the JSON itself when it
    /// starts with `{`, e.g. '{"search": {"lambda": 1.0}}'.
    #[arg(long)]
    pub settings: Option<PathBuf>,
    /// The objective: the paper's E with the terms of our own, or the paper's E alone.
    #[arg(long, value_enum, default_value_t = EnergyArg::Full)]
    pub energy: EnergyArg,
    /// How the poses are found (`search.solver` of the settings; this wins).
    #[arg(long, value_enum)]
    pub search: Option<crate::cli::args::SearchArg>,
    /// The subject's own rig (`rig learn`'s or `envelope learn`'s, learned from this capture's
    /// tracks): the jaw is held to its manifold and ranges, and its poses are the jaw prior's
    /// starts, in place of the average joint's.
    #[arg(long = "rig", id = "subject_rig", value_name = "RIG")]
    pub rig: Option<PathBuf>,
}

impl TrackingArgs {
    /// The capture at `dir`, loaded as these arguments ask.
    pub fn open(&self, dir: &Path) -> anyhow::Result<Capture> {
        let capture = Capture::open_with(dir, self.load.open_options())
            .with_context(|| format!("invalid capture {}", dir.display()))?;
        super::report::notes(&capture);
        Ok(capture)
    }

    pub fn backend(&self) -> Backend {
        self.engine.backend.into()
    }

    pub fn region(&self) -> Region {
        self.engine.region.map_or(Region::Relevant, Into::into)
    }

    /// The tracking settings: the file's or the defaults, with the options that override them.
    pub fn settings(&self) -> anyhow::Result<TrackSettings> {
        Ok(TrackSettings {
            jaw_space: self
                .rig
                .as_deref()
                .map(|path| -> anyhow::Result<_> {
                    let rig = load_rig(path)?;
                    Ok(Arc::new(rig_space(
                        rig.as_ref(),
                        &path.display().to_string(),
                    )?))
                })
                .transpose()?,
            ..track_settings(self.settings.as_deref(), self.energy, self.search)?
        })
    }
}

impl RunArgs {
    /// The session these arguments ask for on `capture`.
    pub fn session_options(&self, capture: &Capture) -> anyhow::Result<SessionOptions> {
        Ok(SessionOptions {
            frames: self
                .frames
                .as_deref()
                .map(|s| parse_frames(s, capture))
                .transpose()?,
            backend: self.how.backend(),
            region: self.how.region(),
            overlays: self.overlays.clone(),
            resume: self.resume,
            force: self.force,
            locate: self.locate,
            settings: self.how.settings()?,
            ..SessionOptions::new(&self.output)
        })
    }
}

#[derive(clap::Args)]
pub struct Args {
    #[command(flatten)]
    pub run: RunArgs,
    /// Track, learn the subject's rig from the frames tracked `ok` (`rig learn`'s defaults),
    /// and track again held to it: OUTPUT's first pass and rig go beside it
    /// (NAME.pass1.json, NAME.rig.json).
    #[arg(long, conflicts_with = "subject_rig")]
    pub two_pass: bool,
}

pub fn run(Args { run: a, two_pass }: Args) -> anyhow::Result<()> {
    let capture = a.how.open(&a.capture)?;
    let mut options = a.session_options(&capture)?;
    if two_pass {
        let first = SessionOptions {
            output: a.output.with_extension("pass1.json"),
            ..options.clone()
        };
        let summary = super::run::track(&capture, first.clone())?;
        println!("first pass:");
        super::report::track_summary(&first.output, &summary);
        if let Some(report) = score_records(&capture, &first.output, &summary.records)? {
            super::report::score(&report);
        }
        let rig_path = a.output.with_extension("rig.json");
        let rig = learn_rig(&capture, &first.output)?;
        rig.save(&rig_path)?;
        println!(
            "learned the subject's rig -> {}\nsecond pass, held to it:",
            rig_path.display()
        );
        options.settings.jaw_space =
            Some(Arc::new(rig_space(&rig, &rig_path.display().to_string())?));
    }
    let summary = super::run::track(&capture, options)?;
    super::report::track_summary(&a.output, &summary);
    if let Some(report) = score_records(&capture, &a.output, &summary.records)? {
        println!();
        super::report::score(&report);
    }
    Ok(())
}

/// The rig of the frames `path` has tracked `ok`, learned as `rig learn` does by default.
fn learn_rig(capture: &Capture, path: &Path) -> anyhow::Result<JawRig> {
    let jaws = read_jaw_poses(path)?.poses;
    let metric = MeshMetric::new(capture.lower());
    let rig = super::run::with_progress("learning the subject's rig", |progress| {
        JawRig::learn(&jaws, &metric, &RigSettings::default(), progress)
    })
    .with_context(|| {
        format!(
            "learning a rig from the {} frames of {} tracked ok",
            jaws.len(),
            path.display()
        )
    })?;
    Ok(rig.with_anatomy(capture.lower(), &jaws))
}
