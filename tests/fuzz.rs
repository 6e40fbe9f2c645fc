//! Property tests over hostile input: every reader gets mutated copies of valid files (bytes
//! flipped, inserted and cut; JSON values replaced by extremes) and must answer with a value or
//! an error, never a panic, a hang or an abort. The seeds are checked in, all written by another
//! program: the capture `fixtures/tiny-capture` and the corpus `fixtures/fuzz` (meshes in every
//! format, a journal, a tracks.json; `make_corpus.py` there writes it), and the calibration files
//! of `fixtures/calib` (OpenCV 4 and 5, COLMAP; its `make.py`).
//!
//! CI runs `PROPTEST_CASES` cases per target (64 by default here); run longer with e.g.
//! `PROPTEST_CASES=100000 cargo test --release --test fuzz`.

use std::path::{Path, PathBuf};

use jawtrack::capture::{BoiSource, Capture, MaskMode, Mesh};
use proptest::prelude::*;

fn config() -> ProptestConfig {
    let cases = std::env::var("PROPTEST_CASES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(64);
    ProptestConfig {
        cases,
        failure_persistence: None,
        ..ProptestConfig::default()
    }
}

fn fixture() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/tiny-capture")
}

/// A seed of the corpus.
fn corpus(name: &str) -> Vec<u8> {
    std::fs::read(
        Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("fixtures/fuzz")
            .join(name),
    )
    .unwrap()
}

/// The mesh seeds: the fixture capture's ASCII STL and the corpus's.
const MESH_SEEDS: [(&str, &str); 5] = [
    ("stl", "tiny-capture"),
    ("stl", "mesh.stl"),
    ("obj", "mesh.obj"),
    ("ply", "mesh-ascii.ply"),
    ("ply", "mesh-binary.ply"),
];

fn mesh_seed(k: usize) -> (&'static str, Vec<u8>) {
    match MESH_SEEDS[k] {
        (ext, "tiny-capture") => (
            ext,
            std::fs::read(fixture().join("meshes/upper.stl")).unwrap(),
        ),
        (ext, name) => (ext, corpus(name)),
    }
}

fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for entry in std::fs::read_dir(from).unwrap() {
        let entry = entry.unwrap();
        let target = to.join(entry.file_name());
        if entry.file_type().unwrap().is_dir() {
            copy_dir(&entry.path(), &target);
        } else {
            std::fs::copy(entry.path(), &target).unwrap();
        }
    }
}

/// An edit of a byte string: flip, insert or cut at a position (taken modulo the length).
#[derive(Debug, Clone)]
enum Edit {
    Set(usize, u8),
    Insert(usize, Vec<u8>),
    Cut(usize, usize),
}

fn edits() -> impl Strategy<Value = Vec<Edit>> {
    let edit = prop_oneof![
        (any::<usize>(), any::<u8>()).prop_map(|(i, b)| Edit::Set(i, b)),
        (any::<usize>(), prop::collection::vec(any::<u8>(), 1..16))
            .prop_map(|(i, b)| Edit::Insert(i, b)),
        (any::<usize>(), 1usize..64).prop_map(|(i, n)| Edit::Cut(i, n)),
    ];
    prop::collection::vec(edit, 1..8)
}

fn apply(bytes: &[u8], edits: &[Edit]) -> Vec<u8> {
    let mut out = bytes.to_vec();
    for e in edits {
        let at = |i: usize, len: usize| if len == 0 { 0 } else { i % len };
        match e {
            Edit::Set(i, b) => {
                let i = at(*i, out.len());
                if let Some(x) = out.get_mut(i) {
                    *x = *b;
                }
            }
            Edit::Insert(i, b) => {
                let i = at(*i, out.len() + 1);
                out.splice(i..i, b.iter().copied());
            }
            Edit::Cut(i, n) => {
                let i = at(*i, out.len());
                let end = (i + n).min(out.len());
                out.drain(i..end);
            }
        }
    }
    out
}

