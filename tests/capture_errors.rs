//! Bad input gets an error that names the file, the field and what is wrong; never a panic.

mod common;

use std::path::Path;

use common::{assert_mentions, edit_json, error_of, fresh_capture};
use jawtrack::capture::Capture;

#[test]
fn the_template_opens() {
    let (_t, dir) = fresh_capture();
    let c = Capture::open(&dir).unwrap();
    assert_eq!(c.cameras().len(), 3);
    assert_eq!(c.frame_count(), 6);
}

#[test]
fn missing_capture_json() {
    let (_t, dir) = fresh_capture();
    std::fs::remove_file(dir.join("capture.json")).unwrap();
    assert_mentions(&error_of(&dir), &["capture.json", "not found"]);
}

#[test]
fn malformed_json_names_the_place() {
    let (_t, dir) = fresh_capture();
    std::fs::write(
        dir.join("capture.json"),
        "{\"format\": \"jawtrack-capture/1\", \"cameras\": [\"cam0\",",
    )
    .unwrap();
    assert_mentions(
        &error_of(&dir),
        &["capture.json", "malformed JSON", "cameras"],
    );
}

#[test]
fn wrong_format() {
    let (_t, dir) = fresh_capture();
    edit_json(&dir.join("capture.json"), |v| {
        v["format"] = "jawtrack-capture/2".into()
    });
    assert_mentions(
        &error_of(&dir),
        &["capture.json", "`format`", "jawtrack-capture/2"],
    );
}

#[test]
fn missing_camera_file() {
    let (_t, dir) = fresh_capture();
    std::fs::remove_file(dir.join("cameras/cam1.json")).unwrap();
    assert_mentions(&error_of(&dir), &["cam1.json", "not found"]);
}

#[test]
fn camera_named_without_a_file() {
    let (_t, dir) = fresh_capture();
    edit_json(&dir.join("capture.json"), |v| {
        v["cameras"].as_array_mut().unwrap().push("cam9".into())
    });
    assert_mentions(
        &error_of(&dir),
        &["cameras/cam9.json", "camera file for `cam9`", "not found"],
    );
}

#[test]
fn missing_mesh() {
    let (_t, dir) = fresh_capture();
    std::fs::remove_file(dir.join("meshes/lower.obj")).unwrap();
    assert_mentions(&error_of(&dir), &["meshes/lower.obj", "not found"]);
}

#[test]
fn rotation_that_is_not_a_rotation() {
    let (_t, dir) = fresh_capture();
    edit_json(&dir.join("cameras/cam0.json"), |v| {
        v["rotation"][0][0] = 1.5.into()
    });
    assert_mentions(
        &error_of(&dir),
        &["cam0.json", "`rotation`", "not a rotation"],
    );
    let (_t, dir) = fresh_capture();
    // A reflection is orthogonal but not a rotation.
    edit_json(&dir.join("cameras/cam2.json"), |v| {
        for k in 0..3 {
            let x = -v["rotation"][2][k].as_f64().unwrap();
            v["rotation"][2][k] = x.into();
        }
    });
    assert_mentions(
        &error_of(&dir),
        &["cam2.json", "`rotation`", "not a rotation"],
    );
}

#[test]
fn non_finite_numbers() {
    // JSON has no NaN or infinity: they are refused by the parser, with the field named.
    let (_t, dir) = fresh_capture();
    let path = dir.join("cameras/cam0.json");
    let text = std::fs::read_to_string(&path)
        .unwrap()
        .replace("\"fx\": 1030.0", "\"fx\": 1e999");
    std::fs::write(&path, text).unwrap();
    assert_mentions(&error_of(&dir), &["cam0.json", "`fx`", "out of range"]);
    let (_t, dir) = fresh_capture();
    let path = dir.join("init.json");
    let text = std::fs::read_to_string(&path).unwrap();
    let text = text.replacen("\"translation\": [", "\"translation\": [NaN, ", 1);
    std::fs::write(&path, text).unwrap();
    assert_mentions(&error_of(&dir), &["init.json", "malformed JSON", "upper"]);
}

