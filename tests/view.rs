//! `jawtrack view` in a real browser: Chromium headless (SwiftShader's WebGL2), driven over
//! WebDriver by chromedriver, as a user would drive it: the page loads with every outside host
//! unreachable, moving the opening slider redraws the jaw and nothing else, a dragged vertex
//! lands on its target by IK, a keyframed animation exports as glTF the Khronos validator
//! accepts and its keys re-import, and a tracked capture scrubs with each camera's overlay.
//!
//! Needs `chromium` and `chromedriver` (Debian: chromium, chromium-driver). Without them the
//! tests skip with a message, unless JAWTRACK_REQUIRE_BROWSER=1 (set by CI, which installs
//! them).

mod common;

use common::ok;

use std::path::{Path, PathBuf};
use std::process::Command;

use common::browser::{Browser, serve};
use serde_json::{Value, json};

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

fn have_browser() -> bool {
    let found = ["chromium", "chromedriver"]
        .iter()
        .all(|p| Command::new(p).arg("--version").output().is_ok());
    if !found {
        assert!(
            std::env::var_os("JAWTRACK_REQUIRE_BROWSER").is_none(),
            "JAWTRACK_REQUIRE_BROWSER is set but `chromium` or `chromedriver` is not on the PATH"
        );
        eprintln!("skipped: no `chromium` and `chromedriver` on the PATH");
    }
    found
}

fn fixture() -> &'static common::RigFixture {
    common::rig_fixture()
}

fn f64s(v: &Value) -> Vec<f64> {
    v.as_array()
        .unwrap_or_else(|| panic!("not a list: {v}"))
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect()
}

/// The page loads with no host but this one reachable, and every resource came from it;
/// moving the opening slider moves the jaw: the pictures differ inside the moving meshes'
/// screen box (before and after) and are the same everywhere else. While it moves, coarse
/// meshes (the same vertices, fewer triangles) are drawn into fewer pixels.
#[test]
fn the_page_loads_offline_and_the_opening_slider_moves_only_the_jaw() {
    if !have_browser() {
        return;
    }
    let f = fixture();
    let (_server, url) = serve(&[s(&f.rig), "--capture", s(&f.capture)]);
    let b = Browser::start();
    b.go(&url);
    let origins =
        b.js("return performance.getEntriesByType('resource').map((e) => new URL(e.name).origin)");
    let here = url.trim_end_matches('/');
    for o in origins.as_array().unwrap() {
        assert_eq!(o.as_str().unwrap(), here, "a resource from elsewhere");
    }
    assert_eq!(
        b.js("return !!document.querySelector('canvas').getContext('webgl2')"),
        json!(true)
    );

    // The screen box of the lower arch and mandible at the current pose.
    let moving_box = "const b = [1e9, 1e9, -1e9, -1e9];
        for (const part of ['lower', 'mandible']) { const count = window.view.vertexCount(part);
          for (let v = 0; v < count; v++) { const [x, y] = window.view.toCanvas(window.view.posed(part, v));
            b[0] = Math.min(b[0], x); b[1] = Math.min(b[1], y); b[2] = Math.max(b[2], x); b[3] = Math.max(b[3], y); } }
        return b;";
    let before_box = f64s(&b.js(moving_box));
    let before = b.canvas_shot();
    let redraws = b.js("return window.view.redraws.length").as_u64().unwrap();
    // While the slider moves the page draws the coarse meshes into half the pixels each way,
    // and the full picture once it rests.
    let moving = b.js("const s = document.getElementById('opening'); s.value = 20; s.dispatchEvent(new Event('input')); const c = document.getElementById('gl'); return [c.width, c.height]");
    assert_eq!(moving, json!([380, 280]));
    b.wait(&format!(
        "return window.view.redraws.length > {redraws} && window.view.idle()"
    ));
    assert_eq!(
        b.js("const c = document.getElementById('gl'); return [c.width, c.height]"),
        json!([760, 560])
    );
    let counts = b.js("return Promise.all(['lower', 'lower.coarse'].map(async (n) => Array.from(new Uint32Array(await (await fetch(`/mesh/${n}.bin`)).arrayBuffer(), 0, 2))))");
    let (full, coarse) = (f64s(&counts[0]), f64s(&counts[1]));
    assert_eq!(full[0], coarse[0], "the same vertices: {counts}");
    assert!(coarse[1] <= 3000.0 && coarse[1] < full[1] / 2.0, "{counts}");
    let opening = b
        .js("return window.view.reply.animator.opening_deg")
        .as_f64()
        .unwrap();
    assert!((opening - 20.0).abs() < 0.05, "opening {opening}");
    let after_box = f64s(&b.js(moving_box));
    let after = b.canvas_shot_changed_from(&before);
    if let Some(dir) = std::env::var_os("JAWTRACK_VIEW_SHOTS") {
        let dir = PathBuf::from(dir);
        before.save(dir.join("before.png")).unwrap();
        after.save(dir.join("after.png")).unwrap();
    }
    assert_eq!(before.dimensions(), after.dimensions());
    // Device pixels per CSS pixel (1 here; kept general).
    let scale = before.width() as f64
        / b.js("return window.view.canvasRect().width")
            .as_f64()
            .unwrap();
    let inside = |x: u32, y: u32| {
        let (x, y) = (x as f64 / scale, y as f64 / scale);
        [&before_box, &after_box]
            .iter()
            .any(|bx| x >= bx[0] - 3.0 && x <= bx[2] + 3.0 && y >= bx[1] - 3.0 && y <= bx[3] + 3.0)
    };
    let (mut changed_inside, mut changed_outside) = (0, 0);
    for (x, y, p) in after.enumerate_pixels() {
        if p != before.get_pixel(x, y) {
            if inside(x, y) {
                changed_inside += 1;
            } else {
                changed_outside += 1;
            }
        }
    }
    assert!(
        changed_inside > 2000,
        "only {changed_inside} pixels changed"
    );
    assert_eq!(changed_outside, 0, "pixels changed away from the jaw");
    // The page reports its frame time (benches/view.rs measures it).
    let reported = b.js("return document.getElementById('frame-time').textContent");
    assert!(
        reported.as_str().unwrap().starts_with("redraw "),
        "{reported}"
    );
}

