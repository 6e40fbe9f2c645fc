//! Findings of `benches/probes.py` (hostile input through the release binary) at 7a98bd6, the
//! commit before these fixes: each test fails there and passes after. The findings of the first
//! probe run (bf99878) have their tests beside the errors they concern (capture_errors.rs,
//! settings.rs, track/output.rs).

mod common;

use std::path::Path;

use common::{assert_mentions, edit_json, error_of, fresh_capture};
use jawtrack::capture::{Capture, OpenOptions};

/// Move `rel` out of the capture and leave a link to it in its place.
#[cfg(unix)]
fn link_out(dir: &Path, rel: &str) {
    let outside = dir.parent().unwrap().join("elsewhere");
    std::fs::rename(dir.join(rel), &outside).unwrap();
    std::os::unix::fs::symlink(&outside, dir.join(rel)).unwrap();
}

/// init.json, a camera's mask folder and a single mask file could each be a link out of the
/// capture folder (only the paths capture.json names were checked).
#[cfg(unix)]
#[test]
fn links_out_of_the_capture_in_place_of_init_json_a_mask_folder_or_a_mask_are_refused() {
    let cases = [
        ("init.json", "init.json"),
        ("masks/cam0", "masks.dir (cam0/)"),
        ("masks/cam1/000000.png", "000000.png"),
    ];
    for (rel, named) in cases {
        let (_t, dir) = fresh_capture();
        link_out(&dir, rel);
        assert_mentions(
            &error_of(&dir),
            &[named, "outside the capture", "--allow-outside"],
        );
        let allowed = OpenOptions {
            allow_outside: true,
            ..Default::default()
        };
        assert!(Capture::open_with(&dir, allowed).is_ok(), "{rel}");
    }
}

/// A bootstrap pixel of 1e6 or 1e308 triangulated to a NaN pose, reported only when the first
/// frame was written, as a fault of tracks.json.
#[test]
fn bootstrap_pixels_outside_the_image_are_refused_in_init_json() {
    for px in ["1e6", "1e308", "-3"] {
        let (_t, dir) = fresh_capture();
        let text = format!(
            r#"{{"upper": {{"points": [{{"vertex": 1, "pixels": {{"cam0": [{px}, 20], "cam1": [30, 40]}}}},
                                     {{"vertex": 2, "pixels": {{"cam0": [10, 20], "cam1": [30, 40]}}}},
                                     {{"vertex": 3, "pixels": {{"cam0": [10, 20], "cam1": [30, 40]}}}}]}},
                "lower": {{"rotation": [[1,0,0],[0,1,0],[0,0,1]], "translation": [0,0,0]}}}}"#
        );
        std::fs::write(dir.join("init.json"), text).unwrap();
        let msg = error_of(&dir);
        assert_mentions(
            &msg,
            &[
                "init.json",
                "`upper.points[0].pixels.cam0`",
                "outside the camera's",
            ],
        );
        assert!(msg.len() < 400, "{msg}");
    }
}

/// A palette PNG was reported as "found Rgb8"; a mask cut short passed `validate --quick`
/// (which reads headers only).
#[test]
fn a_palette_mask_is_named_so_and_a_truncated_one_is_refused_from_its_header() {
    let (_t, dir) = fresh_capture();
    let mask = dir.join("masks/cam0/000000.png");
    let grey = image::open(&mask).unwrap().to_luma8();
    let mut palette = Vec::new();
    let mut encoder = png::Encoder::new(&mut palette, grey.width(), grey.height());
    encoder.set_color(png::ColorType::Indexed);
    encoder.set_palette((0..=255u8).flat_map(|v| [v, v, v]).collect::<Vec<u8>>());
    encoder
        .write_header()
        .unwrap()
        .write_image_data(grey.as_raw())
        .unwrap();
    std::fs::write(&mask, &palette).unwrap();
    assert_mentions(
        &error_of(&dir),
        &["000000.png", "a palette (indexed-colour) PNG"],
    );

    let (_t, dir) = fresh_capture();
    let mask = dir.join("masks/cam1/000001.png");
    let bytes = std::fs::read(&mask).unwrap();
    std::fs::write(&mask, &bytes[..bytes.len() * 2 / 3]).unwrap();
    assert_mentions(&error_of(&dir), &["000001.png", "truncated", "IEND"]);
}

fn jawtrack(args: &[&str]) -> (Option<i32>, String) {
    let out = common::jawtrack(args);
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stderr).into(),
    )
}

/// `energy --lambda NaN` printed NaN energies and `--max-triangles 0` was taken; such flags are
/// refused by their parsers (exit 2, naming the flag).
#[test]
fn flags_out_of_their_range_are_refused_where_they_enter() {
    let (_t, dir) = fresh_capture();
    let c = dir.to_str().unwrap();
    let cases: [(&[&str], &str); 5] = [
        (
            &["energy", c, "--frame", "0", "--lambda", "NaN"],
            "--lambda",
        ),
        (&["energy", c, "--frame", "0", "--lambda=-1"], "--lambda"),
        (&["validate", c, "--max-triangles", "0"], "--max-triangles"),
        (
            &["mesh", "boi", "in.obj", "out.obj", "--band-mm", "inf"],
            "--band-mm",
        ),
        (&["rig", "pose", "rig.json", "NaN", "0", "0"], "D1"),
    ];
    for (args, flag) in cases {
        let (code, err) = jawtrack(args);
        assert_eq!(code, Some(2), "{args:?}: {err}");
        assert!(err.contains(flag), "{args:?}: {err}");
    }
}

/// A settings value of 1e308 was echoed as 309 digits.
#[test]
fn huge_numbers_in_messages_are_shown_with_an_exponent() {
    let (_t, dir) = fresh_capture();
    edit_json(&dir.join("cameras/cam0.json"), |v| v["fx"] = 1e300.into());
    assert_mentions(&error_of(&dir), &["`fx`", "1e300 px"]);
    let mut settings = jawtrack::track::TrackSettings::default();
    settings.search.scales = vec![1e308];
    let msg = settings.validate().unwrap_err().to_string();
    assert_mentions(&msg, &["search.scales[0]", "found 1e308"]);
}
