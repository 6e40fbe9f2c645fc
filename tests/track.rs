//! Tracking on short synthetic sequences: accuracy with margins, resume after an interruption,
//! frames without data.

mod common;

use std::path::Path;
use std::process::Command;

use common::copy_dir;
use jawtrack::capture::Capture;
use jawtrack::formats::TracksJson;
use jawtrack::synth::{MaskKind, Preset, SynthOptions, generate};

/// A 48-frame clean capture (the first frames move at realistic speed), once per test binary.
fn capture48() -> &'static Path {
    static DIR: std::sync::OnceLock<tempfile::TempDir> = std::sync::OnceLock::new();
    DIR.get_or_init(|| {
        let t = tempfile::tempdir().unwrap();
        let opts = SynthOptions {
            frames: 48,
            seed: 4,
            preset: Preset::Clean,
            masks: MaskKind::PerArch,
            ..SynthOptions::default()
        };
        generate(&t.path().join("c"), &opts, &|| {}).unwrap();
        t
    })
    .path()
    .join("c")
    .leak()
}

fn jawtrack(args: &[&str]) -> std::process::Output {
    let out = Command::new(env!("CARGO_BIN_EXE_jawtrack"))
        .args(args)
        .args(["--backend", "cpu"])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "jawtrack {args:?} failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

/// `jawtrack track CAPTURE -o OUT [extra]` on the CPU reference.
fn track(capture: &Path, out: &Path, extra: &[&str]) {
    let mut args = vec![
        "track",
        capture.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
    ];
    args.extend(extra);
    jawtrack(&args);
}

fn score(capture: &Path, tracks: &Path) -> serde_json::Value {
    let out = Command::new(env!("CARGO_BIN_EXE_jawtrack"))
        .args([
            "score",
            capture.to_str().unwrap(),
            tracks.to_str().unwrap(),
            "--json",
        ])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).unwrap()
}

fn frames_of(path: &Path) -> Vec<u32> {
    let t: TracksJson = serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
    t.frames.iter().map(|f| f.frame).collect()
}

#[test]
fn a_short_clean_sequence_is_tracked_accurately() {
    let t = tempfile::tempdir().unwrap();
    let out = t.path().join("tracks.json");
    let cap = capture48();
    track(cap, &out, &["--frames", "0..6"]);
    let s = score(cap, &out);
    assert_eq!(s["frames"], 6);
    assert_eq!(s["frames_ok"], 6, "{s}");
    // Measured on 48 clean frames: about 0.02-0.03 mm median per arch, 0.05 for the jaw. The
    // margins here hold a regression well before the goals (0.03 / 0.15 mm) are lost for good.
    for (part, limit) in [("upper", 0.08), ("lower", 0.08), ("jaw", 0.12)] {
        let m = s[part]["mean_vertex_mm"]["median"].as_f64().unwrap();
        let worst = s[part]["mean_vertex_mm"]["max"].as_f64().unwrap();
        assert!(
            m < limit && worst < 4.0 * limit,
            "{part}: median {m} mm, max {worst} mm"
        );
    }
    // tracks.json follows the spec: jaw pose, energy terms, area error, status; no journal left.
    let tj: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
    assert_eq!(tj["format"], "jawtrack-tracks/1");
    let f0 = &tj["frames"][0];
    for key in ["upper", "lower", "jaw", "energy", "area_error", "status"] {
        assert!(!f0[key].is_null(), "frame record without `{key}`: {f0}");
    }
    assert!(f0["energy"]["upper"]["uncovered"].is_u64());
    assert!(!t.path().join("tracks.json.journal").exists());
}