/// Seen from the side, the front-most mandible vertex under the cursor is dragged to where
/// the rig puts it at 15° of opening; on release IK has brought it within 0.5 mm of the point
/// the page aimed at, and the sliders followed.
#[test]
fn a_dragged_vertex_lands_on_its_target() {
    if !have_browser() {
        return;
    }
    let f = fixture();
    let (_server, url) = serve(&[s(&f.rig), "--capture", s(&f.capture)]);
    let b = Browser::start();
    b.go(&url);
    b.js("window.view.setOrbit(Math.PI / 2, 0)");
    // A vertex the cursor picks at its own place (the front-most one there), and where it
    // goes at 15° of opening with the protrusion in the middle of its valid range there.
    let plan = b.js_async(
        "const v = window.view, part = v.movingPart();
         let vertex = 0, best = -1e9;
         for (let i = 0; i < v.vertexCount(part); i++) { const p = v.posed(part, i); if (p[2] - p[1] > best) { best = p[2] - p[1]; vertex = i; } }
         for (let k = 0; k < 5; k++) { const [x, y] = v.toCanvas(v.posed(part, vertex)); const hit = v.pick(x, y); if (!hit || (hit.part === part && hit.vertex === vertex)) break; vertex = hit.vertex; }
         const from = v.toCanvas(v.posed(part, vertex));
         const rest = v.jaw(), params = v.params;
         const ask = async (target) => (await fetch('/api/pose', {method: 'POST', headers: {'Content-Type': 'application/json'}, body: JSON.stringify({target, from: params})})).json();
         const range = (await ask([15, 0, 0])).protrusion_range_mm;
         const reply = await ask([15, 0, (range[0] + range[1]) / 2]);
         if (!reply.valid || !reply.reached) return 'not a valid pose: ' + JSON.stringify(reply);
         const m = reply.jaw, p = v.vertexPosition(part, vertex);
         const moved = [0, 1, 2].map((r) => m[r] * p[0] + m[4 + r] * p[1] + m[8 + r] * p[2] + m[12 + r]);
         const to = v.toCanvas(moved);
         const r = v.canvasRect();
         return {part, vertex, from: [from[0] + r.x, from[1] + r.y], to: [to[0] + r.x, to[1] + r.y], rest};",
    );
    assert!(plan.is_object(), "{plan}");
    let from = f64s(&plan["from"]);
    let to = f64s(&plan["to"]);
    assert!(
        (from[0] - to[0]).hypot(from[1] - to[1]) > 20.0,
        "the drag is too short to test: {plan}"
    );
    b.drag([from[0], from[1]], [to[0], to[1]]);
    b.wait("return window.view.idle() && window.view.lastDrag !== null && !window.view.dragging()");
    let drag = b.js("return window.view.lastDrag");
    assert_eq!(drag["vertex"], plan["vertex"], "{drag}");
    let target = f64s(&drag["target"]);
    let reached = f64s(&b.js(&format!(
        "return window.view.posed('{}', {})",
        drag["part"].as_str().unwrap(),
        drag["vertex"]
    )));
    let miss = (0..3)
        .map(|k| (target[k] - reached[k]).powi(2))
        .sum::<f64>()
        .sqrt();
    assert!(
        miss < 0.5,
        "the vertex is {miss} mm from its target: {drag}"
    );
    let opening = b
        .js("return Number(document.getElementById('opening').value)")
        .as_f64()
        .unwrap();
    assert!(
        opening > 5.0,
        "the opening slider did not follow: {opening}"
    );
    eprintln!(
        "drag: vertex {} within {miss:.3} mm of its target; IK {} ms; opening slider at {opening:.1}°",
        drag["vertex"], drag["milliseconds"]
    );
}

