//! The CPU reference energy: the software rasteriser of [`super::raster`] and an exact
//! six-bin count per camera, parallel over candidates and cameras (rayon). Only the region
//! the scored arch can touch is rendered and counted; the rest of the frame is class none,
//! and its counts follow from the mask totals.

use std::cell::RefCell;

use rayon::prelude::*;

use super::raster::{self, CLASS_BODY, CLASS_BOI, Placed, Target};
use super::{
    Counts, Energy, EnergyEngine, MASK_NONE, MASK_OTHER, MASK_OWN, Region, Scene,
    counts_with_outside, mask_totals,
};
use crate::capture::{Arch, ArchPoses, FrameMasks, LabelMask};
use crate::error::Result;
use crate::geometry::Camera;

/// A frame's mask for one camera with its per-arch pixel totals.
struct PreparedMask {
    mask: LabelMask,
    /// Per scored arch (upper, lower): see `mask_totals`.
    totals: [[u64; 2]; 2],
}

pub struct CpuEnergy {
    scene: Scene,
    region: Region,
    frame: Vec<Option<PreparedMask>>,
}

#[derive(Default)]
struct Scratch {
    scored: Placed,
    other: Placed,
    target: Target,
}

thread_local! {
    static SCRATCH: RefCell<Scratch> = RefCell::new(Scratch::default());
}

impl CpuEnergy {
    pub fn new(scene: Scene) -> Self {
        Self::with_region(scene, Region::Footprint)
    }

    pub fn with_region(scene: Scene, region: Region) -> Self {
        let n = scene.cameras.len();
        CpuEnergy {
            scene: scene.compacted(),
            region,
            frame: (0..n).map(|_| None).collect(),
        }
    }

    fn camera_counts(&self, cam_index: usize, arch: Arch, poses: &ArchPoses) -> Counts {
        let (Some(cam), Some(prep)) = (&self.scene.cameras[cam_index], &self.frame[cam_index])
        else {
            return Counts::default();
        };
        SCRATCH.with(|s| {
            let s = &mut *s.borrow_mut();
            render(&self.scene, self.region, cam, arch, poses, s);
            count(
                cam,
                &s.target,
                &prep.mask,
                arch,
                prep.totals[(arch == Arch::Lower) as usize],
            )
        })
    }
}

/// Render the scored arch (body/BOI) and the other arch (see `Scene::other_arch_class`) over
/// the scored arch's footprint (grown to the other arch's in combined mode).
fn render(
    scene: &Scene,
    region: Region,
    cam: &Camera,
    arch: Arch,
    poses: &ArchPoses,
    s: &mut Scratch,
) {
    let mesh = scene.mesh(arch);
    let other = scene.mesh(arch.other());
    let cam_from = |p: &crate::geometry::Pose| cam.camera_from_world.compose(p);
    s.scored.place(cam, mesh, &cam_from(poses.get(arch)));
    s.other
        .place(cam, other, &cam_from(poses.get(arch.other())));
    let other_class = scene.other_arch_class();
    let rect = match region {
        Region::FullFrame => raster::Rect::full(cam.width, cam.height),
        Region::Footprint if other_class != raster::CLASS_NONE => {
            s.scored.footprint(cam).union(&s.other.footprint(cam))
        }
        Region::Footprint => s.scored.footprint(cam),
    };
    s.target.reset(rect);
    raster::rasterise(
        cam,
        other,
        &s.other,
        other_class,
        other_class,
        &mut s.target,
    );
    raster::rasterise(cam, mesh, &s.scored, CLASS_BODY, CLASS_BOI, &mut s.target);
}

