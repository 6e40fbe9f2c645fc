//! Findings of the third hostile-input probe (issue 35: the page's server, calibration and
//! video imports, outputs that overwrite inputs), each reproduced through the release binary
//! at ab3de3b: every test here fails there and passes after.

mod common;

use std::io::{Read, Write};
use std::net::TcpStream;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

use common::{
    assert_mentions, edit_json, error_of, fresh_capture, have_ffmpeg, jawtrack, ok, refused,
};

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

fn fixture() -> &'static common::RigFixture {
    common::rig_fixture()
}

// ---- the page's server ----

struct Server {
    child: common::browser::Killed,
    port: u16,
}

impl Server {
    fn start() -> Server {
        let f = fixture();
        let (child, url) = common::browser::serve(&[s(&f.rig), "--capture", s(&f.capture)]);
        Server {
            child,
            port: common::browser::port_of(&url),
        }
    }

    fn alive(&mut self) -> bool {
        self.child.alive()
    }

    /// Send `raw` as it is; the status code and body of the reply.
    fn raw(&self, raw: &[u8]) -> (u16, String) {
        let mut c = TcpStream::connect(("127.0.0.1", self.port)).unwrap();
        c.set_read_timeout(Some(Duration::from_secs(30))).unwrap();
        c.write_all(raw).unwrap();
        let mut reply = Vec::new();
        let _ = c.read_to_end(&mut reply);
        let text = String::from_utf8_lossy(&reply).into_owned();
        let status = text
            .split_whitespace()
            .nth(1)
            .and_then(|c| c.parse().ok())
            .unwrap_or(0);
        let body = text.split_once("\r\n\r\n").map_or("", |b| b.1).to_owned();
        (status, body)
    }

    fn request(
        &self,
        method: &str,
        path: &str,
        headers: &[(&str, &str)],
        body: &str,
    ) -> (u16, String) {
        let mut head = format!(
            "{method} {path} HTTP/1.1\r\nContent-Length: {}\r\n",
            body.len()
        );
        if !headers.iter().any(|h| h.0 == "Host") {
            head.push_str(&format!("Host: 127.0.0.1:{}\r\n", self.port));
        }
        for (k, v) in headers {
            head.push_str(&format!("{k}: {v}\r\n"));
        }
        head.push_str("\r\n");
        head.push_str(body);
        self.raw(head.as_bytes())
    }

    fn post(&self, path: &str, body: &str) -> (u16, String) {
        self.request("POST", path, &[("Content-Type", "application/json")], body)
    }
}

