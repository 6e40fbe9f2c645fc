//! The rasteriser against hand-counted coverage: top-left fill rule, clipping, footprints.

use super::*;
use crate::geometry::Distortion;

fn camera(width: u32, height: u32, cx: f64, cy: f64) -> Camera {
    Camera {
        name: "c".into(),
        width,
        height,
        fx: 100.0,
        fy: 100.0,
        cx,
        cy,
        distortion: Distortion::NONE,
        camera_from_world: Pose::IDENTITY,
    }
}

/// An axis-aligned square [x0, x1] x [y0, y1] at depth z, as two triangles.
fn square(x0: f32, y0: f32, x1: f32, y1: f32, z: f32) -> Mesh {
    Mesh {
        positions: vec![[x0, y0, z], [x1, y0, z], [x1, y1, z], [x0, y1, z]],
        triangles: vec![[0, 1, 2], [0, 2, 3]],
        boi: vec![false, false],
    }
}

fn render(cam: &Camera, mesh: &Mesh, pose: &Pose) -> Target {
    let mut placed = Placed::default();
    placed.place(cam, mesh, pose);
    let mut t = Target::default();
    t.reset(Rect::full(cam.width, cam.height));
    rasterise(mesh, &placed, CLASS_BODY, CLASS_BOI, &mut t);
    t
}

fn count(t: &Target, class: u8) -> usize {
    t.class.iter().filter(|&&c| c == class).count()
}

#[test]
fn floor_i32_is_floor() {
    let mut values = vec![
        0.0f32, -0.0, 0.5, -0.5, 1.0, -1.0, 255.5, -255.5, 2.56e8, -2.56e8,
    ];
    values.extend((-2000..2000).map(|k| k as f32 * 0.37 + 0.001));
    values.extend([16_777_217.0f32, -16_777_217.0, 8_388_607.5, -8_388_607.5]);
    for x in values {
        assert_eq!(floor_i32(x), x.floor() as i32, "{x}");
    }
}

#[test]
fn square_with_edges_on_pixel_centres_follows_the_top_left_rule() {
    // Edges at u = 40 and 60, v = 30 and 50 exactly on pixel centres: left and top
    // columns/rows are in, right and bottom are out: 20 x 20 pixels, the shared diagonal
    // counted once.
    let cam = camera(100, 80, 50.0, 40.0);
    let t = render(
        &cam,
        &square(-10.0, -10.0, 10.0, 10.0, 100.0),
        &Pose::IDENTITY,
    );
    assert_eq!(count(&t, CLASS_BODY), 400);
    let at = |x: usize, y: usize| t.class[y * 100 + x];
    assert_eq!(at(40, 30), CLASS_BODY);
    assert_eq!(at(59, 49), CLASS_BODY);
    assert_eq!(at(60, 30), CLASS_NONE);
    assert_eq!(at(40, 50), CLASS_NONE);
    assert_eq!(at(39, 30), CLASS_NONE);
}

#[test]
fn winding_does_not_matter_and_half_pixel_edges_are_exact() {
    // Edges at u = 39.5 .. 59.5: centres 40..=59 inside, 20 x 20 again, either winding.
    let cam = camera(100, 80, 49.5, 39.5);
    let mut m = square(-10.0, -10.0, 10.0, 10.0, 100.0);
    assert_eq!(count(&render(&cam, &m, &Pose::IDENTITY), CLASS_BODY), 400);
    for t in &mut m.triangles {
        t.swap(1, 2);
    }
    assert_eq!(count(&render(&cam, &m, &Pose::IDENTITY), CLASS_BODY), 400);
}

#[test]
fn depth_test_keeps_the_nearer_surface() {
    // A BOI square at z = 100 in front of a larger body square at z = 120.
    let cam = camera(100, 80, 50.0, 40.0);
    let mut front = square(-10.0, -10.0, 10.0, 10.0, 100.0);
    front.boi = vec![true, true];
    let back = square(-24.0, -24.0, 24.0, 24.0, 120.0); // 40 x 40 px
    let mut both = back.clone();
    let n = both.positions.len() as u32;
    both.positions.extend(&front.positions);
    both.triangles
        .extend(front.triangles.iter().map(|t| t.map(|i| i + n)));
    both.boi.extend(&front.boi);
    let t = render(&cam, &both, &Pose::IDENTITY);
    assert_eq!(count(&t, CLASS_BOI), 400);
    assert_eq!(count(&t, CLASS_BODY), 1600 - 400);
    // Drawn in the other order, the same picture.
    let mut rev = both.clone();
    rev.triangles.reverse();
    rev.boi.reverse();
    let t2 = render(&cam, &rev, &Pose::IDENTITY);
    assert_eq!(t2.class, t.class);
}

