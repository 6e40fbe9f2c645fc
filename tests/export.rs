//! Motion out: `jawtrack export` on a synthetic capture's ground truth writes CSV in
//! anatomical units and glTF that the Khronos glTF validator accepts with no errors and no
//! warnings.
//!
//! The validator runs under Node from the npm package `gltf-validator`, found in the folder
//! JAWTRACK_GLTF_VALIDATOR names (its node_modules/); without it that part is skipped with a
//! message, unless JAWTRACK_REQUIRE_GLTF_VALIDATOR=1 (set by CI, which installs it).

mod common;

use std::path::Path;
use std::process::Command;

use common::validate_gltf as validate;
use jawtrack::synth::{MaskKind, Preset};

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

#[test]
fn tracked_motion_exports_as_csv_and_valid_gltf() {
    let cap = common::template(Preset::Clean, MaskKind::PerArch);
    let t = tempfile::tempdir().unwrap();
    let (gltf, csv) = (t.path().join("jaw.gltf"), t.path().join("jaw.csv"));
    let out = Command::new(env!("CARGO_BIN_EXE_jawtrack"))
        .args([
            "export",
            s(cap),
            s(&cap.join("gt/poses.json")),
            "--gltf",
            s(&gltf),
            "--csv",
            s(&csv),
            "--fps",
            "30",
        ])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );

    // CSV: a row a frame; zero at the rest bite; the incisal point's travel, split along the
    // jaw frame's axes, adds back up to its displacement.
    let text = std::fs::read_to_string(&csv).unwrap();
    let rows: Vec<Vec<f64>> = text
        .lines()
        .skip(1)
        .map(|l| {
            l.split(',')
                .enumerate()
                .filter(|(i, _)| *i != 2)
                .map(|(_, v)| v.parse().unwrap())
                .collect()
        })
        .collect();
    assert_eq!(rows.len(), 6);
    assert!(text.starts_with("frame,time_s,status,opening_deg,"));
    let rest = rows
        .iter()
        .find(|r| r[2..6].iter().all(|v| v.abs() < 1e-9))
        .expect("a row at the rest bite");
    for r in &rows {
        let parts = (r[3] * r[3] + r[4] * r[4] + r[5] * r[5]).sqrt();
        let moved =
            ((r[6] - rest[6]).powi(2) + (r[7] - rest[7]).powi(2) + (r[8] - rest[8]).powi(2)).sqrt();
        assert!((parts - moved).abs() < 2e-3, "{r:?}");
        assert!((r[1] - (r[0] - rows[0][0]) / 30.0).abs() < 1e-6);
    }
    assert!(
        rows.iter().any(|r| r[2] > 5.0),
        "the exercise opens the jaw"
    );

    // glTF: the arches and the mandible, the lower arch animated over the six frames.
    let root = gltf_json::Root::from_slice(&std::fs::read(&gltf).unwrap()).unwrap();
    let names: Vec<_> = root.nodes.iter().filter_map(|n| n.name.clone()).collect();
    assert_eq!(names, ["upper", "mandible", "lower"]);
    assert_eq!(root.animations.len(), 1);
    let input = root.animations[0].samplers[0].input.value();
    assert_eq!(root.accessors[input].count.0, 6);
    if let Some(report) = validate(&gltf) {
        assert_eq!(report["errors"], 0, "{report}");
        assert_eq!(report["warnings"], 0, "{report}");
        assert_eq!(report["animations"], 1, "{report}");
    }
}

#[test]
fn a_posed_arch_without_animation_is_valid_gltf_too() {
    use jawtrack::export::gltf::{Key, Part, write_gltf};
    let arch = jawtrack::anatomy::procedural_arch(false);
    let part = Part {
        name: "lower",
        mesh: &arch,
        colour: [1.0, 1.0, 1.0, 1.0],
    };
    let bytes = write_gltf(
        None,
        &part,
        None,
        &[Key {
            time_s: 0.0,
            jaw: jawtrack::geometry::Pose::IDENTITY,
        }],
        "one",
    );
    let root = gltf_json::Root::from_slice(&bytes).unwrap();
    assert!(root.animations.is_empty());
    let t = tempfile::tempdir().unwrap();
    let path = t.path().join("one.gltf");
    std::fs::write(&path, &bytes).unwrap();
    if let Some(report) = validate(&path) {
        assert_eq!(
            (report["errors"].as_u64(), report["warnings"].as_u64()),
            (Some(0), Some(0)),
            "{report}"
        );
    }
}

#[test]
fn export_errors_are_clear() {
    let cap = common::template(Preset::Clean, MaskKind::PerArch);
    let run = |args: &[&str]| {
        let out = Command::new(env!("CARGO_BIN_EXE_jawtrack"))
            .args(args)
            .output()
            .unwrap();
        assert!(!out.status.success());
        String::from_utf8_lossy(&out.stderr).into_owned()
    };
    let e = run(&["export", s(cap), s(&cap.join("gt/poses.json"))]);
    common::assert_mentions(&e, &["--gltf", "--csv"]);
    let e = run(&[
        "export",
        s(cap),
        s(&cap.join("gt/poses.json")),
        "--csv",
        "/tmp/x.csv",
        "--rest-frame",
        "99",
    ]);
    common::assert_mentions(&e, &["--rest-frame 99", "no such frame"]);
}
