//! Synthetic captures load back through the reader, deterministically; on clean captures the
//! energy is (nearly) zero at the truth and rises for any single degree of freedom moved by
//! 0.5 mm or 0.5°; the paper's bootstrap recovers first-frame poses; masks read at half their
//! resolution line up with the scaled cameras.

mod common;

use common::{copy_dir, template};
use jawtrack::arch::{Arch, ArchPoses};
use jawtrack::capture::Capture;
use jawtrack::energy::{CpuEnergy, DEFAULT_LAMBDA, EnergyEngine, Scene};
use jawtrack::synth::{MaskKind, Preset, SynthOptions, generate};
use nalgebra::Vector2;

#[test]
fn synthetic_captures_round_trip_through_the_reader() {
    let dir = template(Preset::Realistic, MaskKind::PerArch);
    let c = Capture::open(dir).unwrap();
    assert_eq!(c.camera_names(), ["cam0", "cam1", "cam2"]);
    assert_eq!(c.frames(), 0..6);
    let gt = c.gt().unwrap();
    assert_eq!(gt.len(), 6);
    let init = c.initial_poses().unwrap();
    let (r, t) = init.upper.distance_to(&gt[0].poses.upper);
    assert!(r < 1e-9 && t < 1e-9);
    assert!(c.mandible().unwrap().triangles.len() > c.lower().triangles.len());
    for cam in c.cameras() {
        assert_eq!(cam.mask_size, Some((960, 540)), "half-resolution masks");
    }
    // Every frame decodes, with teeth of both arches in the masks.
    for f in c.frames() {
        let m = c.load_masks(f).unwrap();
        let upper: u64 = m
            .masks
            .iter()
            .flatten()
            .map(|m| m.count(Arch::Upper.mask_bit()))
            .sum();
        let lower: u64 = m
            .masks
            .iter()
            .flatten()
            .map(|m| m.count(Arch::Lower.mask_bit()))
            .sum();
        assert!(upper > 200 && lower > 200, "frame {f}: {upper} {lower}");
    }
}

fn files(dir: &std::path::Path) -> Vec<(String, Vec<u8>)> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p);
            } else {
                out.push((
                    p.strip_prefix(dir).unwrap().display().to_string(),
                    std::fs::read(&p).unwrap(),
                ));
            }
        }
    }
    out.sort();
    out
}

#[test]
fn synthesis_is_deterministic_per_seed() {
    let t = tempfile::tempdir().unwrap();
    let opts = |seed| SynthOptions {
        frames: 3,
        seed,
        preset: Preset::Hard,
        ..SynthOptions::default()
    };
    generate(&t.path().join("a"), &opts(7), &|| {}).unwrap();
    generate(&t.path().join("b"), &opts(7), &|| {}).unwrap();
    generate(&t.path().join("c"), &opts(8), &|| {}).unwrap();
    let (a, b, c) = (
        files(&t.path().join("a")),
        files(&t.path().join("b")),
        files(&t.path().join("c")),
    );
    assert!(a.len() > 10);
    assert!(a == b, "same seed, different capture");
    assert!(a != c, "different seeds, same capture");
    // An existing folder is not overwritten without force.
    let err = generate(&t.path().join("a"), &opts(1), &|| {})
        .unwrap_err()
        .to_string();
    assert!(err.contains("already exists"), "{err}");
}