#[test]
fn geometry_crossing_the_near_plane_is_clipped_not_dropped() {
    // A floor plane y = 10 from z = -50 (behind) to z = 200: its visible part still fills
    // the lower image region up to the horizon.
    let cam = camera(100, 80, 50.0, 40.0);
    let mut floor = square(-1000.0, 10.0, 1000.0, 10.0, 0.0);
    floor.positions = vec![
        [-1000.0, 10.0, -50.0],
        [1000.0, 10.0, -50.0],
        [1000.0, 10.0, 200.0],
        [-1000.0, 10.0, 200.0],
    ];
    let t = render(&cam, &floor, &Pose::IDENTITY);
    // Rows with v >= 40 + 100·10/200 = 45 are floor.
    let at = |x: usize, y: usize| t.class[y * 100 + x];
    assert_eq!(at(50, 79), CLASS_BODY);
    assert_eq!(at(50, 46), CLASS_BODY);
    assert_eq!(at(50, 44), CLASS_NONE);
}

#[test]
fn footprint_covers_everything_drawn() {
    let cam = camera(100, 80, 50.0, 40.0);
    let m = square(-7.3, -3.1, 9.9, 12.2, 90.0);
    let pose = Pose::from_euler_tuple(&[0.2, -0.3, 0.4, 1.0, 2.0, 5.0]);
    // Also through a strong barrel lens and a pincushion one.
    for distortion in [
        Distortion::NONE,
        Distortion::brown([-0.4, 0.1, 0.002, 0.001, 0.0]),
        Distortion::brown([0.3, 0.0, 0.0, 0.0, 0.0]),
        Distortion::OpenCv([
            0.6, 0.2, 0.001, 0.0, 0.0, 1.0, 0.3, 0.0, 0.002, 0.0, -0.001, 0.0,
        ]),
        Distortion::Fisheye([0.1, -0.05, 0.01, -0.002]),
    ] {
        let cam = Camera {
            distortion,
            ..cam.clone()
        };
        let full = render(&cam, &m, &pose);
        let mut placed = Placed::default();
        placed.place(&cam, &m, &pose);
        let lens = Lens::of(&cam);
        for r in [
            placed.footprint(&cam),
            footprint(&cam, lens.as_ref(), &placed.points),
        ] {
            let mut t = Target::default();
            t.reset(r);
            rasterise(&m, &placed, CLASS_BODY, CLASS_BOI, &mut t);
            assert_eq!(count(&t, CLASS_BODY), count(&full, CLASS_BODY));
            assert!(count(&t, CLASS_BODY) > 100);
        }
    }
    let full = render(&cam, &m, &pose);
    let mut placed = Placed::default();
    placed.place(&cam, &m, &pose);
    // The footprint from the snapped vertices is tight: the covered pixels' bounding box,
    // at most a pixel larger on a side (a centre inside the vertices' bounds but off a
    // pointed corner of the triangle).
    let covered: Vec<usize> = (0..full.class.len())
        .filter(|&i| full.class[i] == CLASS_BODY)
        .collect();
    let (xs, ys): (Vec<u32>, Vec<u32>) = covered
        .iter()
        .map(|i| ((i % 100) as u32, (i / 100) as u32))
        .unzip();
    let r = placed.footprint(&cam);
    let (cx0, cx1) = (*xs.iter().min().unwrap(), *xs.iter().max().unwrap());
    let (cy0, cy1) = (*ys.iter().min().unwrap(), *ys.iter().max().unwrap());
    let (rx1, ry1) = (r.x0 + r.width - 1, r.y0 + r.height - 1);
    assert!(
        r.x0 <= cx0 && r.x0 + 1 >= cx0 && rx1 >= cx1 && rx1 <= cx1 + 1,
        "{r:?} vs x {cx0}..={cx1}"
    );
    assert!(
        r.y0 <= cy0 && r.y0 + 1 >= cy0 && ry1 >= cy1 && ry1 <= cy1 + 1,
        "{r:?} vs y {cy0}..={cy1}"
    );
}
