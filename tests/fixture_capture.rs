//! fixtures/tiny-capture was written by fixtures/make_tiny_capture.py, not by jawtrack: STL
//! meshes, BOI face lists, a camera with lens distortion, half-size masks with the spec's
//! default labels, a missing mask, and bootstrap points seen through the distortion.

use std::path::Path;

use jawtrack::arch::Arch;
use jawtrack::capture::masks::decode_mask;
use jawtrack::capture::{ArchInit, Capture, MaskMode};
use jawtrack::energy::raster::render_labels;
use jawtrack::energy::{CpuEnergy, EnergyEngine, Scene};
use jawtrack::geometry::{Camera, Pose, so3_log};
use nalgebra::Vector3;

fn fixture() -> Capture {
    Capture::open(&Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/tiny-capture")).unwrap()
}

#[test]
fn reads_what_another_program_wrote() {
    let c = fixture();
    assert_eq!(c.camera_names(), ["left", "right"]);
    assert_eq!(c.mask_mode(), MaskMode::PerArch { upper: 1, lower: 2 });
    // Its own field (`producer`) is noted, not refused: the spec lets writers add fields.
    assert!(
        c.notes().len() == 1 && c.notes()[0].contains("`producer`"),
        "{:?}",
        c.notes()
    );
    assert_eq!(
        (c.upper().positions.len(), c.upper().triangles.len()),
        (8, 12)
    );
    assert_eq!(
        c.upper().boi,
        (0..12).map(|i| i == 2 || i == 3).collect::<Vec<_>>()
    );
    assert!(
        c.cameras()[0].calibrated.has_distortion() && !c.cameras()[1].calibrated.has_distortion()
    );
    assert_eq!(c.cameras()[0].mask_size, Some((160, 120)));
    // Half-size masks: the mask camera's intrinsics are scaled.
    let mc = c.cameras()[1].mask_camera().unwrap();
    assert_eq!((mc.fx, mc.cx, mc.cy), (150.0, 79.5, 59.5));
    // The missing mask.
    let m1 = c.load_masks(1).unwrap();
    assert!(m1.masks[0].is_some() && m1.masks[1].is_none());
}

#[test]
fn masks_are_used_as_seen_and_models_are_drawn_through_the_lens() {
    let c = fixture();
    let m = c.load_masks(0).unwrap();
    for k in 0..2 {
        let raw = decode_mask(&c.mask_path(k, 0), c.mask_mode(), c.mouth()).unwrap();
        assert!(
            m.masks[k].as_ref() == Some(&raw),
            "camera {k}: mask as written"
        );
    }
    let cam = c.cameras()[0].mask_camera().unwrap();
    assert!(cam.has_distortion(), "the mask camera keeps the lens");
    // The upper box placed near the left camera's top-left corner, where the lens moves its
    // corners by up to 9 pixels: its outline lies where the lens model projects its vertices.
    let pose = Pose::from_translation(Vector3::new(-70.0, 56.0, 0.0));
    let labels = render_labels(&cam, &[(c.upper(), &pose, 1, 1)]);
    let (w, h) = (cam.width as usize, cam.height as usize);
    let lit: Vec<(f64, f64)> = (0..w * h)
        .filter(|&i| labels[i] == 1)
        .map(|i| ((i % w) as f64, (i / w) as f64))
        .collect();
    let bounds = |pts: &mut dyn Iterator<Item = (f64, f64)>| {
        pts.fold(
            [
                f64::INFINITY,
                f64::NEG_INFINITY,
                f64::INFINITY,
                f64::NEG_INFINITY,
            ],
            |b, (u, v)| [b[0].min(u), b[1].max(u), b[2].min(v), b[3].max(v)],
        )
    };
    let drawn = bounds(&mut lit.iter().copied());
    let vertices = |cam: &Camera| {
        bounds(&mut c.upper().positions.iter().map(|p| {
            let x = pose.transform_point(&Vector3::new(p[0] as f64, p[1] as f64, p[2] as f64));
            let px = cam.project(&x).unwrap();
            (px.x, px.y)
        }))
    };
    let through_lens = vertices(&cam);
    let pinhole = vertices(&Camera {
        distortion: jawtrack::geometry::Distortion::NONE,
        ..cam.clone()
    });
    for k in 0..4 {
        assert!(
            (drawn[k] - through_lens[k]).abs() <= 1.0,
            "side {k}: drawn {drawn:?}, lens {through_lens:?}"
        );
    }
    assert!(
        (0..4).any(|k| (pinhole[k] - through_lens[k]).abs() > 4.0),
        "the lens matters here: pinhole {pinhole:?}, lens {through_lens:?}"
    );
}

#[test]
fn bootstrap_through_distortion_recovers_the_poses() {
    let c = fixture();
    assert!(matches!(c.init().unwrap().upper, ArchInit::Points(ref p) if p.len() == 4));
    let poses = c.initial_poses().unwrap();
    // The script placed the boxes at (0, 6, 0) and (0, −6, 2) with no rotation.
    for (arch, t) in [
        (Arch::Upper, Vector3::new(0.0, 6.0, 0.0)),
        (Arch::Lower, Vector3::new(0.0, -6.0, 2.0)),
    ] {
        let p = poses.get(arch);
        assert!(
            (p.translation - t).norm() < 1e-3,
            "{arch:?}: {:?}",
            p.translation
        );
        // so3_log, not nalgebra's `angle()`: its unclamped acos gives NaN for rotations
        // within rounding of the identity.
        let angle = so3_log(&p.rotation).norm();
        assert!(angle < 1e-5, "{arch:?}: {angle} rad");
    }
}

#[test]
fn the_energy_runs_on_it() {
    let c = fixture();
    let poses = c.initial_poses().unwrap();
    let mut e = CpuEnergy::new(Scene::from_capture(&c));
    e.set_frame(&c.load_masks(1).unwrap()).unwrap();
    let en = &e.evaluate(Arch::Upper, &[poses]).unwrap()[0];
    assert!(en.cameras[0].mask_pixels() > 500);
    assert_eq!(en.cameras[1], Default::default(), "no mask, no counts");
    let all: u64 = en.cameras[0].bins.iter().sum();
    assert_eq!(all, 160 * 120);
}
