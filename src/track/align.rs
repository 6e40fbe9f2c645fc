//! Gauss-Newton alignment of one mesh's silhouette to masks: the region step of contour-based
//! trackers (M3T's region modality), read off masks instead of colour statistics. Each visible
//! contour sample looks along its normal for the mask's edge, over a reach that shrinks from
//! coarse to fine; the offset found is the residual, and the sample's normal motion under an
//! se(3) increment, `nᵀ·J`, its row of the Jacobian. A few damped steps per reach move the
//! pose; no energy is rendered on the way.

use nalgebra::{Matrix6, Vector2, Vector6};

use super::penalties::Penalties;
use super::search::Found;
use crate::arch::{Arch, ArchPoses};
use crate::capture::{Capture, FrameMasks, LabelMask};
use crate::energy::contour::{ContourEdges, showing};
use crate::energy::edge_terms::{edge_offset, extra_read, label_read};
use crate::energy::raster::render_target;
use crate::energy::smooth::OCCLUSION_MM;
use crate::energy::target::{CLASS_BODY, CLASS_BOI};
use crate::energy::{EnergyEngine, Weights};
use crate::error::Result;
use crate::geometry::{Camera, Pose};
use crate::mesh::Mesh;

/// One camera and what its mask says at a pixel position (1 on the mesh's label, 0 off it; a
/// bilinear read of a binary mask, or a soft mask's probability).
pub struct MaskView<'a> {
    pub camera: &'a Camera,
    pub mask: &'a dyn Fn(Vector2<f64>) -> f64,
    /// How much a model drawn past the mask's edge at a pixel costs against one short of it
    /// (1): the paper's λ where the mask cannot tell teeth from what hides them (lips), the
    /// over-mouth weight where it labels the mouth interior. `None`: 1 everywhere.
    pub beyond: Option<&'a dyn Fn(Vector2<f64>) -> f64>,
}

#[derive(Debug, Clone)]
pub struct AlignSettings {
    /// How far (pixels) each sample looks for the mask's edge, one entry per stage, coarse
    /// to fine.
    pub reaches_px: Vec<f64>,
    /// Gauss-Newton steps per stage.
    pub steps: usize,
    /// Contour sample spacing (pixels).
    pub spacing_px: f64,
    /// Tikhonov damping of the step, per unit of squared rotation (rad²) and translation (mm²),
    /// in residual pixels²: keeps a step small where few samples constrain it.
    pub damping: [f64; 2],
    /// Leave out the contour the mesh hides from itself (its depth buffer drawn each step):
    /// needed for any mesh that is not convex, such as an arch.
    pub self_occlusion: bool,
}

impl Default for AlignSettings {
    fn default() -> Self {
        AlignSettings {
            reaches_px: vec![8.0, 4.0, 2.0, 1.0, 1.0],
            steps: 2,
            spacing_px: 2.0,
            damping: [1e3, 1.0],
            self_occlusion: true,
        }
    }
}

/// The result of [`align`].
#[derive(Debug, Clone, Copy)]
pub struct Aligned {
    pub pose: Pose,
    /// Gauss-Newton steps taken.
    pub steps: usize,
    /// Samples that found an edge in the last step.
    pub samples: usize,
}

/// The cameras that have a mask in a frame, and what their masks say at a pixel position.
pub struct FrameReads<'a> {
    /// Each camera with a mask: its index in the capture, its mask camera, its mask.
    cameras: Vec<(usize, Camera, &'a LabelMask)>,
}

impl<'a> FrameReads<'a> {
    pub fn new(capture: &Capture, masks: &'a FrameMasks) -> FrameReads<'a> {
        let cameras = capture
            .cameras()
            .iter()
            .zip(&masks.masks)
            .enumerate()
            .filter_map(|(k, (c, m))| Some((k, c.mask_camera()?, m.as_ref()?)))
            .collect();
        FrameReads { cameras }
    }

    pub fn len(&self) -> usize {
        self.cameras.len()
    }

    pub fn is_empty(&self) -> bool {
        self.cameras.is_empty()
    }

    pub fn camera(&self, k: usize) -> &Camera {
        &self.cameras[k].1
    }

    /// Camera `k`'s index in the capture.
    pub fn index(&self, k: usize) -> usize {
        self.cameras[k].0
    }

    /// Camera `k`'s mask of `arch`, read bilinearly (1 on its label, 0 off it).
    pub fn on(&self, k: usize, arch: Arch) -> impl Fn(Vector2<f64>) -> f64 + '_ {
        label_read(self.cameras[k].2, arch)
    }