#[test]
fn focal_length_must_be_positive() {
    for value in [0.0, -1030.0] {
        let (_t, dir) = fresh_capture();
        edit_json(&dir.join("cameras/cam1.json"), |v| v["fy"] = value.into());
        assert_mentions(&error_of(&dir), &["cam1.json", "`fy`", "must be positive"]);
    }
}

#[test]
fn masks_of_one_camera_with_different_sizes() {
    let (_t, dir) = fresh_capture();
    let small = image::GrayImage::new(480, 270);
    small.save(dir.join("masks/cam2/000004.png")).unwrap();
    assert_mentions(
        &error_of(&dir),
        &["masks/cam2/000004.png", "`size`", "480x270", "960x540"],
    );
}

#[test]
fn mask_that_cannot_be_decoded() {
    // Garbage: the header read at open fails.
    let (_t, dir) = fresh_capture();
    std::fs::write(dir.join("masks/cam0/000003.png"), b"not a png at all").unwrap();
    assert_mentions(&error_of(&dir), &["masks/cam0/000003.png", "cannot decode"]);
    // A good header and end with the data between broken: opening works (a file cut short is
    // refused there: hostile_input.rs), reading that frame fails.
    let (_t, dir) = fresh_capture();
    let path = dir.join("masks/cam1/000002.png");
    let mut bytes = std::fs::read(&path).unwrap();
    let middle = bytes.len() / 2;
    bytes[middle..middle + 64].fill(0x5a);
    std::fs::write(&path, &bytes).unwrap();
    let c = Capture::open(&dir).unwrap();
    let msg = c.load_masks(2).unwrap_err().to_string();
    assert_mentions(&msg, &["masks/cam1/000002.png", "cannot decode"]);
    assert!(c.load_masks(1).is_ok());
}

#[test]
fn per_arch_masks_must_be_single_channel_which_opening_checks_from_the_header() {
    // `validate --quick` opens without decoding: the header's pixel format is checked there,
    // so a capture that `validate --quick` passes has masks `track` can read.
    for (name, image) in [
        (
            "rgb",
            image::DynamicImage::ImageRgb8(image::RgbImage::new(960, 540)),
        ),
        (
            "16-bit",
            image::DynamicImage::ImageLuma16(image::ImageBuffer::new(960, 540)),
        ),
    ] {
        let (_t, dir) = fresh_capture();
        image.save(dir.join("masks/cam0/000001.png")).unwrap();
        assert_mentions(
            &error_of(&dir),
            &["000001.png", "`pixel format`", "single-channel"],
        );
        let quick = std::process::Command::new(env!("CARGO_BIN_EXE_jawtrack"))
            .args(["validate", "--quick"])
            .arg(&dir)
            .output()
            .unwrap();
        assert!(!quick.status.success(), "{name}: validate --quick passed");
    }
}

fn write_mesh(dir: &Path, text: &str) {
    std::fs::write(dir.join("meshes/upper.obj"), text).unwrap();
}

#[test]
fn mesh_with_no_faces() {
    let (_t, dir) = fresh_capture();
    write_mesh(&dir, "v 0 0 0\nv 1 0 0\nv 0 1 0\ng boi\n");
    assert_mentions(&error_of(&dir), &["upper.obj", "no faces"]);
}

#[test]
fn mesh_with_nan_vertices() {
    let (_t, dir) = fresh_capture();
    write_mesh(&dir, "v 0 0 0\nv nan 0 0\nv 0 1 0\ng boi\nf 1 2 3\n");
    assert_mentions(
        &error_of(&dir),
        &["upper.obj", "`vertex 2 (counting from 1)`", "non-finite"],
    );
}

