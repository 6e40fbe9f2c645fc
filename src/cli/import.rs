//! `jawtrack import`: calibration files and videos into a capture folder.

use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use jawtrack::footage::calib::{self, ImportOptions, ImportedCamera, Unit};
use jawtrack::footage::video::{self, Extract, FrameFormat};

#[derive(clap::Subcommand)]
pub enum Command {
    /// Cameras from OpenCV FileStorage (YAML/XML) files or a COLMAP text model, written as
    /// CAPTURE/cameras/<name>.json.
    Cameras(CamerasArgs),
    /// Frames of videos (anything ffmpeg reads) as CAPTURE/images/<NAME>/<frame:06>.png.
    Video(VideoArgs),
    /// Masks from segmentation tools (per-object binary PNGs as SAM 2 is saved, or a CVAT
    /// "Segmentation mask 1.1" export) as CAPTURE/masks/<CAMERA>/<frame:06>.png.
    Masks(MasksArgs),
}

#[derive(clap::Args)]
pub struct MasksArgs {
    /// The capture folder.
    pub capture: PathBuf,
    /// The camera the masks are of.
    #[arg(long)]
    pub camera: String,
    /// A folder with a folder of binary PNGs per object (SAM 2): `DIR/<object>/<frame>.png`.
    #[arg(long, conflicts_with = "cvat", required_unless_present = "cvat")]
    pub objects: Option<PathBuf>,
    /// A CVAT "Segmentation mask 1.1" export: labelmap.txt and SegmentationClass/.
    #[arg(long)]
    pub cvat: Option<PathBuf>,
    /// `LABEL=CLASS`: a source object (folder name) or CVAT label, and what it is: upper,
    /// lower, teeth (both arches as one) or mouth (the visible mouth interior).
    #[arg(long = "label", required = true)]
    pub labels: Vec<String>,
    /// Added to the source's frame numbers (a clip segmented from frame 100 on: 100).
    #[arg(long, default_value_t = 0, allow_hyphen_values = true)]
    pub frame_offset: i64,
    /// Overwrite the camera's masks folder.
    #[arg(long)]
    pub replace: bool,
}

#[derive(Clone, Copy, clap::ValueEnum)]
pub enum UnitArg {
    Mm,
    Cm,
    M,
}

#[derive(clap::Args)]
pub struct CamerasArgs {
    /// The capture folder (created if absent).
    pub capture: PathBuf,
    /// `[NAME=]FILE`: an OpenCV .yml/.yaml/.xml file per camera (named by the file's stem
    /// unless NAME= is given), or a COLMAP model folder, cameras.txt or images.txt (cameras
    /// named by their images: `cam0/000000.png` is camera cam0).
    #[arg(required = true)]
    pub files: Vec<String>,
    /// The unit of the files' translations.
    #[arg(long, value_enum, default_value = "mm")]
    pub unit: UnitArg,
    /// The files' extrinsics are camera-to-world (a camera's pose), not OpenCV's and COLMAP's
    /// world-to-camera.
    #[arg(long)]
    pub camera_to_world: bool,
    /// The OpenCV files' 4 distortion coefficients are cv::fisheye's (Kannala-Brandt); such
    /// files do not say so themselves.
    #[arg(long)]
    pub fisheye: bool,
}

#[derive(clap::Args)]
pub struct VideoArgs {
    /// The capture folder (created if absent).
    pub capture: PathBuf,
    /// `NAME=FILE`: the camera's name and its video.
    #[arg(required = true)]
    pub videos: Vec<String>,
    /// The first frame to write (the video's frame number, from 0); files keep that number.
    #[arg(long, default_value_t = 0)]
    pub first: u64,
    /// How many frames to write (all to the end when absent).
    #[arg(long, value_parser = crate::cli::args::count_in(1, 100_000_000))]
    pub count: Option<usize>,
    /// Write JPEG (about a tenth of PNG's size) instead of PNG.
    #[arg(long)]
    pub jpg: bool,
    /// Replace existing images/<NAME>/ folders.
    #[arg(long)]
    pub replace: bool,
}

pub fn run(c: Command) -> anyhow::Result<()> {
    match c {
        Command::Cameras(a) => cameras(a),
        Command::Video(a) => videos(a),
        Command::Masks(a) => masks(a),
    }
}

fn masks(a: MasksArgs) -> anyhow::Result<()> {
    use jawtrack::footage::masks::{Class, Source, import_masks};
    calib::check_name(&a.camera, &a.capture)?;
    let labels = a
        .labels
        .iter()
        .map(|l| {
            let (name, class) = l
                .rsplit_once('=')
                .ok_or_else(|| anyhow::anyhow!("--label {l}: expected LABEL=CLASS"))?;
            let class = Class::parse(class).ok_or_else(|| {
                anyhow::anyhow!("--label {l}: `{class}` is not upper, lower, teeth or mouth")
            })?;
            Ok((name.to_string(), class))
        })
        .collect::<anyhow::Result<Vec<_>>>()?;
    let source = match (a.objects, a.cvat) {
        (Some(d), _) => Source::Objects(d),
        (None, Some(d)) => Source::Cvat(d),
        (None, None) => bail!("give --objects DIR or --cvat DIR"),
    };
    let r = import_masks(
        &a.capture,
        &a.camera,
        &source,
        &labels,
        a.frame_offset,
        a.replace,
    )?;
    println!(
        "{}: {} masks -> {}",
        a.camera,
        r.frames,
        a.capture.join("masks").join(&a.camera).display()
    );
    if r.conflicts > 0 {
        println!(
            "  {} pixels claimed by two arches were left unlabelled",
            r.conflicts
        );
    }
    println!("capture.json needs {}", r.masks_block);
    Ok(())
}