/// The presets with lips label the visible mouth interior (`masks.mouth`) in either mask
/// mode: the lip opening less the teeth, so the label never takes a tooth's pixel; without
/// it (`--no-mouth`) the teeth pixels are those of the labelled masks.
#[test]
fn masks_label_the_mouth_interior_unless_told_not_to() {
    use jawtrack::capture::masks::MOUTH_BIT;
    use jawtrack::capture::{Capture, LOWER_BIT, UPPER_BIT};
    use jawtrack::synth::MaskKind;
    let t = tempfile::tempdir().unwrap();
    for masks in [MaskKind::PerArch, MaskKind::Combined] {
        let opts = |mouth| SynthOptions {
            frames: 8,
            seed: 3,
            masks,
            mouth,
            ..SynthOptions::default()
        };
        let (with, without) = (
            t.path().join(format!("{masks:?}-with")),
            t.path().join(format!("{masks:?}-without")),
        );
        generate(&with, &opts(true), &|| {}).unwrap();
        generate(&without, &opts(false), &|| {}).unwrap();
        let (a, b) = (
            Capture::open(&with).unwrap(),
            Capture::open(&without).unwrap(),
        );
        assert_eq!(a.mouth(), Some(jawtrack::synth::MOUTH_LABEL));
        assert_eq!(b.mouth(), None);
        let mut mouth_pixels = 0;
        for frame in [0, 4, 7] {
            let (ma, mb) = (a.load_masks(frame).unwrap(), b.load_masks(frame).unwrap());
            for (x, y) in ma.masks.iter().zip(&mb.masks) {
                let (x, y) = (x.as_ref().unwrap(), y.as_ref().unwrap());
                let teeth = |m: &jawtrack::capture::LabelMask| {
                    m.data
                        .iter()
                        .map(|l| l & (UPPER_BIT | LOWER_BIT))
                        .collect::<Vec<_>>()
                };
                assert_eq!(
                    teeth(x),
                    teeth(y),
                    "{masks:?} frame {frame}: the label moved teeth"
                );
                assert!(x.data.iter().all(|&l| l & MOUTH_BIT == 0 || l == MOUTH_BIT));
                assert_eq!(y.count(MOUTH_BIT), 0);
                mouth_pixels += x.count(MOUTH_BIT);
            }
        }
        // The mouth is open in these frames: its interior is seen in every camera.
        assert!(
            mouth_pixels > 3 * 3 * 200,
            "{masks:?}: {mouth_pixels} mouth pixels"
        );
    }
}

#[test]
fn another_rig_and_a_lens_are_written_as_given() {
    let t = tempfile::tempdir().unwrap();
    // A two-camera rig: calib/'s side cameras, one given a lens of its own.
    let rig = t.path().join("rig");
    std::fs::create_dir_all(&rig).unwrap();
    let calib = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("calib");
    std::fs::copy(calib.join("cam1.json"), rig.join("left.json")).unwrap();
    let mut right: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(calib.join("cam2.json")).unwrap()).unwrap();
    right["distortion"] = serde_json::json!([-0.1, 0.0, 0.0, 0.0]);
    std::fs::write(rig.join("right.json"), right.to_string()).unwrap();
    let opts = |distortion| SynthOptions {
        frames: 2,
        rig: Some(rig.clone()),
        distortion,
        ..SynthOptions::default()
    };
    generate(&t.path().join("own"), &opts(None), &|| {}).unwrap();
    let c = Capture::open(&t.path().join("own")).unwrap();
    assert_eq!(c.camera_names(), ["left", "right"]);
    assert_eq!(
        c.cameras()[1].calibrated.distortion,
        jawtrack::geometry::Distortion::brown([-0.1, 0.0, 0.0, 0.0, 0.0])
    );
    assert!(!c.cameras()[0].calibrated.has_distortion());
    assert_eq!(c.cameras()[0].mask_size, Some((960, 540)));
    // --distortion replaces every camera's lens.
    generate(
        &t.path().join("lens"),
        &opts(Some(jawtrack::synth::BARREL_LENS)),
        &|| {},
    )
    .unwrap();
    let c = Capture::open(&t.path().join("lens")).unwrap();
    for cam in c.cameras() {
        assert_eq!(cam.calibrated.distortion, jawtrack::synth::BARREL_LENS);
    }
    // A lens that folds back inside the image, and a folder without cameras, are refused.
    let err = generate(
        &t.path().join("x"),
        &opts(Some(jawtrack::geometry::Distortion::brown([
            -0.6, 0.0, 0.0, 0.0, 0.0,
        ]))),
        &|| {},
    )
    .unwrap_err()
    .to_string();
    assert!(
        err.contains("left.json") && err.contains("folds back"),
        "{err}"
    );
    let empty = t.path().join("empty");
    std::fs::create_dir_all(&empty).unwrap();
    let err = generate(
        &t.path().join("y"),
        &SynthOptions {
            rig: Some(empty),
            ..SynthOptions::default()
        },
        &|| {},
    )
    .unwrap_err()
    .to_string();
    assert!(err.contains("holds no camera files"), "{err}");
}