#[test]
fn mesh_with_face_index_out_of_range() {
    let (_t, dir) = fresh_capture();
    write_mesh(&dir, "v 0 0 0\nv 1 0 0\nv 0 1 0\ng boi\nf 1 2 3\nf 1 2 9\n");
    assert_mentions(
        &error_of(&dir),
        &[
            "upper.obj",
            "`face 2 (counting from 1)`",
            "vertex 9 (counting from 1)",
            "3 vertices",
        ],
    );
}

#[test]
fn boundary_of_interest_missing_or_empty() {
    let (_t, dir) = fresh_capture();
    write_mesh(&dir, "v 0 0 0\nv 1 0 0\nv 0 1 0\ng teeth\nf 1 2 3\n");
    assert_mentions(
        &error_of(&dir),
        &[
            "upper.obj",
            "`boi.group`",
            "no group, object or material named `boi`",
        ],
    );
    let (_t, dir) = fresh_capture();
    write_mesh(&dir, "v 0 0 0\nv 1 0 0\nv 0 1 0\ng boi\ng teeth\nf 1 2 3\n");
    assert_mentions(
        &error_of(&dir),
        &["upper.obj", "`boi.group`", "has no faces"],
    );
}

#[test]
fn boundary_of_interest_as_face_lists() {
    let (_t, dir) = fresh_capture();
    std::fs::write(dir.join("meshes/upper.boi.json"), "[0, 1, 2]").unwrap();
    std::fs::write(dir.join("meshes/lower.boi.json"), "[5, 100000000]").unwrap();
    edit_json(
        &dir.join("capture.json"),
        |v| {
            v["boi"] = serde_json::json!({"upper": "meshes/upper.boi.json", "lower": "meshes/lower.boi.json"})
        },
    );
    assert_mentions(
        &error_of(&dir),
        &["lower.boi.json", "`[1]`", "out of range"],
    );
    std::fs::write(dir.join("meshes/lower.boi.json"), "[5, 6]").unwrap();
    let c = Capture::open(&dir).unwrap();
    assert_eq!(c.upper().boi_face_count(), 3);
    assert_eq!(c.lower().boi_face_count(), 2);
}

#[test]
fn frame_range_beyond_the_masks() {
    let (_t, dir) = fresh_capture();
    edit_json(&dir.join("capture.json"), |v| {
        v["frames"]["count"] = 7.into()
    });
    assert_mentions(
        &error_of(&dir),
        &["capture.json", "`frames`", "0..=6", "frame 5"],
    );
}

#[test]
fn a_missing_mask_is_allowed() {
    let (_t, dir) = fresh_capture();
    std::fs::remove_file(dir.join("masks/cam1/000002.png")).unwrap();
    let c = Capture::open(&dir).unwrap();
    let m = c.load_masks(2).unwrap();
    assert!(m.masks[0].is_some() && m.masks[1].is_none() && m.masks[2].is_some());
}

#[test]
fn bad_mask_labels() {
    let (_t, dir) = fresh_capture();
    edit_json(&dir.join("capture.json"), |v| {
        v["masks"]["lower"] = 85.into()
    });
    assert_mentions(
        &error_of(&dir),
        &["capture.json", "`masks.lower`", "both 85"],
    );
    let (_t, dir) = fresh_capture();
    edit_json(&dir.join("capture.json"), |v| {
        v["masks"]["mode"] = "rgb".into()
    });
    assert_mentions(&error_of(&dir), &["`masks.mode`", "\"rgb\""]);
}

/// Found by hostile input: an init.json translation of 1e308 (finite, so it passed) hung
/// tracking in `Pose::compose` (bf99878).
#[test]
fn a_pose_translation_beyond_a_kilometre_is_refused() {
    for value in [1e308, -2e6] {
        let (_t, dir) = fresh_capture();
        edit_json(&dir.join("init.json"), |v| {
            v["upper"]["translation"][0] = value.into()
        });
        let e = error_of(&dir);
        assert!(
            e.contains("init.json") && e.contains("translation") && e.contains("1 km"),
            "{value}: {e}"
        );
    }
}

