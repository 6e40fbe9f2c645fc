//! `jawtrack mesh boi` marks the same faces whatever frame the scan is written in.

use std::path::Path;
use std::process::Command;

use jawtrack::capture::mesh::write_obj;
use jawtrack::capture::{BoiSource, Mesh};

/// The arch turned +90° about x: y up becomes z up, +z anterior becomes −y (a CAD convention).
fn z_up(mesh: &Mesh) -> Mesh {
    Mesh {
        positions: mesh.positions.iter().map(|p| [p[0], -p[2], p[1]]).collect(),
        ..mesh.clone()
    }
}

/// Mark `input` with the CLI; the marked faces.
fn marked(input: &Path, out: &Path, arch: &str) -> Vec<bool> {
    let run = Command::new(env!("CARGO_BIN_EXE_jawtrack"))
        .args(["mesh", "boi"])
        .args([input, out])
        .args(["--arch", arch])
        .output()
        .unwrap();
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    Mesh::load(out, BoiSource::Group("boi")).unwrap().boi
}

#[test]
fn a_z_up_arch_gets_the_same_boundary_of_interest() {
    let t = tempfile::tempdir().unwrap();
    for upper in [true, false] {
        let arch = if upper { "upper" } else { "lower" };
        let mut mesh = jawtrack::anatomy::procedural_arch(upper);
        mesh.boi.iter_mut().for_each(|b| *b = false);
        let (y_up, turned) = (t.path().join("y.obj"), t.path().join("z.obj"));
        write_obj(&mesh, &y_up).unwrap();
        write_obj(&z_up(&mesh), &turned).unwrap();
        let a = marked(&y_up, &t.path().join("y.boi.obj"), arch);
        let b = marked(&turned, &t.path().join("z.boi.obj"), arch);
        let n = a.iter().filter(|&&m| m).count();
        assert!(n > 100, "{arch}: {n} faces marked");
        assert_eq!(a, b, "{arch}: the z-up copy is marked differently");
    }
}

#[test]
fn a_shape_that_does_not_tell_the_bite_side_is_refused() {
    // A slab: both ends of its thinnest axis hold the same surface.
    let mut slab = Mesh {
        positions: Vec::new(),
        triangles: Vec::new(),
        boi: Vec::new(),
    };
    let corners = [[0.0, 0.0], [60.0, 0.0], [60.0, 50.0], [0.0, 50.0]];
    for y in [0.0f32, 10.0] {
        for [x, z] in corners {
            slab.positions.push([x, y, z]);
        }
    }
    for [a, b, c] in [[0, 1, 2], [0, 2, 3], [4, 6, 5], [4, 7, 6]] {
        slab.triangles.push([a, b, c]);
        slab.boi.push(false);
    }
    let t = tempfile::tempdir().unwrap();
    let input = t.path().join("upper.obj");
    write_obj(&slab, &input).unwrap();
    let run = Command::new(env!("CARGO_BIN_EXE_jawtrack"))
        .args(["mesh", "boi"])
        .args([&input, &t.path().join("out.obj")])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&run.stderr);
    assert!(!run.status.success());
    assert!(
        err.contains("upper.obj") && err.contains("cannot tell which side"),
        "{err}"
    );
}
