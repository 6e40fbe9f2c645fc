//! Writing a synthetic capture's files in the capture format: capture.json, cameras, meshes,
//! masks, init.json and ground truth.

use std::path::Path;
use std::time::Instant;

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;

use crate::anatomy::JawControls;
use crate::arch::ArchPoses;
use crate::capture::json::{
    ArchInitJson, BoiJson, CameraJson, CaptureJson, FramesJson, InitJson, MasksJson, MeshesJson,
};
use crate::error::Result;
use crate::formats::{FrameRecordJson, TracksJson};
use crate::geometry::{Camera, Pose};
use crate::io::{write_atomic, write_json_atomic};
use crate::mesh::write_obj;

use std::f64::consts::TAU;

use super::colour::{Exposure, Photos, render_colour};
use super::{
    CameraStats, LOWER_LABEL, MOUTH_LABEL, MaskKind, RenderedMask, Session, SynthOptions,
    SynthReport, UPPER_LABEL, encode_png, encode_png_rgb, render_mask,
};

/// One frame as filmed: its number, the true poses and controls, and each mask camera's mask.
struct FilmedFrame {
    index: u32,
    poses: ArchPoses,
    controls: JawControls,
    stats: Vec<RenderedMask>,
}

/// Writes the whole capture into `dir` and reports what it contains.
pub(super) fn write_capture(
    dir: &Path,
    s: &Session,
    opts: &SynthOptions,
    progress: &(dyn Fn() + Sync),
    started: Instant,
) -> Result<SynthReport> {
    write_json_atomic(&dir.join("capture.json"), &capture_json(s, opts))?;
    write_cameras(dir, s, opts)?;
    write_obj(&s.upper, &dir.join("meshes/upper.obj"))?;
    write_obj(&s.lower, &dir.join("meshes/lower.obj"))?;
    write_obj(&s.mandible, &dir.join("meshes/mandible.obj"))?;

    let frames: Vec<FilmedFrame> = (0..opts.frames)
        .into_par_iter()
        .map(|index| -> Result<_> {
            let frame = film_frame(dir, s, opts, index)?;
            progress();
            Ok(frame)
        })
        .collect::<Result<_>>()?;

    write_ground_truth(dir, &frames)?;
    let mut report = motion_report(s, opts, &frames);
    for (c, cam) in s.mask_cameras.iter().enumerate() {
        report.cameras.push(camera_stats(c, cam, opts, &frames));
    }
    report.seconds = started.elapsed().as_secs_f64();
    Ok(report)
}

/// The capture's capture.json: its cameras, frames, meshes, boi group and mask labels.
fn capture_json(s: &Session, opts: &SynthOptions) -> CaptureJson {
    let names: Vec<String> = s.cameras.iter().map(|(c, _)| c.name.clone()).collect();
    let mouth = opts.writes_mouth().then_some(MOUTH_LABEL as i64);
    CaptureJson {
        format: crate::capture::json::CAPTURE_FORMAT.into(),
        cameras: names,
        frames: FramesJson {
            first: 0,
            count: opts.frames,
            offsets: None,
        },
        meshes: MeshesJson {
            upper: "meshes/upper.obj".into(),
            lower: "meshes/lower.obj".into(),
            mandible: Some("meshes/mandible.obj".into()),
        },
        boi: BoiJson::Group {
            group: "boi".into(),
        },
        masks: match opts.masks {
            MaskKind::PerArch => MasksJson {
                dir: "masks".into(),
                mode: "per-arch".into(),
                upper: Some(UPPER_LABEL as i64),
                lower: Some(LOWER_LABEL as i64),
                mouth,
            },
            MaskKind::Combined => MasksJson {
                dir: "masks".into(),
                mode: "combined".into(),
                upper: None,
                lower: None,
                mouth,
            },
        },
    }
}

/// Each camera's file: as read, or with the lens asked for in place of its own.
fn write_cameras(dir: &Path, s: &Session, opts: &SynthOptions) -> Result<()> {
    for (cam, json) in &s.cameras {
        let path = dir.join("cameras").join(format!("{}.json", cam.name));
        match opts.distortion {
            None => write_atomic(&path, json.as_bytes())?,
            Some(d) => {
                let mut cj: CameraJson =
                    serde_json::from_str(json).expect("read as a camera file before");
                cj.distortion = Some(d.coefficients());
                cj.lens = d.is_fisheye().then(|| "fisheye".to_string());
                write_json_atomic(&path, &cj)?;
            }
        }
    }
    Ok(())
}

