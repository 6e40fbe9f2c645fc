//! What several commands print: summaries of captures, tracking runs, scores and rigs.

use std::path::Path;

use jawtrack::capture::{ArchInit, Capture};
use jawtrack::rig::eval::{EvalReport, Series};
use jawtrack::synth::SynthReport;
use jawtrack::track::score::{ScoreReport, Stats};
use jawtrack::track::{Status, Summary};

/// What opening the capture noticed but did not refuse, on stderr.
pub fn notes(c: &Capture) {
    for note in c.notes() {
        eprintln!("warning: {note}");
    }
}

/// A capture's summary; `pixels` (each camera's mean upper, lower and mouth pixels per mask)
/// when its masks were decoded.
pub fn capture(c: &Capture, pixels: Option<&[[f64; 3]]>) {
    println!("capture {}: valid", c.dir().display());
    let last = c.first_frame() + c.frame_count() - 1;
    println!(
        "frames {}..={} ({}), masks {}, {}",
        c.first_frame(),
        last,
        c.frame_count(),
        c.mask_mode(),
        match c.mouth() {
            Some(v) => format!("visible mouth interior {v}"),
            None => "no mouth label (the over-mouth term is off)".into(),
        }
    );
    cameras(c, pixels, last);
    meshes(c);
    init_and_truth(c);
}

/// The table of cameras: image and mask sizes, masks found up to frame `last`, mean pixels
/// per mask and the lens.
fn cameras(c: &Capture, pixels: Option<&[[f64; 3]]>, last: u32) {
    println!(
        "camera  image      mask       masks found  mean px per mask ({})  distortion",
        match (c.mask_mode(), c.mouth()) {
            (jawtrack::capture::MaskMode::Combined, Some(_)) => "teeth / mouth",
            (jawtrack::capture::MaskMode::Combined, None) => "teeth",
            (_, Some(_)) => "upper / lower / mouth",
            (_, None) => "upper / lower",
        }
    );
    for (i, cam) in c.cameras().iter().enumerate() {
        let k = &cam.calibrated;
        let in_range = cam.frames_present.range(c.first_frame()..=last).count();
        println!(
            "{:<6}  {}x{}  {:<9}  {:>5}/{:<5}  {:<20}  {}",
            k.name,
            k.width,
            k.height,
            cam.mask_size
                .map(|(w, h)| format!("{w}x{h}"))
                .unwrap_or_else(|| "none".into()),
            in_range,
            c.frame_count(),
            mean_pixels(c, pixels, i),
            lens(k)
        );
    }
}

/// Camera `k`'s mean pixels per mask, the labels the capture's masks carry; `-` when the
/// masks were not decoded.
fn mean_pixels(c: &Capture, pixels: Option<&[[f64; 3]]>, k: usize) -> String {
    match pixels {
        None => "-".to_string(),
        Some(p) => {
            let [u, l, m] = p[k];
            match (c.mask_mode(), c.mouth()) {
                (jawtrack::capture::MaskMode::Combined, Some(_)) => format!("{u:.0} / {m:.0}"),
                (jawtrack::capture::MaskMode::Combined, None) => format!("{u:.0}"),
                (_, Some(_)) => format!("{u:.0} / {l:.0} / {m:.0}"),
                (_, None) => format!("{u:.0} / {l:.0}"),
            }
        }
    }
}

/// A camera's lens: none, drawn through, or folding back inside the image.
fn lens(k: &jawtrack::geometry::Camera) -> String {
    match (k.has_distortion(), k.lens_covers_the_image()) {
        (false, _) => "no".to_string(),
        (true, true) => format!(
            "{} (models drawn through the lens)",
            if k.distortion.is_fisheye() {
                "fisheye"
            } else {
                "yes"
            }
        ),
        (true, false) => format!(
            "yes, but the model folds back inside the image, {:.0} px from the centre: \
             nothing is drawn past it",
            k.lens_reach() * k.fx
        ),
    }
}

