//! Every rule of the tracking and rig settings: a value out of range is refused with an error
//! that names the source, the field and the range, never a panic or a silent default.

use std::path::Path;

use jawtrack::rig::RigSettings;
use jawtrack::track::TrackSettings;

/// The error text for tracking settings given as JSON (missing fields take their defaults).
fn track_error(json: &str) -> String {
    let settings: TrackSettings = serde_json::from_str(json).expect("parses");
    settings
        .validate_from(Path::new("my-settings.json"))
        .expect_err(json)
        .to_string()
}

fn rig_error(json: &str) -> String {
    let settings: RigSettings = serde_json::from_str(json).expect("parses");
    settings
        .validate(Path::new("rig.json"))
        .expect_err(json)
        .to_string()
}

/// Each case: the JSON, the field the error must name, and words of the range it must give.
fn check(cases: &[(&str, &str, &str)], error: fn(&str) -> String) {
    for (json, field, range) in cases {
        let e = error(json);
        assert!(
            e.contains(&format!("`{field}`")) && e.contains(range),
            "{json}: expected `{field}` and {range:?} in {e:?}"
        );
    }
}

#[test]
fn the_defaults_pass() {
    TrackSettings::default().validate().unwrap();
    RigSettings::default().validate(Path::new("rig")).unwrap();
}

