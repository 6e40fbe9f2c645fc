//! `jawtrack mesh boi` marks scans in the scan frame and refuses, saying why, a scan written in
//! another frame (it would mark the wrong faces).

use std::path::Path;
use std::process::{Command, Output};

use jawtrack::mesh::Mesh;
use jawtrack::mesh::write_obj;

fn mesh_boi(input: &Path, out: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_jawtrack"))
        .args(["mesh", "boi"])
        .args([input, out])
        .output()
        .unwrap()
}

#[test]
fn a_scan_frame_arch_is_marked_and_a_z_up_copy_is_refused_with_the_reason() {
    let t = tempfile::tempdir().unwrap();
    for upper in [true, false] {
        let name = if upper { "upper" } else { "lower" };
        let mut mesh = jawtrack::anatomy::procedural_arch(upper);
        mesh.boi.iter_mut().for_each(|b| *b = false);
        let y_up = t.path().join(format!("{name}.obj"));
        write_obj(&mesh, &y_up).unwrap();
        let run = mesh_boi(&y_up, &t.path().join(format!("{name}.boi.obj")));
        assert!(
            run.status.success(),
            "{}",
            String::from_utf8_lossy(&run.stderr)
        );

        // Turned +90° about x: y up becomes z up, +z anterior becomes −y (a CAD convention).
        let z_up = Mesh {
            positions: mesh.positions.iter().map(|p| [p[0], -p[2], p[1]]).collect(),
            ..mesh.clone()
        };
        let turned = t.path().join(format!("{name}-z-up.obj"));
        write_obj(&z_up, &turned).unwrap();
        let run = mesh_boi(&turned, &t.path().join("out.obj"));
        let err = String::from_utf8_lossy(&run.stderr);
        assert!(!run.status.success(), "{name}: a z-up arch was marked");
        assert!(
            err.contains("-z-up.obj")
                && err.contains("not in the scan frame")
                && err.contains("thinnest axis lies along z")
                && err.contains("front towards -y"),
            "{err}"
        );
        assert!(!t.path().join("out.obj").exists());
    }
}