    /// What `arch`'s model drawn past its mask's edge costs at a pixel of camera `k`, against
    /// 1 for a model short of it: the energy's weights for a BOI pixel there (λ, and what
    /// [`Self::extra`] adds).
    pub fn beyond(&self, k: usize, arch: Arch, w: &Weights) -> impl Fn(Vector2<f64>) -> f64 + '_ {
        let (extra, lambda) = (self.extra(k, arch, w), w.lambda);
        move |x: Vector2<f64>| lambda + extra(x)
    }

    /// [`align`] `arch`'s mesh to these masks (its mask in every camera, and what a model
    /// drawn past its edge costs there).
    pub fn align(
        &self,
        arch: Arch,
        weights: &Weights,
        mesh: (&Mesh, &ContourEdges),
        start: Pose,
        occluders: &[(&Mesh, &Pose)],
        s: &AlignSettings,
    ) -> Aligned {
        let on: Vec<_> = (0..self.len()).map(|k| self.on(k, arch)).collect();
        let beyond: Vec<_> = (0..self.len())
            .map(|k| self.beyond(k, arch, weights))
            .collect();
        let views: Vec<MaskView> = (0..self.len())
            .map(|k| MaskView {
                camera: self.camera(k),
                mask: &on[k],
                beyond: Some(&beyond[k]),
            })
            .collect();
        align(mesh, start, &views, occluders, s)
    }

    /// What any pixel of `arch`'s model costs at a pixel of camera `k` besides the paper's
    /// terms: the cross-label weight over the other arch's label, the over-mouth weight over
    /// the mouth interior's.
    pub fn extra(&self, k: usize, arch: Arch, w: &Weights) -> impl Fn(Vector2<f64>) -> f64 + '_ {
        extra_read(self.cameras[k].2, arch, w)
    }
}

/// Align `mesh` (its `edges`) from `start` to the masks of `views`, the contour that
/// `occluders` (other meshes at their poses) hide left out. A mesh with a boundary of interest
/// aligns the outline of its visible BOI (the teeth, where the scan also holds gums the lips
/// hide); one without, its silhouette.
pub fn align(
    (mesh, edges): (&Mesh, &ContourEdges),
    start: Pose,
    views: &[MaskView],
    occluders: &[(&Mesh, &Pose)],
    s: &AlignSettings,
) -> Aligned {
    let region = mesh.boi.iter().any(|&b| b).then_some(mesh.boi.as_slice());
    let class = region.map(|_| CLASS_BOI);
    let mut pose = start;
    let mut steps = 0;
    let mut samples = 0;
    for &reach in &s.reaches_px {
        for _ in 0..s.steps {
            let mut h = Matrix6::zeros();
            let mut g = Vector6::zeros();
            samples = 0;
            for v in views {
                let mut contour = edges.outline(mesh, &pose, v.camera, s.spacing_px, region);
                if s.self_occlusion || !occluders.is_empty() || region.is_some() {
                    let mut items = vec![(mesh, &pose, CLASS_BODY, CLASS_BOI)];
                    items.extend(
                        occluders
                            .iter()
                            .map(|&(m, p)| (m, p, CLASS_BODY, CLASS_BODY)),
                    );
                    let depth = render_target(v.camera, &items);
                    contour = showing(&contour, &depth, OCCLUSION_MM, class);
                }
                for c in contour {
                    let Some(d) = edge_offset(&c, v.mask, reach) else {
                        continue;
                    };
                    let row = c.jacobian.transpose() * c.normal;
                    // Tukey's weight on the offset, relative to the reach: an edge found far
                    // off is as likely another edge.
                    let u = d / reach;
                    // A model past the edge (d < 0) costs what the picture beyond says.
                    let cost = match (v.beyond, d < 0.0) {
                        (Some(beyond), true) => beyond(c.pixel + d * c.normal + c.normal),
                        _ => 1.0,
                    };
                    let w = cost * (1.0 - u * u).max(0.0).powi(2) * c.length;
                    h += w * row * row.transpose();
                    g += w * d * row;
                    samples += 1;
                }
            }
            if samples < 6 {
                return Aligned {
                    pose,
                    steps,
                    samples,
                };
            }
            for k in 0..6 {
                h[(k, k)] += s.damping[(k >= 3) as usize];
            }
            let Some(xi) = h.cholesky().map(|c| c.solve(&g)) else {
                return Aligned {
                    pose,
                    steps,
                    samples,
                };
            };
            pose = Pose::exp(&xi).compose(&pose);
            steps += 1;
        }
    }
    Aligned {
        pose,
        steps,
        samples,
    }
}

