//! The page's frame time in a real browser: headless Chromium with SwiftShader's software
//! WebGL2 (this machine's), `jawtrack view` on a rig learned from a synthetic capture, the
//! opening slider swept as a user would (`?bench=N` on the page), the page's own figures
//! printed: from the slider's input to the frame drawn (the pose asked of the server
//! included), and the drawing alone.
//!
//! `cargo bench --bench view [-- --scans ../shared/data/scan-tag0] [--moves 60]`
//! Needs `chromium` and `chromedriver`.

// The tests' browser client; the benchmark uses part of it.
#[allow(dead_code)]
#[path = "../tests/common/browser.rs"]
mod browser;

use std::path::Path;
use std::process::Command;

fn jawtrack(args: &[&str]) {
    let out = Command::new(env!("CARGO_BIN_EXE_jawtrack"))
        .args(args)
        .output()
        .expect("jawtrack runs");
    assert!(
        out.status.success(),
        "jawtrack {args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let value = |flag: &str| {
        args.iter()
            .position(|a| a == flag)
            .and_then(|i| args.get(i + 1).cloned())
    };
    let scans = value("--scans");
    let moves: usize = value("--moves").map_or(60, |m| m.parse().expect("--moves N"));
    let dir = tempfile::tempdir().unwrap();
    let s = |p: &Path| p.to_str().unwrap().to_owned();
    let cap = dir.path().join("cap");
    let mut synth = vec!["synth".to_owned(), s(&cap), "--frames".into(), "40".into()];
    if let Some(m) = &scans {
        synth.extend(["--meshes".into(), m.clone()]);
    }
    jawtrack(&synth.iter().map(String::as_str).collect::<Vec<_>>());
    let rig = dir.path().join("rig.json");
    jawtrack(&[
        "rig",
        "learn",
        &s(&cap.join("gt/poses.json")),
        "--mesh",
        &s(&cap.join("meshes/mandible.obj")),
        "-o",
        &s(&rig),
    ]);
    let (_server, url) = browser::serve(&[&s(&rig), "--capture", &s(&cap)]);
    let b = browser::Browser::start();
    let scale = value("--scale").unwrap_or("1".into());
    b.go(&format!("{url}?bench={moves}&scale={scale}"));
    b.wait("return !!document.getElementById('bench')");
    let figures = b.js("return document.getElementById('bench').textContent");
    println!(
        "view ({}): {}",
        scans.as_deref().unwrap_or("procedural arches"),
        figures.as_str().unwrap()
    );
}
