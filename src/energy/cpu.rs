//! The CPU reference energy: the software rasteriser of [`super::raster`] and an exact
//! six-bin count per camera, parallel over candidates and cameras (rayon). Only the region
//! the scored arch can touch is rendered and counted; the rest of the frame is class none,
//! and its counts follow from the mask totals.

use std::cell::RefCell;
use std::collections::VecDeque;
use std::sync::{Arc, Mutex};

use rayon::prelude::*;

use super::backfaces::{self, AwaySign};
use super::clusters::{self, Cluster};
use super::edge_terms::label_terms;
use super::edge_terms::{EdgeQuery, EdgeTerm};
use super::histogram;
use super::pyramid;
use super::raster::{self, Bounds, CLASS_BODY, CLASS_BOI, Placed, Target};
use super::relevance::{LabelledTiles, Relevance};
use super::{Counts, Energy, EnergyEngine, MaskTotals, Region, Scene, frame_totals};
use crate::arch::{Arch, ArchPoses, PerArch};
use crate::capture::masks::MOUTH_BIT;
use crate::capture::{FrameMasks, LOWER_BIT, LabelMask, UPPER_BIT};
use crate::error::Result;
use crate::geometry::{Camera, Pose};
use crate::mesh::Mesh;

/// A frame's mask for one camera with its per-arch pixel totals.
struct PreparedMask {
    mask: LabelMask,
    /// The mask at the pyramid's coarser levels (1 to [`pyramid::MAX_LEVEL`]), for the edge
    /// terms of coarse stages.
    coarser: Vec<LabelMask>,
    /// Per scored arch (upper, lower): see `mask_totals`.
    totals: PerArch<MaskTotals>,
    /// Where either arch's or the mouth's label is (for [`Region::Relevant`]).
    tiles: LabelledTiles,
}

pub struct CpuEnergy {
    scene: Scene,
    region: Region,
    /// Per arch (upper, lower): the vertices of its boundary-of-interest faces, and its
    /// faces in clusters (the scene's faces are in spatial order).
    boi_vertices: [Vec<u32>; 2],
    clusters: [Vec<Cluster>; 2],
    /// Per arch: which faces face away from a camera, for a closed mesh.
    away: [Option<AwaySign>; 2],
    frame: Vec<Option<PreparedMask>>,
    /// The other arch as lately drawn: a search holds it still while it moves the scored arch,
    /// so it is rasterised once per pose rather than once per candidate.
    other: Mutex<VecDeque<Arc<OtherArch>>>,
}

/// How many drawings of the other arch are kept: a solver's candidates alternate between a
/// few poses of each arch (a result and its start), and each drawing is a whole arch.
const OTHER_ARCHES_KEPT: usize = 4;

/// The other arch drawn alone at one pose, per camera, over its own footprint.
struct OtherArch {
    arch: Arch,
    pose: Pose,
    targets: Vec<Option<Target>>,
}