/// One arch's alignment in a tracked frame: its masks, the other arch as an occluder, and the
/// objective the result is scored by (as the paper's search scores its own).
pub struct ArchAlign<'a> {
    pub capture: &'a Capture,
    pub masks: &'a FrameMasks,
    /// The arch's contour edges ([`ContourEdges::of`] its mesh).
    pub edges: &'a ContourEdges,
    pub arch: Arch,
    /// Both arches' poses: the alignment starts from `arch`'s and holds the other there.
    pub from: ArchPoses,
    pub penalties: &'a Penalties,
    pub weights: Weights,
}

/// Align `q.arch` to its masks in every camera that has one, then score the pose found with
/// the energy (one evaluation), as [`super::search`] reports it.
pub fn align_arch(engine: &dyn EnergyEngine, q: &ArchAlign) -> Result<Found> {
    let capture = q.capture;
    let (mesh, other) = match q.arch {
        Arch::Upper => (capture.upper(), capture.lower()),
        Arch::Lower => (capture.lower(), capture.upper()),
    };
    let reads = FrameReads::new(capture, q.masks);
    let other_pose = *q.from.get(q.arch.other());
    let found = reads.align(
        q.arch,
        &q.weights,
        (mesh, q.edges),
        *q.from.get(q.arch),
        &[(other, &other_pose)],
        &AlignSettings::default(),
    );
    // The start scored too: where the steps made the objective worse (too few samples to
    // hold the pose, an edge that is another's), the start stands.
    let candidates = [q.from.with(q.arch, found.pose), q.from];
    let energies = engine.evaluate(q.arch, &candidates)?;
    let scored = candidates
        .iter()
        .zip(energies)
        .map(|(poses, energy)| Found {
            pose: *poses.get(q.arch),
            objective: energy.objective(&q.weights) + q.penalties.of(poses),
            energy,
            evaluations: 2,
        });
    Ok(scored
        .min_by(|a, b| a.objective.total_cmp(&b.objective))
        .expect("two candidates"))
}

#[cfg(test)]
pub(crate) mod tests {
    use nalgebra::Vector3;

    use super::*;
    use crate::energy::contour::bilinear;
    use crate::energy::target::CLASS_NONE;
    use crate::geometry::looking_at_origin;
    use crate::geometry::so3_exp;

    /// An uneven box (no symmetry a silhouette could confuse), wound outwards.
    fn block() -> Mesh {
        crate::mesh::cuboid([-30.0, -18.0, -12.0], [21.0, 18.0, 15.6])
    }

    /// `mesh` aligned from `truth` moved by `offset`, in `cameras` whose masks show it at
    /// `truth` (its visible BOI when it has one, as a teeth mask does; else all of it): the
    /// pose's error (degrees, mm) before and after, and the steps.
    fn aligned(mesh: &Mesh, cameras: &[Camera], truth: &Pose, offset: Vector6<f64>) -> [f64; 5] {
        let body = if mesh.boi.iter().any(|&b| b) {
            CLASS_NONE
        } else {
            CLASS_BOI
        };
        let masks: Vec<Vec<u8>> = cameras
            .iter()
            .map(|c| render_target(c, &[(mesh, truth, body, CLASS_BOI)]).class)
            .collect();
        let reads: Vec<Box<dyn Fn(Vector2<f64>) -> f64>> = masks
            .iter()
            .zip(cameras)
            .map(|(m, c)| {
                let (w, h) = (c.width as usize, c.height as usize);
                Box::new(move |x: Vector2<f64>| bilinear(m, w, h, |c| c == CLASS_BOI, x))
                    as Box<dyn Fn(Vector2<f64>) -> f64>
            })
            .collect();
        let views: Vec<MaskView> = cameras
            .iter()
            .zip(&reads)
            .map(|(camera, mask)| MaskView {
                camera,
                mask: mask.as_ref(),
                beyond: None,
            })
            .collect();
        let start = Pose::exp(&offset).compose(truth);
        let edges = ContourEdges::of(mesh);
        let clock = std::time::Instant::now();
        let found = align(
            (mesh, &edges),
            start,
            &views,
            &[],
            &AlignSettings::default(),
        );
        let ms = clock.elapsed().as_secs_f64() * 1e3;
        let (rot, trans) = found.pose.distance_to(truth);
        let (rot0, trans0) = start.distance_to(truth);
        eprintln!(
            "error twist {:?}",
            found.pose.compose(&truth.inverse()).log().as_slice()
        );
        eprintln!(
            "from {:.2}° {trans0:.2} mm to {:.3}° {trans:.3} mm in {} steps ({} samples, {ms:.1} ms)",
            rot0.to_degrees(),
            rot.to_degrees(),
            found.steps,
            found.samples
        );
        [
            rot0.to_degrees(),
            trans0,
            rot.to_degrees(),
            trans,
            found.steps as f64,
        ]
    }

