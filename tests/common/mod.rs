//! Helpers shared by the integration tests.
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;

use jawtrack::synth::{MaskKind, Preset, SynthOptions, generate};

pub mod browser;

/// Run the binary under test with `args`.
pub fn jawtrack(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_jawtrack"))
        .args(args)
        .output()
        .unwrap()
}

/// Run it and expect success: its standard output.
pub fn ok(args: &[&str]) -> String {
    let out = jawtrack(args);
    assert!(
        out.status.success(),
        "jawtrack {args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// Run it and expect a refusal, not a panic, whose message mentions each of `parts`: its
/// standard error.
pub fn refused(args: &[&str], parts: &[&str]) -> String {
    let out = jawtrack(args);
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(
        !out.status.success(),
        "accepted: jawtrack {args:?}\n{}",
        String::from_utf8_lossy(&out.stdout)
    );
    assert!(!err.contains("panicked"), "panic: jawtrack {args:?}\n{err}");
    assert_mentions(&err, parts);
    err
}

/// A small synthetic capture, written once per test binary; copy it before changing it.
pub fn template(preset: Preset, masks: MaskKind) -> &'static Path {
    static CELLS: [OnceLock<tempfile::TempDir>; 6] = [const { OnceLock::new() }; 6];
    let p = match preset {
        Preset::Clean => 0,
        Preset::Realistic => 1,
        Preset::Hard => 2,
    };
    written_once(
        &CELLS[p * 2 + (masks == MaskKind::Combined) as usize],
        || SynthOptions {
            masks,
            ..template_options(preset)
        },
    )
}

/// The per-arch template for `preset` filmed through a barrel lens
/// ([`BARREL_LENS`](jawtrack::synth::BARREL_LENS)), written once per test binary.
pub fn lens_template(preset: Preset) -> &'static Path {
    static CELLS: [OnceLock<tempfile::TempDir>; 3] = [const { OnceLock::new() }; 3];
    written_once(&CELLS[preset as usize], || SynthOptions {
        distortion: Some(jawtrack::synth::BARREL_LENS),
        ..template_options(preset)
    })
}

/// The per-arch realistic template filmed through the rational lens (0) or the fisheye (1)
/// ([`RATIONAL_LENS`](jawtrack::synth::RATIONAL_LENS), [`FISHEYE_LENS`](jawtrack::synth::FISHEYE_LENS)),
/// written once per test binary.
pub fn model_lens_template(which: usize) -> &'static Path {
    static CELLS: [OnceLock<tempfile::TempDir>; 2] = [const { OnceLock::new() }; 2];
    let lens = [
        jawtrack::synth::RATIONAL_LENS,
        jawtrack::synth::FISHEYE_LENS,
    ][which];
    written_once(&CELLS[which], || SynthOptions {
        distortion: Some(lens),
        ..template_options(Preset::Realistic)
    })
}

/// Six frames, a segment of the exercise a frame: six different jaw poses.
fn template_options(preset: Preset) -> SynthOptions {
    SynthOptions {
        frames: 6,
        frames_per_segment: 1,
        seed: 3,
        preset,
        ..SynthOptions::default()
    }
}

