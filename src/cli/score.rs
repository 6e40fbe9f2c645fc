use std::path::PathBuf;

use anyhow::{Context, anyhow};
use jawtrack::capture::Capture;
use jawtrack::formats::TracksJson;

#[derive(clap::Args)]
pub struct Args {
    /// The capture folder (with gt/poses.json).
    pub capture: PathBuf,
    /// The tracks.json to score.
    pub tracks: PathBuf,
    /// Print the report as JSON.
    #[arg(long)]
    pub json: bool,
}

pub fn run(a: Args) -> anyhow::Result<()> {
    let capture = Capture::open(&a.capture)
        .with_context(|| format!("invalid capture {}", a.capture.display()))?;
    let tracks: TracksJson = jawtrack::io::read_json(&a.tracks, "tracks file")?;
    let report = jawtrack::track::score_records(&capture, &a.tracks, &tracks.frames)?
        .ok_or_else(|| anyhow!("{}: no gt/poses.json to score against", a.capture.display()))?;
    if a.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        super::report::score(&report);
    }
    Ok(())
}
