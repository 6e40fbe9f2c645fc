//! Property tests over hostile input: every reader gets mutated copies of valid files (bytes
//! flipped, inserted and cut; JSON values replaced by extremes) and must answer with a value or
//! an error, never a panic, a hang or an abort. The seeds are checked in, all written by another
//! program: the capture `fixtures/tiny-capture` and the corpus `fixtures/fuzz` (meshes in every
//! format, a journal, a tracks.json; `make_corpus.py` there writes it), and the calibration files
//! of `fixtures/calib` (OpenCV 4 and 5, COLMAP; its `make.py`); a face sequence is written at
//! run time by `fixtures/face-python/make.py`, and the page's server is asked mutated copies of
//! the page's own requests.
//!
//! CI runs `PROPTEST_CASES` cases per target (64 by default here); run longer with e.g.
//! `PROPTEST_CASES=100000 cargo test --release --test fuzz`.

use std::io::{Read, Write};
use std::net::TcpStream;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::{Mutex, OnceLock};
use std::time::Duration;

mod common;

use jawtrack::capture::{Capture, MaskMode};
use jawtrack::mesh::{BoiSource, Mesh};
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

/// A face sequence of 4 frames (fixtures/face-python/make.py, its calibration moved into
/// those frames), written once per run.
fn face_seed() -> &'static Path {
    static SEED: OnceLock<tempfile::TempDir> = OnceLock::new();
    SEED.get_or_init(|| {
        let t = tempfile::tempdir().unwrap();
        let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/face-python/make.py");
        let status = Command::new("python3")
            .arg(&script)
            .arg(t.path())
            .args(["1", "4"])
            .stdout(Stdio::null())
            .status()
            .expect("python3 runs the face fixture's writer");
        assert!(status.success());
        let face = t.path().join("p1/face.json");
        let mut v: serde_json::Value =
            serde_json::from_slice(&std::fs::read(&face).unwrap()).unwrap();
        v["calibration"] = serde_json::json!({
            "open": 1000, "left": 1001, "right": 1002, "forward": 1003, "backward": 1000
        });
        std::fs::write(&face, serde_json::to_vec(&v).unwrap()).unwrap();
        t
    })
    .path()
    .join("p1")
    .leak()
}

const FACE_FILES: [&str; 5] = [
    "face.json",
    "jaw.json",
    "neutral.obj",
    "mandible.obj",
    "frames/001002.obj",
];

/// Open the face seed with `file` replaced by `bytes` and read every frame: any answer but a
/// panic.
fn open_face_with_file(file: &str, bytes: &[u8]) {
    use jawtrack::skin::{format::FaceSequence, subject::Subject};
    let t = tempfile::tempdir().unwrap();
    let dir = t.path().join("face");
    copy_dir(face_seed(), &dir);
    std::fs::write(dir.join(file), bytes).unwrap();
    if let Ok(seq) = FaceSequence::open(&dir)
        && let Ok(s) = Subject::load(&seq, "fuzz", &|| {})
    {
        let _ = s.rest();
        let _ = s.calibration_indices();
    }
}

/// `jawtrack view` on a synthetic capture and a rig learned on it, started once per run, its
/// standard error kept in a file to look for panics.
struct ViewServer {
    _dir: tempfile::TempDir,
    _server: common::browser::Killed,
    port: u16,
    stderr: PathBuf,
}

fn view_server() -> &'static Mutex<ViewServer> {
    static SERVER: OnceLock<Mutex<ViewServer>> = OnceLock::new();
    SERVER.get_or_init(|| {
        let dir = tempfile::tempdir().unwrap();
        let cap = dir.path().join("cap");
        let rig = dir.path().join("rig.json");
        let s = |p: &Path| p.to_str().unwrap().to_owned();
        common::ok(&["synth", &s(&cap), "--frames", "12"]);
        let (poses, mandible) = (cap.join("gt/poses.json"), cap.join("meshes/mandible.obj"));
        common::ok(&[
            "rig",
            "learn",
            &s(&poses),
            "--mesh",
            &s(&mandible),
            "-o",
            &s(&rig),
        ]);
        let stderr = dir.path().join("view.stderr");
        let (server, url) = common::browser::serve_logging(
            Path::new(env!("CARGO_BIN_EXE_jawtrack")),
            &[&s(&rig), "--capture", &s(&cap), "--tracks", &s(&poses)],
            std::fs::File::create(&stderr).unwrap().into(),
        );
        let port = common::browser::port_of(&url);
        Mutex::new(ViewServer {
            _dir: dir,
            _server: server,
            port,
            stderr,
        })
    })
}

/// Send `raw`, close the sending side, and read the reply (if any) to its end.
fn exchange(port: u16, raw: &[u8]) -> Vec<u8> {
    let mut c = TcpStream::connect(("127.0.0.1", port)).unwrap();
    c.set_read_timeout(Some(Duration::from_secs(20))).unwrap();
    let _ = c.write_all(raw);
    let _ = c.shutdown(std::net::Shutdown::Write);
    let mut reply = Vec::new();
    let _ = c.read_to_end(&mut reply);
    reply
}