/// The nine bins over the whole mask: counted inside the target, derived outside it.
fn count(cam: &Camera, target: &Target, mask: &LabelMask, arch: Arch, totals: [u64; 2]) -> Counts {
    let (own, other) = (arch.mask_bit(), arch.other().mask_bit());
    // Mask state per label value: own, else other, else none.
    let state: [usize; 4] = std::array::from_fn(|m| {
        let m = m as u8;
        if m & own != 0 {
            MASK_OWN
        } else if m & other != 0 {
            MASK_OTHER
        } else {
            MASK_NONE
        }
    });
    let mut bins = [0u64; 9];
    if let Some(r) = target.rect {
        let w = r.width as usize;
        for y in 0..r.height as usize {
            let start = (r.y0 as usize + y) * mask.width as usize + r.x0 as usize;
            let mrow = &mask.data[start..start + w];
            let crow = &target.class[y * w..(y + 1) * w];
            for (&m, &c) in mrow.iter().zip(crow) {
                bins[state[(m & 3) as usize] * 3 + c as usize] += 1;
            }
        }
    }
    counts_with_outside(bins, cam, totals)
}

impl EnergyEngine for CpuEnergy {
    fn name(&self) -> String {
        format!(
            "cpu reference ({} threads), {:?}",
            rayon::current_num_threads(),
            self.region
        )
    }

    fn set_frame(&mut self, masks: &FrameMasks) -> Result<()> {
        self.frame = masks
            .masks
            .iter()
            .map(|m| {
                m.as_ref().map(|mask| PreparedMask {
                    totals: [
                        mask_totals(mask, Arch::Upper),
                        mask_totals(mask, Arch::Lower),
                    ],
                    mask: mask.clone(),
                })
            })
            .collect();
        Ok(())
    }

    fn evaluate(&self, arch: Arch, candidates: &[ArchPoses]) -> Result<Vec<Energy>> {
        let n = self.scene.cameras.len();
        Ok(candidates
            .par_iter()
            .map(|poses| Energy {
                cameras: (0..n)
                    .into_par_iter()
                    .map(|c| self.camera_counts(c, arch, poses))
                    .collect(),
            })
            .collect())
    }
}

#[cfg(test)]
mod tests {
    use super::super::{MASK_NONE, MASK_OTHER, MASK_OWN};
    use super::*;
    use crate::capture::{MaskMode, Mesh};
    use crate::geometry::Pose;
    use nalgebra::Vector3;

    use super::super::hand_counted::{camera, nothing as far_away, square as square_mesh};

    fn engine(mask_rect: (u32, u32, u32, u32), mode: MaskMode) -> CpuEnergy {
        let cam = camera();
        let (x0, y0, x1, y1) = mask_rect;
        let mut data = vec![0u8; 100 * 80];
        for y in y0..y1 {
            for x in x0..x1 {
                data[(y * 100 + x) as usize] =
                    crate::capture::UPPER_BIT | if mode == MaskMode::Combined { 2 } else { 0 };
            }
        }
        let mut e = CpuEnergy::new(Scene {
            cameras: vec![Some(cam)],
            upper: square_mesh(),
            lower: far_away(),
            mode,
        });
        e.set_frame(&FrameMasks {
            frame: 0,
            masks: vec![Some(LabelMask {
                width: 100,
                height: 80,
                data,
            })],
        })
        .unwrap();
        e
    }

    fn at_depth(dx_mm: f64) -> ArchPoses {
        ArchPoses {
            upper: Pose::from_translation(Vector3::new(dx_mm, 0.0, 100.0)),
            lower: Pose::from_translation(Vector3::new(0.0, 0.0, -1000.0)),
        }
    }

    const PER_ARCH: MaskMode = MaskMode::PerArch { upper: 1, lower: 2 };

    #[test]
    fn exact_counts_for_a_square_over_a_rectangular_mask() {
        // Model: columns 40..60, rows 30..50 (BOI rows 30..40). Mask: columns 45..70, rows 35..45.
        let e = engine((45, 35, 70, 45), PER_ARCH);
        let en = &e.evaluate(Arch::Upper, &[at_depth(0.0)]).unwrap()[0];
        let c = en.cameras[0];
        // mask 25 x 10 = 250; covered by the model: columns 45..60 x rows 35..45 = 150,
        // of which BOI rows 35..40: 75, body rows 40..45: 75. Uncovered 100.
        assert_eq!(c.bin(MASK_OWN, 1), 75);
        assert_eq!(c.bin(MASK_OWN, 2), 75);
        assert_eq!(c.uncovered(), 100);
        // BOI off the mask: 20 x 10 BOI pixels − 75 on the mask = 125.
        assert_eq!(c.boi_outside(), 125);
        assert_eq!(c.bin(MASK_NONE, 1), 200 - 75);
        assert_eq!(c.cross(), 0);
        assert_eq!(c.bins.iter().sum::<u64>(), 8000);
        assert_eq!(en.total(0.4), 100.0 + 0.4 * 125.0);
        assert!((en.area_error() - 0.4).abs() < 1e-12);
    }