/// Two keys set with the page's buttons export as glTF that the Khronos validator accepts
/// with its animation, and the keys exported re-import as they were.
#[test]
fn a_keyframed_animation_exports_and_reimports() {
    if !have_browser() {
        return;
    }
    let f = fixture();
    let (_server, url) = serve(&[s(&f.rig), "--capture", s(&f.capture)]);
    let b = Browser::start();
    b.go(&url);
    b.js("document.getElementById('key-time').value = 0; document.getElementById('set-key').click();");
    let redraws = b.js("return window.view.redraws.length").as_u64().unwrap();
    b.js("const s = document.getElementById('opening'); s.value = 18; s.dispatchEvent(new Event('input'));");
    b.wait(&format!(
        "return window.view.redraws.length > {redraws} && window.view.idle()"
    ));
    b.js("document.getElementById('key-time').value = 1.5; document.getElementById('set-key').click();");
    let keys = b.js("return window.view.keys");
    assert_eq!(keys.as_array().unwrap().len(), 2, "{keys}");
    assert!((keys[1]["params"][0].as_f64().unwrap() - 18.0).abs() < 0.05);
    // A key moved in time stays a key, in order.
    b.js("const t = document.querySelectorAll('#keys input')[1]; t.value = 2; t.dispatchEvent(new Event('change'));");
    assert_eq!(b.js("return window.view.keys[1].time").as_f64(), Some(2.0));

    let gltf = b.js_async("return await window.view.exportGltf();");
    let text = gltf.as_str().unwrap();
    assert!(!text.starts_with("error"), "{text}");
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("keys.gltf");
    std::fs::write(&path, text).unwrap();
    if let Some(report) = common::validate_gltf(&path) {
        assert_eq!(report["errors"], 0, "{report}");
        assert_eq!(report["warnings"], 0, "{report}");
        assert_eq!(report["animations"], 1, "{report}");
    }
    let doc: Value = serde_json::from_str(text).unwrap();
    let times = doc["accessors"]
        .as_array()
        .unwrap()
        .iter()
        .filter_map(|a| a["max"].as_array().filter(|m| m.len() == 1))
        .map(|m| m[0].as_f64().unwrap())
        .fold(0.0, f64::max);
    assert!((times - 2.0).abs() < 0.05, "the animation lasts {times} s");

    let keys = b.js("return window.view.keys");
    let exported = b.js("return window.view.keysJson()");
    b.js("window.view.importKeys('[]')");
    assert_eq!(b.js("return window.view.keys.length"), json!(0));
    let again = b.js(&format!(
        "window.view.importKeys({exported}); return window.view.keys"
    ));
    assert_eq!(again, keys);
    // The same keys drive `rig animate --animator` (one keys format for the page and the CLI).
    let keys_file = dir.path().join("keys.json");
    std::fs::write(&keys_file, exported.as_str().unwrap()).unwrap();
    let out = dir.path().join("jaw.json");
    ok(&[
        "rig",
        "animate",
        s(&f.rig),
        "--keys-file",
        s(&keys_file),
        "--animator",
        "-o",
        s(&out),
    ]);
}