/// Values a hostile writer puts in a number's or a string's place.
fn extreme() -> impl Strategy<Value = serde_json::Value> {
    use serde_json::json;
    prop_oneof![
        Just(json!(1e308)),
        Just(json!(-1e308)),
        Just(json!(0)),
        Just(json!(-1)),
        Just(json!(u64::MAX)),
        Just(json!(i64::MIN)),
        Just(json!(4294967296u64)),
        Just(json!(null)),
        Just(json!("")),
        Just(json!("../../../../etc/passwd")),
        Just(json!("/dev/zero")),
        Just(json!([])),
        Just(json!({})),
        any::<f64>().prop_map(|v| json!(v)),
        any::<i64>().prop_map(|v| json!(v)),
    ]
}

/// Replace the `k`-th leaf (in document order, modulo the count) of a JSON value.
fn replace_leaf(v: &mut serde_json::Value, k: usize, with: &serde_json::Value) {
    fn count(v: &serde_json::Value) -> usize {
        match v {
            serde_json::Value::Array(a) if !a.is_empty() => a.iter().map(count).sum(),
            serde_json::Value::Object(o) if !o.is_empty() => o.values().map(count).sum(),
            _ => 1,
        }
    }
    /// Walk to leaf number `*left`, counting down; true once replaced.
    fn walk(v: &mut serde_json::Value, left: &mut usize, with: &serde_json::Value) -> bool {
        match v {
            serde_json::Value::Array(a) if !a.is_empty() => {
                a.iter_mut().any(|x| walk(x, left, with))
            }
            serde_json::Value::Object(o) if !o.is_empty() => {
                o.values_mut().any(|x| walk(x, left, with))
            }
            leaf => {
                if *left == 0 {
                    *leaf = with.clone();
                    return true;
                }
                *left -= 1;
                false
            }
        }
    }
    let mut left = k % count(v);
    walk(v, &mut left, with);
}

/// Open the fixture capture with `file` replaced by `bytes`: any answer but a panic.
fn open_with_file(file: &str, bytes: &[u8]) {
    let t = tempfile::tempdir().unwrap();
    let dir = t.path().join("c");
    copy_dir(&fixture(), &dir);
    std::fs::write(dir.join(file), bytes).unwrap();
    if let Ok(c) = Capture::open(&dir) {
        for f in c.frames() {
            let _ = c.load_masks(f);
        }
        let _ = c.initial_poses();
    }
}

const JSON_FILES: [&str; 4] = [
    "capture.json",
    "cameras/left.json",
    "init.json",
    "meshes/upper.boi.json",
];

