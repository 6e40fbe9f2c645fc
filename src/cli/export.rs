//! `jawtrack export`: tracked motion out, as glTF for Blender and Maya and CSV for analysis.

use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use jawtrack::anatomy::motion::MotionFrame;
use jawtrack::capture::Capture;
use jawtrack::envelope::JawFrame;
use jawtrack::export::gltf::{Key, Part, write_gltf};
use jawtrack::formats::Status;
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
    let mut frames: Vec<(u32, Status, Pose)> = Vec::new();
    for f in &tracks.frames {
        if f.status() == Status::NoData {
            continue;
        }
        let jaw = f.checked_jaw(&a.tracks)?;
        let last = capture.first_frame() as u64 + capture.frame_count() as u64;
        if (f.frame as u64) < capture.first_frame() as u64 || f.frame as u64 >= last {
            bail!(
                "{}: frame {}: the capture has frames {} to {}",
                a.tracks.display(),
                f.frame,
                capture.first_frame(),
                last.saturating_sub(1)
            );
        }
        frames.push((f.frame, f.status(), jaw));
    }
    frames.sort_by_key(|f| f.0);
    if frames.is_empty() {
        bail!("{}: no frame with a pose (all no-data)", a.tracks.display());
    }
    // The jaw frame from the mandible's condyles when the capture has one; else the lower
    // arch's last molars stand in for them (the axes, all that is used, come out the same).
    let landmarks_on = capture.mandible().unwrap_or(capture.lower());
    let landmarks = JawFrame::from_mesh(landmarks_on, None, None)
        .map_err(|e| anyhow::anyhow!("the jaw frame's landmarks: {e}"))?;
    let rest_index = match a.rest_frame {
        Some(n) => frames.iter().position(|f| f.0 == n).with_context(|| {
            format!(
                "--rest-frame {n}: no such frame with a pose in {}",
                a.tracks.display()
            )
        })?,
        None => {
            let ok: Vec<usize> = (0..frames.len())
                .filter(|&i| frames[i].1 == Status::Ok)
                .collect();
            let pool = if ok.is_empty() {
                (0..frames.len()).collect()
            } else {
                ok
            };
            let jaws: Vec<Pose> = pool.iter().map(|&i| frames[i].2).collect();
            pool[MotionFrame::most_closed(&landmarks, &jaws).expect("frames is not empty")]
        }
    };
    let motion = MotionFrame::new(&landmarks, frames[rest_index].2);
    let first = frames[0].0;
    let time = |frame: u32| (frame - first) as f64 / a.fps;
    if let Some(out) = &a.csv {
        let rows: Vec<(u32, f64, &str, Pose)> = frames
            .iter()
            .map(|(n, s, jaw)| (*n, time(*n), s.as_str(), *jaw))
            .collect();
        write_atomic(
            out,
            jawtrack::export::csv::write_csv(&motion, &rows).as_bytes(),
        )?;
        println!("{} frames -> {}", rows.len(), out.display());
    }
    if let Some(out) = &a.gltf {
        let keys: Vec<Key> = frames
            .iter()
            .map(|(n, _, jaw)| Key {
                time_s: time(*n) as f32,
                jaw: *jaw,
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
                mesh: &capture.upper(),
                colour: jawtrack::export::gltf::UPPER_COLOUR,
            }),
            &Part {
                name: "lower",
                mesh: &capture.lower(),
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
    let measured: Vec<_> = frames.iter().map(|f| motion.measure(&f.2)).collect();
    let range = |f: &dyn Fn(&jawtrack::anatomy::motion::Anatomical) -> f64| {
        let v: Vec<f64> = measured.iter().map(f).collect();
        (
            v.iter().copied().fold(f64::INFINITY, f64::min),
            v.iter().copied().fold(f64::NEG_INFINITY, f64::max),
        )
    };
    let (o, i, l, p) = (
        range(&|a| a.opening_deg),
        range(&|a| a.incisal_opening_mm),
        range(&|a| a.lateral_mm),
        range(&|a| a.protrusion_mm),
    );
    println!(
        "rest bite: frame {}; opening {:.1} to {:.1}°, incisal point {:.1} to {:.1} mm down, {:.1} to {:.1} mm to the left, {:.1} to {:.1} mm forwards",
        frames[rest_index].0, o.0, o.1, i.0, i.1, l.0, l.1, p.0, p.1
    );
    Ok(())
}