/// One IK request with a target of 1e308 killed the server (a clamp with NaN bounds); 1e20
/// was "reached" with a residual of 1e20 mm; a pose from 1e308 answered null parameters.
#[test]
fn extreme_numbers_are_refused_and_the_server_lives_on() {
    let mut server = Server::start();
    let (status, body) = server.post(
        "/api/ik",
        r#"{"part":"lower","vertex":0,"target":[1e308,0,0],"from":[0,0,0]}"#,
    );
    assert_eq!(status, 400, "{body}");
    assert_mentions(&body, &["target"]);
    assert!(server.alive(), "the server died");
    let (status, body) = server.post(
        "/api/ik",
        r#"{"part":"lower","vertex":0,"target":[1e20,0,0],"from":[0,0,0]}"#,
    );
    assert_eq!(status, 400, "{body}");
    // A far but finite target is answered, and not as reached.
    let (status, body) = server.post(
        "/api/ik",
        r#"{"part":"lower","vertex":0,"target":[5000,0,0],"from":[0,0,0]}"#,
    );
    assert_eq!(status, 200, "{body}");
    let reply: serde_json::Value = serde_json::from_str(&body).unwrap();
    assert_eq!(reply["reached"], false, "{body}");
    let (status, body) = server.post("/api/pose", r#"{"target":[10,0,0],"from":[1e308,0,0]}"#);
    assert_eq!(status, 400, "{body}");
    assert_mentions(&body, &["from"]);
    let (status, body) = server.post("/api/pose", r#"{"target":[10,0,0]}"#);
    assert_eq!(status, 200, "{body}");
    assert!(!body.contains("null"), "{body}");
    assert!(server.alive());
}

#[test]
fn rig_ik_refuses_a_target_beyond_reach_without_a_panic() {
    let f = fixture();
    refused(
        &[
            "rig",
            "ik",
            s(&f.rig),
            "--point",
            "0,0,0",
            "--target",
            "1e308,0,0",
        ],
        &["target", "finite"],
    );
}

/// A page that rebinds its own name to 127.0.0.1 read the scans (no Host check); text/plain
/// POSTs from any site were answered.
#[test]
fn only_the_page_itself_is_answered() {
    let server = Server::start();
    let (status, _) = server.request("GET", "/api/scene", &[], "");
    assert_eq!(status, 200);
    let (status, body) = server.request("GET", "/mesh/lower.bin", &[("Host", "evil.example")], "");
    assert_eq!(status, 421, "{body}");
    let (status, body) = server.request(
        "GET",
        "/api/scene",
        &[("Host", &format!("localhost:{}", server.port))],
        "",
    );
    assert_eq!(status, 200, "{body}");
    let (status, body) = server.request(
        "POST",
        "/api/pose",
        &[
            ("Content-Type", "application/json"),
            ("Origin", "http://evil.example"),
        ],
        r#"{"target":[10,0,0]}"#,
    );
    assert_eq!(status, 403, "{body}");
    let (status, body) = server.request(
        "POST",
        "/api/pose",
        &[("Content-Type", "text/plain")],
        r#"{"target":[10,0,0]}"#,
    );
    assert_eq!(status, 415, "{body}");
    let origin = format!("http://127.0.0.1:{}", server.port);
    let (status, body) = server.request(
        "POST",
        "/api/pose",
        &[("Content-Type", "application/json"), ("Origin", &origin)],
        r#"{"target":[10,0,0]}"#,
    );
    assert_eq!(status, 200, "{body}");
}

/// A body announced and never sent held the server for everyone; a huge header line took
/// its memory; one long animation kept the page waiting.
#[test]
fn one_slow_or_greedy_client_does_not_hold_the_others() {
    let server = Server::start();
    // Announce 4 MB, send one byte, and keep the connection open.
    let mut slow = TcpStream::connect(("127.0.0.1", server.port)).unwrap();
    write!(
        slow,
        "POST /api/pose HTTP/1.1\r\nHost: 127.0.0.1:{}\r\nContent-Type: application/json\r\nContent-Length: 4000000\r\n\r\n{{",
        server.port
    )
    .unwrap();
    let started = Instant::now();
    let (status, _) = server.request("GET", "/", &[], "");
    assert_eq!(status, 200);
    assert!(
        started.elapsed() < Duration::from_secs(3),
        "GET / waited {:?} behind a slow body",
        started.elapsed()
    );
    // A 1 MB header line is cut off at the head's bound.
    let mut huge = format!(
        "GET / HTTP/1.1\r\nHost: 127.0.0.1:{}\r\nX-Long: ",
        server.port
    )
    .into_bytes();
    huge.extend(std::iter::repeat_n(b'a', 1 << 20));
    huge.extend(b"\r\n\r\n");
    let mut c = TcpStream::connect(("127.0.0.1", server.port)).unwrap();
    c.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
    let _ = c.write_all(&huge);
    let mut reply = Vec::new();
    let _ = c.read_to_end(&mut reply);
    assert!(
        String::from_utf8_lossy(&reply).starts_with("HTTP/1.1 431"),
        "{}",
        String::from_utf8_lossy(&reply[..reply.len().min(200)])
    );
    // Ten minutes at 1000 fps is 600,000 rig solves: refused as too much work.
    let (status, body) = server.post(
        "/api/animation",
        r#"{"keys":[{"time":0,"params":[0,0,0]},{"time":600,"params":[10,0,0]}],"fps":1000}"#,
    );
    assert_eq!(status, 400, "{body}");
    assert_mentions(&body, &["frames"]);
    // The slow client is cut off by the deadline, not answered with a pose.
    slow.set_read_timeout(Some(Duration::from_secs(20)))
        .unwrap();
    let mut reply = String::new();
    let _ = slow.read_to_string(&mut reply);
    assert!(reply.starts_with("HTTP/1.1 408"), "{reply}");
}

// ---- calibration imports ----

/// A 648-byte file of nested YAML aliases took 7.8 GB.
#[test]
fn yaml_aliases_are_refused_before_they_expand() {
    let t = tempfile::tempdir().unwrap();
    let mut yaml = String::from(
        "%YAML:1.0\n---\na0: &a0 [1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0]\n",
    );
    for k in 1..=11 {
        let refs = vec![format!("*a{}", k - 1); 10].join(", ");
        yaml.push_str(&format!("a{k}: &a{k} [{refs}]\n"));
    }
    let file = t.path().join("cam0.yml");
    std::fs::write(&file, yaml).unwrap();
    let cap = t.path().join("cap");
    let started = Instant::now();
    refused(
        &["import", "cameras", s(&cap), s(&file)],
        &["cam0.yml", "alias"],
    );
    assert!(started.elapsed() < Duration::from_secs(10));
}

/// A COLMAP model of the fixture's three cameras, their images repeated under `n` names.
fn colmap_with(t: &Path, images: usize, points_lines: bool) -> PathBuf {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/calib/colmap");
    let dir = t.join("colmap");
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::copy(src.join("cameras.txt"), dir.join("cameras.txt")).unwrap();
    let text = std::fs::read_to_string(src.join("images.txt")).unwrap();
    let first = text
        .lines()
        .find(|l| !l.starts_with('#') && l.split_whitespace().count() >= 10)
        .unwrap();
    let t0: Vec<&str> = first.split_whitespace().collect();
    let mut out = String::new();
    for i in 0..images {
        out.push_str(&format!(
            "{} {} 1 c{i}/000000.png\n",
            i + 1,
            t0[1..8].join(" ")
        ));
        if points_lines {
            out.push('\n');
        }
    }
    std::fs::write(dir.join("images.txt"), out).unwrap();
    dir
}

/// 20,000 COLMAP cameras took 4.7 GB and printed 1.6 million distances.
#[test]
fn a_colmap_model_of_thousands_of_cameras_is_refused() {
    let t = tempfile::tempdir().unwrap();
    let model = colmap_with(t.path(), 2000, true);
    let cap = t.path().join("cap");
    refused(
        &["import", "cameras", s(&cap), s(&model)],
        &["images.txt", "over 64 cameras"],
    );
    assert!(!cap.join("cameras").exists(), "cameras were written");
    // Ten cameras import, with a summary of their distances rather than every pair.
    let t = tempfile::tempdir().unwrap();
    let model = colmap_with(t.path(), 10, true);
    let cap = t.path().join("cap");
    let out = ok(&["import", "cameras", s(&cap), s(&model)]);
    assert!(out.contains("closest"), "{out}");
    assert!(!out.contains("distance c0 - c1"), "{out}");
}

/// images.txt without its POINTS2D lines lost every second image.
#[test]
fn colmap_images_without_their_points_lines_are_refused() {
    let t = tempfile::tempdir().unwrap();
    let model = colmap_with(t.path(), 4, false);
    let cap = t.path().join("cap");
    refused(
        &["import", "cameras", s(&cap), s(&model)],
        &["images.txt", "line 2", "POINTS2D"],
    );
}

/// `rvec: [1e308, 0, 0]` was reported as NaN in rotation[0][0].
#[test]
fn a_rotation_vector_beyond_any_angle_is_named_as_such() {
    let t = tempfile::tempdir().unwrap();
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/calib/opencv4/cam0.yml");
    let text = std::fs::read_to_string(src).unwrap();
    let start = text.find("R: !!opencv-matrix").unwrap();
    let end = text.find("T: !!opencv-matrix").unwrap();
    let edited = format!(
        "{}rvec: [ 1e308, 0., 0. ]\n{}",
        &text[..start],
        &text[end..]
    );
    let file = t.path().join("cam0.yml");
    std::fs::write(&file, edited).unwrap();
    refused(
        &["import", "cameras", s(&t.path().join("cap")), s(&file)],
        &["cam0.yml", "rvec", "rotation vector"],
    );
}

/// `distortion: [1e308, ...]` and `fx: 1e-300` passed validate.
#[test]
fn lenses_beyond_any_camera_are_refused() {
    for (field, value, named) in [
        (
            "distortion",
            serde_json::json!([1e308, 0.0, 0.0, 0.0, 0.0]),
            "distortion[0]",
        ),
        ("fx", serde_json::json!(1e-300), "fx"),
    ] {
        let (_t, dir) = fresh_capture();
        let camera = std::fs::read_dir(dir.join("cameras"))
            .unwrap()
            .next()
            .unwrap()
            .unwrap()
            .path();
        edit_json(&camera, |v| v[field] = value.clone());
        assert_mentions(&error_of(&dir), &[named]);
    }
}

// ---- outputs that overwrite inputs ----

fn copy_of_fixture() -> (tempfile::TempDir, PathBuf) {
    let t = tempfile::tempdir().unwrap();
    let cap = t.path().join("cap");
    common::copy_dir(&fixture().capture, &cap);
    (t, cap)
}

#[test]
fn export_writes_over_neither_its_inputs_nor_itself() {
    let (t, cap) = copy_of_fixture();
    let poses = cap.join("gt/poses.json");
    let scan = cap.join("meshes/upper.obj");
    let scan_before = std::fs::read(&scan).unwrap();
    refused(
        &["export", s(&cap), s(&poses), "--gltf", s(&scan)],
        &["upper.obj", "meshes"],
    );
    assert_eq!(
        std::fs::read(&scan).unwrap(),
        scan_before,
        "the scan was replaced"
    );
    let poses_before = std::fs::read(&poses).unwrap();
    refused(
        &["export", s(&cap), s(&poses), "--csv", s(&poses)],
        &["poses.json", "reads"],
    );
    assert_eq!(std::fs::read(&poses).unwrap(), poses_before);
    let x = t.path().join("x");
    refused(
        &[
            "export",
            s(&cap),
            s(&poses),
            "--csv",
            s(&x),
            "--gltf",
            s(&x),
        ],
        &["twice"],
    );
    // A new file beside the capture is fine.
    ok(&[
        "export",
        s(&cap),
        s(&poses),
        "--csv",
        s(&t.path().join("jaw.csv")),
    ]);
}

/// An edit of a tracks file.
type Edit = fn(&mut serde_json::Value);

/// `export` took a record's `jaw` over its poses, wrote duplicate frames as equal key times,
/// and frames the capture does not have.
#[test]
fn export_refuses_records_that_contradict_themselves_or_the_capture() {
    let (t, cap) = copy_of_fixture();
    let poses = cap.join("gt/poses.json");
    let out = t.path().join("jaw.csv");
    let edited = t.path().join("edited.json");
    let cases: [(&str, Edit, &[&str]); 3] = [
        (
            "a jaw 500 mm off",
            |v| {
                let f = &mut v["frames"][0];
                let lower = f["lower"].clone();
                f["jaw"] = serde_json::json!({"rotation": lower["rotation"], "translation": [500.0, 0.0, 0.0]});
            },
            &["frame 0", "jaw"],
        ),
        (
            "a frame twice",
            |v| {
                let first = v["frames"][0].clone();
                v["frames"].as_array_mut().unwrap().push(first);
            },
            &["twice"],
        ),
        (
            "a frame the capture lacks",
            |v| v["frames"][0]["frame"] = serde_json::json!(100000),
            &["100000", "capture has frames"],
        ),
    ];
    for (what, edit, parts) in cases {
        std::fs::copy(&poses, &edited).unwrap();
        edit_json(&edited, edit);
        eprintln!("{what}");
        refused(&["export", s(&cap), s(&edited), "--csv", s(&out)], parts);
    }
}

#[test]
fn skin_predict_does_not_write_over_the_ground_truth() {
    use jawtrack::synth::face::{FaceSynthOptions, generate_faces};
    let t = tempfile::tempdir().unwrap();
    let opts = FaceSynthOptions {
        subjects: 1,
        frames: 200,
        seed: 3,
        ..FaceSynthOptions::default()
    };
    generate_faces(&t.path().join("faces"), &opts, &|| {}).unwrap();
    let copy = std::fs::read_dir(t.path().join("faces"))
        .unwrap()
        .flatten()
        .map(|e| e.path())
        .find(|p| p.join("face.json").is_file())
        .expect("a subject");
    let model = t.path().join("model.json");
    std::fs::write(&model, "{}").unwrap();
    let jaw = copy.join("jaw.json");
    let before = std::fs::read(&jaw).ok();
    refused(
        &["skin", "predict", s(&model), s(&copy), "--out", s(&jaw)],
        &["jaw.json", "whose files this command reads"],
    );
    assert_eq!(std::fs::read(&jaw).ok(), before);
    refused(
        &["skin", "predict", s(&model), s(&copy), "--out", s(&model)],
        &["model.json", "reads"],
    );
}

/// A subject of jawtrack's own generator (200 frames) in `dir/faces/<name>`, and a model file
/// learned from it.
fn face_and_model(dir: &Path) -> (PathBuf, PathBuf) {
    use jawtrack::synth::face::{FaceSynthOptions, generate_faces};
    let opts = FaceSynthOptions {
        subjects: 1,
        frames: 200,
        seed: 5,
        ..FaceSynthOptions::default()
    };
    generate_faces(&dir.join("faces"), &opts, &|| {}).unwrap();
    let face = std::fs::read_dir(dir.join("faces"))
        .unwrap()
        .flatten()
        .map(|e| e.path())
        .find(|p| p.join("face.json").is_file())
        .expect("a subject");
    let model = dir.join("model.json");
    let out = jawtrack(&["skin", "learn", s(&face), "--out", s(&model)]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    (face, model)
}

/// `skin fill` read a tracks file of any `format` and counted a repeated record again; `skin`
/// took a frame with every vertex at 3e38 mm; its refusals suggested `--allow-outside`, which
/// it does not have; `skin eval`'s errors named `.` instead of the set's folder.
#[test]
fn skin_refuses_foreign_tracks_huge_skin_and_names_its_own_folders() {
    let t = tempfile::tempdir().unwrap();
    let (face, model) = face_and_model(t.path());
    let out = t.path().join("filled.json");
    let tracks = t.path().join("tracks.json");
    let first = std::fs::read_dir(face.join("frames"))
        .unwrap()
        .flatten()
        .map(|e| e.path())
        .min()
        .unwrap();
    let frame: u32 = first
        .file_stem()
        .unwrap()
        .to_str()
        .unwrap()
        .parse()
        .unwrap();
    let record = serde_json::json!({
        "frame": frame,
        "upper": {"rotation": [[1,0,0],[0,1,0],[0,0,1]], "translation": [0,0,0]},
        "lower": {"rotation": [[1,0,0],[0,1,0],[0,0,1]], "translation": [0,-5,0]},
    });
    let fill = |v: serde_json::Value| {
        std::fs::write(&tracks, v.to_string()).unwrap();
        refused(
            &[
                "skin",
                "fill",
                s(&model),
                s(&face),
                "--tracks",
                s(&tracks),
                "--out",
                s(&out),
            ],
            &[],
        )
    };
    let e = fill(serde_json::json!({"format": "other-tracks/2", "frames": [record]}));
    assert_mentions(&e, &["tracks.json", "format", "other-tracks/2"]);
    let e = fill(serde_json::json!({"format": "jawtrack-tracks/1", "frames": [record, record]}));
    assert_mentions(&e, &["tracks.json", "twice"]);
    assert!(!out.exists());

    // Every vertex of one frame at 3e38 mm (written as OBJ, in place of the frame's file).
    let count = jawtrack::mesh::Mesh::load_vertices(&first).unwrap().len();
    let kept = t.path().join("kept-frame");
    std::fs::rename(&first, &kept).unwrap();
    let huge_frame = first.with_extension("obj");
    std::fs::write(&huge_frame, "v 3e38 3e38 3e38\n".repeat(count)).unwrap();
    let predicted = t.path().join("jaw.json");
    let predict = |parts: &[&str]| {
        refused(
            &[
                "skin",
                "predict",
                s(&model),
                s(&face),
                "--out",
                s(&predicted),
            ],
            parts,
        )
    };
    predict(&[
        huge_frame.file_name().unwrap().to_str().unwrap(),
        "vertex 1",
        "beyond",
    ]);
    std::fs::remove_file(&huge_frame).unwrap();
    std::fs::rename(&kept, &first).unwrap();

    // A link out of the face sequence: the remedy is not a flag skin lacks.
    let mandible = face.join("mandible.obj");
    let elsewhere = t.path().join("mandible.obj");
    std::fs::rename(&mandible, &elsewhere).unwrap();
    std::os::unix::fs::symlink(&elsewhere, &mandible).unwrap();
    let e = predict(&["mandible", "face sequence"]);
    assert!(!e.contains("--allow-outside"), "{e}");
    std::fs::remove_file(&mandible).unwrap();
    std::fs::rename(&elsewhere, &mandible).unwrap();

    // A set of one subject: the error names the set's folder.
    let e = refused(
        &["skin", "eval", s(&t.path().join("faces"))],
        &["faces", "subjects"],
    );
    assert!(!e.contains("error: .:"), "{e}");
}

// ---- video imports ----

/// Videos named `-i` could not be imported, `-report` made ffprobe write a log, a name with
/// `concat:` read another file; `--first` beyond any frame left an empty images/; two videos
/// for one camera wrote the first, then failed.
#[test]
fn video_names_are_files_not_options_or_protocols() {
    if !have_ffmpeg() {
        return;
    }
    let t = tempfile::tempdir().unwrap();
    let work = t.path().join("work");
    std::fs::create_dir_all(&work).unwrap();
    let st = Command::new("ffmpeg")
        .args([
            "-v",
            "error",
            "-y",
            "-f",
            "lavfi",
            "-i",
            "testsrc=size=64x48:rate=24:duration=0.5",
        ])
        .args(["-c:v", "libx264", "-pix_fmt", "yuv420p", "-f", "mp4"])
        .arg(work.join("-i"))
        .status()
        .unwrap();
    assert!(st.success());
    std::fs::copy(work.join("-i"), work.join("-report")).unwrap();
    let run = |args: &[&str]| {
        Command::new(env!("CARGO_BIN_EXE_jawtrack"))
            .args(args)
            .current_dir(&work)
            .output()
            .unwrap()
    };
    let out = run(&["import", "video", "cap", "cam0=-i", "cam1=-report"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert_eq!(
        std::fs::read_dir(work.join("cap/images/cam0"))
            .unwrap()
            .count(),
        12
    );
    let logs: Vec<_> = std::fs::read_dir(&work)
        .unwrap()
        .flatten()
        .filter(|e| e.file_name().to_string_lossy().ends_with(".log"))
        .collect();
    assert!(logs.is_empty(), "ffprobe wrote a report: {logs:?}");
    // `concat:-i` names no file here: it is not read as ffmpeg's concat protocol.
    let out = run(&["import", "video", "cap2", "cam0=concat:-i"]);
    assert!(!out.status.success());
    assert!(!work.join("cap2/images/cam0").exists());
    // Beyond any frame number: refused, nothing made.
    let out = run(&[
        "import",
        "video",
        "cap3",
        "cam0=-i",
        "--first",
        "18446744073709551615",
    ]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("999999") && !err.contains("panicked"), "{err}");
    assert!(
        !work.join("cap3/images").exists(),
        "an empty images/ was left"
    );
    // One camera, two videos: refused before anything is written.
    let out = run(&["import", "video", "cap4", "cam0=-i", "cam0=-report"]);
    assert!(!out.status.success());
    assert_mentions(
        &String::from_utf8_lossy(&out.stderr),
        &["cam0", "two videos"],
    );
    assert!(!work.join("cap4").exists());
    // A dangling link in place of the camera's folder: refused, no stage left behind.
    std::fs::create_dir_all(work.join("cap5/images")).unwrap();
    #[cfg(unix)]
    std::os::unix::fs::symlink(work.join("nowhere"), work.join("cap5/images/cam0")).unwrap();
    let out = run(&["import", "video", "cap5", "cam0=-i"]);
    assert!(!out.status.success());
    let left: Vec<_> = std::fs::read_dir(work.join("cap5/images"))
        .unwrap()
        .flatten()
        .map(|e| e.file_name())
        .filter(|n| n.to_string_lossy().starts_with(".import-"))
        .collect();
    assert!(left.is_empty(), "{left:?}");
}

// ---- mask imports ----

/// A 16-bit SAM 2 mask of 0/1 became empty; a fully transparent RGBA mask labelled the whole
/// frame; a CVAT label map with a name or a colour twice gave a class no pixels.
#[test]
fn object_masks_are_read_by_their_values_and_label_maps_by_unique_names() {
    use jawtrack::capture::masks::{MaskMode, UPPER_BIT, decode_mask};
    let t = tempfile::tempdir().unwrap();
    let sam = t.path().join("sam");
    std::fs::create_dir_all(sam.join("1")).unwrap();
    std::fs::create_dir_all(sam.join("2")).unwrap();
    // Object 1: 16-bit, 0 and 1, a 10x5 block.
    image::ImageBuffer::<image::Luma<u16>, _>::from_fn(40, 30, |x, y| {
        image::Luma([u16::from(x < 10 && y < 5)])
    })
    .save(sam.join("1/00000.png"))
    .unwrap();
    // Object 2: white everywhere, transparent but for a 4x4 block.
    image::RgbaImage::from_fn(40, 30, |x, y| {
        let inside = (20..24).contains(&x) && (20..24).contains(&y);
        image::Rgba([255, 255, 255, if inside { 255 } else { 0 }])
    })
    .save(sam.join("2/00000.png"))
    .unwrap();
    let cap = t.path().join("cap");
    ok(&[
        "import",
        "masks",
        s(&cap),
        "--camera",
        "cam0",
        "--objects",
        s(&sam),
        "--label",
        "1=upper",
        "--label",
        "2=lower",
    ]);
    let m = decode_mask(
        &cap.join("masks/cam0/000000.png"),
        MaskMode::PerArch {
            upper: 85,
            lower: 170,
        },
        None,
    )
    .unwrap();
    assert_eq!(m.count(UPPER_BIT), 50);
    assert_eq!(m.count(jawtrack::capture::masks::LOWER_BIT), 16);

    for (map, named) in [
        (
            "background:0,0,0::\nteeth:250,50,83::\nteeth:61,61,245::\n",
            "twice",
        ),
        (
            "background:0,0,0::\nteeth:250,50,83::\ninside:250,50,83::\n",
            "colour of `teeth`",
        ),
    ] {
        let cvat = t.path().join("cvat");
        std::fs::create_dir_all(cvat.join("SegmentationClass")).unwrap();
        std::fs::write(cvat.join("labelmap.txt"), map).unwrap();
        image::RgbImage::from_pixel(32, 24, image::Rgb([250, 50, 83]))
            .save(cvat.join("SegmentationClass/frame_000000.png"))
            .unwrap();
        refused(
            &[
                "import",
                "masks",
                s(&t.path().join("cap2")),
                "--camera",
                "cam0",
                "--cvat",
                s(&cvat),
                "--label",
                "teeth=teeth",
                "--label",
                "inside=mouth",
            ],
            &["labelmap.txt", named],
        );
    }
}