/// With a capture and its tracks: the timeline lists every tracked frame, and scrubbing to
/// one shows its tracked pose and each camera's overlay picture.
#[test]
fn the_tracked_timeline_scrubs_with_the_overlays() {
    if !have_browser() {
        return;
    }
    let f = fixture();
    let tracks = f.capture.join("gt/poses.json");
    let (_server, url) = serve(&[
        s(&f.rig),
        "--capture",
        s(&f.capture),
        "--tracks",
        s(&tracks),
    ]);
    let b = Browser::start();
    b.go(&url);
    assert_eq!(
        b.js("return window.view.scene.timeline.frames.length"),
        json!(40)
    );
    b.js("const s = document.getElementById('scrub'); s.value = 25; s.dispatchEvent(new Event('input'));");
    b.wait("return Array.from(document.querySelectorAll('#overlays img')).every((i) => i.complete && i.naturalWidth > 0)");
    assert_eq!(b.js("return window.view.trackedFrame"), json!(25));
    let sizes = b.js("return Array.from(document.querySelectorAll('#overlays img')).map((i) => [i.naturalWidth, i.naturalHeight])");
    // Each picture is the region around the teeth, at the frame's aspect.
    for size in sizes.as_array().unwrap() {
        let (w, h) = (size[0].as_f64().unwrap(), size[1].as_f64().unwrap());
        assert!((240.0..=960.0).contains(&w) && h <= 540.0, "{sizes}");
        assert!((w / h - 960.0 / 540.0).abs() < 0.05, "{sizes}");
    }
    // The timeline reads: its axes cover the curves in their units, and the frame under the
    // pointer is said in words; a click there shows it.
    let axes = b.js("return window.view.timelineAxes");
    let range = |key: &str| {
        b.js(&format!(
            "const v = window.view.scene.timeline.frames.map((f) => f.animator.{key}); return [Math.min(...v), Math.max(...v)]"
        ))
    };
    let covers = |ticks: &serde_json::Value, [lo, hi]: [f64; 2]| {
        let t: Vec<f64> = ticks
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect();
        assert!(
            t.len() >= 2 && t[0] <= lo && *t.last().unwrap() >= hi,
            "{t:?} for {lo}..{hi}"
        );
    };
    let pair = |v: serde_json::Value| [v[0].as_f64().unwrap(), v[1].as_f64().unwrap()];
    covers(&axes["degrees"], pair(range("opening_deg")));
    let (lat, pro) = (pair(range("lateral_mm")), pair(range("protrusion_mm")));
    covers(&axes["mm"], [lat[0].min(pro[0]), lat[1].max(pro[1])]);
    let frames = axes["frames"].as_array().unwrap();
    assert!(frames.len() >= 3, "{axes}");
    assert!(
        frames
            .iter()
            .all(|f| (0..40).contains(&f.as_i64().unwrap())),
        "{axes}"
    );
    let readout = b.js("return document.getElementById('timeline-readout').textContent");
    assert!(
        readout
            .as_str()
            .unwrap()
            .starts_with("frame 25 (ok): opening "),
        "{readout}"
    );
    let point = |event: &str| {
        format!(
            "const c = document.getElementById('timeline'), r = c.getBoundingClientRect();              const x = 52 + (10 / 39) * (c.width - 104);              c.dispatchEvent(new MouseEvent('{event}', {{clientX: r.left + x * r.width / c.width, clientY: r.top + 40, bubbles: true}}));"
        )
    };
    b.js(&point("mousemove"));
    let readout = b.js("return document.getElementById('timeline-readout').textContent");
    assert!(
        readout.as_str().unwrap().starts_with("frame 10 ("),
        "{readout}"
    );
    assert!(
        readout.as_str().unwrap().contains(" mm, protrusion "),
        "{readout}"
    );
    b.js(&point("click"));
    assert_eq!(b.js("return window.view.trackedFrame"), json!(10));
}

/// Per frame of `tracks`, the jaw's mean vertex error against the truth (mm).
fn jaw_errors(capture: &jawtrack::capture::Capture, tracks: &Path) -> Vec<(u32, f64)> {
    let t: jawtrack::formats::TracksJson =
        serde_json::from_slice(&std::fs::read(tracks).unwrap()).unwrap();
    let report = jawtrack::track::score_records(capture, tracks, &t.frames)
        .unwrap()
        .unwrap();
    report.per_frame.iter().map(|(f, e)| (*f, e[2])).collect()
}