#[test]
fn bootstrap_points_are_checked() {
    let (_t, dir) = fresh_capture();
    std::fs::write(
        dir.join("init.json"),
        r#"{"upper": {"points": [{"vertex": 1, "pixels": {"cam0": [1, 2], "camX": [3, 4]}},
                                 {"vertex": 2, "pixels": {"cam0": [1, 2], "cam1": [3, 4]}},
                                 {"vertex": 3, "pixels": {"cam0": [1, 2], "cam1": [3, 4]}}]},
            "lower": {"points": []}}"#,
    )
    .unwrap();
    assert_mentions(
        &error_of(&dir),
        &[
            "init.json",
            "`upper.points[0].pixels.camX`",
            "no camera named",
        ],
    );
}

#[test]
fn the_cli_reports_errors_and_exits_non_zero() {
    let (_t, dir) = fresh_capture();
    let exe = env!("CARGO_BIN_EXE_jawtrack");
    let ok = std::process::Command::new(exe)
        .arg("validate")
        .arg(&dir)
        .output()
        .unwrap();
    assert!(ok.status.success());
    let out = String::from_utf8_lossy(&ok.stdout);
    assert!(
        out.contains("valid") && out.contains("cam2") && out.contains("ground truth: 6 frames"),
        "{out}"
    );
    edit_json(&dir.join("cameras/cam0.json"), |v| v["fx"] = (-5.0).into());
    let bad = std::process::Command::new(exe)
        .arg("validate")
        .arg(&dir)
        .output()
        .unwrap();
    assert!(!bad.status.success());
    let err = String::from_utf8_lossy(&bad.stderr);
    assert!(
        err.contains("cam0.json") && err.contains("`fx`") && !err.contains("panicked"),
        "{err}"
    );
}

/// Found by hostile input: `track -o /dev/full --force` replaced the device node with an
/// ordinary file (bf99878). A pipe stands in for the device here; it must stay a pipe.
#[cfg(unix)]
#[test]
fn track_refuses_to_replace_an_output_that_is_not_a_regular_file() {
    use std::os::unix::fs::FileTypeExt;
    let (t, dir) = fresh_capture();
    let pipe = t.path().join("tracks.json");
    let made = std::process::Command::new("mkfifo")
        .arg(&pipe)
        .status()
        .unwrap();
    assert!(made.success());
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_jawtrack"))
        .args(["track", "--force", "--frames", "0..1", "-o"])
        .arg(&pipe)
        .arg(&dir)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(
        err.contains("tracks.json") && err.contains("not a regular file"),
        "{err}"
    );
    assert!(
        std::fs::symlink_metadata(&pipe)
            .unwrap()
            .file_type()
            .is_fifo()
    );
    // And the library's atomic writer refuses it too.
    let e = jawtrack::io::write_atomic(&pipe, b"{}")
        .unwrap_err()
        .to_string();
    assert!(e.contains("not a regular file"), "{e}");
}

fn mkfifo(path: &Path) {
    let _ = std::fs::remove_file(path);
    assert!(
        std::process::Command::new("mkfifo")
            .arg(path)
            .status()
            .unwrap()
            .success()
    );
}

/// Found by hostile input: a FIFO in place of capture.json, a camera, a mask or a mesh blocked
/// for ever (bf99878). Each is now refused as not a regular file, without reading it.
#[cfg(unix)]
#[test]
fn a_pipe_in_place_of_any_input_is_refused_not_read() {
    for file in [
        "capture.json",
        "cameras/cam1.json",
        "meshes/upper.obj",
        "init.json",
    ] {
        let (_t, dir) = fresh_capture();
        mkfifo(&dir.join(file));
        assert_mentions(&error_of(&dir), &[file, "not a regular file"]);
    }
    let (_t, dir) = fresh_capture();
    mkfifo(&dir.join("masks/cam0/000001.png"));
    assert_mentions(&error_of(&dir), &["000001.png", "not a regular file"]);
}