#[derive(Default)]
struct Scratch {
    scored: Placed,
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
        // Closed meshes wound outwards (see `backfaces`), faces in spatial order, then
        // vertices numbered by first use (`compacted`): what one cluster reads lies together.
        // A rewound mesh's faces turned away have a positive snapped area.
        let prepare = |mesh: &Mesh| match backfaces::oriented_outwards(mesh) {
            Some(outwards) => (
                clusters::spatially_sorted(&outwards),
                Some(AwaySign::Positive),
            ),
            None => (clusters::spatially_sorted(mesh), None),
        };
        let ((upper, away_upper), (lower, away_lower)) =
            (prepare(&scene.upper), prepare(&scene.lower));
        let scene = Scene {
            upper,
            lower,
            ..scene
        }
        .compacted();
        CpuEnergy {
            boi_vertices: [boi_vertices(&scene.upper), boi_vertices(&scene.lower)],
            clusters: [
                clusters::clusters(&scene.upper),
                clusters::clusters(&scene.lower),
            ],
            away: [away_upper, away_lower],
            scene,
            region,
            frame: (0..n).map(|_| None).collect(),
            other: Mutex::new(VecDeque::new()),
        }
    }

    /// The other arch drawn at `pose`, from the cache when it was drawn there lately.
    fn other_arch(&self, arch: Arch, pose: &Pose) -> Arc<OtherArch> {
        let mut cached = self.other.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(c) = cached.iter().find(|c| c.arch == arch && c.pose == *pose) {
            return c.clone();
        }
        let mesh = self.scene.mesh(arch);
        let class = self.scene.other_arch_class();
        let targets = self
            .scene
            .cameras
            .par_iter()
            .map(|cam| {
                let cam = cam.as_ref()?;
                let mut placed = Placed::default();
                placed.place(cam, mesh, &cam.camera_from_world.compose(pose));
                let mut target = Target::default();
                target.reset(placed.footprint(cam));
                raster::rasterise(mesh, &placed, class, class, &mut target);
                Some(target)
            })
            .collect();
        let drawn = Arc::new(OtherArch {
            arch,
            pose: *pose,
            targets,
        });
        if cached.len() == OTHER_ARCHES_KEPT {
            cached.pop_front();
        }
        cached.push_back(drawn.clone());
        drawn
    }

    fn camera_counts(
        &self,
        cam_index: usize,
        arch: Arch,
        poses: &ArchPoses,
        other: &OtherArch,
    ) -> Counts {
        let (Some(cam), Some(prep), Some(other)) = (
            &self.scene.cameras[cam_index],
            &self.frame[cam_index],
            &other.targets[cam_index],
        ) else {
            return Counts::default();
        };
        SCRATCH.with(|s| {
            let s = &mut *s.borrow_mut();
            let a = arch.index();
            let skip = (self.region == Region::Relevant).then(|| Skip {
                tiles: &prep.tiles,
                boi_vertices: &self.boi_vertices[a],
                clusters: &self.clusters[a],
                away: self.away[a],
            });
            render(&self.scene, self.region, cam, (arch, poses), other, skip, s);
            histogram::count(cam, &s.target, &prep.mask, arch, *prep.totals.get(arch))
        })
    }
}

/// The vertices of a mesh's boundary-of-interest faces, each once.
fn boi_vertices(mesh: &Mesh) -> Vec<u32> {
    let mut v: Vec<u32> = (mesh.triangles.iter().zip(&mesh.boi))
        .filter(|(_, boi)| **boi)
        .flat_map(|(t, _)| *t)
        .collect();
    v.sort_unstable();
    v.dedup();
    v
}

/// What [`Region::Relevant`] needs to skip body faces (see `super::relevance`).
struct Skip<'a> {
    tiles: &'a LabelledTiles,
    boi_vertices: &'a [u32],
    clusters: &'a [Cluster],
    away: Option<AwaySign>,
}

/// Render the scored arch (body/BOI) over the other arch (drawn before, see
/// `Scene::other_arch_class`) within the scored arch's footprint (grown to the other arch's
/// in combined mode). The depth test makes this the same picture as drawing both in turn;
/// with `skip`, body faces that cannot change the energy are left out.
fn render(
    scene: &Scene,
    region: Region,
    cam: &Camera,
    (arch, poses): (Arch, &ArchPoses),
    other: &Target,
    skip: Option<Skip>,
    s: &mut Scratch,
) {
    let mesh = scene.mesh(arch);
    s.scored
        .place(cam, mesh, &cam.camera_from_world.compose(poses.get(arch)));
    let other_rect = other.rect.unwrap_or(raster::Rect::full(0, 0));
    let rect = match region {
        Region::FullFrame => raster::Rect::full(cam.width, cam.height),
        _ if scene.other_arch_class() != raster::CLASS_NONE => {
            s.scored.footprint(cam).union(&other_rect)
        }
        Region::Footprint | Region::Relevant => s.scored.footprint(cam),
    };
    s.target.reset(rect);
    s.target.copy_from(other);
    match skip {
        None => raster::rasterise(mesh, &s.scored, CLASS_BODY, CLASS_BOI, &mut s.target),
        Some(skip) => {
            s.scored.leave_out_faces_turned_away(skip.away);
            let relevance = Relevance {
                tiles: skip.tiles,
                boi: s.scored.footprint_of_vertices(cam, skip.boi_vertices),
            };
            for cluster in skip.clusters {
                if !cluster.has_boi {
                    let r = s.scored.footprint_of_box(cam, &cluster.corners);
                    match Bounds::of_rect(&r) {
                        Some(b) if relevance.body_counts(&b) => {}
                        _ => continue,
                    }
                }
                raster::rasterise_body_where(
                    mesh,
                    cluster.faces.clone(),
                    &s.scored,
                    [CLASS_BODY, CLASS_BOI],
                    &mut s.target,
                    |b| relevance.body_counts(b),
                );
            }
        }
    }
}