/// The page's own requests, as the seeds of the server's target (`{port}` stands for the
/// server's).
const VIEW_SEEDS: [(&str, &str, &str); 7] = [
    ("GET", "/", ""),
    ("GET", "/api/scene", ""),
    ("GET", "/mesh/lower.bin", ""),
    ("GET", "/overlay/cam0/3.png", ""),
    (
        "POST",
        "/api/pose",
        r#"{"target":[1.0,-2.0,3.0],"from":[0.0,0.0,0.0]}"#,
    ),
    (
        "POST",
        "/api/ik",
        r#"{"part":"lower","vertex":10,"target":[0.0,-30.0,10.0],"from":[0.0,0.0,0.0]}"#,
    ),
    (
        "POST",
        "/api/animation",
        r#"{"keys":[{"time":0.0,"params":[0,0,0]},{"time":1.0,"params":[2,0,0]}],"fps":10}"#,
    ),
];

fn view_request(port: u16, seed: usize, body: &str) -> Vec<u8> {
    let (method, path, _) = VIEW_SEEDS[seed];
    format!(
        "{method} {path} HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nOrigin: http://127.0.0.1:{port}\r\nContent-Type: application/json\r\nContent-Length: {}\r\n\r\n{body}",
        body.len()
    )
    .into_bytes()
}

/// Ask the server `raw`; then it must still answer the page, and have written no panic.
fn ask_view_server(raw: &[u8]) {
    let server = view_server().lock().unwrap_or_else(|e| e.into_inner());
    let reply = exchange(server.port, raw);
    assert!(
        reply.is_empty() || reply.starts_with(b"HTTP/1.1 "),
        "not an HTTP reply: {:?}",
        String::from_utf8_lossy(&reply[..reply.len().min(200)])
    );
    let page = exchange(server.port, &view_request(server.port, 1, ""));
    assert!(
        page.starts_with(b"HTTP/1.1 200"),
        "the page's scene after {:?}: {:?}",
        String::from_utf8_lossy(&raw[..raw.len().min(300)]),
        String::from_utf8_lossy(&page[..page.len().min(200)])
    );
    let log = std::fs::read_to_string(&server.stderr).unwrap_or_default();
    assert!(!log.contains("panicked"), "the server panicked:\n{log}");
}

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
        let _ = jawtrack::track::output::TracksWriter::open(&out, true, false, 0..3, "f", &Default::default());
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

    #[test]
    fn face_sequences_with_bytes_edited(file in 0..FACE_FILES.len(), e in edits()) {
        let name = FACE_FILES[file];
        let original = std::fs::read(face_seed().join(name)).unwrap();
        open_face_with_file(name, &apply(&original, &e));
    }

    #[test]
    fn face_sequences_with_a_value_replaced(jaw in any::<bool>(), k in any::<usize>(), with in extreme()) {
        let name = if jaw { "jaw.json" } else { "face.json" };
        let mut v: serde_json::Value =
            serde_json::from_slice(&std::fs::read(face_seed().join(name)).unwrap()).unwrap();
        replace_leaf(&mut v, k, &with);
        open_face_with_file(name, &serde_json::to_vec(&v).unwrap());
    }

    #[test]
    fn view_requests_with_bytes_edited(seed in 0..VIEW_SEEDS.len(), e in edits()) {
        let port = view_server().lock().unwrap_or_else(|e| e.into_inner()).port;
        let raw = view_request(port, seed, VIEW_SEEDS[seed].2);
        ask_view_server(&apply(&raw, &e));
    }

    #[test]
    fn view_questions_with_a_value_replaced(seed in 4..VIEW_SEEDS.len(), k in any::<usize>(), with in extreme()) {
        let port = view_server().lock().unwrap_or_else(|e| e.into_inner()).port;
        let mut v: serde_json::Value = serde_json::from_str(VIEW_SEEDS[seed].2).unwrap();
        replace_leaf(&mut v, k, &with);
        ask_view_server(&view_request(port, seed, &v.to_string()));
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
    let seq = jawtrack::skin::format::FaceSequence::open(face_seed()).unwrap();
    jawtrack::skin::subject::Subject::load(&seq, "seed", &|| {}).unwrap();
    for (seed, &(method, path, body)) in VIEW_SEEDS.iter().enumerate() {
        let port = view_server().lock().unwrap().port;
        let reply = exchange(port, &view_request(port, seed, body));
        assert!(
            reply.starts_with(b"HTTP/1.1 200"),
            "{method} {path}: {:?}",
            String::from_utf8_lossy(&reply[..reply.len().min(300)])
        );
    }
    for name in ["tracks.json.journal", "tracks.json"] {
        let t = tempfile::tempdir().unwrap();
        std::fs::write(t.path().join(name), corpus(name)).unwrap();
        let out = t.path().join("tracks.json");
        let (_, records) = jawtrack::track::output::TracksWriter::open(
            &out,
            true,
            false,
            0..3,
            "f",
            &Default::default(),
        )
        .unwrap();
        assert_eq!(records.len(), 3, "{name}");
    }
}
