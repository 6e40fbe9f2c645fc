//! The jaw rig end to end on synthetic TMJ motion (ground truth, no masks): learning,
//! reconstruction with margins, the rig file, ranges, IK, and errors on bad input.

use std::path::Path;
use std::sync::OnceLock;

use jawtrack::anatomy::MeshMetric;
use jawtrack::formats::{JawPoses, read_jaw_poses, write_jaw_poses};
use jawtrack::mesh::{BoiSource, Mesh};
use jawtrack::rig::eval::{reconstruction, sampled};
use jawtrack::rig::model::RigModel;
use jawtrack::rig::{JawRig, RigSettings};
use jawtrack::synth::{SynthOptions, generate};

struct Fixture {
    _dir: tempfile::TempDir,
    poses: JawPoses,
    mandible: Mesh,
    mandible_obj: std::path::PathBuf,
    metric: MeshMetric,
    rig: JawRig,
}

/// 170 poses: the whole exercise once (opening, both excursions, protrusion, combinations).
fn fixture() -> &'static Fixture {
    static F: OnceLock<Fixture> = OnceLock::new();
    F.get_or_init(|| {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("m");
        let opts = SynthOptions {
            frames: 170,
            frames_per_segment: 10,
            seed: 3,
            no_masks: true,
            ..Default::default()
        };
        generate(&out, &opts, &|| {}).unwrap();
        let poses = read_jaw_poses(&out.join("gt/poses.json")).unwrap();
        let mandible = Mesh::load(&out.join("meshes/mandible.obj"), BoiSource::None).unwrap();
        let metric = MeshMetric::new(&mandible);
        // With the paper's networks, whose figures are checked too.
        let settings = RigSettings {
            paper: true,
            ..Default::default()
        };
        let rig = JawRig::learn(&poses.poses, &metric, &settings, &|_| {}).unwrap();
        Fixture {
            _dir: dir,
            poses,
            mandible,
            mandible_obj: out.join("meshes/mandible.obj"),
            metric,
            rig,
        }
    })
}

#[test]
fn the_rig_reconstructs_synthetic_motion() {
    let f = fixture();
    let rec = reconstruction(&f.rig, &f.poses.poses, &f.metric, None);
    // Measured on this set: rig ≈ 0.2 mm mean, NLPCA-5 ≈ 0.03 mm; PCA-1 several mm.
    assert!(rec.rig.stats.mean < 0.5, "rig {:?}", rec.rig.stats);
    assert!(
        rec.rig_clamped.stats.max < 2.0,
        "clamped {:?}",
        rec.rig_clamped.stats
    );
    assert!(
        rec.nlpca[4].stats.mean < 0.2,
        "NLPCA-5 {:?}",
        rec.nlpca[4].stats
    );
    assert!(
        rec.pca[0].stats.mean > 5.0 * rec.rig.stats.mean,
        "PCA-1 {:?}",
        rec.pca[0].stats
    );
    assert!(rec.valid_share > 0.8, "valid share {}", rec.valid_share);
    // Opening is the first parameter: opening the mouth moves the front of the mandible down.
    let front = f
        .metric
        .probes()
        .iter()
        .copied()
        .max_by(|a, b| a.z.total_cmp(&b.z))
        .unwrap();
    let [lo, hi] = f.rig.ranges.d1_range();
    let closed = f
        .rig
        .pose(&f.rig.clamp(&[lo, 0.0, 0.0]))
        .transform_point(&front);
    let open = f
        .rig
        .pose(&f.rig.clamp(&[hi, 0.0, 0.0]))
        .transform_point(&front);
    assert!(
        closed.y - open.y > 30.0,
        "opening moves the chin by {} mm",
        closed.y - open.y
    );
}