/// The page as the tracker's workbench. The lower arch is lost from frame 20 on (2 mm off,
/// flagged); on frame 20 the user drags it back with the mouse in camera 0's picture (the
/// energy's terms drop as it moves), saves the frame as hand-set and tracks the frames after it
/// again: they come back to the tracker's usual error, tracks.json marks frame 20 as set by
/// hand, and the file as it was is kept. A re-track stopped at once keeps every frame.
#[test]
fn a_lost_frame_corrected_with_the_mouse_tracks_again_from_there() {
    if !have_browser() {
        return;
    }
    use jawtrack::formats::{PoseJson, Status, TracksJson};
    use jawtrack::geometry::Pose;
    use nalgebra::Vector3;
    let f = fixture();
    let dir = tempfile::tempdir().unwrap();
    let tracks = dir.path().join("tracks.json");
    ok(&[
        "track",
        s(&f.capture),
        "-o",
        s(&tracks),
        "--search",
        "gauss-newton",
    ]);
    let capture = jawtrack::capture::Capture::open(&f.capture).unwrap();
    let usual = jaw_errors(&capture, &tracks);
    let usual_max = usual.iter().map(|e| e.1).fold(0.0, f64::max);

    // Lose the lower arch from frame 20 on: 2 mm along camera 0's x axis.
    let cam = capture.cameras()[0].mask_camera().unwrap();
    let shift = cam.camera_from_world.rotation.inverse() * Vector3::new(2.0, 0.0, 0.0);
    let mut t: TracksJson = serde_json::from_slice(&std::fs::read(&tracks).unwrap()).unwrap();
    for r in t.frames.iter_mut().filter(|r| r.frame >= 20) {
        let poses = r.poses(&tracks).unwrap();
        let lower = Pose::from_translation(shift).compose(&poses.lower);
        r.lower = PoseJson::from(&lower);
        r.jaw = Some(PoseJson::from(&poses.upper.inverse().compose(&lower)));
        r.tracked = None;
        r.status = Some(Status::LowConfidence);
    }
    std::fs::write(&tracks, serde_json::to_vec(&t).unwrap()).unwrap();
    let lost = jaw_errors(&capture, &tracks);
    assert!(
        lost.iter().filter(|e| e.0 > 20).all(|e| e.1 > 1.5),
        "{lost:?}"
    );
    // How far that is in camera 0's picture, at the lower arch's centre.
    let (lo, hi) = capture.lower().bounds();
    let centre = Vector3::from_fn(|i, _| 0.5 * (lo[i] + hi[i]) as f64);
    let lower20 = t.frames[20].poses(&tracks).unwrap().lower;
    let depth = cam
        .camera_from_world
        .transform_point(&lower20.transform_point(&centre))
        .z;
    let pixels = 2.0 * cam.fx / depth;

    let (_server, url) = serve(&[
        s(&f.rig),
        "--capture",
        s(&f.capture),
        "--tracks",
        s(&tracks),
        "--search",
        "gauss-newton",
    ]);
    let b = Browser::start();
    b.go(&url);
    b.js("const s = document.getElementById('scrub'); s.value = 20; s.dispatchEvent(new Event('input'));");
    b.wait("return Array.from(document.querySelectorAll('#overlays img')).every((i) => i.complete && i.naturalWidth > 0)");
    let img = b.js("const i = document.getElementById('overlay-cam0'); i.scrollIntoView(); const r = i.getBoundingClientRect(); return [r.left, r.top, r.width, r.height, i.naturalWidth / i.clientWidth]");
    let v = f64s(&img);
    let from = [v[0] + v[2] / 2.0, v[1] + v[3] / 2.0];
    b.drag(from, [from[0] - pixels / v[4], from[1]]);
    b.wait("return window.view.workIdle() && window.view.draft() !== null");
    let draft = b.js("return window.view.draft()");
    assert_eq!(draft["frame"], json!(20));
    let (now, saved) = (
        draft["terms"]["lower"]["paper"].as_f64().unwrap(),
        draft["saved"]["lower"]["paper"].as_f64().unwrap(),
    );
    assert!(
        now < 0.5 * saved,
        "the lower arch's E went from {saved} to {now}"
    );
    let readout = |b: &Browser| {
        b.js("return document.getElementById('timeline-readout').textContent")
            .as_str()
            .unwrap()
            .to_owned()
    };
    let said = readout(&b);
    assert!(
        said.starts_with("frame 20 (low-confidence, moved and not saved)"),
        "{said}"
    );
    b.js("document.getElementById('save-frame').click()");
    b.wait("return window.view.scene.timeline.frames[20].hand_set === true");
    let said = readout(&b);
    assert!(said.starts_with("frame 20 (ok, hand-set)"), "{said}");
    b.js("document.getElementById('retrack').click()");
    b.wait("return document.getElementById('work-status').textContent.startsWith('re-tracked')");
    let status = b.js("return document.getElementById('work-status').textContent");
    assert!(
        status.as_str().unwrap().contains("tracked 19 frames again"),
        "{status}"
    );
    // The timeline shows the new frames: no longer flagged.
    assert_eq!(
        b.js("return window.view.scene.timeline.frames.slice(21).filter((f) => f.status !== 'ok').length"),
        json!(0)
    );

    let written: TracksJson = serde_json::from_slice(&std::fs::read(&tracks).unwrap()).unwrap();
    assert_eq!(written.frames.len(), 40);
    let hand: Vec<u32> = written
        .frames
        .iter()
        .filter(|r| r.hand_set)
        .map(|r| r.frame)
        .collect();
    assert_eq!(hand, vec![20]);
    let kept: TracksJson =
        serde_json::from_slice(&std::fs::read(jawtrack::view::backup_path(&tracks)).unwrap())
            .unwrap();
    assert_eq!(
        serde_json::to_value(&kept.frames[30]).unwrap(),
        serde_json::to_value(&t.frames[30]).unwrap()
    );
    let after = jaw_errors(&capture, &tracks);
    eprintln!(
        "jaw error from frame 20 on: usual {:?}, lost {:?}, corrected {:?} ({status})",
        usual[20..]
            .iter()
            .map(|e| (e.1 * 1e3).round() / 1e3)
            .collect::<Vec<_>>(),
        lost[20..]
            .iter()
            .map(|e| (e.1 * 1e3).round() / 1e3)
            .collect::<Vec<_>>(),
        after[20..]
            .iter()
            .map(|e| (e.1 * 1e3).round() / 1e3)
            .collect::<Vec<_>>(),
    );
    for &(frame, e) in after.iter().filter(|e| e.0 >= 20) {
        assert!(
            e < usual_max + 0.15,
            "frame {frame}: jaw {e:.3} mm after the correction; the run's worst was {usual_max:.3}"
        );
    }

    // Stopped at once: the frames from where it stopped are as they were.
    b.js("const s = document.getElementById('scrub'); s.value = 0; s.dispatchEvent(new Event('input'));");
    b.js("document.getElementById('retrack').click()");
    b.wait("return !document.getElementById('stop-retrack').disabled");
    b.js("document.getElementById('stop-retrack').click()");
    b.wait("return document.getElementById('work-status').textContent.startsWith('re-tracked')");
    let status = b.js("return document.getElementById('work-status').textContent");
    let status = status.as_str().unwrap();
    let at: usize = status
        .split("stopped at frame ")
        .nth(1)
        .and_then(|rest| rest.split(';').next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("{status}"));
    assert!(at < 20, "{status}");
    let stopped: TracksJson = serde_json::from_slice(&std::fs::read(&tracks).unwrap()).unwrap();
    assert_eq!(stopped.frames.len(), 40);
    for k in at..40 {
        assert_eq!(
            serde_json::to_value(&stopped.frames[k]).unwrap(),
            serde_json::to_value(&written.frames[k]).unwrap(),
            "frame {k}"
        );
    }
    assert!(!dir.path().join("tracks.retrack.json").exists());
}

