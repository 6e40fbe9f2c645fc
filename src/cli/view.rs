//! `jawtrack view`: the rig for animators in a local page (src/view/).

use std::io::Write;
use std::net::{IpAddr, Ipv4Addr, SocketAddr};
use std::path::PathBuf;

use anyhow::{Context, bail};
use jawtrack::capture::Capture;
use std::sync::Arc;

use jawtrack::view::{Meshes, Retracking, Viewer, Workbench, serve};

use crate::cli::args::load_mesh;
use crate::cli::track::TrackingArgs;

#[derive(clap::Args)]
pub struct Args {
    /// The rig file: `rig learn`'s, or `envelope learn`'s. Without one (a take with no rig
    /// yet) the page shows the capture alone: its timeline and overlays, frames to correct,
    /// the first pose to pick; no sliders.
    #[arg(required_unless_present = "capture")]
    pub rig: Option<PathBuf>,
    /// A capture: its meshes are drawn, the first pose can be picked on its pictures (written
    /// as init.json), and with --tracks its frames are on the timeline.
    #[arg(long)]
    pub capture: Option<PathBuf>,
    /// The capture's tracks.json (with --capture): the timeline and each camera's overlay.
    /// Frames corrected on the page, and those tracked again from them, are written back to
    /// it (atomically; the file as first read is kept as NAME.before-view.json).
    #[arg(long, requires = "capture")]
    pub tracks: Option<PathBuf>,
    /// Without a capture: the upper arch (upper frame), drawn fixed.
    #[arg(long, conflicts_with = "capture")]
    pub upper: Option<PathBuf>,
    /// Without a capture: the lower arch (lower frame), moved by the rig.
    #[arg(long, conflicts_with = "capture", required_unless_present = "capture")]
    pub lower: Option<PathBuf>,
    /// The mandible (lower frame); a capture's own is used when it names one.
    #[arg(long)]
    pub mandible: Option<PathBuf>,
    /// The port (0: any free one). The page is served on this machine only (127.0.0.1)
    /// unless --host says otherwise.
    #[arg(long, default_value_t = 8080)]
    pub port: u16,
    #[arg(long, default_value_t = IpAddr::V4(Ipv4Addr::LOCALHOST))]
    pub host: IpAddr,
    /// How frames are tracked again from a corrected one (as `track`'s options): give those
    /// tracks.json was tracked with.
    #[command(flatten, next_help_heading = "Tracking again")]
    pub how: TrackingArgs,
}

pub fn run(a: Args) -> anyhow::Result<()> {
    let rig = a
        .rig
        .as_deref()
        .map(crate::cli::args::load_rig)
        .transpose()?;
    let mandible = a
        .mandible
        .as_deref()
        .map(|p| load_mesh(p).map(|m| m.0))
        .transpose()?;
    let (meshes, opened, tracked) = match &a.capture {
        Some(dir) => {
            let capture = Capture::open_with(
                dir,
                jawtrack::capture::OpenOptions {
                    masks_to_come: true,
                    ..a.how.load.open_options()
                },
            )
            .with_context(|| format!("invalid capture {}", dir.display()))?;
            let capture = Arc::new(capture);
            let meshes = Meshes {
                upper: Some(capture.upper().clone()),
                lower: capture.lower().clone(),
                mandible: mandible.or_else(|| capture.mandible().cloned()),
            };
            let retracking = Retracking {
                settings: a.how.settings()?,
                backend: a.how.backend(),
                region: a.how.region(),
            };
            let tracked = a
                .tracks
                .as_deref()
                .map(|t| Workbench::open(Arc::clone(&capture), t, retracking).map(Arc::new))
                .transpose()?;
            if let (Some(t), true) = (
                &a.tracks,
                tracked.as_ref().is_some_and(|w| w.other_settings),
            ) {
                eprintln!(
                    "note: {} was not tracked with these options (or not by this jawtrack): frames tracked again from the page use these",
                    t.display()
                );
            }
            (meshes, Some(capture), tracked)
        }
        None => {
            let Some(lower) = &a.lower else {
                bail!("give --capture CAPTURE, or the meshes: --lower LOWER [--upper UPPER]");
            };
            let meshes = Meshes {
                upper: a
                    .upper
                    .as_deref()
                    .map(|p| load_mesh(p).map(|m| m.0))
                    .transpose()?,
                lower: load_mesh(lower)?.0,
                mandible,
            };
            (meshes, None, None)
        }
    };
    // Without a rig the timeline reads the tracked motion in the same units as `export`.
    let motion = match (&rig, &opened, &a.tracks) {
        (None, Some(capture), Some(path)) => {
            let tracks: jawtrack::formats::TracksJson =
                jawtrack::io::read_json(path, "tracks file")?;
            Some(jawtrack::export::motion::tracked_motion(capture, &tracks, path, None)?.motion)
        }
        _ => None,
    };
    let viewer = Viewer::new(rig.zip(a.rig.as_deref()), motion, meshes, opened, tracked)?;
    serve(&viewer, SocketAddr::new(a.host, a.port), |addr| {
        println!("jawtrack view: http://{addr}/ (Ctrl-C to stop)");
        let _ = std::io::stdout().flush();
    })
    .with_context(|| format!("serving on {}:{}", a.host, a.port))?;
    Ok(())
}