/// Each of the six pose parameters moved by ±0.5 mm or ±0.5°.
/// Each degree of freedom moved by `step` (degrees or mm) either way.
fn single_dof_moves(truth: &ArchPoses, arch: Arch, step: f64) -> Vec<ArchPoses> {
    (0..12)
        .map(|k| {
            let mut d = [0.0; 6];
            let step = if k / 2 < 3 { step.to_radians() } else { step };
            d[k / 2] = if k % 2 == 0 { step } else { -step };
            truth.with(arch, truth.get(arch).with_euler_offset(&d))
        })
        .collect()
}

fn truth_is_the_minimum(masks: MaskKind) {
    let c = Capture::open(template(Preset::Clean, masks)).unwrap();
    let mut engine = CpuEnergy::new(Scene::from_capture(&c));
    for f in c.frames() {
        engine.set_frame(&c.load_masks(f).unwrap()).unwrap();
        let truth = c.gt_poses(f).unwrap();
        for arch in Arch::BOTH {
            let at_truth = &engine.evaluate(arch, &[truth]).unwrap()[0];
            // The clean masks are renders of the same meshes at these poses: only pixel
            // centres on an edge can differ (poses went through JSON and f32).
            assert!(
                at_truth.total(DEFAULT_LAMBDA) <= 0.002 * at_truth.mask_pixels() as f64,
                "frame {f} {arch:?}: {at_truth:?}"
            );
            let moved = engine
                .evaluate(arch, &single_dof_moves(&truth, arch, 0.5))
                .unwrap();
            for (k, e) in moved.iter().enumerate() {
                assert!(
                    e.total(DEFAULT_LAMBDA) > at_truth.total(DEFAULT_LAMBDA),
                    "frame {f} {arch:?} move {k}: {} <= {}",
                    e.total(DEFAULT_LAMBDA),
                    at_truth.total(DEFAULT_LAMBDA)
                );
            }
        }
    }
}

#[test]
fn energy_at_the_truth_is_lower_than_any_single_dof_move_per_arch_masks() {
    truth_is_the_minimum(MaskKind::PerArch);
}

#[test]
fn energy_at_the_truth_is_lower_than_any_single_dof_move_combined_masks() {
    truth_is_the_minimum(MaskKind::Combined);
}

#[test]
fn bootstrap_points_recover_the_first_poses() {
    let t = tempfile::tempdir().unwrap();
    let dir = t.path().join("c");
    copy_dir(template(Preset::Clean, MaskKind::PerArch), &dir);
    let c = Capture::open(&dir).unwrap();
    let truth = c.gt_poses(0).unwrap();
    // Four vertices per arch, seen in all three (full-resolution, calibrated) cameras, with
    // a quarter-pixel of click error.
    let points = |arch: Arch| -> serde_json::Value {
        let mesh = c.mesh(arch);
        let n = mesh.positions.len();
        let picks = [n / 7, n / 3, n / 2, 5 * n / 6];
        serde_json::Value::Array(
            picks
                .iter()
                .enumerate()
                .map(|(k, &v)| {
                    let p = mesh.positions[v];
                    let world = truth.get(arch).transform_point(&nalgebra::Vector3::new(
                        p[0] as f64,
                        p[1] as f64,
                        p[2] as f64,
                    ));
                    let mut pixels = serde_json::Map::new();
                    for cam in c.cameras() {
                        let px = cam.calibrated.project(&world).unwrap()
                            + Vector2::new(0.25, -0.25) * (k as f64 - 1.5);
                        pixels.insert(cam.calibrated.name.clone(), serde_json::json!([px.x, px.y]));
                    }
                    serde_json::json!({"vertex": v, "pixels": pixels})
                })
                .collect(),
        )
    };
    let init = serde_json::json!({"upper": {"points": points(Arch::Upper)}, "lower": {"points": points(Arch::Lower)}});
    std::fs::write(dir.join("init.json"), init.to_string()).unwrap();
    let c = Capture::open(&dir).unwrap();
    let got = c.initial_poses().unwrap();
    for arch in Arch::BOTH {
        let (r, tr) = got.get(arch).distance_to(truth.get(arch));
        assert!(
            r.to_degrees() < 0.5 && tr < 0.5,
            "{arch:?}: {:.3}° {tr:.3} mm",
            r.to_degrees()
        );
    }
}

#[test]
fn the_energy_region_skips_body_faces_without_changing_the_energy() {
    for masks in [MaskKind::PerArch, MaskKind::Combined] {
        let c = Capture::open(template(Preset::Realistic, masks)).unwrap();
        assert!(common::energy_region_matches_footprint(&c, 3.0) >= 100);
    }
}

