//! A take cut into chunks and put back together: `merge`, `batch local`/`run`/`status`, and a
//! real Slurm job array (`batch slurm --submit`) when Slurm runs here (CI starts one and sets
//! JAWTRACK_REQUIRE_SLURM so that the test fails there, not skips, without it).

mod common;

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::OnceLock;
use std::time::{Duration, Instant};

use common::{ok, refused};
use jawtrack::anatomy::MeshMetric;
use jawtrack::batch::Plan;
use jawtrack::capture::Capture;
use jawtrack::formats::TracksJson;
use jawtrack::synth::{MaskKind, Preset, SynthOptions, generate};

/// A clean 30-frame take, written once.
fn take() -> &'static Path {
    static DIR: OnceLock<tempfile::TempDir> = OnceLock::new();
    DIR.get_or_init(|| {
        let t = tempfile::tempdir().unwrap();
        let opts = SynthOptions {
            frames: 30,
            seed: 4,
            preset: Preset::Clean,
            masks: MaskKind::PerArch,
            ..SynthOptions::default()
        };
        generate(&t.path().join("take"), &opts, &|| {}).unwrap();
        t
    })
    .path()
    .join("take")
    .leak()
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// The take tracked in one run with `options`, once per set of options.
fn single(options: &'static [&'static str]) -> PathBuf {
    static RUNS: OnceLock<std::sync::Mutex<Vec<(String, tempfile::TempDir)>>> = OnceLock::new();
    let runs = RUNS.get_or_init(Default::default);
    let mut runs = runs.lock().unwrap();
    let key = options.join(" ");
    if let Some((_, t)) = runs.iter().find(|(k, _)| *k == key) {
        return t.path().join("tracks.json");
    }
    let t = tempfile::tempdir().unwrap();
    let out = t.path().join("tracks.json");
    let mut args = vec!["track", s(take()), "-o", s(&out)];
    args.extend(options);
    ok(&args);
    runs.push((key, t));
    out
}

fn read(path: &Path) -> TracksJson {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

/// Per frame of both files: the frame, and how far apart they put the jaw and the upper arch
/// (mm, mean vertex distance).
fn gaps(a: &Path, b: &Path) -> Vec<(u32, f64, f64)> {
    let capture = Capture::open(take()).unwrap();
    let upper = MeshMetric::new(capture.upper());
    let lower = MeshMetric::new(capture.lower());
    let (ra, rb) = (read(a), read(b));
    assert_eq!(ra.frames.len(), rb.frames.len(), "{a:?} and {b:?}");
    ra.frames
        .iter()
        .zip(&rb.frames)
        .map(|(x, y)| {
            assert_eq!(x.frame, y.frame);
            let (px, py) = (x.poses(a).unwrap(), y.poses(b).unwrap());
            (
                x.frame,
                lower.mean_distance(&px.jaw(), &py.jaw()),
                upper.mean_distance(&px.upper, &py.upper),
            )
        })
        .collect()
}

fn worst(gaps: &[(u32, f64, f64)]) -> f64 {
    gaps.iter().map(|g| g.1.max(g.2)).fold(0.0, f64::max)
}

const GN: &[&str] = &["--search", "gauss-newton"];

/// `jawtrack batch KIND <the take> -o DIR --chunk-frames N --overlap K`, then `extra`.
fn plan_args<'a>(
    kind: &'a str,
    dir: &'a Path,
    chunk: &'a str,
    overlap: &'a str,
    extra: &[&'a str],
) -> Vec<&'a str> {
    let mut args = vec![
        "batch",
        kind,
        s(take()),
        "-o",
        s(dir),
        "--chunk-frames",
        chunk,
        "--overlap",
        overlap,
    ];
    args.extend(extra);
    args
}

