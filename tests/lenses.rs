//! The lens models against OpenCV itself: projections.json holds what cv2.projectPoints and
//! cv2.fisheye.projectPoints give for the classic, rational, thin-prism and fisheye models
//! (fixtures/lens/make.py). The camera file reader, the f64 projection and the energy's f32
//! lens must all give those pixels.

use std::path::Path;

use jawtrack::capture::camera_from_json;
use jawtrack::capture::json::CameraJson;
use jawtrack::energy::lens::Lens;
use nalgebra::{Vector2, Vector3};

#[test]
fn every_model_projects_as_opencv_does() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/lens/projections.json");
    let cases: Vec<serde_json::Value> =
        serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    assert_eq!(cases.len(), 4);
    for case in &cases {
        let name = case["name"].as_str().unwrap();
        let cj: CameraJson = serde_json::from_value(case["camera"].clone()).unwrap();
        let cam = camera_from_json(&cj, &path, name).unwrap();
        assert_eq!(
            cam.distortion.is_fisheye(),
            case["lens"] == "fisheye",
            "{name}"
        );
        let lens = Lens::of(&cam).unwrap();
        let (mut worst, mut worst_f32) = (0.0f64, 0.0f64);
        let pairs = case["points"]
            .as_array()
            .unwrap()
            .iter()
            .zip(case["pixels"].as_array().unwrap());
        for (p, px) in pairs {
            let p = Vector3::new(
                p[0].as_f64().unwrap(),
                p[1].as_f64().unwrap(),
                p[2].as_f64().unwrap(),
            );
            let want = Vector2::new(px[0].as_f64().unwrap(), px[1].as_f64().unwrap());
            let got = cam.project(&p).unwrap();
            worst = worst.max((got - want).norm());
            let d = lens.apply((p.x / p.z) as f32, (p.y / p.z) as f32).unwrap();
            let f32_px = Vector2::new(cam.fx * d[0] as f64 + cam.cx, cam.fy * d[1] as f64 + cam.cy);
            worst_f32 = worst_f32.max((f32_px - want).norm());
            // Undistortion inverts it.
            let back = cam.pixel_to_normalised(got);
            assert!(
                (back - Vector2::new(p.x / p.z, p.y / p.z)).norm() < 1e-9,
                "{name}"
            );
        }
        assert!(
            worst < 1e-6,
            "{name}: f64 projection off OpenCV's by {worst} px"
        );
        assert!(
            worst_f32 < 2e-3,
            "{name}: the energy's f32 lens off by {worst_f32} px"
        );
    }
}

#[test]
fn lens_fields_are_checked() {
    let path = Path::new("cam.json");
    let base = r#"{"width": 640, "height": 480, "fx": 500, "fy": 500, "cx": 320, "cy": 240,
        "rotation": [[1,0,0],[0,1,0],[0,0,1]], "translation": [0,0,0]"#;
    let read = |extra: &str| {
        let cj: CameraJson = serde_json::from_str(&format!("{base}, {extra}}}")).unwrap();
        camera_from_json(&cj, path, "cam").map_err(|e| e.to_string())
    };
    let e = read(r#""lens": "fisheye", "distortion": [0.1, 0.0, 0.0]"#).unwrap_err();
    assert!(
        e.contains("`distortion`") && e.contains("4 coefficients"),
        "{e}"
    );
    let e = read(r#""lens": "fisheye""#).unwrap_err();
    assert!(
        e.contains("`distortion`") && e.contains("fisheye lens needs"),
        "{e}"
    );
    let e = read(r#""lens": "omni", "distortion": [0.1, 0.0, 0.0, 0.0]"#).unwrap_err();
    assert!(e.contains("`lens`") && e.contains("omni"), "{e}");
    let e = read(r#""distortion": [0.1, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]"#).unwrap_err();
    assert!(e.contains("`distortion`") && e.contains("found 7"), "{e}");
    assert!(
        read(r#""distortion": [0.1, 0.0, 0.0, 0.0, 0.0, 0.2, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]"#)
            .is_ok()
    );
}