/// Motion from a joint model written apart from jawtrack's (benches/other_joint.py: other
/// condylar paths, a Bennett shift, opening limited by the excursions, chewing cycles), 300
/// poses: the coupled rig must hold where the paper's sum of modes does not.
#[test]
fn the_coupled_rig_holds_on_another_joint_model() {
    let f = fixture();
    let dir = tempfile::tempdir().unwrap();
    let mesh = &f.mandible_obj;
    let poses_path = dir.path().join("other.json");
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("benches/other_joint.py");
    let out = std::process::Command::new("python3")
        .arg(&script)
        .args(["make", "--frames", "300", "--seed", "3", "--mandible"])
        .arg(mesh)
        .arg("-o")
        .arg(&poses_path)
        .output()
        .expect("python3 runs benches/other_joint.py");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let poses = read_jaw_poses(&poses_path).unwrap();
    assert_eq!(poses.len(), 300);
    let mean_error = |model| {
        let settings = RigSettings {
            model,
            ..Default::default()
        };
        let rig = JawRig::learn(&poses.poses, &f.metric, &settings, &|_| {}).unwrap();
        let rec = reconstruction(&rig, &poses.poses, &f.metric, None);
        assert!(rec.nlpca.is_empty() && rec.paper_rig.is_none());
        rec.rig.stats.mean
    };
    // Measured: coupled 0.11 mm, additive 0.23 mm.
    let (coupled, additive) = (
        mean_error(RigModel::Coupled),
        mean_error(RigModel::Additive),
    );
    assert!(coupled < 0.2, "coupled rig {coupled} mm");
    assert!(
        coupled < 0.7 * additive,
        "coupled {coupled} vs additive {additive} mm"
    );
}

#[test]
fn dynamic_ranges_stay_closer_to_the_captured_poses() {
    let f = fixture();
    let s = sampled(&f.rig, &f.poses.poses, &f.metric, 200, 1);
    assert!(
        s.dynamic_ranges.stats.mean < s.static_ranges.stats.mean,
        "dynamic {:?} vs fixed {:?}",
        s.dynamic_ranges.stats,
        s.static_ranges.stats
    );
}

#[test]
fn the_rig_file_round_trips_and_is_checked() {
    let f = fixture();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("rig.json");
    f.rig.save(&path).unwrap();
    let back = JawRig::load(&path).unwrap();
    let d = [0.1, -0.03, 0.02];
    let (r, t) = back.pose(&d).distance_to(&f.rig.pose(&d));
    assert!(r < 1e-12 && t < 1e-9);
    // A damaged file names the field.
    let mut json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    json["format"] = "jawtrack-rig/9".into();
    std::fs::write(&path, json.to_string()).unwrap();
    let e = JawRig::load(&path).unwrap_err().to_string();
    assert!(
        e.contains("rig.json") && e.contains("`format`") && e.contains("jawtrack-rig/1"),
        "{e}"
    );
    json["format"] = "jawtrack-rig/1".into();
    json["network"]["weights"] = serde_json::json!([1.0, 2.0]);
    std::fs::write(&path, json.to_string()).unwrap();
    let e = JawRig::load(&path).unwrap_err().to_string();
    assert!(e.contains("`network`") && e.contains("weights"), "{e}");
    // Couplings that do not match their sizes are named too.
    let mut json: serde_json::Value = serde_json::to_value(&f.rig).unwrap();
    json["couplings"]["pairs"][1]["w2"] = serde_json::json!([0.5]);
    std::fs::write(&path, json.to_string()).unwrap();
    let e = JawRig::load(&path).unwrap_err().to_string();
    assert!(e.contains("`couplings`") && e.contains("pairs[1]"), "{e}");
    // A file from before the input scaling was stored takes the network's, and poses the same.
    let mut json: serde_json::Value = serde_json::to_value(&f.rig).unwrap();
    json.as_object_mut().unwrap().remove("input");
    std::fs::write(&path, json.to_string()).unwrap();
    let old = JawRig::load(&path).unwrap();
    let (r, t) = old.pose(&d).distance_to(&f.rig.pose(&d));
    assert!(r < 1e-12 && t < 1e-9, "{r} {t}");
}