/// The meshes as tracked: upper, lower and the mandible when there is one.
fn meshes(c: &Capture) {
    let simplified = match c.simplified_mm() {
        Some(0.0) => "as loaded".to_string(),
        Some(mm) => format!("simplified within {mm:.3} mm"),
        None => "simplified to --max-triangles".to_string(),
    };
    let describe = |name: &str, m: &jawtrack::mesh::Mesh, how: &str| {
        let (lo, hi) = m.bounds();
        println!(
            "mesh {name} as tracked ({how}): {} vertices, {} triangles, {} BOI triangles, size {:.1} x {:.1} x {:.1} mm",
            m.positions.len(),
            m.triangles.len(),
            m.boi_face_count(),
            hi[0] - lo[0],
            hi[1] - lo[1],
            hi[2] - lo[2]
        );
    };
    describe("upper", c.upper(), &simplified);
    describe("lower", c.lower(), &simplified);
    if let Some(m) = &c.mandible() {
        describe("mandible", m, "as loaded");
    }
}

/// How tracking starts (init.json) and how many frames of ground truth there are.
fn init_and_truth(c: &Capture) {
    match &c.init() {
        None => println!(
            "init.json: absent (tracking finds the first frame's poses from per-arch masks)"
        ),
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
    match &c.gt() {
        None => println!("ground truth: none"),
        Some(gt) => println!("ground truth: {} frames", gt.len()),
    }
}

pub fn synth(out: &Path, r: &SynthReport) {
    println!(
        "wrote {} ({} frames in {:.2} s)",
        out.display(),
        r.frames,
        r.seconds
    );
    println!(
        "meshes as written: upper {} triangles ({} BOI), lower {} ({} BOI); reading simplifies them (validate prints what is tracked)",
        r.triangles[0], r.boi_triangles[0], r.triangles[1], r.boi_triangles[1]
    );
    println!(
        "motion: opening up to {:.1} mm, lateral {:.1} to {:.1} mm, protrusion up to {:.1} mm, condylar travel up to {:.1} mm",
        r.max_opening_mm,
        r.lateral_mm[0],
        r.lateral_mm[1],
        r.max_protrusion_mm,
        r.max_condylar_travel_mm
    );
    println!(
        "camera  mask size  frames with mask  mean mask px (upper, lower, mouth)  visible share (upper, lower)"
    );
    for c in &r.cameras {
        println!(
            "{:<6}  {}x{}    {:>5}             {:>7.0} {:>7.0} {:>7.0}             {:>5.1}% {:>5.1}%",
            c.name,
            c.mask_size[0],
            c.mask_size[1],
            c.frames_with_mask,
            c.mean_mask_pixels[0],
            c.mean_mask_pixels[1],
            c.mean_mouth_pixels,
            100.0 * c.visible_share[0],
            100.0 * c.visible_share[1]
        );
    }
}

pub fn track_summary(output: &Path, s: &Summary) {
    println!(
        "tracked {} frames ({} now) -> {}: {} ok, {} low-confidence, {} no-data",
        s.records.len(),
        s.tracked_now,
        output.display(),
        s.count(Status::Ok),
        s.count(Status::LowConfidence),
        s.count(Status::NoData)
    );
    if s.manifold_released {
        println!(
            "the jaw's manifold does not fit this subject ({} frames tracked ok lay farther than \
             jaw_manifold_release_mm off it, by their median): let go for the rest of the take",
            jawtrack::track::state::JUDGING_FRAMES
        );
    }
    if s.tracked_now > 0 {
        let per_frame = |n: usize| n as f64 / s.tracked_now as f64;
        if s.steps > 0 {
            // Time goes to the steps' drawing and sampling as well as to the evaluations.
            println!(
                "time {:.2} s per frame ({} energy evaluations per frame, {:.1} Gauss-Newton steps), search {}, backend {}",
                s.seconds / s.tracked_now as f64,
                s.evaluations / s.tracked_now,
                per_frame(s.steps),
                s.solver.name(),
                s.backend
            );
        } else {
            println!(
                "time {:.2} s per frame ({} energy evaluations per frame, {:.2} ms each), search {}, backend {}",
                s.seconds / s.tracked_now as f64,
                s.evaluations / s.tracked_now,
                s.seconds * 1e3 / s.evaluations.max(1) as f64,
                s.solver.name(),
                s.backend
            );
        }
    }
}

pub fn score(r: &ScoreReport) {
    println!(
        "against {}, {} frames ({} ok, {} low-confidence ({} with the teeth hidden, {} found again \
         after a loss), {} no-data): median / 95th percentile / max",
        r.reference,
        r.frames,
        r.frames_ok,
        r.frames_low_confidence,
        r.frames_teeth_hidden,
        r.frames_recovered,
        r.frames_no_data
    );
    let line = |name: &str, what: &str, s: &Stats| {
        println!(
            "  {name:<6} {what:<22} {:>8.3} {:>8.3} {:>8.3}",
            s.median, s.p95, s.max
        );
    };
    for (name, e) in [("upper", &r.upper), ("lower", &r.lower), ("jaw", &r.jaw)] {
        line(name, "mean vertex error (mm)", &e.mean_vertex_mm);
        line(name, "rotation error (deg)", &e.rotation_deg);
        line(name, "translation error (mm)", &e.translation_mm);
    }
    line("upper", "area error (%)", &r.area_error_percent[0]);
    line("lower", "area error (%)", &r.area_error_percent[1]);
    let f = &r.flags;
    println!(
        "flags: {} of {} frames with the jaw off by more than {} mm are flagged (recall {:.0}%); \
         {} of the {} others are (false flags {:.0}%)",
        f.wrong_flagged,
        f.wrong,
        f.wrong_mm,
        100.0 * f.recall,
        f.right_flagged,
        f.right,
        100.0 * f.false_flag_rate
    );
}

pub fn rig_eval(r: &EvalReport) {
    println!(
        "reconstruction error of {} poses: largest vertex distance on a mesh of {} vertices (mm)",
        r.poses, r.mesh_vertices
    );
    let rec = &r.reconstruction;
    let mut names: Vec<&str> = rec
        .pca
        .iter()
        .chain(&rec.nlpca)
        .map(|s| s.name.as_str())
        .collect();
    names.extend(
        [&rec.pca3_plain, &rec.rig, &rec.rig_clamped]
            .into_iter()
            .chain(&rec.paper_rig)
            .map(|s| s.name.as_str()),
    );
    if let Some(s) = &r.sampled {
        names.extend([
            s.dynamic_ranges.name.as_str(),
            s.static_ranges.name.as_str(),
        ]);
    }
    // One column width for every row's name, so that the numbers line up.
    let width = names
        .iter()
        .map(|n| n.chars().count())
        .max()
        .unwrap_or(5)
        .max(5);
    println!(
        "{:<width$} {:>6} {:>8} {:>8} {:>8}",
        "model", "mean", "median", "p95", "max"
    );
    let row = |s: &Series| {
        println!(
            "{:<width$} {:>6.3} {:>8.3} {:>8.3} {:>8.3}",
            s.name, s.stats.mean, s.stats.median, s.stats.p95, s.stats.max
        )
    };
    rec.pca.iter().for_each(row);
    row(&rec.pca3_plain);
    rec.nlpca.iter().for_each(row);
    row(&rec.rig);
    row(&rec.rig_clamped);
    rec.paper_rig.iter().for_each(row);
    println!(
        "{:.1}% of the poses encode inside the valid ranges; encoding {:.3} ms a pose, decoding {:.2} µs",
        100.0 * rec.valid_share,
        r.encode_ms,
        r.decode_us
    );
    if let Some(s) = &r.sampled {
        println!(
            "{} random rig poses, distance to the nearest captured pose (mm):",
            s.dynamic_ranges.errors_mm.len()
        );
        row(&s.dynamic_ranges);
        row(&s.static_ranges);
    }
}

pub fn rig_compare(poses: usize, vertices: usize, rows: &[jawtrack::envelope::compare::Row]) {
    println!(
        "{poses} poses; errors on a mesh of {vertices} vertices (mm): largest vertex distance per pose, and the front-weighted mean distance"
    );
    println!(
        "rig                                 params   max: mean      p95      max   front-weighted: mean      max   learn (s)"
    );
    for r in rows {
        println!(
            "{:<36} {:>5} {:>10.3} {:>8.3} {:>8.3} {:>22.3} {:>8.3} {:>11.2}",
            r.name,
            r.parameters,
            r.max_vertex_mm.mean,
            r.max_vertex_mm.p95,
            r.max_vertex_mm.max,
            r.front_weighted_mm.mean,
            r.front_weighted_mm.max,
            r.learn_seconds
        );
    }
}