/// The Gauss-Newton solver (`--search gauss-newton`) tracks the same clean frames as well as
/// the paper's search within a few hundredths of a millimetre, with a tenth of its energy
/// evaluations; the experimental contour solver (`search.solver = contour`) within a few
/// tenths, with fewer than half (docs/energy.md has the figures). The default (`auto`) is
/// the paper's search on these per-arch masks, which do not label the mouth.
#[test]
fn the_gauss_newton_and_contour_solvers_track_clean_frames_with_few_evaluations() {
    let t = tempfile::tempdir().unwrap();
    let cap = capture48();
    // Energy evaluations per frame, as `track` reports them.
    let evaluations = |out: &std::process::Output| -> u64 {
        let text = String::from_utf8_lossy(&out.stdout);
        text.split(" energy evaluations per frame")
            .next()
            .and_then(|head| head.rsplit('(').next())
            .and_then(|n| n.trim().parse().ok())
            .unwrap_or_else(|| panic!("no evaluation count in {text}"))
    };
    let run = |name: &str, extra: &[&str]| {
        let out = t.path().join(name);
        let mut args = vec!["track", cap.to_str().unwrap(), "-o", out.to_str().unwrap()];
        args.extend(["--frames", "0..6"]);
        args.extend(extra);
        (evaluations(&jawtrack(&args)), out)
    };
    let median = |path: &Path, part: &str| {
        let s = score(cap, path);
        assert_eq!(s["frames"], 6);
        s[part]["mean_vertex_mm"]["median"].as_f64().unwrap()
    };
    let (by_paper, paper) = run("paper.json", &["--search", "paper"]);
    let (by_gn, gn) = run("gn.json", &["--search", "gauss-newton"]);
    let frames = |path: &Path| -> serde_json::Value {
        let t: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
        t["frames"].clone()
    };
    let (_, auto) = run("auto.json", &[]);
    assert_eq!(frames(&auto), frames(&paper), "auto on teeth masks alone");
    for part in ["upper", "lower", "jaw"] {
        let (m, p) = (median(&gn, part), median(&paper, part));
        assert!(
            m < p + 0.05 && m < 0.15,
            "{part}: median {m} mm (paper {p})"
        );
    }
    assert!(
        by_gn * 10 < by_paper && by_gn <= 60,
        "gauss-newton: {by_gn} evaluations a frame against {by_paper}"
    );
    let settings = r#"{"search": {"solver": "contour"}}"#;
    let (by_contour, contour) = run("contour.json", &["--settings", settings]);
    for part in ["upper", "lower", "jaw"] {
        let m = median(&contour, part);
        assert!(m < 0.5, "contour, {part}: median {m} mm");
    }
    assert!(
        by_contour * 2 < by_paper,
        "{by_contour} evaluations a frame against {by_paper}"
    );
    // The fingerprint tells the runs apart (resume may not mix them).
    let fp = |path: &Path| -> String {
        let t: TracksJson = serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
        t.fingerprint.unwrap()
    };
    assert_ne!(fp(&paper), fp(&contour));
    assert_ne!(fp(&paper), fp(&gn));
}