#[test]
fn chunks_tracked_here_merge_into_the_run_of_one_task() {
    let t = tempfile::tempdir().unwrap();
    let dir = t.path().join("batch");
    let mut args = plan_args("local", &dir, "10", "4", &["--tasks", "2", "--"]);
    args.extend(GN);
    let said = ok(&args);
    assert!(said.contains("3 tasks (3 to run, 2 at a time)"), "{said}");
    let merged = dir.join("take/tracks.json");
    let whole = single(GN);
    let gaps = gaps(&whole, &merged);
    assert_eq!(gaps.len(), 30);
    // Where the later chunk takes over, it tracks from its own start; on a clean take both
    // land within the 0.05 mm (about 0.01 mm here).
    assert!(worst(&gaps) < 0.05, "{gaps:?}");
    // The merged run is the whole run: the same fingerprint, so `track --resume` accepts it
    // and has nothing left to do.
    assert_eq!(read(&merged).fingerprint, read(&whole).fingerprint);
    let mut resume = vec!["track", s(take()), "-o", s(&merged), "--resume"];
    resume.extend(GN);
    let said = ok(&resume);
    assert!(said.contains("tracked 30 frames (0 now)"), "{said}");
    let said = ok(&["batch", "status", s(&dir)]);
    assert!(
        said.contains("3 of 3 chunks finished, 38 of 38 frames, merged"),
        "{said}"
    );
    // A batch folder is not planned over.
    refused(
        &plan_args("local", &dir, "10", "4", &[]),
        &["holds a batch already", "batch status"],
    );
}

/// Track the take's frames `frames` into `out` with Gauss-Newton (`--locate` for a later chunk).
fn chunk(out: &Path, frames: &str, locate: bool) {
    let mut args = vec!["track", s(take()), "-o", s(out), "--frames", frames];
    if locate {
        args.push("--locate");
    }
    args.extend(GN);
    ok(&args);
}

#[test]
fn a_chunk_that_disagrees_is_tracked_again_from_the_one_before() {
    let t = tempfile::tempdir().unwrap();
    let (p0, p1) = (t.path().join("p0.json"), t.path().join("p1.json"));
    chunk(&p0, "0..12", false);
    chunk(&p1, "8..30", true);
    // The later chunk's jaw a millimetre off, as tracked and as settled.
    common::edit_json(&p1, |v| {
        for f in v["frames"].as_array_mut().unwrap() {
            for at in ["/lower/translation/0", "/tracked/lower/translation/0"] {
                let x = f.pointer_mut(at).unwrap();
                *x = (x.as_f64().unwrap() + 1.0).into();
            }
        }
    });
    let merged = t.path().join("merged.json");
    let mut args = vec!["merge", s(take()), s(&p1), s(&p0), "-o", s(&merged)];
    args.extend(GN);
    let said = ok(&args);
    assert!(said.contains("overlap 8..12, checked 10..12"), "{said}");
    assert!(said.contains("FLAGGED"), "{said}");
    assert!(
        said.contains("its 18 frames after the overlap tracked again"),
        "{said}"
    );
    // Tracked again as a resumed run goes on: the frames a single run tracks.
    let gaps = gaps(&single(GN), &merged);
    assert!(worst(&gaps) < 1e-6, "{gaps:?}");
    // Without --force an existing output stays.
    refused(&args, &["merged.json", "already exists", "--force"]);
}

#[test]
fn merge_refuses_chunks_that_cannot_make_one_run() {
    let t = tempfile::tempdir().unwrap();
    let p = |name: &str| t.path().join(name);
    chunk(&p("a.json"), "0..6", false);
    chunk(&p("b.json"), "9..14", true);
    let out = p("out.json");
    let merge = |parts: &[&Path], extra: &[&'static str]| -> Vec<String> {
        let mut args = vec!["merge".to_string(), s(take()).to_string()];
        args.extend(parts.iter().map(|p| s(p).to_string()));
        args.extend(["-o".to_string(), s(&out).to_string()]);
        args.extend(extra.iter().map(|e| e.to_string()));
        args
    };
    let refused = |args: Vec<String>, parts: &[&str]| {
        refused(&args.iter().map(String::as_str).collect::<Vec<_>>(), parts)
    };
    refused(
        merge(&[&p("a.json"), &p("b.json")], GN),
        &["b.json", "frames 6..9 are in no chunk"],
    );
    // Tracked with other settings than merge is given.
    refused(
        merge(&[&p("a.json")], &[]),
        &["a.json", "fingerprint", "other settings"],
    );
    // A chunk still being tracked (or interrupted).
    std::fs::write(p("a.json.journal"), "{}\n").unwrap();
    refused(
        merge(&[&p("a.json")], GN),
        &["a.json", "unfinished", "track --resume"],
    );
    std::fs::remove_file(p("a.json.journal")).unwrap();
    chunk(&p("c.json"), "2..5", true);
    refused(
        merge(&[&p("a.json"), &p("c.json")], GN),
        &["c.json", "adds nothing"],
    );
}

