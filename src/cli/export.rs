//! `jawtrack export`: tracked motion out, as glTF for Blender and Maya and CSV for analysis.

use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use jawtrack::capture::Capture;
use jawtrack::export::gltf::{Key, Part, write_gltf};
use jawtrack::export::tracked_motion;
use jawtrack::geometry::Pose;
use jawtrack::io::write_atomic;

#[derive(clap::Args)]
pub struct Args {
    /// The capture the motion was tracked in (its scans become the meshes).
    pub capture: PathBuf,
    /// tracks.json (or gt/poses.json); frames with status no-data are left out.
    pub tracks: PathBuf,
    /// Write a glTF 2.0 file (buffer embedded): the upper arch fixed, the lower arch and the
    /// mandible animated, in metres.
    #[arg(long)]
    pub gltf: Option<PathBuf>,
    /// Write per-frame poses as CSV: opening (degrees), the incisal point's travel (mm), the
    /// pose itself.
    #[arg(long)]
    pub csv: Option<PathBuf>,
    /// Frames per second of the footage (the animation's time base).
    #[arg(long, default_value_t = 24.0, value_parser = crate::cli::args::number_in(0.1, 10_000.0))]
    pub fps: f64,
    /// The frame taken as the rest bite (zero of every parameter); default: the ok frame with
    /// the lower incisal point highest.
    #[arg(long)]
    pub rest_frame: Option<u32>,
}

pub fn run(a: Args) -> anyhow::Result<()> {
    if a.gltf.is_none() && a.csv.is_none() {
        bail!("nothing to write: give --gltf OUT.gltf and/or --csv OUT.csv");
    }
    let capture = Capture::open(&a.capture).context("opening the capture")?;
    let (files, folders) = jawtrack::capture::capture_reads(&capture);
    let mut reads = jawtrack::io::Reads {
        files: files.iter().map(PathBuf::as_path).collect(),
        folders: folders.iter().map(PathBuf::as_path).collect(),
    };
    reads.files.push(&a.tracks);
    let outputs: Vec<&Path> = a.gltf.iter().chain(&a.csv).map(PathBuf::as_path).collect();
    jawtrack::io::check_outputs(&reads, &outputs)?;
    let tracks = jawtrack::formats::read_tracks(&a.tracks)?;
    let m = tracked_motion(&capture, &tracks, &a.tracks, a.rest_frame)?;
    let time = |frame: u32| m.time_s(frame, a.fps);
    if let Some(out) = &a.csv {
        let rows: Vec<(u32, f64, &str, Pose)> = m
            .keys
            .iter()
            .map(|k| (k.frame, time(k.frame), k.status.as_str(), k.jaw))
            .collect();
        write_atomic(
            out,
            jawtrack::export::csv::write_csv(&m.motion, &rows).as_bytes(),
        )?;
        println!("{} frames -> {}", rows.len(), out.display());
    }
    if let Some(out) = &a.gltf {
        let keys: Vec<Key> = m
            .keys
            .iter()
            .map(|k| Key {
                time_s: time(k.frame) as f32,
                jaw: k.jaw,
            })
            .collect();
        let mandible = capture.mandible().map(|m| Part {
            name: "mandible",
            mesh: m,
            colour: jawtrack::export::gltf::MANDIBLE_COLOUR,
        });
        let bytes = write_gltf(
            Some(&Part {
                name: "upper",
                mesh: capture.upper(),
                colour: jawtrack::export::gltf::UPPER_COLOUR,
            }),
            &Part {
                name: "lower",
                mesh: capture.lower(),
                colour: jawtrack::export::gltf::LOWER_COLOUR,
            },
            mandible.as_ref(),
            &keys,
            "tracked jaw",
        );
        write_atomic(out, &bytes)?;
        println!(
            "{} keys over {:.2} s -> {} ({:.1} MB)",
            keys.len(),
            keys.last().map_or(0.0, |k| k.time_s),
            out.display(),
            bytes.len() as f64 / 1e6
        );
    }
    let r = m.ranges();
    println!(
        "rest bite: frame {}; opening {:.1} to {:.1}°, incisal point {:.1} to {:.1} mm down, {:.1} to {:.1} mm to the left, {:.1} to {:.1} mm forwards",
        m.keys[m.rest].frame,
        r.opening_deg.0,
        r.opening_deg.1,
        r.incisal_opening_mm.0,
        r.incisal_opening_mm.1,
        r.lateral_mm.0,
        r.lateral_mm.1,
        r.protrusion_mm.0,
        r.protrusion_mm.1
    );
    Ok(())
}