/// One frame's true poses, its masks (and colour pictures when asked for) written out.
fn film_frame(dir: &Path, s: &Session, opts: &SynthOptions, index: u32) -> Result<FilmedFrame> {
    let controls = s.controls(index, opts);
    let poses = frame_poses(s, opts, index);
    let show = s.lip_show(index, opts);
    let stats = write_masks(dir, s, opts, index, &poses, show)?;
    if opts.images {
        write_colour(dir, s, opts, index, &poses, show)?;
    }
    Ok(FilmedFrame {
        index,
        poses,
        controls,
        stats,
    })
}

/// How much further the lips are drawn back in hard photos (mm): enough to show the gums.
const HARD_EXTRA_SHOW_MM: f64 = 5.0;

/// Both arches' true poses at frame `index`.
fn frame_poses(s: &Session, opts: &SynthOptions, index: u32) -> ArchPoses {
    let upper = s.world_from_upper(index);
    ArchPoses {
        upper,
        lower: upper.compose(&s.jaw.jaw_pose(&s.controls(index, opts))),
    }
}

/// The poses the subject passes through while the shutter is open: the frame's alone, or
/// for hard photos a half-frame shutter centred on it (a quarter of the way to each
/// neighbouring frame's poses).
fn shutter_poses(
    s: &Session,
    opts: &SynthOptions,
    index: u32,
    poses: &ArchPoses,
) -> Vec<ArchPoses> {
    if opts.photos != Photos::Hard || opts.frames < 2 {
        return vec![*poses];
    }
    let towards = |other: u32| {
        let o = frame_poses(s, opts, other);
        let step =
            |a: &Pose, b: &Pose| a.compose(&Pose::exp(&(a.inverse().compose(b).log() * 0.25)));
        ArchPoses {
            upper: step(&poses.upper, &o.upper),
            lower: step(&poses.lower, &o.lower),
        }
    };
    let before = if index > 0 {
        towards(index - 1)
    } else {
        *poses
    };
    let after = if index + 1 < opts.frames {
        towards(index + 1)
    } else {
        *poses
    };
    vec![before, *poses, after]
}

/// One frame's mask per mask camera (none with `no_masks`), written where one was drawn.
fn write_masks(
    dir: &Path,
    s: &Session,
    opts: &SynthOptions,
    index: u32,
    poses: &ArchPoses,
    show: [f64; 2],
) -> Result<Vec<RenderedMask>> {
    let mut stats = Vec::with_capacity(s.mask_cameras.len());
    for (c, cam) in s.mask_cameras.iter().enumerate() {
        if opts.no_masks {
            break;
        }
        // Persistent errors: the same draws every frame (per camera).
        let drawn_at = if opts.persistent_noise {
            0
        } else {
            index as u64
        };
        let mut rng = ChaCha8Rng::seed_from_u64(
            opts.seed ^ (drawn_at << 8 | c as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15),
        );
        let m = render_mask(s, cam, poses, show, opts, &mut rng);
        if let Some(png) = &m.png {
            write_atomic(
                &dir.join("masks")
                    .join(&cam.name)
                    .join(format!("{index:06}.png")),
                png,
            )?;
        }
        stats.push(m);
    }
    Ok(stats)
}

/// The true poses of every frame (gt/poses.json) and the first frame's as init.json.
fn write_ground_truth(dir: &Path, frames: &[FilmedFrame]) -> Result<()> {
    let records: Vec<FrameRecordJson> = frames
        .iter()
        .map(|f| FrameRecordJson {
            frame: f.index,
            upper: (&f.poses.upper).into(),
            lower: (&f.poses.lower).into(),
            jaw: Some((&f.poses.jaw()).into()),
            energy: None,
            area_error: None,
            status: None,
            jaw_source: None,
            tracked: None,
            hand_set: false,
            teeth_hidden: false,
            recovered: false,
            edge_offsets: None,
        })
        .collect();
    write_json_atomic(
        &dir.join("gt/poses.json"),
        &TracksJson {
            fingerprint: None,
            format: crate::formats::TRACKS_FORMAT.into(),
            frames: records,
        },
    )?;
    let first = &frames[0].poses;
    write_json_atomic(
        &dir.join("init.json"),
        &InitJson {
            upper: ArchInitJson::Pose((&first.upper).into()),
            lower: ArchInitJson::Pose((&first.lower).into()),
        },
    )
}

