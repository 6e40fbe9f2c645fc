use std::path::PathBuf;

use anyhow::{Context, anyhow};
use jawtrack::capture::Capture;
use jawtrack::formats::TracksJson;
use jawtrack::track::score::score_against;

#[derive(clap::Args)]
pub struct Args {
    /// The capture folder (with gt/poses.json).
    pub capture: PathBuf,
    /// The tracks.json to score.
    pub tracks: PathBuf,
    /// Score against this run's tracks.json instead of the ground truth (e.g. a run merged
    /// from chunks against the run of one task, or a GPU run against the CPU reference's).
    #[arg(long)]
    pub against: Option<PathBuf>,
    /// Print the report as JSON.
    #[arg(long)]
    pub json: bool,
}

pub fn run(a: Args) -> anyhow::Result<()> {
    let capture = Capture::open(&a.capture)
        .with_context(|| format!("invalid capture {}", a.capture.display()))?;
    let tracks: TracksJson = jawtrack::io::read_json(&a.tracks, "tracks file")?;
    let report = match &a.against {
        None => jawtrack::track::score_records(&capture, &a.tracks, &tracks.frames)?
            .ok_or_else(|| anyhow!("{}: no gt/poses.json to score against", a.capture.display()))?,
        Some(other) => {
            let reference: TracksJson = jawtrack::io::read_json(other, "tracks file")?;
            let poses = reference
                .frames
                .iter()
                .map(|r| Ok((r.frame, r.poses(other)?)))
                .collect::<jawtrack::error::Result<std::collections::BTreeMap<_, _>>>()?;
            let tracked = tracks
                .frames
                .iter()
                .map(|r| Ok((r.clone(), r.poses(&a.tracks)?)))
                .collect::<jawtrack::error::Result<Vec<_>>>()?;
            score_against(&capture, &tracked, &other.display().to_string(), &|frame| {
                poses.get(&frame).copied()
            })
        }
    };
    if a.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        super::report::score(&report);
    }
    Ok(())
}