#[test]
fn every_search_rule_names_its_field_and_range() {
    check(
        &[
            (
                r#"{"search":{"fd_step_rad":0}}"#,
                "search.fd_step_rad",
                "above 0",
            ),
            (
                r#"{"search":{"fd_step_mm":0}}"#,
                "search.fd_step_mm",
                "above 0",
            ),
            (
                r#"{"search":{"fd_step_mm":-1}}"#,
                "search.fd_step_mm",
                "found -1",
            ),
            (
                r#"{"search":{"line_max_rad":2}}"#,
                "search.line_max_rad",
                "at most 1",
            ),
            (
                r#"{"search":{"line_max_mm":0}}"#,
                "search.line_max_mm",
                "above 0",
            ),
            (
                r#"{"search":{"line_tolerance":0}}"#,
                "search.line_tolerance",
                "from 0.000001",
            ),
            (
                r#"{"search":{"max_rounds":100000}}"#,
                "search.max_rounds",
                "from 0 to 1000",
            ),
            (r#"{"search":{"min_gain":-1}}"#, "search.min_gain", "from 0"),
            (
                r#"{"search":{"sample_rounds":1000}}"#,
                "search.sample_rounds",
                "from 0 to 100",
            ),
            (
                r#"{"search":{"samples":0}}"#,
                "search.samples",
                "from 1 to 4096",
            ),
            (
                r#"{"search":{"samples":1000000000}}"#,
                "search.samples",
                "from 1 to 4096",
            ),
            (
                r#"{"search":{"sample_rad":0}}"#,
                "search.sample_rad",
                "above 0",
            ),
            (
                r#"{"search":{"sample_mm":100}}"#,
                "search.sample_mm",
                "at most 50",
            ),
            (
                r#"{"search":{"scales":[]}}"#,
                "search.scales",
                "from 1 to 16 entries",
            ),
            (
                r#"{"search":{"scales":[1,-1]}}"#,
                "search.scales[1]",
                "above 0",
            ),
            (
                r#"{"search":{"scales":[0]}}"#,
                "search.scales[0]",
                "above 0",
            ),
            (
                r#"{"search":{"lambda":1e308}}"#,
                "search.lambda",
                "from 0 to 1000",
            ),
            (
                r#"{"search":{"cross_weight":-0.5}}"#,
                "search.cross_weight",
                "from 0 to 1000",
            ),
            (
                r#"{"search":{"mouth_weight":2000}}"#,
                "search.mouth_weight",
                "from 0 to 1000",
            ),
            (
                r#"{"search":{"gauss_newton":{"fallback_ratio":-1}}}"#,
                "search.gauss_newton.fallback_ratio",
                "from 0 to 1000000000",
            ),
            (
                r#"{"search":{"gauss_newton":{"reaches_px":[]}}}"#,
                "search.gauss_newton.reaches_px",
                "from 1 to 16 entries",
            ),
        ],
        track_error,
    );
}

#[test]
fn every_tracking_rule_names_its_field_and_range() {
    check(
        &[
            (
                r#"{"per_arch_passes":0}"#,
                "per_arch_passes",
                "from 1 to 16",
            ),
            (
                r#"{"combined_passes":17}"#,
                "combined_passes",
                "from 1 to 16",
            ),
            (r#"{"settle_mm":-1}"#, "settle_mm", "from 0 to 100"),
            (
                r#"{"labelled":{"jaw_prior_grid":[5,3,101]}}"#,
                "labelled.jaw_prior_grid[2]",
                "from 0 to 100",
            ),
            (
                r#"{"labelled":{"jaw_prior_nearest":10001}}"#,
                "labelled.jaw_prior_nearest",
                "from 0 to 10000",
            ),
            (
                r#"{"labelled":{"sample_rounds":101}}"#,
                "labelled.sample_rounds",
                "from 0 to 100",
            ),
            (
                r#"{"low_confidence_area_error":2}"#,
                "low_confidence_area_error",
                "from 0 to 1",
            ),
            (
                r#"{"low_confidence_floor":-0.1}"#,
                "low_confidence_floor",
                "from 0 to 1",
            ),
            (
                r#"{"low_confidence_ratio":-1}"#,
                "low_confidence_ratio",
                "from 0",
            ),
            (
                r#"{"confidence_window":0}"#,
                "confidence_window",
                "from 1 to 10000",
            ),
            (
                r#"{"jaw_prior_grid":[1000,1000,1000]}"#,
                "jaw_prior_grid[0]",
                "from 0 to 100",
            ),
            (
                r#"{"jaw_prior_grid":[100,100,100]}"#,
                "jaw_prior_grid",
                "more than the 10000",
            ),
            (
                r#"{"jaw_prior_fine_grid":[201,1,1]}"#,
                "jaw_prior_fine_grid[0]",
                "from 0 to 200",
            ),
            (
                r#"{"jaw_prior_nearest":1000000}"#,
                "jaw_prior_nearest",
                "from 0 to 10000",
            ),
            (r#"{"restarts":0}"#, "restarts", "from 1 to 100"),
            (r#"{"restarts":128}"#, "restarts", "from 1 to 100"),
            (
                r#"{"contact_weight":-1}"#,
                "contact_weight",
                "from 0 to 1000000",
            ),
            (
                r#"{"contact_tolerance_mm":1000}"#,
                "contact_tolerance_mm",
                "from 0 to 100",
            ),
            (
                r#"{"jaw_manifold_weight":-2}"#,
                "jaw_manifold_weight",
                "from 0 to 1000000",
            ),
            (
                r#"{"jaw_manifold_tolerance_mm":-1}"#,
                "jaw_manifold_tolerance_mm",
                "from 0 to 100",
            ),
            (
                r#"{"window":{"frames":101}}"#,
                "window.frames",
                "from 0 to 100",
            ),
            (
                r#"{"window":{"head_acceleration":-1}}"#,
                "window.head_acceleration",
                "from 0 to 1000000000000",
            ),
            (
                r#"{"window":{"jaw_acceleration":-1}}"#,
                "window.jaw_acceleration",
                "from 0 to 1000000000000",
            ),
            (
                r#"{"window":{"acceleration_scale_mm":1001}}"#,
                "window.acceleration_scale_mm",
                "from 0 to 1000",
            ),
        ],
        track_error,
    );
    assert!(track_error(r#"{"restarts":0}"#).starts_with("my-settings.json:"));
}

#[test]
fn every_rig_rule_names_its_field_and_range() {
    check(
        &[
            (
                r#"{"network":{"hidden":100000000}}"#,
                "network.hidden",
                "from 1 to 1024",
            ),
            (
                r#"{"network":{"hidden":0}}"#,
                "network.hidden",
                "from 1 to 1024",
            ),
            (
                r#"{"network":{"weight_decay":-1}}"#,
                "network.weight_decay",
                "from 0 to 1000",
            ),
            (
                r#"{"network":{"max_iterations":100000000}}"#,
                "network.max_iterations",
                "to 10000000",
            ),
            (
                r#"{"network":{"memory":0}}"#,
                "network.memory",
                "from 1 to 1000",
            ),
            (
                r#"{"network":{"input_std":0}}"#,
                "network.input_std",
                "above 0",
            ),
            (r#"{"mode":{"hidden":0}}"#, "mode.hidden", "from 1 to 1024"),
            (
                r#"{"modes":{"hidden":2000}}"#,
                "modes.hidden",
                "from 1 to 1024",
            ),
            (
                r#"{"modes":{"max_iterations":100000000}}"#,
                "modes.max_iterations",
                "to 10000000",
            ),
            (
                r#"{"modes":{"memory":0}}"#,
                "modes.memory",
                "from 1 to 1000",
            ),
            (
                r#"{"modes":{"weight_decay":-1}}"#,
                "modes.weight_decay",
                "from 0 to 1000",
            ),
            (r#"{"alpha":-1}"#, "alpha", "above 0"),
            (r#"{"alpha":0}"#, "alpha", "above 0"),
            (
                r#"{"encode_steps":100000}"#,
                "encode_steps",
                "from 0 to 1000",
            ),
        ],
        rig_error,
    );
}

#[test]
fn track_refuses_bad_settings_before_tracking_and_does_not_panic() {
    let t = tempfile::tempdir().unwrap();
    let cap = t.path().join("cap");
    let bin = env!("CARGO_BIN_EXE_jawtrack");
    let synth = std::process::Command::new(bin)
        .args([
            "synth",
            cap.to_str().unwrap(),
            "--frames",
            "2",
            "--preset",
            "clean",
        ])
        .output()
        .unwrap();
    assert!(synth.status.success());
    for (settings, field) in [
        (r#"{"search":{"samples":0}}"#, "search.samples"),
        (r#"{"search":{"scales":[-1]}}"#, "search.scales[0]"),
        (r#"{"search":{"scales":[]}}"#, "search.scales"),
        (r#"{"search":{"fd_step_mm":0}}"#, "search.fd_step_mm"),
        (
            r#"{"search":{"line_tolerance":0}}"#,
            "search.line_tolerance",
        ),
    ] {
        let out = std::process::Command::new(bin)
            .args(["track", cap.to_str().unwrap(), "-o"])
            .arg(t.path().join("tracks.json"))
            .args(["--settings", settings])
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{settings}: {err}");
        assert!(
            err.contains("--settings") && err.contains(&format!("`{field}`")),
            "{settings}: {err}"
        );
        assert!(!err.contains("panicked"), "{err}");
    }
    // Inline segmentation settings are named by their own option.
    for (settings, field) in [
        (r#"{"reach": -1}"#, "reach"),
        (r#"{"shaded_crowns": 0.2}"#, "shaded_crowns"),
    ] {
        let out = std::process::Command::new(bin)
            .args(["segment", cap.to_str().unwrap(), "-o"])
            .arg(t.path().join("tracks.json"))
            .args(["--segment-settings", settings])
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{settings}: {err}");
        assert!(
            err.contains("--segment-settings") && err.contains(&format!("`{field}`")),
            "{settings}: {err}"
        );
    }
}
