use nalgebra::Vector6;

use super::*;
use crate::energy::raster::render_target;
use crate::energy::target::{CLASS_BODY, CLASS_NONE};
use crate::geometry::Distortion;

fn camera() -> Camera {
    Camera {
        name: "c".into(),
        width: 800,
        height: 800,
        fx: 1000.0,
        fy: 1000.0,
        cx: 400.0,
        cy: 400.0,
        distortion: Distortion::NONE,
        camera_from_world: Pose::IDENTITY,
    }
}

/// A cube of side `s` centred at the origin, wound outwards.
fn cube(s: f32) -> Mesh {
    crate::mesh::cuboid([-s / 2.0; 3], [s / 2.0; 3])
}

/// The cube 150 mm in front of the camera, turned so that three faces show.
fn posed() -> Pose {
    Pose::new(
        crate::geometry::so3_exp(&Vector3::new(0.4, 0.6, 0.1)),
        Vector3::new(3.0, -2.0, 150.0),
    )
}

fn covered(mesh: &Mesh, pose: &Pose) -> f64 {
    let t = render_target(&camera(), &[(mesh, pose, CLASS_BODY, CLASS_BODY)]);
    t.class.iter().filter(|&&c| c != CLASS_NONE).count() as f64
}

/// The contour integral of the outward motion: d(covered pixels)/dt along ξ.
fn area_rate(mesh: &Mesh, pose: &Pose, xi: &Vector6<f64>) -> f64 {
    let c = ContourEdges::of(mesh).contour(mesh, pose, &camera(), 1.0);
    c.iter()
        .map(|p| (p.jacobian * xi).dot(&p.normal) * p.length)
        .sum()
}

/// The Jacobian of `p`'s pixel in `cam` against central differences of its projection
/// (the camera's own `project`) under each se(3) component.
fn assert_jacobian_is_the_projection_s_derivative(cam: &Camera, p: Vector3<f64>, tol: f64) {
    let view = View { cam };
    let (pixel, _, j) = view.point(&p).unwrap();
    let expected = cam.project(&p).unwrap();
    assert!((pixel - expected).norm() < 1e-9, "{pixel} vs {expected}");
    for k in 0..6 {
        let h = 1e-6;
        let mut xi = Vector6::zeros();
        xi[k] = h;
        let plus = cam.project(&Pose::exp(&xi).transform_point(&p)).unwrap();
        let minus = cam.project(&Pose::exp(&-xi).transform_point(&p)).unwrap();
        let fd = (plus - minus) / (2.0 * h);
        let err = (fd - j.column(k)).norm();
        assert!(
            err < tol * (1.0 + fd.norm()),
            "ξ[{k}]: {fd} vs {}",
            j.column(k)
        );
    }
}

#[test]
fn the_jacobian_is_the_derivative_of_the_projection() {
    let cam = Camera {
        camera_from_world: Pose::new(
            crate::geometry::so3_exp(&Vector3::new(0.1, -0.2, 0.05)),
            Vector3::new(5.0, 1.0, 20.0),
        ),
        ..camera()
    };
    assert_jacobian_is_the_projection_s_derivative(&cam, Vector3::new(12.0, -7.0, 130.0), 1e-4);
    // Through a lens (the lens's own derivative is taken by differences: a looser bound).
    let lens = Camera {
        distortion: Distortion::brown([-0.3, 0.12, 0.001, -0.002, 0.0]),
        ..camera()
    };
    assert_jacobian_is_the_projection_s_derivative(&lens, Vector3::new(30.0, -20.0, 140.0), 1e-3);
}

#[test]
fn the_contour_is_the_outline_and_its_normals_point_out() {
    let (mesh, pose) = (cube(40.0), posed());
    let c = ContourEdges::of(&mesh).contour(&mesh, &pose, &camera(), 2.0);
    let t = render_target(&camera(), &[(&mesh, &pose, CLASS_BODY, CLASS_BODY)]);
    let class = |x: Vector2<f64>| t.class[x.y.round() as usize * 800 + x.x.round() as usize];
    let right = c
        .iter()
        .filter(|p| class(p.pixel + 2.0 * p.normal) == CLASS_NONE)
        .filter(|p| class(p.pixel - 2.0 * p.normal) != CLASS_NONE)
        .count();
    assert!(c.len() > 100, "{} points", c.len());
    // All but those within a pixel or two of the outline's corners.
    assert!(right * 100 >= c.len() * 95, "{right} of {} right", c.len());
    // The outline's length: the contour of a convex body is its perimeter.
    let perimeter: f64 = c.iter().map(|p| p.length).sum();
    let area = covered(&mesh, &pose);
    assert!(
        perimeter > 2.0 * (std::f64::consts::PI * area).sqrt(),
        "{perimeter}"
    );
    assert!(perimeter < 4.5 * area.sqrt(), "{perimeter} for {area} px");
}