/// Found by hostile input: STL and PLY files claiming more triangles or vertices than they
/// hold aborted allocating gigabytes inside their readers (bf99878, from /dev/zero).
#[test]
fn mesh_headers_that_claim_more_than_the_file_holds_are_refused() {
    let (_t, dir) = fresh_capture();
    let mut stl = vec![0u8; 84];
    stl[80..84].copy_from_slice(&u32::MAX.to_le_bytes());
    std::fs::write(dir.join("meshes/upper.stl"), &stl).unwrap();
    edit_json(&dir.join("capture.json"), |v| {
        v["meshes"]["upper"] = "meshes/upper.stl".into();
        v["boi"] =
            serde_json::json!({"upper": "meshes/upper.boi.json", "lower": "meshes/lower.boi.json"});
    });
    assert_mentions(
        &error_of(&dir),
        &["upper.stl", "`triangle count`", "4294967295"],
    );

    let (_t, dir) = fresh_capture();
    let ply = "ply\nformat binary_little_endian 1.0\nelement vertex 4000000000\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n";
    std::fs::write(dir.join("meshes/upper.ply"), ply).unwrap();
    edit_json(&dir.join("capture.json"), |v| {
        v["meshes"]["upper"] = "meshes/upper.ply".into();
        v["boi"] =
            serde_json::json!({"upper": "meshes/upper.boi.json", "lower": "meshes/lower.boi.json"});
    });
    assert_mentions(
        &error_of(&dir),
        &["upper.ply", "`element counts`", "4000000001"],
    );
}

/// Found by hostile input (bf99878): capture.json could name files anywhere (`/etc/passwd`
/// was opened as a face list). Each path must stay in the capture folder unless the user
/// says otherwise.
#[test]
fn paths_in_capture_json_may_not_leave_the_capture() {
    let outside_file = |dir: &Path| {
        let p = dir.parent().unwrap().join("elsewhere.obj");
        std::fs::copy(dir.join("meshes/upper.obj"), &p).unwrap();
        p
    };
    type Edit = fn(&mut serde_json::Value, &str);
    let cases: [(&str, Edit, &str); 6] = [
        (
            "meshes.upper",
            |v, abs| v["meshes"]["upper"] = abs.into(),
            "absolute",
        ),
        (
            "meshes.lower",
            |v, _| v["meshes"]["lower"] = "meshes/../../elsewhere.obj".into(),
            "climbs out",
        ),
        (
            "masks.dir",
            |v, _| v["masks"]["dir"] = "..".into(),
            "climbs out",
        ),
        (
            "masks.dir",
            |v, _| v["masks"]["dir"] = "/".into(),
            "absolute",
        ),
        (
            "boi.upper",
            |v, _| v["boi"] = serde_json::json!({"upper": "/etc/passwd", "lower": "x.json"}),
            "absolute",
        ),
        (
            "meshes.mandible",
            |v, _| v["meshes"]["mandible"] = "../elsewhere.obj".into(),
            "climbs out",
        ),
    ];
    for (field, edit, why) in cases {
        let (_t, dir) = fresh_capture();
        let abs = outside_file(&dir);
        edit_json(&dir.join("capture.json"), |v| {
            edit(v, abs.to_str().unwrap())
        });
        assert_mentions(
            &error_of(&dir),
            &[
                "capture.json",
                &format!("`{field}`"),
                why,
                "--allow-outside",
            ],
        );
    }
    // A link out of the folder is followed and refused too.
    #[cfg(unix)]
    {
        let (_t, dir) = fresh_capture();
        let abs = outside_file(&dir);
        std::fs::remove_file(dir.join("meshes/upper.obj")).unwrap();
        std::os::unix::fs::symlink(&abs, dir.join("meshes/upper.obj")).unwrap();
        assert_mentions(&error_of(&dir), &["`meshes.upper`", "through a link"]);
        // ... unless the user allows it.
        let options = jawtrack::capture::OpenOptions {
            allow_outside: true,
            ..Default::default()
        };
        assert!(Capture::open_with(&dir, options).is_ok());
    }
}

