use std::path::PathBuf;

use anyhow::Context;
use jawtrack::capture::Capture;
use jawtrack::energy::Region;
use jawtrack::track::{SessionOptions, score_records};

use super::args::{EnergyArg, EngineArgs, LoadArgs, parse_frames, track_settings};

/// What `track` and `segment` share: the capture, the output, the frames, the engine, the
/// settings, and how a run that exists is continued or started over.
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
    #[command(flatten)]
    pub engine: EngineArgs,
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
            backend: self.engine.backend.into(),
            region: self.engine.region.map_or(Region::Relevant, Into::into),
            overlays: self.overlays.clone(),
            resume: self.resume,
            force: self.force,
            settings: track_settings(self.settings.as_deref(), self.energy, self.search)?,
            ..SessionOptions::new(&self.output)
        })
    }
}

#[derive(clap::Args)]
pub struct Args {
    #[command(flatten)]
    pub run: RunArgs,
}

pub fn run(Args { run: a }: Args) -> anyhow::Result<()> {
    let capture = Capture::open_with(&a.capture, a.load.open_options())
        .with_context(|| format!("invalid capture {}", a.capture.display()))?;
    super::report::notes(&capture);
    let options = a.session_options(&capture)?;
    let summary = super::run::track(&capture, options)?;
    super::report::track_summary(&a.output, &summary);
    if let Some(report) = score_records(&capture, &a.output, &summary.records)? {
        println!();
        super::report::score(&report);
    }
    Ok(())
}