#[test]
fn ik_reaches_a_reachable_target_quickly() {
    let f = fixture();
    let point = f.metric.probes()[0];
    let goal = f.rig.clamp(&[0.15, 0.03, 0.0]);
    let target = f.rig.pose(&goal).transform_point(&point);
    let r =
        jawtrack::rig::ik::solve(&f.rig, &point, &target, &[0.0; 3], &Default::default()).unwrap();
    assert!(r.residual_mm < 0.05, "{r:?}");
    // Targets beyond reach and starts that are not numbers are refused, not solved into NaN.
    let far = nalgebra::Vector3::new(1e308, 0.0, 0.0);
    let e = jawtrack::rig::ik::solve(&f.rig, &point, &far, &[0.0; 3], &Default::default());
    assert_eq!(
        e.unwrap_err(),
        jawtrack::rig::ik::IkError::Coordinate("target")
    );
    let e = jawtrack::rig::ik::solve(&f.rig, &point, &target, &[f64::NAN; 3], &Default::default());
    assert_eq!(e.unwrap_err(), jawtrack::rig::ik::IkError::Start);
    // The ranges' projection gives a valid, finite vector for any input.
    for d in [[f64::NAN; 3], [f64::INFINITY, f64::NEG_INFINITY, 1e308]] {
        let c = f.rig.clamp(&d);
        assert!(
            c.iter().all(|v| v.is_finite()) && f.rig.is_valid(&c),
            "{d:?} -> {c:?}"
        );
    }
    assert!(f.rig.is_valid(&r.params));
}