impl EnergyEngine for CpuEnergy {
    fn name(&self) -> String {
        format!(
            "cpu reference ({} threads), {}",
            rayon::current_num_threads(),
            self.region.name()
        )
    }

    fn edge_terms(&self, q: &EdgeQuery) -> Result<Vec<Option<EdgeTerm>>> {
        let masks: Vec<Option<&LabelMask>> = q
            .cameras
            .iter()
            .map(|&k| {
                let f = self.frame.get(k).and_then(|f| f.as_ref())?;
                match q.params.level {
                    0 => Some(&f.mask),
                    l => f.coarser.get(l - 1),
                }
            })
            .collect();
        Ok(label_terms(q.samples, &masks, &q.moved, &q.params))
    }

    fn set_frame(&mut self, masks: &FrameMasks) -> Result<()> {
        self.frame = masks
            .masks
            .par_iter()
            .map(|m| {
                m.as_ref().map(|mask| PreparedMask {
                    totals: frame_totals(mask),
                    // Body faces matter over the mouth interior too (over-mouth).
                    tiles: LabelledTiles::new(mask, UPPER_BIT | LOWER_BIT | MOUTH_BIT),
                    coarser: (1..=pyramid::MAX_LEVEL)
                        .map(|l| pyramid::mask(mask, l))
                        .collect(),
                    mask: mask.clone(),
                })
            })
            .collect();
        Ok(())
    }

    fn evaluate(&self, arch: Arch, candidates: &[ArchPoses]) -> Result<Vec<Energy>> {
        let n = self.scene.cameras.len();
        let mut out = Vec::with_capacity(candidates.len());
        // Runs of candidates that hold the other arch at one pose (a search's batches, all
        // of them) share its drawing.
        for run in candidates.chunk_by(|a, b| a.get(arch.other()) == b.get(arch.other())) {
            let other = self.other_arch(arch.other(), run[0].get(arch.other()));
            let energies: Vec<Energy> = run
                .par_iter()
                .map(|poses| Energy {
                    cameras: (0..n)
                        .into_par_iter()
                        .map(|c| self.camera_counts(c, arch, poses, &other))
                        .collect(),
                })
                .collect();
            out.extend(energies);
        }
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::super::{MASK_MOUTH, MASK_NONE, MASK_OTHER, MASK_OWN, Weights};
    use super::*;
    use crate::capture::MaskMode;
    use crate::geometry::Pose;
    use crate::mesh::Mesh;
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
                soft: None,
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
        assert_eq!(c.over_mouth(), 0);
        let en = Energy { cameras: vec![c] };
        let w = Weights {
            lambda: 0.4,
            cross: 1.0,
            mouth: 0.0,
        };
        assert_eq!(en.objective(&w), 100.0 + 0.4 * 50.0 + 100.0);
    }

    /// The engine with the upper label on `teeth` and the mouth interior's on `mouth`
    /// (x0, y0, x1, y1), in `mode`.
    fn mouth_engine(
        teeth: (usize, usize, usize, usize),
        mouth: (usize, usize, usize, usize),
        mode: MaskMode,
    ) -> CpuEnergy {
        let mut e = engine(
            (
                teeth.0 as u32,
                teeth.1 as u32,
                teeth.2 as u32,
                teeth.3 as u32,
            ),
            mode,
        );
        let mut mask = match &e.frame[0] {
            Some(p) => p.mask.clone(),
            None => unreachable!(),
        };
        for y in mouth.1..mouth.3 {
            for x in mouth.0..mouth.2 {
                mask.data[y * 100 + x] = crate::capture::masks::MOUTH_BIT;
            }
        }
        e.set_frame(&FrameMasks {
            frame: 0,
            masks: vec![Some(mask)],
        })
        .unwrap();
        e
    }