/// Gauss-Newton, the default search on a realistic capture (lips over the gums, wandering
/// boundaries, specular holes, the mouth labelled), tracks its first frames within the
/// tracker's usual error, and a start it cannot bring back (a frame it finds lost) goes to the
/// paper's search, which costs far more evaluations.
#[test]
fn gauss_newton_holds_realistic_frames_and_falls_back_when_lost() {
    let t = tempfile::tempdir().unwrap();
    let cap = t.path().join("cap");
    copy_dir(common::template(Preset::Realistic, MaskKind::PerArch), &cap);
    let out = t.path().join("gn.json");
    let run = |extra: &[&str]| {
        let mut args = vec!["track", cap.to_str().unwrap(), "-o", out.to_str().unwrap()];
        args.extend(["--frames", "0..4", "--force"]);
        args.extend(extra);
        jawtrack(&args)
    };
    let text = String::from_utf8_lossy(&run(&[]).stdout).to_string();
    assert!(text.contains(", search gauss-newton,"), "{text}");
    // The capture's joint is the average one: its manifold is kept.
    assert!(!text.contains("manifold does not fit"), "{text}");
    let s = score(&cap, &out);
    for part in ["upper", "lower", "jaw"] {
        let m = s[part]["mean_vertex_mm"]["median"].as_f64().unwrap();
        assert!(m < 0.6, "{part}: median {m} mm");
    }
    // Both arches started 12 mm off: the first frame is lost for Gauss-Newton.
    let init = cap.join("init.json");
    let mut v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&init).unwrap()).unwrap();
    shift_init(&mut v, 12.0);
    std::fs::write(&init, v.to_string()).unwrap();
    // Its area error (0.105) is under the default bound for a fresh look (0.2): lowered here.
    let text =
        String::from_utf8_lossy(&run(&["--settings", r#"{"relocate_area_error": 0.1}"#]).stdout)
            .to_string();
    let per_frame: f64 = text
        .split(" energy evaluations per frame")
        .next()
        .and_then(|head| head.rsplit('(').next())
        .and_then(|n| n.trim().parse().ok())
        .unwrap_or_else(|| panic!("no evaluation count in {text}"));
    assert!(
        per_frame > 100.0,
        "{per_frame} evaluations a frame: no fallback"
    );
    // Lost, the arches are found afresh from the masks (measured: jaw 0.09 mm in the first
    // frame of a capture like this one, 12 mm off at the start).
    let s = score(&cap, &out);
    let first = s["per_frame"][0][1][2].as_f64().unwrap();
    assert!(
        first < 0.6,
        "jaw {first} mm in the first frame: not found again"
    );
}

/// Without init.json the first frame's poses come from its masks alone, whatever the meshes'
/// model frame (measured: jaw 0.00-0.27 mm in the first frame on realistic masks, 0.01 on
/// clean ones; a run from the true poses has 0.0-0.31 there).
#[test]
fn without_init_json_the_arches_are_found_from_the_masks() {
    let t = tempfile::tempdir().unwrap();
    let realistic = t.path().join("realistic");
    copy_dir(
        common::template(Preset::Realistic, MaskKind::PerArch),
        &realistic,
    );
    let z_up = t.path().join("z-up");
    in_z_up_frame(common::template(Preset::Clean, MaskKind::PerArch), &z_up);
    for (cap, arch_mm, jaw_mm) in [(&realistic, 1.0, 0.6), (&z_up, 0.2, 0.2)] {
        std::fs::remove_file(cap.join("init.json")).unwrap();
        let out = t.path().join("tracks.json");
        track(
            cap,
            &out,
            &["--frames", "0..2", "--search", "gauss-newton", "--force"],
        );
        let s = score(cap, &out);
        let first = &s["per_frame"][0][1];
        let [upper, lower, jaw] = [0, 1, 2].map(|k| first[k].as_f64().unwrap());
        assert!(
            upper < arch_mm && lower < arch_mm && jaw < jaw_mm,
            "{}: first frame upper {upper}, lower {lower}, jaw {jaw} mm",
            cap.display()
        );
    }
    // A chunk later in a take, where init.json's first-frame poses do not hold: `--locate`.
    let chunk = t.path().join("chunk");
    copy_dir(
        common::template(Preset::Realistic, MaskKind::PerArch),
        &chunk,
    );
    let out = t.path().join("chunk.json");
    track(
        &chunk,
        &out,
        &["--frames", "3..5", "--search", "gauss-newton", "--locate"],
    );
    let s = score(&chunk, &out);
    assert_eq!(s["per_frame"][0][0], 3, "{s}");
    // This template moves a whole movement a frame: a run started at frame 3 from the true
    // poses leaves its jaw 0.43 mm off there (measured), the masks' own limit.
    let jaw = s["per_frame"][0][1][2].as_f64().unwrap();
    assert!(jaw < 0.8, "frame 3 found from its masks: jaw {jaw} mm");
}

/// A first frame whose masks show no teeth cannot place the arches: the error says which
/// frame, where its masks are and what would do instead.
#[test]
fn without_init_json_a_frame_without_teeth_is_a_clear_error() {
    let t = tempfile::tempdir().unwrap();
    let cap = t.path().join("cap");
    copy_dir(common::template(Preset::Realistic, MaskKind::PerArch), &cap);
    std::fs::remove_file(cap.join("init.json")).unwrap();
    let capture = Capture::open(&cap).unwrap();
    for k in 0..capture.cameras().len() {
        let path = capture.mask_path(k, 0);
        let (w, h) = image::image_dimensions(&path).unwrap();
        image::GrayImage::new(w, h).save(&path).unwrap();
    }
    let out = t.path().join("tracks.json");
    common::refused(
        &["track", cap.to_str().unwrap(), "-o", out.to_str().unwrap()],
        &["masks", "frame 0", "0 camera(s)", "init.json"],
    );
}

/// Both arches of an init.json moved `mm` sideways (the jaw as it was).
fn shift_init(init: &mut serde_json::Value, mm: f64) {
    for arch in ["upper", "lower"] {
        let x = &mut init[arch]["translation"][0];
        *x = serde_json::json!(x.as_f64().unwrap() + mm);
    }
}

fn poses_of(path: &Path) -> Vec<serde_json::Value> {
    let t: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
    t["frames"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| serde_json::json!([f["upper"], f["lower"]]))
        .collect()
}

/// The mouth label only adds the over-mouth term: with the paper's energy (`--energy paper`)
/// a labelled capture tracks exactly as the same capture without its label, and with the
/// full energy tracks.json reports the term.
#[test]
fn the_mouth_label_adds_a_term_and_changes_nothing_else() {
    let t = tempfile::tempdir().unwrap();
    // The realistic template's masks label the mouth.
    let labelled = common::template(Preset::Realistic, MaskKind::PerArch);
    let unlabelled = t.path().join("unlabelled");
    copy_dir(labelled, &unlabelled);
    let cj = unlabelled.join("capture.json");
    let mut v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&cj).unwrap()).unwrap();
    assert!(
        v["masks"]["mouth"].is_number(),
        "the synthetic capture has a label"
    );
    v["masks"].as_object_mut().unwrap().remove("mouth");
    std::fs::write(&cj, v.to_string()).unwrap();
    let (a, b, c) = (
        t.path().join("a.json"),
        t.path().join("b.json"),
        t.path().join("c.json"),
    );
    track(labelled, &a, &["--energy", "paper", "--frames", "0..3"]);
    track(&unlabelled, &b, &["--energy", "paper", "--frames", "0..3"]);
    assert_eq!(poses_of(&a), poses_of(&b));
    track(labelled, &c, &["--frames", "0..3"]);
    assert_ne!(poses_of(&a), poses_of(&c), "the term moves the poses");
    let tracks: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&c).unwrap()).unwrap();
    let energy = &tracks["frames"][1]["energy"]["lower"];
    assert!(energy["over_mouth"].is_u64(), "{energy}");
    let unlabelled_tracks: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&b).unwrap()).unwrap();
    assert_eq!(
        unlabelled_tracks["frames"][1]["energy"]["lower"]["over_mouth"],
        0
    );
}

