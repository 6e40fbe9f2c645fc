//! The masks' pyramid, for the smooth energy's coarse stages: a stage at level L draws the
//! arches through cameras of 1/2^L the masks' resolution and reads masks reduced as much
//! (M3T's region modality searches its contours over scales the same way). Its samples are
//! fewer at the same spacing in its own pixels, its search for an edge is as many of its own
//! pixels shorter, and its drawing covers a quarter of the pixels a level; the finer stages
//! then take the pose on from where it leaves it.
//!
//! Level L + 1's pixel (i, j) is level L's pixel (2i, 2j): the masks decimated, not averaged.
//! The arches drawn through the level's camera are then sampled at the very points the masks
//! are, so at the true pose the coarse stage has nothing to move. A block's most common label
//! (what `LabelMask::reduced` gives a whole capture) puts a pixel's centre between four of the
//! masks' and breaks ties along every edge in a checkerboard; the most common label around
//! (2i, 2j) fills the notches between teeth. Either moved the arches of a closed mouth, drawn
//! at the truth, two to five times as far as the masks themselves do (`track::joint`'s tests).

use rayon::prelude::*;

use crate::capture::LabelMask;
use crate::geometry::Camera;

/// The coarsest level the engines keep (level 1: half the masks' resolution).
pub const MAX_LEVEL: usize = 1;

/// How many of the masks' pixels a pixel of `level` spans along each axis.
pub fn factor(level: usize) -> u32 {
    1 << level
}

/// The mask of `level` (`mask` itself is level 0).
pub fn mask(mask: &LabelMask, level: usize) -> LabelMask {
    let mut m = mask.clone();
    for _ in 0..level {
        m = halved(&m);
    }
    m
}

/// One level down: pixel (i, j) is level L's pixel (2i, 2j).
fn halved(m: &LabelMask) -> LabelMask {
    let (w, h) = (m.width as usize, m.height as usize);
    let (hw, hh) = (w.div_ceil(2), h.div_ceil(2));
    let mut data = vec![0u8; hw * hh];
    data.par_chunks_mut(hw.max(1))
        .enumerate()
        .for_each(|(j, out)| {
            let row = &m.data[2 * j * w..(2 * j + 1) * w];
            for (label, &v) in out.iter_mut().zip(row.iter().step_by(2)) {
                *label = v;
            }
        });
    let soft = m.soft.as_ref().map(|soft| {
        (0..hw * hh)
            .map(|i| soft[2 * (i / hw) * w + 2 * (i % hw)])
            .collect()
    });
    LabelMask {
        soft,
        width: hw as u32,
        height: hh as u32,
        data,
    }
}

/// The camera of `level` for masks seen through `camera` (level 0): pixel centres on every
/// 2^L-th of the masks', the focal lengths and the principal point scaled by 1/2^L.
pub fn camera(camera: &Camera, level: usize) -> Camera {
    let k = factor(level);
    let s = 1.0 / k as f64;
    Camera {
        width: camera.width.div_ceil(k),
        height: camera.height.div_ceil(k),
        fx: camera.fx * s,
        fy: camera.fy * s,
        cx: camera.cx * s,
        cy: camera.cy * s,
        ..camera.clone()
    }
}

#[cfg(test)]
mod tests {
    use nalgebra::Vector3;

    use super::*;
    use crate::geometry::{Distortion, Pose};

    fn cam(width: u32, height: u32) -> Camera {
        Camera {
            name: "c".into(),
            width,
            height,
            fx: 800.0,
            fy: 790.0,
            cx: 330.0,
            cy: 241.0,
            distortion: Distortion::NONE,
            camera_from_world: Pose::IDENTITY,
        }
    }

    /// A point's pixel at level 1 is half its pixel at level 0: level 1's pixel i lies on
    /// level 0's pixel 2i.
    #[test]
    fn a_level_s_camera_sees_each_point_at_half_its_pixel() {
        let (c0, c1) = (cam(641, 481), camera(&cam(641, 481), 1));
        assert_eq!((c1.width, c1.height), (321, 241));
        for p in [
            Vector3::new(0.0, 0.0, 200.0),
            Vector3::new(13.0, -7.5, 180.0),
            Vector3::new(-40.0, 25.0, 230.0),
        ] {
            let (x0, x1) = (c0.project(&p).unwrap(), c1.project(&p).unwrap());
            assert!((x1 - x0 / 2.0).norm() < 1e-9, "{x0} -> {x1}");
        }
    }

    /// Level 1 holds level 0's pixels at even coordinates, whatever their neighbours.
    #[test]
    fn a_level_s_mask_is_the_masks_decimated() {
        let (w, h) = (33u32, 21u32);
        let data: Vec<u8> = (0..w * h).map(|i| (i * 7 % 5) as u8).collect();
        let m0 = LabelMask {
            soft: None,
            width: w,
            height: h,
            data,
        };
        let m = mask(&m0, 1);
        assert_eq!((m.width, m.height), (17, 11));
        for y in 0..11 {
            for x in 0..17 {
                assert_eq!(
                    m.data[(y * 17 + x) as usize],
                    m0.data[(2 * y * w + 2 * x) as usize],
                    "({x}, {y})"
                );
            }
        }
        assert_eq!(mask(&m0, 0), m0);
        // The soft evidence with them.
        let soft: Vec<[u8; 2]> = (0..w * h)
            .map(|i| [(i % 251) as u8, (i % 7) as u8])
            .collect();
        let m = mask(
            &LabelMask {
                soft: Some(soft.clone()),
                ..m0
            },
            1,
        );
        let halved = m.soft.expect("evidence");
        for y in 0..11 {
            for x in 0..17 {
                assert_eq!(
                    halved[(y * 17 + x) as usize],
                    soft[(2 * y * w + 2 * x) as usize]
                );
            }
        }
    }
}
