//! `jawtrack sync`: per-camera frame offsets from a light switched off and on.

use std::path::PathBuf;

use anyhow::{Context, bail};
use jawtrack::footage::sync;

#[derive(clap::Args)]
pub struct Args {
    /// The capture folder, with images/<camera>/ from `jawtrack import video`.
    pub capture: PathBuf,
    /// Look for the event only in file frames FIRST..END (e.g. 0..300).
    #[arg(long, value_parser = crate::cli::args::frame_window)]
    pub frames: Option<std::ops::Range<u32>>,
    /// Frames per second, to give the cameras' spread within a frame in milliseconds.
    #[arg(long, value_parser = crate::cli::args::number_in(0.1, 10_000.0))]
    pub fps: Option<f64>,
    /// Print the offsets without writing them into capture.json.
    #[arg(long)]
    pub dry_run: bool,
}

pub fn run(a: Args) -> anyhow::Result<()> {
    let names = sync::camera_names(&a.capture)?;
    if names.len() < 2 {
        bail!(
            "{}: sync needs two cameras or more, found {}",
            a.capture.display(),
            names.len()
        );
    }
    let mut events = Vec::new();
    for name in &names {
        let dir = a.capture.join("images").join(name);
        let mut files = sync::frame_files(&dir)?;
        if let Some(r) = &a.frames {
            files.retain(|(n, _)| r.contains(n));
        }
        let first = files.first().map(|f| f.0).unwrap_or(0);
        if let Some(w) = files.windows(2).find(|w| w[1].0 != w[0].0 + 1) {
            bail!(
                "{}: frames {} and {} are not consecutive: sync needs every frame",
                dir.display(),
                w[0].0,
                w[1].0
            );
        }
        let bar = crate::cli::progress_bar(files.len() as u64, name);
        let b = sync::brightness(&files, &|| bar.inc(1))?;
        bar.finish_and_clear();
        let Some(event) = sync::detect(first, &b) else {
            bail!(
                "{}: no light switched off in {} frames (no drop in brightness stands out)",
                dir.display(),
                files.len()
            );
        };
        println!(
            "{name}: light off at frame {:.2}{}, brightness {:.0} -> {:.0}",
            event.off,
            event
                .on
                .map(|t| format!(", on at {t:.2}"))
                .unwrap_or_default(),
            event.bright,
            event.dark
        );
        events.push((name.clone(), event));
    }
    let syncs = sync::offsets(&events)?;
    let lo = syncs.iter().map(|c| c.within).fold(f64::INFINITY, f64::min);
    let hi = syncs
        .iter()
        .map(|c| c.within)
        .fold(f64::NEG_INFINITY, f64::max);
    for c in &syncs {
        println!(
            "{}: offset {} frames, {:+.2} frame within",
            c.name, c.offset, c.within
        );
    }
    let spread = hi - lo;
    println!(
        "the cameras lie within {spread:.2} frame of each other{}",
        a.fps
            .map(|f| format!(" ({:.1} ms at {f} fps)", 1000.0 * spread / f))
            .unwrap_or_default()
    );
    let cj = a.capture.join("capture.json");
    if a.dry_run {
        return Ok(());
    }
    if !cj.is_file() {
        println!(
            "{} does not exist yet: put these offsets in its frames.offsets",
            cj.display()
        );
        return Ok(());
    }
    sync::write_offsets(&cj, &syncs).context("writing frames.offsets")?;
    println!("frames.offsets written to {}", cj.display());
    Ok(())
}