/// Overlays show the teeth labels in white and the mouth interior in blue, never one as the
/// other (the paper's colours, plus ours for the mouth).
#[test]
fn overlays_tell_the_mouth_from_the_teeth() {
    use jawtrack::capture::masks::MOUTH_BIT;
    let t = tempfile::tempdir().unwrap();
    let capture = common::template(Preset::Realistic, MaskKind::PerArch);
    let overlays = t.path().join("overlays");
    track(
        capture,
        &t.path().join("tracks.json"),
        &["--frames", "0..3", "--overlays", overlays.to_str().unwrap()],
    );
    let c = Capture::open(capture).unwrap();
    // The front camera in the frame where the mouth is widest open.
    let (frame, mask) = (0..3)
        .map(|f| (f, c.load_masks(f).unwrap().masks[0].clone().unwrap()))
        .max_by_key(|(_, m)| m.count(MOUTH_BIT))
        .unwrap();
    let name = &c.cameras()[0].calibrated.name;
    let picture = image::open(overlays.join(name).join(format!("{frame:06}.png")))
        .unwrap()
        .to_rgb8();
    assert_eq!(
        (picture.width(), picture.height()),
        (mask.width, mask.height)
    );
    let (mut blue, mut mouth) = (0, 0);
    for (px, &label) in picture.pixels().zip(&mask.data) {
        let [r, g, b] = px.0;
        let white = r >= 200 && g >= 200 && b >= 200;
        let pure_blue = r == 0 && g == 0 && b > 100;
        if label & MOUTH_BIT != 0 {
            mouth += 1;
            assert!(!white, "a mouth pixel drawn as teeth");
            blue += pure_blue as usize;
        } else {
            assert!(!pure_blue, "a pixel off the mouth drawn as mouth");
        }
    }
    assert!(
        mouth > 100 && blue > mouth / 2,
        "{blue} of {mouth} mouth pixels blue"
    );
}

#[test]
fn an_interrupted_run_resumes_after_its_last_complete_frame() {
    let t = tempfile::tempdir().unwrap();
    let out = t.path().join("tracks.json");
    let cap = capture48();
    let (c, o) = (cap.to_str().unwrap(), out.to_str().unwrap());
    jawtrack(&["track", c, "-o", o, "--frames", "0..3"]);
    let first: TracksJson = serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
    // An interruption in frame 3: the journal holds frames 0..3 and half a line of frame 3.
    let journal = t.path().join("tracks.json.journal");
    // The journal's first line names the run (tracks.json keeps the same fingerprint).
    let head =
        serde_json::json!({"fingerprint": first.fingerprint.clone().expect("a fingerprint")});
    let mut lines: Vec<String> = std::iter::once(head.to_string())
        .chain(
            first
                .frames
                .iter()
                .map(|f| serde_json::to_string(f).unwrap()),
        )
        .collect();
    let cut = lines[3].clone();
    lines.push(cut[..cut.len() / 2].to_string());
    std::fs::write(&journal, lines.join("\n")).unwrap();
    // Without --resume or --force the output is not touched.
    let refused = Command::new(env!("CARGO_BIN_EXE_jawtrack"))
        .args(["track", c, "-o", o, "--backend", "cpu"])
        .output()
        .unwrap();
    assert!(!refused.status.success());
    assert!(String::from_utf8_lossy(&refused.stderr).contains("--resume"));
    jawtrack(&["track", c, "-o", o, "--frames", "0..5", "--resume"]);
    assert_eq!(frames_of(&out), vec![0, 1, 2, 3, 4]);
    let resumed: TracksJson =
        serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
    // Every frame as tracked is kept; the window settles the earlier run's last frames again
    // with the frames after them (a frame is final once the window's frames after it are in).
    let tracked = |f: &jawtrack::formats::FrameRecordJson| f.tracked.as_ref().map(|t| t.upper);
    for (a, b) in first.frames.iter().zip(&resumed.frames) {
        assert!(tracked(a).is_some(), "frame {}: no tracked poses", a.frame);
        assert_eq!(
            tracked(a),
            tracked(b),
            "frame {} changed on resume",
            a.frame
        );
    }
    let s = score(cap, &out);
    assert!(
        s["jaw"]["mean_vertex_mm"]["max"].as_f64().unwrap() < 0.5,
        "{s}"
    );
}

