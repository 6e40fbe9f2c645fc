//! Helpers shared by the integration tests.
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use jawtrack::synth::{MaskKind, Preset, SynthOptions, generate};

/// A small synthetic capture, written once per test binary; copy it before changing it.
pub fn template(preset: Preset, masks: MaskKind) -> &'static Path {
    static CELLS: [OnceLock<tempfile::TempDir>; 6] = [const { OnceLock::new() }; 6];
    let p = match preset {
        Preset::Clean => 0,
        Preset::Realistic => 1,
        Preset::Hard => 2,
    };
    let cell = &CELLS[p * 2 + (masks == MaskKind::Combined) as usize];
    cell.get_or_init(|| {
        let dir = tempfile::tempdir().unwrap();
        let opts = SynthOptions {
            frames: 6,
            // A segment of the exercise a frame: six different jaw poses.
            frames_per_segment: 1,
            seed: 3,
            preset,
            masks,
            ..SynthOptions::default()
        };
        generate(&dir.path().join("c"), &opts, &|| {}).unwrap();
        dir
    })
    .path()
    .join("c")
    .leak()
}

/// A fresh, writable copy of the clean per-arch template.
pub fn fresh_capture() -> (tempfile::TempDir, PathBuf) {
    let dir = tempfile::tempdir().unwrap();
    let dst = dir.path().join("c");
    copy_dir(template(Preset::Clean, MaskKind::PerArch), &dst);
    (dir, dst)
}

pub fn copy_dir(src: &Path, dst: &Path) {
    std::fs::create_dir_all(dst).unwrap();
    for e in std::fs::read_dir(src).unwrap() {
        let e = e.unwrap();
        let to = dst.join(e.file_name());
        if e.file_type().unwrap().is_dir() {
            copy_dir(&e.path(), &to);
        } else {
            std::fs::copy(e.path(), to).unwrap();
        }
    }
}

/// ../shared/data/scan-tag0, the real dental scans. CI sets JAWTRACK_REQUIRE_DATA=1 so that
/// a missing folder fails there; elsewhere the test is skipped with a message.
pub fn scan_dir() -> Option<PathBuf> {
    let dir = std::env::var_os("JAWTRACK_SCAN_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data/scan-tag0"));
    if dir.join("upper.obj").exists() {
        return Some(dir);
    }
    if std::env::var_os("JAWTRACK_REQUIRE_DATA").is_some() {
        panic!(
            "{} has no upper.obj and JAWTRACK_REQUIRE_DATA is set",
            dir.display()
        );
    }
    eprintln!(
        "skipped: no real scans at {} (set JAWTRACK_SCAN_DIR)",
        dir.display()
    );
    None
}

/// Edit a JSON file in place.
pub fn edit_json(path: &Path, f: impl FnOnce(&mut serde_json::Value)) {
    let mut v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
    f(&mut v);
    std::fs::write(path, serde_json::to_string_pretty(&v).unwrap()).unwrap();
}