/// The report's counts and the extremes of the jaw's motion, before the cameras' statistics.
fn motion_report(s: &Session, opts: &SynthOptions, frames: &[FilmedFrame]) -> SynthReport {
    let rest_incisor = s.jaw.rest.transform_point(&s.lower_incisor);
    let mut report = SynthReport {
        frames: opts.frames,
        triangles: [s.upper.triangles.len(), s.lower.triangles.len()],
        boi_triangles: [s.upper.boi_face_count(), s.lower.boi_face_count()],
        cameras: Vec::new(),
        max_opening_mm: 0.0,
        lateral_mm: [0.0, 0.0],
        max_protrusion_mm: 0.0,
        max_condylar_travel_mm: 0.0,
        seconds: 0.0,
    };
    for f in frames {
        let d = f.poses.jaw().transform_point(&s.lower_incisor) - rest_incisor;
        report.max_opening_mm = report.max_opening_mm.max(-d.y);
        report.lateral_mm = [report.lateral_mm[0].min(d.x), report.lateral_mm[1].max(d.x)];
        report.max_protrusion_mm = report.max_protrusion_mm.max(d.z);
        let (sl, sr, _) = s.jaw.joint_state(&f.controls);
        report.max_condylar_travel_mm = report.max_condylar_travel_mm.max(sl.max(sr));
    }
    report
}

/// Mask camera `c`'s statistics over all frames.
fn camera_stats(
    c: usize,
    cam: &Camera,
    opts: &SynthOptions,
    frames: &[FilmedFrame],
) -> CameraStats {
    let mut with_mask = 0;
    let mut mask = [0u64; 2];
    let mut mouth = 0u64;
    let mut alone = [0u64; 2];
    for f in frames {
        let Some(m) = f.stats.get(c) else { continue };
        with_mask += m.png.is_some() as u32;
        mouth += m.mouth_pixels;
        for k in 0..2 {
            mask[k] += m.mask_pixels[k];
            alone[k] += m.alone_pixels[k];
        }
    }
    CameraStats {
        name: cam.name.clone(),
        mask_size: [cam.width, cam.height],
        frames_with_mask: with_mask,
        mean_mask_pixels: mask.map(|m| m as f64 / opts.frames as f64),
        mean_mouth_pixels: mouth as f64 / opts.frames as f64,
        visible_share: [0, 1].map(|k| {
            if alone[k] == 0 {
                0.0
            } else {
                mask[k] as f64 / alone[k] as f64
            }
        }),
    }
}

/// One frame's colour pictures and their true labels, per camera.
fn write_colour(
    dir: &Path,
    s: &Session,
    opts: &SynthOptions,
    index: u32,
    poses: &ArchPoses,
    show: [f64; 2],
) -> Result<()> {
    let shutter = &shutter_poses(s, opts, index, poses);
    // Lips drawn back far enough to show the gums.
    let show = match opts.photos {
        Photos::Hard => show.map(|mm| mm + HARD_EXTRA_SHOW_MM),
        Photos::Clean => show,
    };
    for (c, cam) in s.mask_cameras.iter().enumerate() {
        // The camera's white balance stays; the light flickers a little from frame to frame.
        let mut camera_rng = ChaCha8Rng::seed_from_u64(opts.seed ^ (0xC0_10E5 + c as u64));
        let white = [0; 3].map(|_| camera_rng.random_range(0.96..=1.04));
        let mut rng = ChaCha8Rng::seed_from_u64(
            opts.seed ^ ((index as u64) << 8 | c as u64).wrapping_mul(0xD1B5_4A32_D192_ED03),
        );
        let off = opts.light_off.as_ref().is_some_and(|r| r.contains(&index));
        let mut gain = if off { 0.04 } else { 1.0 } * rng.random_range(0.98..=1.02);
        let mut white = white;
        if opts.photos == Photos::Hard {
            // The camera's automatic exposure and white balance wander over the take.
            let phase: [f64; 4] = std::array::from_fn(|_| camera_rng.random_range(0.0..TAU));
            let t = index as f64;
            gain *= 1.0 + 0.12 * (TAU * t / 40.0 + phase[3]).sin();
            for k in 0..3 {
                white[k] *= 1.0 + 0.06 * (TAU * t / 55.0 + phase[k]).sin();
            }
        }
        let frame = render_colour(
            cam,
            [&s.upper, &s.lower],
            shutter,
            &s.lips,
            show,
            Exposure { gain, white },
            opts.photos,
            &mut rng,
        );
        let name = format!("{index:06}.png");
        write_atomic(
            &dir.join("images").join(&cam.name).join(&name),
            &encode_png_rgb(&frame.rgb, cam.width, cam.height),
        )?;
        write_atomic(
            &dir.join("gt/masks").join(&cam.name).join(&name),
            &encode_png(&frame.labels, cam.width, cam.height),
        )?;
    }
    Ok(())
}
