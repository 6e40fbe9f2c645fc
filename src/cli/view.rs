//! `jawtrack view`: the rig for animators in a local page (src/view/).

use std::io::Write;
use std::net::{IpAddr, Ipv4Addr, SocketAddr};
use std::path::PathBuf;

use anyhow::{Context, bail};
use jawtrack::capture::Capture;
use jawtrack::view::{Meshes, Tracked, Viewer, serve};

use crate::cli::args::load_mesh;

#[derive(clap::Args)]
pub struct Args {
    /// The rig file: `rig learn`'s, or `envelope learn`'s.
    pub rig: PathBuf,
    /// A capture: its meshes are drawn, and with --tracks its frames are on the timeline.
    #[arg(long)]
    pub capture: Option<PathBuf>,
    /// The capture's tracks.json (with --capture): the timeline and each camera's overlay.
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
}

pub fn run(a: Args) -> anyhow::Result<()> {
    let rig = crate::cli::args::load_rig(&a.rig)?;
    let mandible = a
        .mandible
        .as_deref()
        .map(|p| load_mesh(p).map(|m| m.0))
        .transpose()?;
    let (meshes, tracked) = match &a.capture {
        Some(dir) => {
            let capture = Capture::open_with(
                dir,
                jawtrack::capture::OpenOptions {
                    masks_to_come: true,
                    ..Default::default()
                },
            )
            .with_context(|| format!("invalid capture {}", dir.display()))?;
            let meshes = Meshes {
                upper: Some(capture.upper().clone()),
                lower: capture.lower().clone(),
                mandible: mandible.or_else(|| capture.mandible().cloned()),
            };
            let tracked = a
                .tracks
                .as_deref()
                .map(|t| Tracked::read(capture, t))
                .transpose()?;
            (meshes, tracked)
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
            (meshes, None)
        }
    };
    let viewer = Viewer::new(rig, &a.rig, meshes, tracked)?;
    serve(&viewer, SocketAddr::new(a.host, a.port), |addr| {
        println!("jawtrack view: http://{addr}/ (Ctrl-C to stop)");
        let _ = std::io::stdout().flush();
    })
    .with_context(|| format!("serving on {}:{}", a.host, a.port))?;
    Ok(())
}
