//! fixtures/tiny-capture was written by fixtures/make_tiny_capture.py, not by jawtrack: STL
//! meshes, BOI face lists, a camera with lens distortion, half-size masks with the spec's
//! default labels, a missing mask, and bootstrap points seen through the distortion.

use std::path::Path;

use jawtrack::capture::masks::decode_mask;
use jawtrack::capture::{Arch, ArchInit, Capture, MaskMode};
use jawtrack::energy::{CpuEnergy, EnergyEngine, Scene};
use nalgebra::Vector3;

fn fixture() -> Capture {
    Capture::open(&Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/tiny-capture")).unwrap()
}

#[test]
fn reads_what_another_program_wrote() {
    let c = fixture();
    assert_eq!(c.camera_names(), ["left", "right"]);
    assert_eq!(c.mask_mode, MaskMode::PerArch { upper: 1, lower: 2 });
    assert_eq!((c.upper.positions.len(), c.upper.triangles.len()), (8, 12));
    assert_eq!(
        c.upper.boi,
        (0..12).map(|i| i == 2 || i == 3).collect::<Vec<_>>()
    );
    assert!(c.cameras[0].calibrated.has_distortion() && !c.cameras[1].calibrated.has_distortion());
    assert_eq!(c.cameras[0].mask_size, Some((160, 120)));
    // Half-size masks: the mask camera's intrinsics are scaled.
    let mc = c.cameras[1].mask_camera().unwrap();
    assert_eq!((mc.fx, mc.cx, mc.cy), (150.0, 79.5, 59.5));
    // The missing mask.
    let m1 = c.load_masks(1).unwrap();
    assert!(m1.masks[0].is_some() && m1.masks[1].is_none());
}

#[test]
fn masks_of_a_distorted_camera_are_undistorted_once_at_load() {
    let c = fixture();
    let m = c.load_masks(0).unwrap();
    let raw_left = decode_mask(&c.mask_path(0, 0), c.mask_mode).unwrap();
    let raw_right = decode_mask(&c.mask_path(1, 0), c.mask_mode).unwrap();
    assert!(
        m.masks[1].as_ref().unwrap() == &raw_right,
        "no distortion: unchanged"
    );
    let left = m.masks[0].as_ref().unwrap();
    let changed = left
        .data
        .iter()
        .zip(&raw_left.data)
        .filter(|(a, b)| a != b)
        .count();
    assert!(
        changed > 100,
        "distortion removed: {changed} pixels changed"
    );
    // Barrel distortion (k1 < 0) pulls the image in; undistorting spreads it out again: each
    // label covers more pixels, and labels stay labels.
    for bit in [1u8, 2] {
        let (a, b) = (raw_left.count(bit) as f64, left.count(bit) as f64);
        assert!(b > a * 1.01 && b < a * 1.3, "label {bit}: {a} -> {b}");
    }
    // The undistorted corner of the upper-arch rectangle lies where the camera model says.
    let cam = c.cameras[0].calibrated.scaled_to(160, 120);
    let corner = cam.pixel_to_normalised(nalgebra::Vector2::new(12.0, 30.0));
    let (u, v) = (corner.x * cam.fx + cam.cx, corner.y * cam.fy + cam.cy);
    assert!(
        u < 11.0 && v < 29.0,
        "barrel undistortion moves the corner outwards: ({u}, {v})"
    );
    let near =
        |du: f64, dv: f64| left.data[((v + dv).round() as usize) * 160 + (u + du).round() as usize];
    assert_eq!(near(1.5, 1.5), 1, "inside the corner");
    assert_eq!(near(-1.5, -1.5), 0, "outside the corner");
    assert!(left.data.iter().all(|&v| v <= 2));
}

#[test]
fn bootstrap_through_distortion_recovers_the_poses() {
    let c = fixture();
    assert!(matches!(c.init.as_ref().unwrap().upper, ArchInit::Points(ref p) if p.len() == 4));
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
        assert!(p.rotation.angle() < 1e-5);
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