    #[test]
    fn drawing_over_the_mouth_interior_counts_as_over_mouth() {
        // Teeth on columns 40..60 (the square's place), mouth interior on 60..80. The square
        // moved 5 px right draws 5 columns over the mouth: 5 x 20 = 100 pixels, 50 of them BOI.
        let e = mouth_engine((40, 30, 60, 50), (60, 30, 80, 50), PER_ARCH);
        let en = &e.evaluate(Arch::Upper, &[at_depth(5.0)]).unwrap()[0];
        let c = en.cameras[0];
        assert_eq!(c.over_mouth(), 100);
        assert_eq!(c.bin(MASK_MOUTH, 2), 50);
        assert_eq!(c.bin(MASK_MOUTH, 0), 400 - 100);
        assert_eq!(
            c.boi_outside(),
            50,
            "BOI over the mouth is outside the mask"
        );
        assert_eq!(c.uncovered(), 100);
        assert_eq!(c.cross(), 0);
        assert_eq!(c.bins.iter().sum::<u64>(), 8000);
        assert_eq!(c.paper_bins().iter().sum::<u64>(), 8000);
        // The paper's E is the same as with the mouth unlabelled; the objective adds μ·100.
        let plain = engine((40, 30, 60, 50), PER_ARCH);
        let p = &plain.evaluate(Arch::Upper, &[at_depth(5.0)]).unwrap()[0];
        assert_eq!(p.total(0.4), en.total(0.4));
        assert_eq!(p.over_mouth(), 0);
        let w = Weights {
            lambda: 0.4,
            cross: 1.0,
            mouth: 2.0,
        };
        assert_eq!(en.objective(&w), en.total(0.4) + 200.0);
        // Moved left, it draws over the unlabelled background only.
        let left = &e.evaluate(Arch::Upper, &[at_depth(-5.0)]).unwrap()[0];
        assert_eq!(left.over_mouth(), 0);
    }

    #[test]
    fn with_combined_masks_either_arch_over_the_mouth_counts() {
        // The other arch (no BOI) sits over the mouth interior, columns 60..80 at z = 101 mm
        // (about 19.8 px wide): scoring the upper arch counts its pixels over the mouth too.
        let mut e = mouth_engine((40, 30, 60, 50), (60, 30, 80, 50), MaskMode::Combined);
        e.scene.lower = Mesh {
            boi: vec![false; 4],
            ..square_mesh()
        };
        let poses = ArchPoses {
            upper: Pose::from_translation(Vector3::new(0.0, 0.0, 100.0)),
            lower: Pose::from_translation(Vector3::new(20.0, 0.0, 101.0)),
        };
        let c = e.evaluate(Arch::Upper, &[poses]).unwrap()[0].cameras[0];
        assert!((360..=400).contains(&c.over_mouth()), "{c:?}");
        assert_eq!(c.bin(MASK_MOUTH, 2), 0);
    }

    #[test]
    fn the_other_arch_s_drawing_follows_its_pose_within_a_batch() {
        // Combined mode (the other arch covers the mask): a batch whose candidates move the
        // other arch back and forth scores each as a fresh engine scores it alone.
        let mut lower_square = Mesh {
            boi: vec![false; 4],
            ..square_mesh()
        };
        lower_square.positions.iter_mut().for_each(|p| p[0] += 5.0);
        let fresh = || {
            let mut e = engine((40, 30, 70, 50), MaskMode::Combined);
            e.scene.lower = lower_square.clone();
            e
        };
        let at = |dx: f64| ArchPoses {
            upper: Pose::from_translation(Vector3::new(0.0, 0.0, 100.0)),
            lower: Pose::from_translation(Vector3::new(dx, 0.0, 101.0)),
        };
        let batch = [at(0.0), at(3.0), at(3.0), at(0.0), at(-4.0)];
        let together = fresh().evaluate(Arch::Upper, &batch).unwrap();
        for (poses, e) in batch.iter().zip(&together) {
            let alone = fresh().evaluate(Arch::Upper, &[*poses]).unwrap().remove(0);
            assert_eq!(alone.cameras, e.cameras);
        }
        assert_ne!(together[0].uncovered(), together[1].uncovered());
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