/// Found by hostile input (bf99878): a resumed run re-read its poses from JSON and went on from
/// slightly different numbers (`…810006` → `…81001`). Killed with SIGKILL once it has written
/// `k` frames and resumed, a run must write the very bytes an uninterrupted one does.
#[test]
fn a_run_killed_and_resumed_writes_the_same_bytes_as_one_never_interrupted() {
    let t = tempfile::tempdir().unwrap();
    let cap = capture48();
    let c = cap.to_str().unwrap();
    // The paper's search, and Gauss-Newton with the window over frames (which settles each
    // frame six frames later: a kill leaves frames tracked but not yet settled).
    for (name, extra) in [
        ("paper", vec!["--frames", "0..7"]),
        ("gn", vec!["--frames", "0..24", "--search", "gauss-newton"]),
    ] {
        let whole = t.path().join(format!("{name}-whole.json"));
        track(cap, &whole, &extra);
        for k in [1, 4] {
            let out = t.path().join(format!("{name}-killed{k}.json"));
            let journal = t.path().join(format!("{name}-killed{k}.json.journal"));
            let mut child = Command::new(env!("CARGO_BIN_EXE_jawtrack"))
                .args(["track", c, "-o", out.to_str().unwrap()])
                .args(&extra)
                .args(["--backend", "cpu"])
                .stdout(std::process::Stdio::null())
                .stderr(std::process::Stdio::null())
                .spawn()
                .unwrap();
            // The journal's head line, then one line per frame.
            let lines = || {
                std::fs::read_to_string(&journal)
                    .map(|s| s.matches('\n').count())
                    .unwrap_or(0)
            };
            while lines() < k + 1 {
                assert!(
                    child.try_wait().unwrap().is_none(),
                    "{name}: the run ended before it could be killed after {k} frames"
                );
                std::thread::sleep(std::time::Duration::from_millis(2));
            }
            child.kill().unwrap(); // SIGKILL on Unix
            child.wait().unwrap();
            let mut resume = extra.clone();
            resume.push("--resume");
            track(cap, &out, &resume);
            assert!(
                std::fs::read(&whole).unwrap() == std::fs::read(&out).unwrap(),
                "{name}: killed after {k} frames and resumed, tracks.json differs from an \
                 uninterrupted run's"
            );
        }
    }
}

#[test]
fn frames_without_masks_keep_the_last_pose_and_tracking_recovers() {
    let t = tempfile::tempdir().unwrap();
    let cap = t.path().join("c");
    copy_dir(capture48(), &cap);
    for camera in ["cam0", "cam1", "cam2"] {
        std::fs::remove_file(cap.join("masks").join(camera).join("000002.png")).unwrap();
    }
    assert!(Capture::open(&cap).is_ok(), "a missing mask is allowed");
    let out = t.path().join("tracks.json");
    track(&cap, &out, &["--frames", "0..5"]);
    let tj: TracksJson = serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
    let status: Vec<&str> = tj
        .frames
        .iter()
        .map(|f| f.status.unwrap().as_str())
        .collect();
    assert_eq!(status, ["ok", "ok", "no-data", "ok", "ok"]);
    assert_eq!(
        tj.frames[2].upper, tj.frames[1].upper,
        "no-data keeps the last good pose"
    );
    assert!(tj.frames[2].energy.is_none());
    let s = score(&cap, &out);
    let per_frame = s["per_frame"].as_array().unwrap();
    let jaw_error_at = |i: usize| per_frame[i][1][2].as_f64().unwrap();
    assert!(
        jaw_error_at(4) < 0.2,
        "recovered after the gap: {}",
        jaw_error_at(4)
    );
}

/// A run of `capture` over frames `first` (`A..B`), resumed over 0..5, writes the bytes of
/// `one_run` (one run over 0..5); `after` names what the first run stopped after.
fn resumes_the_same(capture: &Path, one_run: &Path, first: &str, after: &str) {
    let resumed = one_run.with_file_name("resumed.json");
    track(capture, &resumed, &["--frames", first]);
    track(capture, &resumed, &["--frames", "0..5", "--resume"]);
    assert!(
        std::fs::read(one_run).unwrap() == std::fs::read(&resumed).unwrap(),
        "resumed after {after}, tracks.json differs from one run's"
    );
}

/// Lips closed over the teeth in frame 2 (its masks show none): the frame is written
/// `low-confidence` with `teeth_hidden`, tracking goes on from it as from an `ok` frame (the
/// same poses as with the flag off), and a run resumed after it writes what one run does.
#[test]
fn frames_whose_masks_hide_the_teeth_are_flagged_and_tracking_goes_on() {
    let t = tempfile::tempdir().unwrap();
    let cap = t.path().join("c");
    copy_dir(capture48(), &cap);
    for camera in ["cam0", "cam1", "cam2"] {
        let path = cap.join("masks").join(camera).join("000002.png");
        let mut mask = image::open(&path).unwrap().into_luma8();
        mask.pixels_mut().for_each(|p| p.0[0] = 0);
        mask.save(&path).unwrap();
    }
    let read = |p: &Path| -> TracksJson {
        serde_json::from_str(&std::fs::read_to_string(p).unwrap()).unwrap()
    };
    let status = |t: &TracksJson| -> Vec<(&'static str, bool)> {
        t.frames
            .iter()
            .map(|f| (f.status.unwrap().as_str(), f.teeth_hidden))
            .collect()
    };
    let flagged = t.path().join("flagged.json");
    track(&cap, &flagged, &["--frames", "0..5"]);
    let off = t.path().join("off.json");
    let no_flag = [
        "--frames",
        "0..5",
        "--settings",
        r#"{"hidden_teeth_share": 0}"#,
    ];
    track(&cap, &off, &no_flag);
    let (a, b) = (read(&flagged), read(&off));
    let ok = ("ok", false);
    assert_eq!(status(&a), [ok, ok, ("low-confidence", true), ok, ok]);
    assert_eq!(status(&b), [ok; 5]);
    for (x, y) in a.frames.iter().zip(&b.frames) {
        assert_eq!((x.upper, x.lower), (y.upper, y.lower), "frame {}", x.frame);
    }
    resumes_the_same(&cap, &flagged, "0..3", "the hidden frame");
}