fn split_named(arg: &str) -> (Option<&str>, &Path) {
    match arg.split_once('=') {
        Some((name, file)) if !name.contains('/') && !name.is_empty() => {
            (Some(name), Path::new(file))
        }
        _ => (None, Path::new(arg)),
    }
}

fn is_colmap(path: &Path) -> bool {
    path.is_dir()
        || matches!(
            path.file_name().and_then(|n| n.to_str()),
            Some("cameras.txt" | "images.txt")
        )
}

/// Every pair's distance is printed for up to this many cameras; beyond, the closest and widest.
const SHOWN_PAIRS_UP_TO: usize = 6;

fn cameras(a: CamerasArgs) -> anyhow::Result<()> {
    let options = ImportOptions {
        unit: match a.unit {
            UnitArg::Mm => Unit::Mm,
            UnitArg::Cm => Unit::Cm,
            UnitArg::M => Unit::M,
        },
        camera_to_world: a.camera_to_world,
        fisheye: a.fisheye,
    };
    let mut cams: Vec<ImportedCamera> = Vec::new();
    for arg in &a.files {
        let (name, file) = split_named(arg);
        if is_colmap(file) {
            if name.is_some() {
                bail!("{arg}: a COLMAP model names its cameras by their images; drop the NAME=");
            }
            cams.extend(calib::read_colmap(file, &options)?);
        } else {
            let stem = file
                .file_stem()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_default();
            let name = name.map(str::to_string).unwrap_or(stem);
            cams.push(calib::read_opencv(file, &name, &options)?);
        }
    }
    if cams.len() > calib::MAX_CAMERAS {
        bail!(
            "{} cameras: at most {} in one capture (a capture films the teeth with a few)",
            cams.len(),
            calib::MAX_CAMERAS
        );
    }
    let written = calib::write_cameras(&a.capture, &cams).context("writing the cameras")?;
    for (c, path) in cams.iter().zip(&written) {
        let (o, d) = (c.centre(), c.view_direction());
        println!(
            "{} -> {}: {}x{}, f = ({:.1}, {:.1}) px, centre ({:.1}, {:.1}, {:.1}) mm, looking along ({:.2}, {:.2}, {:.2})",
            c.name,
            path.display(),
            c.json.width,
            c.json.height,
            c.json.fx,
            c.json.fy,
            o.x,
            o.y,
            o.z,
            d.x,
            d.y,
            d.z
        );
        for note in &c.notes {
            println!("  {note}");
        }
    }
    let baselines = calib::baselines(&cams);
    if cams.len() <= SHOWN_PAIRS_UP_TO {
        for &(i, j, dist) in &baselines {
            println!("distance {} - {}: {dist:.1} mm", cams[i].name, cams[j].name);
        }
    } else {
        let by = |f: fn(f64, f64) -> bool| {
            baselines
                .iter()
                .copied()
                .reduce(|a, b| if f(b.2, a.2) { b } else { a })
        };
        if let (Some(near), Some(far)) = (by(|a, b| a < b), by(|a, b| a > b)) {
            println!(
                "distances between {} cameras: closest {} - {} {:.1} mm, widest {} - {} {:.1} mm",
                cams.len(),
                cams[near.0].name,
                cams[near.1].name,
                near.2,
                cams[far.0].name,
                cams[far.1].name,
                far.2
            );
        }
    }
    // Cameras filming teeth from about 20 cm stand centimetres to a metre apart.
    let widest = baselines.iter().map(|b| b.2).fold(0.0, f64::max);
    if !baselines.is_empty() && widest < 5.0 {
        println!(
            "note: the cameras lie within {widest:.2} mm of each other: are the translations in metres (--unit m) or centimetres (--unit cm)?"
        );
    } else if widest > 5000.0 {
        println!(
            "note: cameras {widest:.0} mm apart: are the translations in millimetres already (--unit mm)?"
        );
    }
    Ok(())
}

fn videos(a: VideoArgs) -> anyhow::Result<()> {
    let mut jobs = Vec::new();
    for arg in &a.videos {
        let (Some(name), file) = split_named(arg) else {
            bail!("{arg}: give each video as NAME=FILE (the camera's name, then its video)");
        };
        calib::check_name(name, file)?;
        if jobs.iter().any(|(n, _)| n == name) {
            bail!("{arg}: camera `{name}` is given two videos; give each camera one");
        }
        jobs.push((name.to_string(), file.to_path_buf()));
    }
    let options = Extract {
        first: a.first,
        count: a.count.map(|n| n as u64),
        format: if a.jpg {
            FrameFormat::Jpg
        } else {
            FrameFormat::Png
        },
        replace: a.replace,
    };
    for (name, file) in jobs {
        let info = video::probe(&file)?;
        let total = info
            .frames
            .map(|n| n.saturating_sub(a.first))
            .map(|n| a.count.map_or(n, |c| n.min(c as u64)));
        let out = a.capture.join("images").join(&name);
        let bar = crate::cli::progress_bar(total.unwrap_or(0), &name);
        let written = video::extract(&file, &out, &options, |n| bar.set_position(n))?;
        bar.finish_and_clear();
        println!(
            "{name}: {written} frames of {}x{}{} -> {}/{:06}.{} ..",
            info.width,
            info.height,
            info.fps
                .map(|f| format!(" at {f:.3} fps"))
                .unwrap_or_default(),
            out.display(),
            a.first,
            options.format.extension()
        );
    }
    Ok(())
}