#[test]
fn masks_read_at_a_fraction_of_their_resolution_line_up_with_the_cameras() {
    use jawtrack::capture::OpenOptions;
    let dir = template(Preset::Clean, MaskKind::PerArch);
    let open = |k: u32| {
        Capture::open_with(
            dir,
            OpenOptions {
                mask_reduce: k,
                ..OpenOptions::default()
            },
        )
    };
    let (full, half) = (open(1).unwrap(), open(2).unwrap());
    let frame = full.frames().start + 3;
    let (mf, mh) = (
        full.load_masks(frame).unwrap(),
        half.load_masks(frame).unwrap(),
    );
    for (i, cam) in half.cameras().iter().enumerate() {
        let (w, h) = full.cameras()[i].mask_size.unwrap();
        assert_eq!(cam.mask_size, Some((w / 2, h / 2)));
        let m = mh.masks[i].as_ref().unwrap();
        assert_eq!((m.width, m.height), (w / 2, h / 2));
        // Each block's majority, ties alternating: the teeth keep their area within the
        // share of pixels an edge crosses.
        let mf = mf.masks[i].as_ref().unwrap();
        for bit in [1, 2] {
            let (a, b) = (mf.count(bit) as f64, 4.0 * m.count(bit) as f64);
            assert!(
                (a - b).abs() < 0.05 * a,
                "camera {i} label {bit}: {a} against {b}"
            );
        }
    }
    // Against an independent drawing: the two arches rendered straight into the scaled
    // cameras at the truth differ from the reduced masks only along edges, and less than when
    // drawn half a pixel to any side (the scaling's pixel-centre convention).
    let truth = half.gt_poses(frame).unwrap();
    for (i, cam) in half.cameras().iter().enumerate() {
        let m = mh.masks[i].as_ref().unwrap();
        let cam = cam.mask_camera().unwrap();
        let differ = |dx: f64, dy: f64| {
            let cam = jawtrack::geometry::Camera {
                cx: cam.cx + dx,
                cy: cam.cy + dy,
                ..cam.clone()
            };
            let drawn = jawtrack::energy::raster::render_labels(
                &cam,
                &[
                    (half.upper(), &truth.upper, 1, 1),
                    (half.lower(), &truth.lower, 2, 2),
                ],
            );
            drawn.iter().zip(&m.data).filter(|(a, b)| a != b).count()
        };
        let aligned = differ(0.0, 0.0);
        let teeth = m.data.iter().filter(|&&v| v != 0).count();
        assert!(
            aligned * 20 < teeth,
            "camera {i}: {aligned} of {teeth} differ"
        );
        for (dx, dy) in [(0.5, 0.0), (-0.5, 0.0), (0.0, 0.5), (0.0, -0.5)] {
            let shifted = differ(dx, dy);
            assert!(
                aligned * 5 < shifted * 4,
                "camera {i}: {aligned} differ, {shifted} half a pixel off ({dx}, {dy})"
            );
        }
    }
    // The scaled cameras see the reduced masks where the models are: at the truth only edge
    // pixels are left uncovered (the clean masks' area error is 0 at full resolution), and a
    // millimetre's move costs several times more.
    let mut engine = CpuEnergy::new(Scene::from_capture(&half));
    engine.set_frame(&mh).unwrap();
    for arch in Arch::BOTH {
        let at_truth = engine.evaluate(arch, &[truth]).unwrap().remove(0);
        assert!(at_truth.area_error() < 0.03, "{arch:?}: {at_truth:?}");
        let moved = single_dof_moves(&truth, arch, 1.0);
        for (k, e) in engine.evaluate(arch, &moved).unwrap().iter().enumerate() {
            assert!(
                e.total(DEFAULT_LAMBDA) > at_truth.total(DEFAULT_LAMBDA),
                "{arch:?} move {k}: {} against {} at the truth",
                e.total(DEFAULT_LAMBDA),
                at_truth.total(DEFAULT_LAMBDA)
            );
        }
    }
    // A factor that does not divide the masks' sides is refused, naming the folder and field.
    let err = open(7).unwrap_err().to_string();
    assert!(
        err.contains("cam0") && err.contains("size") && err.contains("1/7"),
        "{err}"
    );
}