/// Frame 2's masks claim teeth where there are none (a block of upper arch in a corner of each
/// camera): no pose explains them, and the frame is tracked `low-confidence`. Frame 3, clean
/// again, is tracked `ok` from a start frame 2 could not vouch for: it is written
/// `low-confidence` with `recovered`, tracking goes on from it as from an `ok` frame, and a
/// run resumed after it writes what one run does.
#[test]
fn the_first_frame_found_again_after_a_loss_is_flagged_and_tracking_goes_on() {
    let t = tempfile::tempdir().unwrap();
    let cap = t.path().join("c");
    copy_dir(capture48(), &cap);
    let spec: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(cap.join("capture.json")).unwrap()).unwrap();
    let upper = spec["masks"]["upper"].as_u64().unwrap() as u8;
    for camera in ["cam0", "cam1", "cam2"] {
        let path = cap.join("masks").join(camera).join("000002.png");
        let mut mask = image::open(&path).unwrap().into_luma8();
        let (w, h) = mask.dimensions();
        for (x, y, p) in mask.enumerate_pixels_mut() {
            if x < w / 3 && y < h / 3 {
                p.0[0] = upper;
            }
        }
        mask.save(&path).unwrap();
    }
    let out = t.path().join("tracks.json");
    track(&cap, &out, &["--frames", "0..5"]);
    let tj: TracksJson = serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
    let status: Vec<(&str, bool)> = tj
        .frames
        .iter()
        .map(|f| (f.status.unwrap().as_str(), f.recovered))
        .collect();
    let (ok, low) = (("ok", false), ("low-confidence", false));
    assert_eq!(status, [ok, ok, low, ("low-confidence", true), ok]);
    let s = score(&cap, &out);
    let jaw_error_at = |i: usize| s["per_frame"][i][1][2].as_f64().unwrap();
    assert!(jaw_error_at(4) < 0.2, "found again: {}", jaw_error_at(4));
    resumes_the_same(&cap, &out, "0..4", "the recovered frame");
}

/// The capture with its meshes written in another model frame (z up, -y anterior: a common
/// CAD convention) and its poses changed to match: the same motion, other files.
fn in_z_up_frame(src: &Path, dst: &Path) {
    copy_dir(src, dst);
    // model' = R model, R = 90° about x: (x, y, z) -> (x, -z, y).
    for arch in ["upper", "lower"] {
        let path = dst.join("meshes").join(format!("{arch}.obj"));
        let obj: String = std::fs::read_to_string(&path)
            .unwrap()
            .lines()
            .map(|line| match line.strip_prefix("v ") {
                Some(v) => {
                    let c: Vec<f64> = v.split_whitespace().map(|x| x.parse().unwrap()).collect();
                    format!("v {} {} {}\n", c[0], -c[2], c[1])
                }
                None => format!("{line}\n"),
            })
            .collect();
        std::fs::write(&path, obj).unwrap();
    }
    // A pose maps model to world: R_pose' = R_pose Rᵀ, each row (a, b, c) -> (a, -c, b).
    let turn = |pose: &mut serde_json::Value| {
        for row in pose["rotation"].as_array_mut().unwrap() {
            let r: Vec<f64> = serde_json::from_value(row.clone()).unwrap();
            *row = serde_json::json!([r[0], -r[2], r[1]]);
        }
    };
    common::edit_json(&dst.join("init.json"), |v| {
        turn(&mut v["upper"]);
        turn(&mut v["lower"]);
    });
    common::edit_json(&dst.join("gt/poses.json"), |v| {
        for f in v["frames"].as_array_mut().unwrap() {
            turn(&mut f["upper"]);
            turn(&mut f["lower"]);
            f.as_object_mut().unwrap().remove("jaw");
        }
    });
}

#[test]
fn meshes_in_another_model_frame_track_as_well() {
    // Six frames, a whole movement apart: the jaw prior finds each. With the prior built in
    // the meshes' own axes, the z-up copy lost the jaw (31.6 mm in frame 5); measured now:
    // 0.17 mm (as written) and 0.20 mm (z up), worst frame.
    let t = tempfile::tempdir().unwrap();
    let src = common::template(Preset::Clean, MaskKind::PerArch);
    let z_up = t.path().join("z-up");
    in_z_up_frame(src, &z_up);
    for cap in [src, z_up.as_path()] {
        let out = t.path().join("tracks.json");
        track(cap, &out, &["--force"]);
        let s = score(cap, &out);
        let worst = s["jaw"]["mean_vertex_mm"]["max"].as_f64().unwrap();
        assert!(worst < 0.6, "{}: jaw worst {worst} mm", cap.display());
    }
}