/// The first pose picked with the mouse, for a take without init.json (nor a rig): four points
/// clicked on each arch's model in the 3-D view and where the truth puts those vertices in two
/// cameras' pictures; the page fits them, writes init.json in the format's bootstrap form, and
/// the take tracks from it as it does from the true first pose.
#[test]
fn a_first_pose_picked_by_clicks_tracks_like_init_json() {
    if !have_browser() {
        return;
    }
    use jawtrack::formats::TracksJson;
    use nalgebra::Vector3;
    let f = fixture();
    let dir = tempfile::tempdir().unwrap();
    let cap = dir.path().join("cap");
    common::copy_dir(&f.capture, &cap);
    std::fs::remove_file(cap.join("init.json")).unwrap();
    let capture = jawtrack::capture::Capture::open(&cap).unwrap();
    let truth = capture.gt_poses(0).unwrap();

    // A take with no rig yet: the page shows the capture alone.
    let (_server, url) = serve(&["--capture", s(&cap)]);
    let b = Browser::start();
    b.go(&url);
    assert_eq!(
        b.js("return [document.getElementById('first-pose').hidden, document.querySelector('.rig-only').hidden, document.getElementById('rig-kind').textContent]"),
        json!([false, true, "No rig: the capture alone"])
    );
    b.wait("return Array.from(document.querySelectorAll('#pictures img')).every((i) => i.complete && i.naturalWidth > 0)");
    b.js("document.getElementById('pick-mode').click(); window.scrollTo(0, 0)");
    for (arch, pose) in [("upper", truth.upper), ("lower", truth.lower)] {
        b.js(&format!(
            "document.querySelector('input[name=pick-arch][value={arch}]').click(); window.scrollTo(0, 0)"
        ));
        // Four points spread over the arch as the 3-D view shows it: its leftmost, rightmost,
        // top and bottom vertices on the screen.
        let targets = b.js(&format!(
            "const n = window.view.vertexCount('{arch}'), r = window.view.canvasRect(), at = [];
             for (let v = 0; v < n; v++) at.push(window.view.toCanvas(window.view.posed('{arch}', v)));
             const by = (f) => at.reduce((b, p) => (f(p) < f(b) ? p : b));
             return [by((p) => p[0]), by((p) => -p[0]), by((p) => p[1]), by((p) => -p[1])].map((p) => [r.x + p[0], r.y + p[1]]);"
        ));
        for t in targets.as_array().unwrap() {
            let before = b.js("return window.view.firstPose().points.length");
            b.click([t[0].as_f64().unwrap(), t[1].as_f64().unwrap()]);
            let after = b.js("return window.view.firstPose().points.length");
            assert_eq!(
                after.as_u64(),
                before.as_u64().map(|n| n + 1),
                "no vertex under {t}"
            );
            let picked = b.js("const p = window.view.firstPose(); return p.points[p.current]");
            assert_eq!(picked["arch"], json!(arch));
            let vertex = picked["vertex"].as_u64().unwrap() as usize;
            let mesh = if arch == "upper" {
                capture.upper()
            } else {
                capture.lower()
            };
            let v = mesh.positions[vertex];
            let world = pose.transform_point(&Vector3::new(v[0] as f64, v[1] as f64, v[2] as f64));
            for (k, cam) in ["cam0", "cam1"].iter().enumerate() {
                let c = capture.cameras()[k].mask_camera().unwrap();
                let px = c.project(&world).unwrap();
                // The picture shows the region around the mask's labels.
                let img = b.js(&format!(
                    "const i = document.getElementById('picture-{cam}'); i.scrollIntoView(); const r = i.getBoundingClientRect(); const o = window.view.scene.capture.crops[{k}]; return [r.left, r.top, i.clientWidth / i.naturalWidth, o[0], o[1]]"
                ));
                let g = f64s(&img);
                b.click([
                    g[0] + (px.x - g[3] + 0.5) * g[2],
                    g[1] + (px.y - g[4] + 0.5) * g[2],
                ]);
            }
            b.js("window.scrollTo(0, 0)");
        }
    }
    b.js("document.getElementById('write-init').click()");
    b.wait(
        "return document.getElementById('pick-status').textContent.startsWith('init.json written')",
    );
    let fitted = b.js("return window.view.firstPose().fitted");
    // The pose init.json gives: the truth's to a fraction of a millimetre.
    let written = jawtrack::capture::Capture::open(&cap)
        .unwrap()
        .initial_poses()
        .unwrap();
    for (got, want) in [(written.upper, truth.upper), (written.lower, truth.lower)] {
        let q = nalgebra::UnitQuaternion::from_rotation_matrix(
            &(got.rotation.inverse() * want.rotation),
        );
        let (mm, deg) = (
            (got.translation - want.translation).norm(),
            2.0 * q.vector().norm().atan2(q.scalar().abs()).to_degrees(),
        );
        eprintln!("picked first pose: {mm:.3} mm, about {deg:.2}° off the truth");
        assert!(mm < 0.5 && deg < 1.5, "{mm} mm, {deg}°");
    }
    for arch in ["upper", "lower"] {
        let r = f64s(&fitted["residual_px"][arch]);
        assert_eq!(r.len(), 4);
        assert!(r.iter().all(|&e| e < 3.0), "{arch}: {r:?}");
    }
    let init: serde_json::Value =
        serde_json::from_slice(&std::fs::read(cap.join("init.json")).unwrap()).unwrap();
    assert_eq!(init["upper"]["points"].as_array().unwrap().len(), 4);
    assert_eq!(
        init["lower"]["points"][0]["pixels"]
            .as_object()
            .unwrap()
            .len(),
        2
    );

    // Both takes tracked the same way: from the picked start and from the true one.
    let (picked, true_start) = (dir.path().join("picked.json"), dir.path().join("true.json"));
    for (c, out) in [(&cap, &picked), (&f.capture, &true_start)] {
        ok(&[
            "track",
            s(c),
            "-o",
            s(out),
            "--frames",
            "0..10",
            "--search",
            "gauss-newton",
        ]);
    }
    let (a, b_) = (
        jaw_errors(&capture, &picked),
        jaw_errors(&capture, &true_start),
    );
    let t: TracksJson = serde_json::from_slice(&std::fs::read(&picked).unwrap()).unwrap();
    eprintln!("jaw error per frame: picked start {a:?}, true start {b_:?}");
    // Frame by frame the tracker's own noise is a few tenths of a millimetre (docs/cluster.md:
    // the same take from two starts differs by 0.22 / 0.47 / 0.75 mm): the runs are compared as
    // wholes, within that.
    let stats = |v: &[(u32, f64)]| {
        let mut e: Vec<f64> = v.iter().map(|x| x.1).collect();
        e.sort_by(f64::total_cmp);
        (e[e.len() / 2], e[e.len() - 1])
    };
    let ((median, worst), (median0, worst0)) = (stats(&a), stats(&b_));
    assert!(
        median < median0 + 0.25 && worst < worst0 + 0.3,
        "jaw median / max {median:.3} / {worst:.3} mm from the picked start, {median0:.3} / {worst0:.3} from the true one"
    );
    assert_eq!(t.frames.len(), 10);
}