/// The number of frames a run's journal holds.
fn journal_frames(part: &Path) -> usize {
    let mut name = part.file_name().unwrap().to_os_string();
    name.push(".journal");
    std::fs::read_to_string(part.with_file_name(name))
        .map(|s| s.matches('\n').count().saturating_sub(1))
        .unwrap_or(0)
}

#[test]
fn a_killed_task_keeps_its_frames_and_the_batch_goes_on() {
    let t = tempfile::tempdir().unwrap();
    let dir = t.path().join("batch");
    // Planned for Slurm (written, not submitted), run here.
    let mut args = plan_args("slurm", &dir, "15", "3", &["--"]);
    args.extend(GN);
    ok(&args);
    let plan = Plan::load(&dir).unwrap();
    let part = plan.takes[0].chunks[1].part.clone();
    let mut child = Command::new(env!("CARGO_BIN_EXE_jawtrack"))
        .args(plan.task_args(1))
        .current_dir(&plan.workdir)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    while journal_frames(&part) < 2 {
        assert!(
            child.try_wait().unwrap().is_none(),
            "the task ended before it could be killed"
        );
        std::thread::sleep(Duration::from_millis(2));
    }
    child.kill().unwrap();
    child.wait().unwrap();
    let kept = journal_frames(&part);
    let said = ok(&["batch", "status", s(&dir)]);
    assert!(
        said.contains(&format!("task 1 (frames 12..30): {kept} of 18 frames")),
        "{said}"
    );
    assert!(said.contains("2 tasks unfinished"), "{said}");
    let journal = std::fs::read_to_string(part.with_file_name("chunk-0001.json.journal")).unwrap();
    let before: Vec<serde_json::Value> = journal
        .lines()
        .skip(1)
        .take(kept)
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    let said = ok(&["batch", "run", s(&dir), "--tasks", "2"]);
    assert!(said.contains("2 tasks (2 to run, 2 at a time)"), "{said}");
    // The frames tracked before the kill are kept as they were.
    let after: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&part).unwrap()).unwrap();
    for (i, b) in before.iter().enumerate() {
        assert_eq!(
            after["frames"][i]["tracked"], b["tracked"],
            "frame {i} of the chunk"
        );
    }
    assert!(dir.join("take/tracks.json").exists());
    assert!(worst(&gaps(&single(GN), &dir.join("take/tracks.json"))) < 0.1);
}

/// Whether Slurm answers here; with JAWTRACK_REQUIRE_SLURM set it must.
fn slurm_here() -> bool {
    let up = Command::new("sinfo")
        .arg("-h")
        .output()
        .is_ok_and(|o| o.status.success() && !o.stdout.is_empty());
    if !up {
        assert!(
            std::env::var_os("JAWTRACK_REQUIRE_SLURM").is_none(),
            "JAWTRACK_REQUIRE_SLURM is set but Slurm does not answer (sinfo)"
        );
        eprintln!("skipped: no Slurm here (sinfo)");
    }
    up
}

/// Wait until none of `jobs` is in Slurm's queue.
fn wait_for(jobs: &[String]) {
    let started = Instant::now();
    loop {
        let out = Command::new("squeue")
            .args(["-h", "-o", "%i", "-j", &jobs.join(",")])
            .output()
            .unwrap();
        let text = String::from_utf8_lossy(&out.stdout);
        if text.trim().is_empty() {
            return;
        }
        assert!(
            started.elapsed() < Duration::from_secs(600),
            "jobs {jobs:?} still queued after 10 minutes:\n{text}"
        );
        std::thread::sleep(Duration::from_millis(200));
    }
}

/// The job ids of a batch's last submission: (array, merge).
fn last_jobs(dir: &Path) -> (Option<String>, String) {
    let jobs: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("jobs.json")).unwrap()).unwrap();
    let last = jobs.as_array().unwrap().last().unwrap().clone();
    (
        last["array_job"].as_str().map(String::from),
        last["merge_job"].as_str().unwrap().to_string(),
    )
}