proptest! {
    #![proptest_config(config())]

    #[test]
    fn capture_files_with_bytes_edited(file in 0..JSON_FILES.len(), e in edits()) {
        let name = JSON_FILES[file];
        let original = std::fs::read(fixture().join(name)).unwrap();
        open_with_file(name, &apply(&original, &e));
    }

    #[test]
    fn capture_files_with_a_value_replaced(file in 0..JSON_FILES.len(), k in any::<usize>(), with in extreme()) {
        let name = JSON_FILES[file];
        let mut v: serde_json::Value =
            serde_json::from_slice(&std::fs::read(fixture().join(name)).unwrap()).unwrap();
        replace_leaf(&mut v, k, &with);
        open_with_file(name, &serde_json::to_vec(&v).unwrap());
    }

    #[test]
    fn meshes_with_bytes_edited(seed in 0..MESH_SEEDS.len(), e in edits()) {
        let t = tempfile::tempdir().unwrap();
        let (ext, seed) = mesh_seed(seed);
        let path = t.path().join(format!("m.{ext}"));
        std::fs::write(&path, apply(&seed, &e)).unwrap();
        let _ = Mesh::load(&path, BoiSource::GroupIfPresent("boi"));
    }

    #[test]
    fn masks_with_bytes_edited(e in edits(), combined in any::<bool>()) {
        let seed = std::fs::read(fixture().join("masks/left/000000.png")).unwrap();
        let t = tempfile::tempdir().unwrap();
        let path = t.path().join("000000.png");
        std::fs::write(&path, apply(&seed, &e)).unwrap();
        let mode = if combined { MaskMode::Combined } else { MaskMode::PerArch { upper: 1, lower: 2 } };
        let _ = jawtrack::capture::masks::mask_header(&path, mode);
        let _ = jawtrack::capture::masks::decode_mask(&path, mode, None);
    }

    #[test]
    fn journals_and_tracks_with_bytes_edited(e in edits(), journal in any::<bool>()) {
        let t = tempfile::tempdir().unwrap();
        let out = t.path().join("tracks.json");
        let name = if journal { "tracks.json.journal" } else { "tracks.json" };
        std::fs::write(t.path().join(name), apply(&corpus(name), &e)).unwrap();
        let _ = jawtrack::track::output::TracksWriter::open(&out, true, false, 0..3, "f");
    }

    #[test]
    fn calibration_files_with_bytes_edited(seed in 0..CALIB_SEEDS.len(), e in edits()) {
        use jawtrack::footage::calib::{ImportOptions, read_colmap, read_opencv};
        let t = tempfile::tempdir().unwrap();
        let (dir, name) = CALIB_SEEDS[seed];
        let calib = Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/calib").join(dir);
        let seed = std::fs::read(calib.join(name)).unwrap();
        let o = ImportOptions::default();
        if dir == "colmap" {
            for other in ["cameras.txt", "images.txt"] {
                std::fs::copy(calib.join(other), t.path().join(other)).unwrap();
            }
            std::fs::write(t.path().join(name), apply(&seed, &e)).unwrap();
            let _ = read_colmap(t.path(), &o);
        } else {
            let path = t.path().join(name);
            std::fs::write(&path, apply(&seed, &e)).unwrap();
            let _ = read_opencv(&path, "cam", &o);
        }
    }

    #[test]
    fn settings_with_a_value_replaced(k in any::<usize>(), with in extreme(), rig in any::<bool>()) {
        if rig {
            let mut v = serde_json::to_value(jawtrack::rig::RigSettings::default()).unwrap();
            replace_leaf(&mut v, k, &with);
            if let Ok(s) = serde_json::from_value::<jawtrack::rig::RigSettings>(v) {
                let _ = s.validate(Path::new("fuzz"));
            }
        } else {
            let mut v = serde_json::to_value(jawtrack::track::TrackSettings::default()).unwrap();
            replace_leaf(&mut v, k, &with);
            if let Ok(s) = serde_json::from_value::<jawtrack::track::TrackSettings>(v) {
                let _ = s.validate();
            }
        }
    }
}

/// The calibration seeds: files OpenCV 4 and 5 wrote, and a COLMAP model (fixtures/calib).
const CALIB_SEEDS: [(&str, &str); 5] = [
    ("opencv4", "cam0.yml"),
    ("opencv5", "cam1.xml"),
    ("opencv4", "cam2.yml"),
    ("colmap", "cameras.txt"),
    ("colmap", "images.txt"),
];

/// Fuzzing starts from valid inputs: every seed reads as it is.
#[test]
fn every_seed_of_the_corpus_reads() {
    for (k, which) in MESH_SEEDS.iter().enumerate() {
        let t = tempfile::tempdir().unwrap();
        let (ext, seed) = mesh_seed(k);
        let path = t.path().join(format!("m.{ext}"));
        std::fs::write(&path, seed).unwrap();
        let mesh = Mesh::load(&path, BoiSource::GroupIfPresent("boi"))
            .unwrap_or_else(|e| panic!("{which:?}: {e}"));
        assert!(mesh.triangles.len() >= 8, "{which:?}");
    }
    for name in ["tracks.json.journal", "tracks.json"] {
        let t = tempfile::tempdir().unwrap();
        std::fs::write(t.path().join(name), corpus(name)).unwrap();
        let out = t.path().join("tracks.json");
        let (_, records) =
            jawtrack::track::output::TracksWriter::open(&out, true, false, 0..3, "f").unwrap();
        assert_eq!(records.len(), 3, "{name}");
    }
}