    #[test]
    fn moving_the_model_one_pixel_changes_the_counts_exactly() {
        // 1 mm at 100 mm with f = 100 px is exactly one pixel.
        let e = engine((40, 30, 60, 50), PER_ARCH);
        let es = e
            .evaluate(Arch::Upper, &[at_depth(0.0), at_depth(1.0), at_depth(-3.0)])
            .unwrap();
        assert_eq!(es[0].uncovered(), 0);
        assert_eq!(es[0].boi_outside(), 0);
        assert_eq!(es[1].uncovered(), 20);
        assert_eq!(es[1].boi_outside(), 10);
        assert_eq!(es[2].uncovered(), 60);
        assert_eq!(es[2].boi_outside(), 30);
    }

    #[test]
    fn combined_mode_counts_the_other_arch_as_cover() {
        // The other arch is a square covering the mask's right part at the same depth.
        let mut e = engine((40, 30, 70, 50), MaskMode::Combined);
        e.scene.lower = Mesh {
            boi: vec![false; 4],
            ..square_mesh()
        };
        let poses = ArchPoses {
            upper: Pose::from_translation(Vector3::new(0.0, 0.0, 100.0)),
            lower: Pose::from_translation(Vector3::new(10.0, 0.0, 101.0)),
        };
        let en = &e.evaluate(Arch::Upper, &[poses]).unwrap()[0];
        // Mask 30 x 20 = 600; upper covers 40..60, lower (at x = 10 mm, z = 101) covers about
        // columns 50..70: nothing of the mask is left but a sliver from the depth difference.
        assert!(en.uncovered() < 30, "{:?}", en);
        let alone = engine((40, 30, 70, 50), MaskMode::Combined);
        assert_eq!(
            alone.evaluate(Arch::Upper, &[poses]).unwrap()[0].uncovered(),
            200
        );
    }

    #[test]
    fn covering_the_other_arch_s_pixels_counts_as_cross() {
        // Per-arch mask: the upper arch's label on columns 40..60 (the square's place), the
        // lower's on columns 60..80. The upper square moved 5 px right covers 5 columns of
        // lower-labelled pixels in front: 5 x 20 = 100 cross pixels, 50 of them BOI.
        let mut e = engine((40, 30, 60, 50), PER_ARCH);
        let mut frame_mask = match &e.frame[0] {
            Some(p) => p.mask.clone(),
            None => unreachable!(),
        };
        for y in 30..50 {
            for x in 60..80 {
                frame_mask.data[y * 100 + x] = crate::capture::LOWER_BIT;
            }
        }
        e.set_frame(&FrameMasks {
            frame: 0,
            masks: vec![Some(frame_mask)],
        })
        .unwrap();
        let c = e.evaluate(Arch::Upper, &[at_depth(5.0)]).unwrap()[0].cameras[0];
        assert_eq!(c.cross(), 100);
        assert_eq!(c.bin(MASK_OTHER, 2), 50);
        assert_eq!(
            c.boi_outside(),
            50,
            "BOI over the other arch is outside this arch's mask"
        );
        assert_eq!(c.uncovered(), 100);
        assert_eq!(c.paper_bins().iter().sum::<u64>(), 8000);
        let en = Energy { cameras: vec![c] };
        assert_eq!(en.objective(0.4, 1.0), 100.0 + 0.4 * 50.0 + 100.0);
    }

    #[test]
    fn a_camera_without_a_mask_contributes_nothing() {
        let mut e = engine((40, 30, 60, 50), PER_ARCH);
        e.set_frame(&FrameMasks {
            frame: 0,
            masks: vec![None],
        })
        .unwrap();
        let en = &e.evaluate(Arch::Upper, &[at_depth(0.0)]).unwrap()[0];
        assert_eq!(en.cameras[0], Counts::default());
    }
}