/// Found by hostile input (bf99878): `--simplify-mm NaN` tripped a C assertion (abort).
#[test]
fn a_simplification_distance_that_is_not_a_distance_is_refused() {
    let (_t, dir) = fresh_capture();
    for bad in ["NaN", "-1", "inf"] {
        let out = std::process::Command::new(env!("CARGO_BIN_EXE_jawtrack"))
            .args(["validate", "--quick", &format!("--simplify-mm={bad}")])
            .arg(&dir)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{bad}: {err}");
        assert!(
            err.contains("--simplify-mm") && err.contains("from 0 to 100 mm"),
            "{bad}: {err}"
        );
    }
}

/// `frames.offsets` (the spec's, optional): a camera started late has its files numbered
/// ahead; frame f of that camera is file f + offset, for masks as for every reader.
#[test]
fn frame_offsets_shift_a_cameras_files() {
    let (_t, dir) = fresh_capture();
    let original = Capture::open(&dir).unwrap();
    let before: Vec<_> = original
        .frames()
        .map(|f| original.load_masks(f).unwrap())
        .collect();
    let cam1 = dir.join("masks/cam1");
    let mut files: Vec<_> = std::fs::read_dir(&cam1)
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    files.sort();
    for path in files.iter().rev() {
        let n: u32 = path.file_stem().unwrap().to_str().unwrap().parse().unwrap();
        std::fs::rename(path, cam1.join(format!("{:06}.png", n + 3))).unwrap();
    }
    edit_json(&dir.join("capture.json"), |v| {
        v["frames"]["offsets"] = serde_json::json!({"cam1": 3})
    });
    let shifted = Capture::open(&dir).unwrap();
    assert_eq!(
        shifted.cameras()[1].frames_present,
        original.cameras()[1].frames_present
    );
    for (f, masks) in shifted.frames().zip(&before) {
        assert_eq!(
            shifted.load_masks(f).unwrap().masks,
            masks.masks,
            "frame {f}"
        );
    }
    // An offset for a camera the capture does not have is named.
    edit_json(&dir.join("capture.json"), |v| {
        v["frames"]["offsets"] = serde_json::json!({"cam9": 1})
    });
    assert_mentions(&error_of(&dir), &["`frames.offsets.cam9`", "no camera"]);
}

/// Found by hostile input (bf99878): unknown fields in capture.json were silently accepted
/// (`frames.step`), so a misspelt optional field did nothing. Other programs may add fields of
/// their own (the spec lets them), so an unknown field is named in a warning, not refused.
#[test]
fn an_unknown_field_in_capture_json_is_named() {
    let (_t, dir) = fresh_capture();
    edit_json(&dir.join("capture.json"), |v| {
        v["frames"]["step"] = 2.into()
    });
    let c = Capture::open(&dir).unwrap();
    assert_eq!(c.notes().len(), 1);
    assert_mentions(
        &c.notes()[0],
        &["capture.json", "`frames.step`", "not a field"],
    );
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_jawtrack"))
        .args(["validate", "--quick"])
        .arg(&dir)
        .output()
        .unwrap();
    assert!(out.status.success());
    assert_mentions(
        &String::from_utf8_lossy(&out.stderr),
        &["warning:", "`frames.step`"],
    );
}

/// `masks.mouth` (the spec's, optional) is read and checked: not an arch's label, and below
/// 128 with combined masks.
#[test]
fn the_mouth_label_is_checked() {
    let (_t, dir) = fresh_capture();
    let labels = Capture::open(&dir).unwrap().mask_mode();
    let jawtrack::capture::MaskMode::PerArch { upper, .. } = labels else {
        panic!("a per-arch capture");
    };
    edit_json(&dir.join("capture.json"), |v| {
        v["masks"]["mouth"] = 3.into()
    });
    assert_eq!(Capture::open(&dir).unwrap().mouth(), Some(3));
    edit_json(&dir.join("capture.json"), |v| {
        v["masks"]["mouth"] = upper.into()
    });
    assert_mentions(&error_of(&dir), &["`masks.mouth`", "an arch's label"]);
    edit_json(&dir.join("capture.json"), |v| {
        v["masks"]["mode"] = "combined".into();
        v["masks"]["mouth"] = 200.into();
    });
    assert_mentions(&error_of(&dir), &["`masks.mouth`", "below 128"]);
}