    #[test]
    fn a_few_steps_bring_the_silhouettes_onto_their_masks() {
        let cameras = [
            looking_at_origin(Vector3::new(0.0, 0.0, -200.0)),
            looking_at_origin(Vector3::new(140.0, -30.0, -140.0)),
            looking_at_origin(Vector3::new(-140.0, 40.0, -140.0)),
        ];
        let truth = Pose::new(
            so3_exp(&Vector3::new(0.3, -0.2, 0.5)),
            Vector3::new(2.0, -1.0, 3.0),
        );
        // Off by 5° and 7 mm.
        let offset = Vector6::new(0.05, -0.06, 0.04, 4.0, -3.0, 5.0);
        let [_, _, rot, trans, _] = aligned(&block(), &cameras, &truth, offset);
        assert!(rot < 0.1 && trans < 0.1, "{rot:.3}° {trans:.3} mm");
    }

    /// At the true pose every sample of the teeth outline finds the mask's edge where it is,
    /// to the mask's pixel; samples whose region continues beyond them (a tooth over the
    /// tooth behind) are left out, as they show no edge.
    #[test]
    fn at_the_true_pose_the_outline_finds_the_teeth_mask_s_edge_where_it_is() {
        let cameras = [
            looking_at_origin(Vector3::new(0.0, 0.0, 200.0)),
            looking_at_origin(Vector3::new(90.0, 10.0, 180.0)),
        ];
        let mesh = crate::anatomy::procedural_arch(true);
        let truth = Pose::from_translation(Vector3::new(0.0, 0.0, -10.0));
        let edges = ContourEdges::of(&mesh);
        for cam in &cameras {
            let m = render_target(cam, &[(&mesh, &truth, CLASS_NONE, CLASS_BOI)]).class;
            let read = |x: Vector2<f64>| bilinear(&m, 640, 480, |c| c == CLASS_BOI, x);
            let all = edges.outline(&mesh, &truth, cam, 2.0, Some(&mesh.boi));
            let depth = render_target(cam, &[(&mesh, &truth, CLASS_BODY, CLASS_BOI)]);
            let shown = showing(&all, &depth, OCCLUSION_MM, Some(CLASS_BOI));
            let mut ds: Vec<f64> = shown
                .iter()
                .filter_map(|c| edge_offset(c, &read, 4.0))
                .map(f64::abs)
                .collect();
            ds.sort_by(f64::total_cmp);
            let p95 = ds[ds.len() * 19 / 20];
            eprintln!(
                "{} of {} samples found an edge; |offset| median {:.3}, p95 {p95:.3} px",
                ds.len(),
                shown.len(),
                ds[ds.len() / 2]
            );
            assert!(ds.len() * 10 >= shown.len() * 9 && ds.len() > 100);
            assert!(p95 < 0.75, "p95 {p95} px");
        }
    }

    #[test]
    fn an_arch_seen_from_the_front_is_aligned_to_its_masks() {
        // Three cameras 200 mm in front of the mouth (+z anterior), as the footage has them.
        let cameras = [
            looking_at_origin(Vector3::new(0.0, 0.0, 200.0)),
            looking_at_origin(Vector3::new(90.0, 10.0, 180.0)),
            looking_at_origin(Vector3::new(-90.0, 10.0, 180.0)),
        ];
        let arch = crate::anatomy::procedural_arch(true);
        let truth = Pose::from_translation(Vector3::new(0.0, 0.0, -10.0));
        let offset = Vector6::new(0.03, 0.02, -0.02, 1.5, -1.0, 2.0);
        let [_, _, rot, trans, _] = aligned(&arch, &cameras, &truth, offset);
        // The teeth outline alone (silhouette and gum line) constrains the pose less than a
        // whole silhouette, and a tooth's edge over the tooth behind it shows no mask edge.
        assert!(rot < 0.5 && trans < 0.1, "{rot:.3}° {trans:.3} mm");
    }
}