#[test]
fn jaw_pose_files_round_trip_and_bad_ones_are_named() {
    let f = fixture();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("jaw.json");
    write_jaw_poses(&path, &f.poses.frames[..5], &f.poses.poses[..5]).unwrap();
    let back = read_jaw_poses(&path).unwrap();
    assert_eq!(back.frames, f.poses.frames[..5]);
    let (r, t) = back.poses[3].distance_to(&f.poses.poses[3]);
    assert!(r < 1e-9 && t < 1e-9);

    let write = |name: &str, text: &str| {
        let p = dir.path().join(name);
        std::fs::write(&p, text).unwrap();
        read_jaw_poses(&p).unwrap_err().to_string()
    };
    let e = write("a.json", r#"{"format": "jawtrack-jaw/7", "poses": []}"#);
    assert!(
        e.contains("a.json") && e.contains("`format`") && e.contains("jawtrack-jaw/1"),
        "{e}"
    );
    let e = write(
        "b.json",
        r#"{"format": "jawtrack-jaw/1", "poses": [{"frame": 0, "rotation": [[1,0,0],[0,1,0],[0,0,2]], "translation": [0,0,0]}]}"#,
    );
    assert!(
        e.contains("poses[0].rotation") && e.contains("rotation matrix"),
        "{e}"
    );
    let pose = r#"{"rotation": [[1,0,0],[0,1,0],[0,0,1]], "translation": [0,0,0]}"#;
    let e = write(
        "c.json",
        &format!(
            r#"{{"frames": [{{"frame": 0, "upper": {pose}, "lower": {pose}, "status": "no-data"}}]}}"#
        ),
    );
    assert!(
        e.contains("no usable jaw poses") && e.contains("1 frames skipped"),
        "{e}"
    );
    // A status the spec does not have is named, not taken for `ok`.
    let e = write(
        "c2.json",
        &format!(
            r#"{{"frames": [{{"frame": 0, "upper": {pose}, "lower": {pose}, "status": "lost"}}]}}"#
        ),
    );
    assert!(
        e.contains("frames[0].status") && e.contains("lost") && e.contains("low-confidence"),
        "{e}"
    );
    let e = write("d.json", r#"{"frames": [{"frame": 0, "upper": 3}]}"#);
    assert!(e.contains("d.json") && e.contains("frames[0].upper"), "{e}");
    assert!(
        read_jaw_poses(Path::new("/nonexistent/jaw.json"))
            .unwrap_err()
            .to_string()
            .contains("not found")
    );
}

#[test]
fn too_few_poses_is_an_error() {
    let f = fixture();
    let e =
        JawRig::learn(&f.poses.poses[..5], &f.metric, &Default::default(), &|_| {}).unwrap_err();
    assert!(e.to_string().contains("at least 12"), "{e}");
}

#[test]
fn the_envelope_rig_beats_the_traditional_ones() {
    use jawtrack::envelope::JawFrame;
    use jawtrack::envelope::compare::compare;
    let f = fixture();
    let frame = JawFrame::from_mesh(&f.mandible, None, None).unwrap();
    // The landmarks: condyles behind and above the teeth, 90-110 mm apart; the reference point
    // at the front.
    let (l, r, p) = (frame.condyle_left, frame.condyle_right, frame.reference);
    assert!(
        l[0] > r[0] && (l[0] - r[0] - 100.0).abs() < 15.0,
        "{l:?} {r:?}"
    );
    assert!(p[2] > l[2] + 60.0 && p[1] < l[1], "{p:?}");
    let rows = compare(&f.poses.poses, &frame, &f.metric).unwrap();
    let get = |name: &str| {
        rows.iter()
            .find(|r| r.name.starts_with(name))
            .unwrap()
            .max_vertex_mm
    };
    // Measured on this set: envelope ≈ 0.1 mm mean, traditional 3-DOF ≈ 0.5, 1-DOF ≈ 4.
    let env = get("envelope");
    assert!(env.mean < 0.4, "envelope {env:?}");
    assert!(get("traditional 3-DOF").mean > 2.0 * env.mean, "{rows:#?}");
    assert!(get("traditional 1-DOF").mean > 5.0 * env.mean, "{rows:#?}");
}

#[test]
fn the_envelope_rig_file_round_trips_and_controls_work() {
    use jawtrack::envelope::{EnvelopeRig, JawFrame};
    let f = fixture();
    let frame = JawFrame::from_mesh(&f.mandible, None, None).unwrap();
    let rig = EnvelopeRig::learn(&f.poses.poses, &frame, &f.metric).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("envelope.json");
    rig.save(&path).unwrap();
    let back = EnvelopeRig::load(&path).unwrap();
    let s = [0.3, 0.6, 0.5];
    let (r, t) = back.pose_at_cube(&s).distance_to(&rig.pose_at_cube(&s));
    assert!(r < 1e-12 && t < 1e-9);
    // Direct manipulation: the pose puts the reference point where asked (inside the envelope).
    let target = rig.shield.point(&s);
    let pose = rig.pose_at(&target);
    assert!(
        (rig.point_of(&pose) - target).norm() < 0.5,
        "{:?} vs {target:?}",
        rig.point_of(&pose)
    );
    // Far outside: projected onto the envelope, and still a valid pose.
    let far = target + nalgebra::Vector3::new(0.0, 0.0, 80.0);
    assert!(!rig.shield.contains(&far) && rig.shield.contains(&rig.shield.project(&far)));
    let mut json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    json["rbf"]["sigmas"] = serde_json::json!([1.0]);
    std::fs::write(&path, json.to_string()).unwrap();
    let e = EnvelopeRig::load(&path).unwrap_err().to_string();
    assert!(e.contains("envelope.json") && e.contains("`rbf`"), "{e}");
}

#[test]
fn full_adaptation_to_another_joint_beats_reduced() {
    use jawtrack::envelope::adapt::{Adaptation, adapt, extremal_poses};
    use jawtrack::envelope::{EnvelopeRig, JawFrame};
    let f = fixture();
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("b");
    let opts = SynthOptions {
        frames: 170,
        frames_per_segment: 10,
        seed: 3,
        no_masks: true,
        joint: jawtrack::synth::Joint::Variant,
        ..Default::default()
    };
    generate(&out, &opts, &|| {}).unwrap();
    let poses_b = read_jaw_poses(&out.join("gt/poses.json")).unwrap().poses;
    let mandible_b = Mesh::load(&out.join("meshes/mandible.obj"), BoiSource::None).unwrap();
    let metric_b = MeshMetric::new(&mandible_b);
    let frame_b = JawFrame::from_mesh(&mandible_b, None, None).unwrap();
    let frame_a = JawFrame::from_mesh(&f.mandible, None, None).unwrap();
    let source = EnvelopeRig::learn(&f.poses.poses, &frame_a, &f.metric).unwrap();
    let measured = extremal_poses(&poses_b, &frame_b);
    let mean_error = |mode| {
        let rig = adapt(&source, &measured, &frame_b, &metric_b, mode).unwrap();
        poses_b
            .iter()
            .map(|p| metric_b.max_distance(p, &rig.reconstruct(p)))
            .sum::<f64>()
            / poses_b.len() as f64
    };
    let (reduced, full) = (
        mean_error(Adaptation::Reduced),
        mean_error(Adaptation::Full),
    );
    // Measured on 833 poses: full ≈ 0.54 mm, reduced ≈ 0.90 mm.
    assert!(
        full < 1.0 && full < reduced,
        "full {full} reduced {reduced}"
    );
}

/// Animator units: zero at the rest bite, and the network parameters solved for a pose given
/// in degrees and millimetres land on it.
#[test]
fn the_rig_speaks_degrees_and_millimetres() {
    let f = fixture();
    let rig = f.rig.clone().with_anatomy(&f.mandible, &f.poses.poses);
    let rest = rig.encode(
        &rig.anatomy
            .as_ref()
            .unwrap()
            .rest
            .to_pose(Path::new("r"), "rest")
            .unwrap(),
    );
    let at_rest = rig.anatomical(&rest).unwrap();
    // The rig's own pose for the rest bite's parameters is within its reconstruction error.
    assert!(
        at_rest.opening_deg.abs() < 0.5 && at_rest.incisal_opening_mm.abs() < 0.5,
        "{at_rest:?}"
    );
    for target in [[10.0, 0.0, 0.0], [20.0, 3.0, 1.0], [5.0, -2.0, 2.0]] {
        let d = rig
            .params_for(&target)
            .unwrap_or_else(|| panic!("{target:?} unreachable"));
        let got = rig.anatomical(&d).unwrap();
        assert!(
            (got.opening_deg - target[0]).abs() < 1e-3,
            "{target:?}: {got:?}"
        );
        assert!(
            (got.lateral_mm - target[1]).abs() < 1e-3,
            "{target:?}: {got:?}"
        );
        assert!(
            (got.protrusion_mm - target[2]).abs() < 1e-3,
            "{target:?}: {got:?}"
        );
    }
    // Opening the jaw 20° moves the incisal point down by centimetres, as a hinge of ~9 cm does.
    let d = rig.params_for(&[20.0, 0.0, 0.0]).unwrap();
    let open = rig.anatomical(&d).unwrap();
    assert!(
        open.incisal_opening_mm > 20.0 && open.incisal_opening_mm < 40.0,
        "{open:?}"
    );
    // A rig file keeps its anatomy.
    let t = tempfile::tempdir().unwrap();
    rig.save(&t.path().join("rig.json")).unwrap();
    let back = JawRig::load(&t.path().join("rig.json")).unwrap();
    assert_eq!(back.anatomical(&d), rig.anatomical(&d));
    assert!(
        f.rig.anatomical(&d).is_none(),
        "a rig without its anatomy says so"
    );
}

/// Keys in degrees and millimetres are interpolated in those units.
#[test]
fn an_animation_keyed_in_degrees_opens_linearly() {
    use jawtrack::rig::animate::{Key, KeyError, animate_animator};
    let f = fixture();
    let rig = f.rig.clone().with_anatomy(&f.mandible, &f.poses.poses);
    let keys = [
        Key {
            time: 0.0,
            params: [0.0, 0.0, 0.0],
        },
        Key {
            time: 1.0,
            params: [20.0, 0.0, 1.0],
        },
    ];
    let frames = animate_animator(&rig, &keys, 10.0).unwrap();
    assert_eq!(frames.len(), 11);
    for fr in frames.iter().filter(|fr| !fr.clamped) {
        let a = rig.anatomical(&fr.params).unwrap();
        assert!(
            (a.opening_deg - 20.0 * fr.time).abs() < 1e-3,
            "{fr:?}: {a:?}"
        );
        assert!((a.protrusion_mm - fr.time).abs() < 1e-3, "{fr:?}: {a:?}");
    }
    assert!(frames.iter().filter(|fr| !fr.clamped).count() >= 3);
    assert_eq!(
        animate_animator(&f.rig, &keys, 10.0).unwrap_err(),
        KeyError::NoAnatomy
    );
}

/// `rig sample` and `rig ik` speak degrees and mm too: each sampled pose's animator values
/// pose the same jaw through `rig pose`, and IK started from an animator pose reports its
/// answer in those units.
#[test]
fn sample_and_ik_report_degrees_and_millimetres() {
    let f = fixture();
    let rig = f.rig.clone().with_anatomy(&f.mandible, &f.poses.poses);
    let t = tempfile::tempdir().unwrap();
    let rig_path = t.path().join("rig.json");
    rig.save(&rig_path).unwrap();
    let run = |args: &[&str]| -> String {
        let out = std::process::Command::new(env!("CARGO_BIN_EXE_jawtrack"))
            .args(args)
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{args:?}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        String::from_utf8_lossy(&out.stdout).into_owned()
    };
    let out = t.path().join("samples.json");
    let rig_s = rig_path.to_str().unwrap();
    run(&[
        "rig",
        "sample",
        rig_s,
        "-n",
        "4",
        "-o",
        out.to_str().unwrap(),
    ]);
    let units: Vec<[f64; 3]> = serde_json::from_str(
        &std::fs::read_to_string(out.with_extension("animator.json")).unwrap(),
    )
    .unwrap();
    let params: Vec<[f64; 3]> =
        serde_json::from_str(&std::fs::read_to_string(out.with_extension("params.json")).unwrap())
            .unwrap();
    assert_eq!(units.len(), 4);
    for (u, d) in units.iter().zip(&params) {
        let (o, l, p) = (u[0].to_string(), u[1].to_string(), u[2].to_string());
        let posed: serde_json::Value = serde_json::from_str(&run(&[
            "rig",
            "pose",
            rig_s,
            "--opening-deg",
            &o,
            "--lateral-mm",
            &l,
            "--protrusion-mm",
            &p,
        ]))
        .unwrap();
        let want = rig.pose(d);
        let got: jawtrack::formats::PoseJson =
            serde_json::from_value(posed["pose"].clone()).unwrap();
        let got = got.to_pose(Path::new("pose"), "pose").unwrap();
        let moved = (got.translation - want.translation).norm();
        assert!(moved < 0.01, "sample {u:?}: {moved} mm apart");
    }

    let ik: serde_json::Value = serde_json::from_str(&run(&[
        "rig",
        "ik",
        rig_s,
        "--point",
        "0,-10,40",
        "--target",
        "0,-22,38",
        "--from-animator",
        "5,0,0",
    ]))
    .unwrap();
    let opening = ik["animator"]["opening_deg"].as_f64().unwrap();
    assert!(
        opening.is_finite() && ik["valid"].as_bool().is_some(),
        "{ik}"
    );
}
