use std::path::{Path, PathBuf};

use anyhow::Context;
use jawtrack::capture::{ArchInit, Capture};

#[derive(clap::Args)]
pub struct Args {
    /// The capture folder (with capture.json).
    pub capture: PathBuf,
    /// Only read mask headers; do not decode every mask.
    #[arg(long)]
    pub quick: bool,
}

pub fn run(a: Args) -> anyhow::Result<()> {
    let capture = open_and_check(&a.capture, !a.quick)?;
    print_summary(&capture);
    Ok(())
}

/// Open a capture and (optionally) decode every mask of every frame.
pub fn open_and_check(dir: &Path, decode_all: bool) -> anyhow::Result<Capture> {
    let capture =
        Capture::open(dir).with_context(|| format!("invalid capture {}", dir.display()))?;
    if decode_all {
        let bar = super::progress_bar(capture.frame_count as u64, "decoding masks");
        for frame in capture.frames() {
            capture
                .load_masks(frame)
                .with_context(|| format!("invalid capture {}", dir.display()))?;
            bar.inc(1);
        }
        bar.finish_and_clear();
    }
    Ok(capture)
}

pub fn print_summary(c: &Capture) {
    println!("capture {}: valid", c.dir.display());
    let last = c.first_frame + c.frame_count - 1;
    println!(
        "frames {}..={} ({}), masks {:?}",
        c.first_frame, last, c.frame_count, c.mask_mode
    );
    println!("camera  image      mask       masks found  distortion");
    for cam in &c.cameras {
        let k = &cam.calibrated;
        let in_range = cam.frames_present.range(c.first_frame..=last).count();
        println!(
            "{:<6}  {}x{}  {:<9}  {:>5}/{:<5}  {}",
            k.name,
            k.width,
            k.height,
            cam.mask_size
                .map(|(w, h)| format!("{w}x{h}"))
                .unwrap_or_else(|| "none".into()),
            in_range,
            c.frame_count,
            match (k.has_distortion(), k.lens_covers_the_image()) {
                (false, _) => "no".to_string(),
                (true, true) => "yes (models drawn through the lens)".to_string(),
                (true, false) => format!(
                    "yes, but the model folds back inside the image, {:.0} px from the centre: \
                     nothing is drawn past it",
                    k.lens_reach() * k.fx
                ),
            }
        );
    }
    let describe = |name: &str, m: &jawtrack::capture::Mesh| {
        let (lo, hi) = m.bounds();
        println!(
            "mesh {name}: {} vertices, {} triangles, {} BOI triangles, size {:.1} x {:.1} x {:.1} mm",
            m.positions.len(),
            m.triangles.len(),
            m.boi_face_count(),
            hi[0] - lo[0],
            hi[1] - lo[1],
            hi[2] - lo[2]
        );
    };
    describe("upper", &c.upper);
    describe("lower", &c.lower);
    if let Some(m) = &c.mandible {
        describe("mandible", m);
    }
    match &c.init {
        None => println!("init.json: absent (tracking will need first-frame poses)"),
        Some(init) => {
            let kind = |a: &ArchInit| match a {
                ArchInit::Pose(_) => "pose".to_string(),
                ArchInit::Points(p) => format!("{} bootstrap points", p.len()),
            };
            println!(
                "init.json: upper {}, lower {}",
                kind(&init.upper),
                kind(&init.lower)
            );
        }
    }
    match &c.gt {
        None => println!("ground truth: none"),
        Some(gt) => println!("ground truth: {} frames", gt.len()),
    }
}