#[test]
fn a_capture_filmed_through_a_lens_tracks_as_well() {
    // The six-frame clean capture of the test above, with a barrel lens written to the camera
    // files and the masks drawn through it. Measured: worst jaw 0.09 mm through the lens,
    // 0.17 mm without it. On masks drawn independently of the energy (README, The energy),
    // undistorting the masks at load instead (the code before) tracked the lower arch at
    // 0.071 mm median, drawing through the lens at 0.027.
    let t = tempfile::tempdir().unwrap();
    let cap = common::lens_template(Preset::Clean);
    let out = t.path().join("tracks.json");
    track(cap, &out, &[]);
    let s = score(cap, &out);
    assert_eq!(s["frames_ok"], 6, "{s}");
    for (part, median, worst) in [
        ("upper", 0.06, 0.3),
        ("lower", 0.06, 0.3),
        ("jaw", 0.1, 0.4),
    ] {
        let m = s[part]["mean_vertex_mm"]["median"].as_f64().unwrap();
        let w = s[part]["mean_vertex_mm"]["max"].as_f64().unwrap();
        assert!(
            m < median && w < worst,
            "{part}: median {m} mm, worst {w} mm"
        );
    }
}

#[test]
fn masks_read_at_half_their_resolution_track_nearly_as_well() {
    // The clean capture's first six frames with `--mask-reduce 2` (480x270 masks, 0.8 mm a
    // pixel at the teeth). Measured: medians upper 0.14, lower 0.17, jaw 0.26 mm, worst jaw
    // 0.36, against a worst jaw of 0.17 mm at full resolution (the lens test above). The
    // margins catch a lost or misplaced track; the alignment itself is tested exactly in
    // synth_and_energy.rs.
    let t = tempfile::tempdir().unwrap();
    let out = t.path().join("tracks.json");
    let cap = capture48();
    track(cap, &out, &["--frames", "0..6", "--mask-reduce", "2"]);
    let s = score(cap, &out);
    assert_eq!(s["frames_ok"], 6, "{s}");
    for (part, median, worst) in [("upper", 0.3, 0.6), ("lower", 0.3, 0.6), ("jaw", 0.45, 0.8)] {
        let m = s[part]["mean_vertex_mm"]["median"].as_f64().unwrap();
        let w = s[part]["mean_vertex_mm"]["max"].as_f64().unwrap();
        assert!(
            m < median && w < worst,
            "{part}: median {m} mm, worst {w} mm"
        );
    }
}