fn written_once(
    cell: &'static OnceLock<tempfile::TempDir>,
    opts: impl FnOnce() -> SynthOptions,
) -> &'static Path {
    cell.get_or_init(|| {
        let dir = tempfile::tempdir().unwrap();
        generate(&dir.path().join("c"), &opts(), &|| {}).unwrap();
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

/// The `Energy` region against the `Footprint` region on every frame of a capture, for
/// candidates up to `offset` (degrees and mm) from the truth: the same energy, cross,
/// over-mouth and area error for every candidate, while body pixels off the mask are skipped (the energy
/// region counts fewer of them in most camera views). Returns how many were compared.
pub fn energy_region_matches_footprint(capture: &jawtrack::capture::Capture, offset: f64) -> usize {
    use jawtrack::arch::Arch;
    use jawtrack::energy::{CpuEnergy, EnergyEngine, MASK_NONE, Region, Scene};
    use rand::{RngExt, SeedableRng};

    let scene = Scene::from_capture(capture);
    let mut footprint = CpuEnergy::with_region(scene.clone(), Region::Footprint);
    let mut energy = CpuEnergy::with_region(scene, Region::Relevant);
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
    let (mut compared, mut views, mut skipped) = (0, 0, 0);
    for f in capture.frames() {
        let masks = capture.load_masks(f).unwrap();
        footprint.set_frame(&masks).unwrap();
        energy.set_frame(&masks).unwrap();
        let truth = capture.gt_poses(f).unwrap();
        for arch in Arch::BOTH {
            let mut candidates = vec![truth];
            candidates.extend((0..12).map(|_| {
                let d: [f64; 6] = std::array::from_fn(|k| {
                    let a = if k < 3 { offset.to_radians() } else { offset };
                    rng.random_range(-a..=a)
                });
                truth.with(arch, truth.get(arch).with_euler_offset(&d))
            }));
            let a = footprint.evaluate(arch, &candidates).unwrap();
            let b = energy.evaluate(arch, &candidates).unwrap();
            for (k, (a, b)) in a.iter().zip(&b).enumerate() {
                for (x, y) in a.cameras.iter().zip(&b.cameras) {
                    let read = |c: &jawtrack::energy::Counts| {
                        (
                            c.uncovered(),
                            c.boi_outside(),
                            c.cross(),
                            c.over_mouth(),
                            c.mask_pixels(),
                        )
                    };
                    assert_eq!(read(x), read(y), "frame {f} {arch:?} candidate {k}");
                    skipped += (y.bin(MASK_NONE, 1) < x.bin(MASK_NONE, 1)) as usize;
                    views += 1;
                }
                compared += 1;
            }
        }
    }
    eprintln!(
        "energy region: {compared} candidates, body faces skipped in {skipped} of {views} camera views"
    );
    assert!(skipped * 2 > views, "{skipped} of {views}");
    compared
}

/// Open the capture and return the error text; panics if it opened.
pub fn error_of(dir: &Path) -> String {
    match jawtrack::capture::Capture::open(dir) {
        Ok(_) => panic!("{} opened without error", dir.display()),
        Err(e) => e.to_string(),
    }
}

pub fn assert_mentions(msg: &str, parts: &[&str]) {
    for p in parts {
        assert!(msg.contains(p), "error {msg:?} does not mention {p:?}");
    }
}

/// `{errors, warnings, animations}` from the Khronos validator, or `None` when it is not
/// installed (and not required).
pub fn validate_gltf(gltf: &Path) -> Option<serde_json::Value> {
    let dir = std::env::var_os("JAWTRACK_GLTF_VALIDATOR").map(PathBuf::from);
    let found = dir
        .as_ref()
        .is_some_and(|d| d.join("node_modules/gltf-validator").is_dir());
    if !found {
        assert!(
            std::env::var_os("JAWTRACK_REQUIRE_GLTF_VALIDATOR").is_none(),
            "JAWTRACK_REQUIRE_GLTF_VALIDATOR is set but JAWTRACK_GLTF_VALIDATOR ({dir:?}) holds no node_modules/gltf-validator"
        );
        eprintln!(
            "skipped the glTF validator: set JAWTRACK_GLTF_VALIDATOR to a folder with `npm install gltf-validator` done"
        );
        return None;
    }
    let script = r#"
const fs = require("fs");
const v = require("gltf-validator");
const path = process.argv[process.argv.length - 1];
v.validateBytes(new Uint8Array(fs.readFileSync(path)), { uri: path, maxIssues: 0 }).then((r) => {
  console.log(JSON.stringify({ errors: r.issues.numErrors, warnings: r.issues.numWarnings,
    animations: r.info.animationCount, messages: r.issues.messages.slice(0, 5) }));
}).catch((e) => { console.error(e); process.exit(2); });
"#;
    let out = Command::new("node")
        .arg("-e")
        .arg(script)
        .arg(gltf)
        .env("NODE_PATH", dir.unwrap().join("node_modules"))
        .output()
        .expect("node runs");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    Some(serde_json::from_slice(&out.stdout).unwrap())
}

/// `ffmpeg` is installed, or the test is skipped (failed where CI requires it).
pub fn have_ffmpeg() -> bool {
    let found = std::process::Command::new("ffmpeg")
        .arg("-version")
        .output()
        .is_ok();
    if !found {
        assert!(
            std::env::var_os("JAWTRACK_REQUIRE_FFMPEG").is_none(),
            "JAWTRACK_REQUIRE_FFMPEG is set but `ffmpeg` is not on the PATH"
        );
        eprintln!("skipped: no `ffmpeg` on the PATH");
    }
    found
}

/// A Python with numpy (JAWTRACK_PYTHON, else `python3`), for benches/other_capture.py, or the
/// test is skipped (failed where CI sets JAWTRACK_REQUIRE_NUMPY).
pub fn python_with_numpy() -> Option<String> {
    let python = std::env::var("JAWTRACK_PYTHON").unwrap_or_else(|_| "python3".into());
    let found = std::process::Command::new(&python)
        .args(["-c", "import numpy"])
        .output()
        .is_ok_and(|o| o.status.success());
    if !found {
        assert!(
            std::env::var_os("JAWTRACK_REQUIRE_NUMPY").is_none(),
            "JAWTRACK_REQUIRE_NUMPY is set but `{python}` cannot import numpy"
        );
        eprintln!("skipped: `{python}` cannot import numpy (set JAWTRACK_PYTHON)");
    }
    found.then_some(python)
}

/// A synthetic capture (40 frames) and a rig learned on its ground truth, made once per test
/// binary.
pub struct RigFixture {
    _dir: tempfile::TempDir,
    pub capture: PathBuf,
    pub rig: PathBuf,
}

pub fn rig_fixture() -> &'static RigFixture {
    static F: OnceLock<RigFixture> = OnceLock::new();
    F.get_or_init(|| {
        let dir = tempfile::tempdir().unwrap();
        let capture = dir.path().join("cap");
        let s = |p: &Path| p.to_str().unwrap().to_owned();
        ok(&["synth", &s(&capture), "--frames", "40"]);
        let rig = dir.path().join("rig.json");
        let (poses, mesh) = (
            capture.join("gt/poses.json"),
            capture.join("meshes/mandible.obj"),
        );
        ok(&[
            "rig",
            "learn",
            &s(&poses),
            "--mesh",
            &s(&mesh),
            "-o",
            &s(&rig),
        ]);
        RigFixture {
            _dir: dir,
            capture,
            rig,
        }
    })
}