#[test]
fn the_contour_integral_is_the_rate_of_the_covered_area() {
    let (mesh, pose) = (cube(40.0), posed());
    // Towards the camera, sideways, and turning about the cube's own axes.
    let moves = [
        Vector6::new(0.0, 0.0, 0.0, 0.0, 0.0, -1.0),
        Vector6::new(0.0, 0.0, 0.0, 1.0, 0.5, 0.0),
        Vector6::new(0.01, 0.0, 0.0, 0.0, -1.5, 0.0),
        Vector6::new(0.0, 0.01, 0.0, -1.5, 0.0, 0.0),
    ];
    let h = 2.0;
    for xi in moves {
        let plus = covered(&mesh, &(Pose::exp(&(xi * h)).compose(&pose)));
        let minus = covered(&mesh, &(Pose::exp(&(xi * -h)).compose(&pose)));
        let fd = (plus - minus) / (2.0 * h);
        let rate = area_rate(&mesh, &pose, &xi);
        eprintln!(
            "ξ {:?}: contour {rate:.1} px, pixel count {fd:.1} px",
            xi.as_slice()
        );
        // Pixel counting leaves about a pixel per unit of contour: a few per cent of the
        // rate at these steps.
        assert!(
            (rate - fd).abs() < 0.05 * fd.abs() + 40.0,
            "ξ {xi}: {rate} vs {fd} px"
        );
    }
}

#[test]
fn the_uncovered_gradient_is_the_rate_of_the_uncovered_count() {
    // The mask: the cube's silhouette at another pose (what the camera saw); the model
    // starts off it, so part of the mask is uncovered and part of the model is outside.
    let (mesh, truth) = (cube(40.0), posed());
    let start = Pose::exp(&Vector6::new(0.03, -0.02, 0.05, 4.0, -3.0, 6.0)).compose(&truth);
    let cam = camera();
    let mask = render_target(&cam, &[(&mesh, &truth, CLASS_BODY, CLASS_BODY)]).class;
    let uncovered = |pose: &Pose| {
        let t = render_target(&cam, &[(&mesh, pose, CLASS_BODY, CLASS_BODY)]);
        mask.iter()
            .zip(&t.class)
            .filter(|&(&m, &c)| m != CLASS_NONE && c == CLASS_NONE)
            .count() as f64
    };
    let contour = ContourEdges::of(&mesh).contour(&mesh, &start, &cam, 1.0);
    let g = uncovered_gradient(&contour, |x| {
        bilinear(&mask, 800, 800, |c| c != CLASS_NONE, x)
    });
    let h = 1.0;
    for k in 0..6 {
        // Steps of about a millimetre at the cube either way.
        let scale = if k < 3 { 0.005 } else { 1.0 };
        let mut xi = Vector6::zeros();
        xi[k] = scale * h;
        let fd = (uncovered(&(Pose::exp(&xi).compose(&start)))
            - uncovered(&(Pose::exp(&-xi).compose(&start))))
            / (2.0 * h);
        let rate = g[k] * scale;
        eprintln!("ξ[{k}]: gradient {rate:.1} px, pixel count {fd:.1} px");
        assert!(
            (rate - fd).abs() < 0.08 * fd.abs() + 40.0,
            "ξ[{k}]: {rate} vs {fd}"
        );
    }
}

#[test]
fn a_hidden_edge_is_left_out_against_the_depth_buffer() {
    let (mesh, pose) = (cube(40.0), posed());
    // A wall in front of the cube's left half.
    let wall = Mesh {
        positions: vec![
            [-200.0, -200.0, 100.0],
            [3.0, -200.0, 100.0],
            [3.0, 200.0, 100.0],
            [-200.0, 200.0, 100.0],
        ],
        triangles: vec![[0, 1, 2], [0, 2, 3]],
        boi: vec![false, false],
    };
    let cam = camera();
    let all = ContourEdges::of(&mesh).contour(&mesh, &pose, &cam, 2.0);
    let alone = render_target(&cam, &[(&mesh, &pose, CLASS_BODY, CLASS_BODY)]);
    let both = render_target(
        &cam,
        &[
            (&mesh, &pose, CLASS_BODY, CLASS_BODY),
            (&wall, &Pose::IDENTITY, CLASS_BODY, CLASS_BODY),
        ],
    );
    assert_eq!(visible(&all, &alone, 2.0).len(), all.len());
    let shown = visible(&all, &both, 2.0);
    // The wall covers the image left of x = 3 mm at 100 mm: pixel 430 and less.
    assert!(
        shown.iter().all(|p| p.pixel.x > 428.0),
        "a hidden point kept"
    );
    assert!(!shown.is_empty() && shown.len() < all.len());
}