/// Found by hostile input (bf99878): each of these was accepted without a word.
#[test]
fn silently_accepted_inputs_are_named() {
    // Grey + alpha per-arch masks: the spec's per-arch masks are single-channel.
    let (_t, dir) = fresh_capture();
    image::DynamicImage::ImageLumaA8(image::ImageBuffer::new(960, 540))
        .save(dir.join("masks/cam0/000001.png"))
        .unwrap();
    assert_mentions(&error_of(&dir), &["000001.png", "single-channel"]);
    // A focal length of 1e308 and a 1x1 image.
    let (_t, dir) = fresh_capture();
    edit_json(&dir.join("cameras/cam0.json"), |v| v["fx"] = 1e308.into());
    assert_mentions(&error_of(&dir), &["cam0.json", "`fx`", "beyond"]);
    let (_t, dir) = fresh_capture();
    edit_json(&dir.join("cameras/cam0.json"), |v| {
        v["width"] = 1.into();
        v["height"] = 1.into();
    });
    assert_mentions(
        &error_of(&dir),
        &["cam0.json", "`width/height`", "8 to 65536"],
    );
    // Ground truth of another format, and a frame given twice.
    let (_t, dir) = fresh_capture();
    edit_json(&dir.join("gt/poses.json"), |v| v["format"] = "x".into());
    assert_mentions(&error_of(&dir), &["poses.json", "`format`", "\"x\""]);
    let (_t, dir) = fresh_capture();
    edit_json(&dir.join("gt/poses.json"), |v| {
        let first = v["frames"][0].clone();
        v["frames"].as_array_mut().unwrap().push(first);
    });
    assert_mentions(&error_of(&dir), &["poses.json", ".frame`", "given twice"]);
}

/// Found by hostile input (bf99878): a 0-byte OBJ was reported as "no group named `boi`".
#[test]
fn an_empty_mesh_file_says_it_has_no_faces() {
    let (_t, dir) = fresh_capture();
    std::fs::write(dir.join("meshes/upper.obj"), "").unwrap();
    assert_mentions(
        &error_of(&dir),
        &["upper.obj", "`faces`", "no faces (0 vertices)"],
    );
}

/// Found by hostile input (bf99878): `synth --frames 1000000000` grew to 4.6 GB and aborted.
#[test]
fn synth_refuses_a_frame_count_beyond_its_bound() {
    let t = tempfile::tempdir().unwrap();
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_jawtrack"))
        .args(["synth", "--frames", "1000000000"])
        .arg(t.path().join("c"))
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert_mentions(&err, &["--frames", "1..=100000"]);
}

/// Found by hostile input (bf99878): a `.ply` pointed at another file printed its first line
/// whole. Errors quote at most a short, printable token of a foreign file.
#[test]
fn a_foreign_file_is_not_echoed_in_errors() {
    let (_t, dir) = fresh_capture();
    let secret = "root:x:0:0:root:/root:/bin/bash-with-a-long-tail-of-private-text-".repeat(4);
    std::fs::write(
        dir.join("meshes/upper.ply"),
        format!("{secret}\n{secret}\n"),
    )
    .unwrap();
    edit_json(&dir.join("capture.json"), |v| {
        v["meshes"]["upper"] = "meshes/upper.ply".into();
        v["boi"] =
            serde_json::json!({"upper": "meshes/upper.boi.json", "lower": "meshes/lower.boi.json"});
    });
    let e = error_of(&dir);
    assert_mentions(&e, &["upper.ply", "not a readable PLY file"]);
    assert!(!e.contains(&secret[..80]), "{e}");
}