/// The envelope rig on the same page: its sliders pose the jaw in the same units, inside
/// Posselt's envelope (a pose beyond it comes as near as it can, then the protrusion band
/// there is reached exactly), and a keyed animation exports as valid glTF.
#[test]
fn the_envelope_rig_drives_the_same_page() {
    if !have_browser() {
        return;
    }
    let f = fixture();
    let dir = tempfile::tempdir().unwrap();
    let envelope = dir.path().join("envelope.json");
    ok(&[
        "envelope",
        "learn",
        s(&f.capture.join("gt/poses.json")),
        "--mesh",
        s(&f.capture.join("meshes/mandible.obj")),
        "-o",
        s(&envelope),
    ]);
    let (_server, url) = serve(&[s(&envelope), "--capture", s(&f.capture)]);
    let b = Browser::start();
    b.go(&url);
    assert_eq!(b.js("return window.view.scene.rig"), json!("envelope rig"));
    let rest = b
        .js("return window.view.reply.animator.opening_deg")
        .as_f64()
        .unwrap();
    assert!(
        rest.abs() < 0.05,
        "the page opens at the rest bite: {rest}°"
    );
    let jaw_before = b.js("return window.view.jaw()");
    let target = b.js_async(
        "const r = await window.view.poseFor([12, 0, 0]);
         const band = r.protrusion_range_mm; const mid = (band[0] + band[1]) / 2;
         const s = await window.view.poseFor([12, 0, mid]);
         return {valid: s.valid, reached: s.reached, opening: s.animator.opening_deg, protrusion: s.animator.protrusion_mm, mid};",
    );
    assert_eq!(target["reached"], json!(true), "{target}");
    assert_eq!(target["valid"], json!(true), "{target}");
    assert!(
        (target["opening"].as_f64().unwrap() - 12.0).abs() < 0.01,
        "{target}"
    );
    assert_ne!(b.js("return window.view.jaw()"), jaw_before);
    b.js("document.getElementById('key-time').value = 0; document.getElementById('set-key').click();");
    b.js_async("await window.view.poseFor([0, 0, 0]); return true;");
    b.js("document.getElementById('key-time').value = 1; document.getElementById('set-key').click();");
    let gltf = b.js_async("return await window.view.exportGltf();");
    let text = gltf.as_str().unwrap();
    assert!(!text.starts_with("error"), "{text}");
    let path = dir.path().join("envelope.gltf");
    std::fs::write(&path, text).unwrap();
    if let Some(report) = common::validate_gltf(&path) {
        assert_eq!(report["errors"], 0, "{report}");
        assert_eq!(report["animations"], 1, "{report}");
    }
}