#[test]
fn a_slurm_job_array_tracks_the_chunks_and_a_cancelled_task_resumes() {
    if !slurm_here() {
        return;
    }
    let t = tempfile::tempdir().unwrap();
    let dir = t.path().join("batch");
    // The paper's search (the default): slow enough a frame to cancel a task mid-chunk.
    ok(&plan_args("slurm", &dir, "10", "4", &["--submit"]));
    let (array, merge) = last_jobs(&dir);
    let array = array.expect("an array job");
    let plan = Plan::load(&dir).unwrap();
    let part = plan.takes[0].chunks[1].part.clone();
    let started = Instant::now();
    while journal_frames(&part) < 1 {
        assert!(
            started.elapsed() < Duration::from_secs(300),
            "task 1 never started"
        );
        std::thread::sleep(Duration::from_millis(5));
    }
    let cancel = Command::new("scancel")
        .arg(format!("{array}_1"))
        .status()
        .unwrap();
    assert!(cancel.success());
    wait_for(&[array.clone(), merge.clone()]);
    // The merge job went with the task it depended on; the cancelled task kept its frames.
    let kept = journal_frames(&part);
    assert!((1..14).contains(&kept), "{kept} frames");
    assert!(!dir.join("take/tracks.json").exists());
    let said = ok(&["batch", "status", s(&dir)]);
    assert!(
        said.contains(&format!("task 1 (frames 6..20): {kept} of 14 frames")),
        "{said}"
    );
    let said = ok(&["batch", "submit", s(&dir)]);
    assert!(said.contains("(1 of 3 tasks not yet finished)"), "{said}");
    let (again, merge) = last_jobs(&dir);
    wait_for(&[again.unwrap(), merge]);
    let merged = dir.join("take/tracks.json");
    assert!(
        merged.exists(),
        "no merged run; merge log:\n{}",
        std::fs::read_to_string(dir.join("logs/merge.log")).unwrap_or_default()
    );
    // The paper's search lands less exactly than Gauss-Newton (about 0.05 mm here).
    let gaps = gaps(&single(&[]), &merged);
    assert!(worst(&gaps) < 0.1, "{gaps:?}");
}

/// The Python with Ray to run the driver with (JAWTRACK_RAY_PYTHON, else python3), when it
/// imports Ray; with JAWTRACK_REQUIRE_RAY set it must.
fn ray_python() -> Option<String> {
    let python = std::env::var("JAWTRACK_RAY_PYTHON").unwrap_or_else(|_| "python3".into());
    let has_ray = Command::new(&python)
        .args(["-c", "import ray"])
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|s| s.success());
    if !has_ray {
        assert!(
            std::env::var_os("JAWTRACK_REQUIRE_RAY").is_none(),
            "JAWTRACK_REQUIRE_RAY is set but {python} cannot import ray"
        );
        eprintln!("skipped: {python} has no ray");
        return None;
    }
    Some(python)
}

#[test]
fn the_ray_driver_runs_the_plan_and_runs_again_what_failed() {
    let Some(python) = ray_python() else {
        return;
    };
    let t = tempfile::tempdir().unwrap();
    let dir = t.path().join("batch");
    let mut args = plan_args("ray", &dir, "10", "4", &["--"]);
    args.extend(GN);
    ok(&args);
    let driver = dir.join("ray_batch.py");
    // A chunk whose journal is not one: its task fails (each retry too), the merge waits.
    let journal = dir.join("take/parts/chunk-0001.json.journal");
    std::fs::create_dir_all(journal.parent().unwrap()).unwrap();
    std::fs::write(&journal, "not a journal\n{\n").unwrap();
    let run = || {
        Command::new(&python)
            .args([s(&driver), s(&dir), "--cpus", "1", "--retries", "1"])
            .output()
            .unwrap()
    };
    let out = run();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{err}");
    assert!(
        err.contains("task 1 FAILED") && err.contains("ray-track-1.log"),
        "{err}"
    );
    assert!(!dir.join("take/tracks.json").exists());
    // Put right, the driver runs again: the finished chunks have nothing left to do.
    std::fs::remove_file(&journal).unwrap();
    let out = run();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let merged = dir.join("take/tracks.json");
    assert!(String::from_utf8_lossy(&out.stdout).contains("merged -> "));
    assert!(worst(&gaps(&single(GN), &merged)) < 0.05);
}
