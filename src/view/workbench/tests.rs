use super::*;
use crate::synth::{SynthOptions, generate};
use crate::track::output::journal_path;
use crate::track::{Session, SessionOptions};

fn bench_on(frames: u32) -> (tempfile::TempDir, Workbench) {
    let dir = tempfile::tempdir().unwrap();
    let cap = dir.path().join("cap");
    generate(
        &cap,
        &SynthOptions {
            frames,
            ..SynthOptions::default()
        },
        &|| {},
    )
    .unwrap();
    let capture = Capture::open(&cap).unwrap();
    let w = Workbench::open(
        Arc::new(capture),
        &cap.join("gt/poses.json"),
        Retracking {
            settings: TrackSettings::default(),
            backend: Backend::Cpu,
            region: Region::Relevant,
        },
    )
    .unwrap();
    (dir, w)
}

/// The lower arch lost on frames 0..6 (3 mm off, flagged), frame 6 set right by hand and
/// the frames before it tracked backwards from there: they come back to the truth, and the
/// frames after it are as they were.
#[test]
fn a_run_lost_before_a_corrected_frame_is_tracked_backwards() {
    let dir = tempfile::tempdir().unwrap();
    let cap = dir.path().join("cap");
    generate(
        &cap,
        &SynthOptions {
            frames: 10,
            ..SynthOptions::default()
        },
        &|| {},
    )
    .unwrap();
    let capture = Capture::open(&cap).unwrap();
    let mut settings = TrackSettings::default();
    settings.search.solver = crate::track::Solver::GaussNewton;
    let tracks = dir.path().join("tracks.json");
    let options = SessionOptions {
        backend: Backend::Cpu,
        settings: settings.clone(),
        ..SessionOptions::new(&tracks)
    };
    let mut t = TracksJson {
        format: TRACKS_FORMAT.into(),
        fingerprint: None,
        frames: Session::open(&capture, options)
            .unwrap()
            .run(&mut |_| {})
            .unwrap()
            .records,
    };
    let after = t.frames[7].clone();
    for r in &mut t.frames[..6] {
        let mut lower = r.poses(&tracks).unwrap().lower;
        lower.translation.x += 3.0;
        r.lower = PoseJson::from(&lower);
        r.tracked = None;
        r.status = Some(Status::LowConfidence);
    }
    write_json_atomic(&tracks, &t).unwrap();
    let gt: Vec<ArchPoses> = (0..10).map(|f| capture.gt_poses(f).unwrap()).collect();
    let truth = |frame: u32| gt[frame as usize];
    let w = Arc::new(
        Workbench::open(
            Arc::new(capture),
            &tracks,
            Retracking {
                settings,
                backend: Backend::Cpu,
                region: Region::Relevant,
            },
        )
        .unwrap(),
    );
    lock(&w.frames).drafts.insert(6, truth(6));
    w.correct(6).unwrap();
    let job = w
        .retrack(&RetrackQuery {
            frame: 6,
            backward: true,
        })
        .unwrap();
    assert!(
        job.running && job.backward && job.until == Some(0),
        "{job:?}"
    );
    while w.job().running {
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    let job = w.job();
    assert_eq!(job.done, 6, "{job:?}");
    let written: TracksJson = crate::io::read_json(&tracks, "tracks").unwrap();
    assert_eq!(written.frames.len(), 10);
    assert!(written.frames[6].hand_set);
    for r in &written.frames[..6] {
        let p = r.poses(&tracks).unwrap();
        let off = (p.lower.translation - truth(r.frame).lower.translation).norm();
        assert!(
            off < 0.5,
            "frame {}: lower {off:.2} mm from the truth",
            r.frame
        );
    }
    // The window settles frame 7 again beside its new neighbours; its tracked poses stay.
    assert_eq!(
        serde_json::to_value(&written.frames[7].tracked).unwrap(),
        serde_json::to_value(&after.tracked).unwrap()
    );
    assert!(!journal_path(&tracks).exists());
}

fn edit(w: &Workbench, arch: ArchName, op: EditOp) -> ArchPoses {
    w.edit(&EditQuery { frame: 1, arch, op }).unwrap().poses
}

/// A drag moves the arch's centre in that camera's picture by the pixels dragged; a turn
/// keeps the centre where it was; a nudge and its opposite cancel; reset restores.
#[test]
fn moves_by_hand_do_what_the_page_says() {
    let (_dir, w) = bench_on(3);
    let cam = w.camera("cam0").unwrap();
    let saved = w.frames().0[1].poses;
    let at = |p: &ArchPoses| {
        cam.project(&p.lower.transform_point(&w.centres[1]))
            .unwrap()
    };
    let dragged = edit(
        &w,
        ArchName::Lower,
        EditOp::Drag {
            camera: "cam0".into(),
            pixels: [12.0, -7.0],
        },
    );
    let moved = at(&dragged) - at(&saved);
    assert!(
        (moved.x - 12.0).abs() < 0.05 && (moved.y + 7.0).abs() < 0.05,
        "{moved}"
    );
    assert_eq!(dragged.upper, saved.upper);
    let turned = edit(
        &w,
        ArchName::Lower,
        EditOp::Turn {
            camera: "cam1".into(),
            degrees: [5.0, -3.0],
        },
    );
    assert!((at(&turned) - at(&dragged)).norm() < 1e-6);
    let angle = turned
        .lower
        .rotation
        .angle_to(&dragged.lower.rotation)
        .to_degrees();
    assert!((angle - 34f64.sqrt()).abs() < 0.05, "{angle}");
    let there = edit(
        &w,
        ArchName::Upper,
        EditOp::Nudge {
            mm: [0.3, 0.0, -0.2],
            degrees: [0.0, 1.0, 0.0],
        },
    );
    assert!((there.upper.translation - saved.upper.translation).norm() > 0.2);
    let back = edit(
        &w,
        ArchName::Upper,
        EditOp::Nudge {
            mm: [-0.3, 0.0, 0.2],
            degrees: [0.0, -1.0, 0.0],
        },
    );
    assert!((back.upper.translation - saved.upper.translation).norm() < 1e-9);
    assert_eq!(edit(&w, ArchName::Lower, EditOp::Reset), saved);
    let far = w.edit(&EditQuery {
        frame: 1,
        arch: ArchName::Lower,
        op: EditOp::Drag {
            camera: "cam0".into(),
            pixels: [f64::NAN, 0.0],
        },
    });
    assert!(far.unwrap_err().contains("pixels"));
    let nowhere = w.edit(&EditQuery {
        frame: 1,
        arch: ArchName::Lower,
        op: EditOp::Depth {
            camera: "cam9".into(),
            mm: 1.0,
        },
    });
    assert!(nowhere.unwrap_err().contains("cam9"));
}