#[test]
fn settings_come_from_a_file_or_inline_and_a_misspelt_field_is_an_error() {
    let t = tempfile::tempdir().unwrap();
    let cap = capture48();
    let c = cap.to_str().unwrap();
    let settings = r#"{"search": {"scales": [1.0], "sample_rounds": 0}, "jaw_prior_nearest": 5}"#;
    let file = t.path().join("settings.json");
    std::fs::write(&file, settings).unwrap();
    let (from_file, inline) = (t.path().join("a.json"), t.path().join("b.json"));
    let f = file.to_str().unwrap();
    track(cap, &from_file, &["--frames", "0..2", "--settings", f]);
    track(cap, &inline, &["--frames", "0..2", "--settings", settings]);
    let read = |p: &Path| -> TracksJson {
        serde_json::from_str(&std::fs::read_to_string(p).unwrap()).unwrap()
    };
    let (a, b) = (read(&from_file), read(&inline));
    assert_eq!(a.frames.len(), 2);
    for (x, y) in a.frames.iter().zip(&b.frames) {
        assert_eq!((x.upper, x.lower), (y.upper, y.lower));
    }
    // A misspelt field names where it came from and the field; nothing is written.
    let refused = |settings: &str, out: &Path| {
        let r = Command::new(env!("CARGO_BIN_EXE_jawtrack"))
            .args(["track", c, "-o", out.to_str().unwrap(), "--backend", "cpu"])
            .args(["--settings", settings])
            .output()
            .unwrap();
        assert!(!r.status.success());
        assert!(!out.exists());
        String::from_utf8_lossy(&r.stderr).into_owned()
    };
    let err = refused(r#"{"search": {"lamda": 1.0}}"#, &t.path().join("c.json"));
    assert!(
        err.contains("--settings") && err.contains("search.lamda") && err.contains("unknown field"),
        "{err}"
    );
    std::fs::write(&file, r#"{"restart": 2}"#).unwrap();
    let err = refused(f, &t.path().join("d.json"));
    assert!(err.contains(f) && err.contains("`restart`"), "{err}");
    // The message says it once (no cause chain repeating it).
    assert_eq!(err.matches("unknown field").count(), 1, "{err}");
}

/// `--two-pass` tracks, learns the subject's rig from the frames tracked ok and tracks again
/// held to it (measured on 48 realistic frames: jaw 0.32 / 0.68 mm median / p95 in the first
/// pass, 0.35 / 1.14 in the second: docs/tracking.md).
#[test]
fn two_passes_learn_the_subjects_rig_and_track_held_to_it() {
    let t = tempfile::tempdir().unwrap();
    let cap = t.path().join("cap");
    generate(
        &cap,
        &SynthOptions {
            frames: 16,
            seed: 5,
            preset: Preset::Realistic,
            ..SynthOptions::default()
        },
        &|| {},
    )
    .unwrap();
    let out = t.path().join("tracks.json");
    track(&cap, &out, &["--search", "gauss-newton", "--two-pass"]);
    let first = t.path().join("tracks.pass1.json");
    let rig = t.path().join("tracks.rig.json");
    assert!(
        first.exists() && rig.exists(),
        "no first pass or rig beside the output"
    );
    let jaw = |path: &Path| {
        score(&cap, path)["jaw"]["mean_vertex_mm"]["median"]
            .as_f64()
            .unwrap()
    };
    let (one, two) = (jaw(&first), jaw(&out));
    assert!(
        two < 0.6 && two < one + 0.15,
        "jaw median {one} mm, then {two} mm held to the rig"
    );
    // The rig file is one `track --rig` takes too; a file that is not a rig is refused.
    let again = t.path().join("again.json");
    track(
        &cap,
        &again,
        &["--search", "gauss-newton", "--rig", rig.to_str().unwrap()],
    );
    let from_file = jaw(&again);
    assert!(
        (from_file - two).abs() < 0.02,
        "{from_file} mm from the file, {two} mm"
    );
    common::refused(
        &[
            "track",
            cap.to_str().unwrap(),
            "-o",
            t.path().join("x.json").to_str().unwrap(),
            "--rig",
            first.to_str().unwrap(),
        ],
        &["tracks.pass1.json"],
    );
}

/// Both floors the bench reports, on clean per-arch masks (with the mouth labelled): the
/// pixel count's minimum and where Gauss-Newton's steps on the smooth energy settle, each
/// from the true poses, lie at the truth. With realistic masks' noise both lie farther off,
/// the smooth energy's twice as far (0.42-0.51 mm against 0.17-0.26 when this was written),
/// but within a millimetre. The pixel count's floor is searched from the tracked poses too and
/// keeps the lower landing: a start 2 mm off never raises it.
#[test]
fn the_floors_lie_at_the_truth_on_clean_masks() {
    use jawtrack::arch::{Arch, ArchPoses};
    use jawtrack::energy::{CpuEnergy, EnergyEngine, Scene};
    use jawtrack::geometry::Pose;
    use jawtrack::track::floor::{FloorCheck, floor_poses, objective_sum};
    use jawtrack::track::prior_and_penalties;
    use nalgebra::Vector3;
    for (preset, pixel_mm, smooth_mm) in [(Preset::Clean, 0.04, 0.1), (Preset::Realistic, 0.5, 1.0)]
    {
        let capture = Capture::open(common::template(preset, MaskKind::PerArch)).unwrap();
        let settings = jawtrack::track::TrackSettings::default().for_capture(&capture);
        let (_, penalties) =
            prior_and_penalties(&capture, &settings, &capture.initial_poses().unwrap());
        let mut engine = CpuEnergy::new(Scene::from_capture(&capture));
        for frame in [0, 3] {
            let masks = capture.load_masks(frame).unwrap();
            engine.set_frame(&masks).unwrap();
            let truth = capture.gt_poses(frame).unwrap();
            let f = FloorCheck::of(
                &capture,
                &engine,
                &masks,
                (&truth, &truth),
                (&settings.search, &penalties),
            )
            .unwrap();
            eprintln!(
                "{preset:?} frame {frame}: floor {:.4} mm, smooth {:.4} mm",
                f.jaw_mm, f.smooth_jaw_mm
            );
            assert!(f.jaw_mm < pixel_mm, "{preset:?} frame {frame}: {f:?}");
            assert!(
                f.smooth_jaw_mm < smooth_mm,
                "{preset:?} frame {frame}: {f:?}"
            );
            // A tracked pose 2 mm off is a second start: the floor keeps the lower landing,
            // never above the truth's own.
            let shift = Pose::from_translation(Vector3::new(2.0, 0.0, 0.0));
            let off = truth.with(Arch::Lower, shift.compose(&truth.lower));
            let weights = settings.search.weights();
            let alone = floor_poses(&capture, &engine, (&truth, &truth), frame, &weights).unwrap();
            let both = floor_poses(&capture, &engine, (&truth, &off), frame, &weights).unwrap();
            let objective = |p: &ArchPoses| objective_sum(&engine, p, &weights).unwrap();
            assert!(
                objective(&both) <= objective(&alone),
                "{preset:?} frame {frame}: {} > {}",
                objective(&both),
                objective(&alone)
            );
            if preset == Preset::Clean {
                let metric = jawtrack::anatomy::MeshMetric::new(capture.lower());
                let jaw_mm = metric.mean_distance(&both.jaw(), &truth.jaw());
                assert!(jaw_mm < pixel_mm, "frame {frame}: {jaw_mm} mm");
            }
        }
    }
}
