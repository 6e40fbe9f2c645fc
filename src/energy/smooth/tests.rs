use nalgebra::{Vector3, Vector6};

use super::*;
use crate::anatomy::{procedural_arch, rest_bite};
use crate::arch::Arch;
use crate::capture::{FrameMasks, LabelMask, MaskMode};
use crate::energy::edge_terms::EdgeParams;
use crate::energy::raster::render_target;
use crate::energy::{CpuEnergy, EnergyEngine, Scene, Weights};
use crate::geometry::{Pose, looking_at_origin};

/// Both procedural arches at a bite opened by `open` (rad about the lateral axis), seen by
/// three 640×480 cameras 200 mm in front (4 px a millimetre there), with per-arch teeth masks
/// drawn at the truth (label 1 upper, 2 lower: the classes drawn).
pub(crate) struct TwoArches {
    pub upper: Mesh,
    pub lower: Mesh,
    pub truth: ArchPoses,
    pub cameras: [Camera; 3],
    pub masks: Vec<Vec<u8>>,
}

pub(crate) fn two_arches(open: f64) -> TwoArches {
    let (upper, lower) = (procedural_arch(true), procedural_arch(false));
    let bite = rest_bite(&upper, &lower);
    let upper_pose = Pose::from_translation(Vector3::new(0.0, 0.0, -10.0));
    let open = Pose::from_euler_tuple(&[open, 0.0, 0.0, 0.0, 0.0, 0.0]);
    let truth = ArchPoses {
        upper: upper_pose,
        lower: upper_pose.compose(&bite).compose(&open),
    };
    let cameras = [
        looking_at_origin(Vector3::new(0.0, 0.0, 200.0)),
        looking_at_origin(Vector3::new(90.0, 10.0, 180.0)),
        looking_at_origin(Vector3::new(-90.0, 10.0, 180.0)),
    ];
    let items = [(&upper, &truth.upper, 1, 1), (&lower, &truth.lower, 2, 2)];
    let masks = cameras
        .iter()
        .map(|c| render_target(c, &items).class)
        .collect();
    TwoArches {
        upper,
        lower,
        truth,
        cameras,
        masks,
    }
}

/// [`two_arches`] with the mouth open: the CPU engine on that frame.
struct Fixture {
    scene: Scene,
    engine: CpuEnergy,
    edges: [ContourEdges; 2],
    truth: ArchPoses,
}

impl Fixture {
    fn new() -> Fixture {
        let TwoArches {
            upper,
            lower,
            truth,
            cameras,
            masks,
        } = two_arches(0.15);
        let masks = cameras
            .iter()
            .zip(masks)
            .map(|(c, data)| {
                Some(LabelMask {
                    soft: None,
                    width: c.width,
                    height: c.height,
                    data,
                })
            })
            .collect();
        let edges = [ContourEdges::of(&upper), ContourEdges::of(&lower)];
        let scene = Scene {
            cameras: cameras.into_iter().map(Some).collect(),
            upper,
            lower,
            mode: MaskMode::PerArch { upper: 1, lower: 2 },
        };
        let mut engine = CpuEnergy::new(scene.clone());
        engine.set_frame(&FrameMasks { frame: 0, masks }).unwrap();
        Fixture {
            scene,
            engine,
            edges,
            truth,
        }
    }

    fn cameras(&self) -> Vec<&Camera> {
        self.scene.cameras.iter().flatten().collect()
    }

    /// The samples drawn at `poses`.
    fn samples(&self, poses: &ArchPoses) -> Vec<EdgeSample> {
        let s = &self.scene;
        let arches = [(&s.upper, &self.edges[0]), (&s.lower, &self.edges[1])];
        samples(arches, poses, &self.cameras(), true, 1.0)
    }

    /// The normal equations of `samples` moved by `moved`, with the paper's weights.
    fn sums(
        &self,
        samples: &[EdgeSample],
        moved: [Vector6<f64>; 2],
        reach_px: f64,
        smoothing_px: f64,
    ) -> NormalEquations {
        let q = EdgeQuery {
            samples,
            cameras: &[0, 1, 2],
            moved,
            params: EdgeParams {
                reach_px,
                smoothing_px,
                weights: Weights::paper(0.4),
                level: 0,
            },
        };
        normal_equations(samples, &self.engine.edge_terms(&q).unwrap())
    }

    /// The pixel-count energy (the paper's, both arches) at `poses`.
    fn counted(&self, poses: &ArchPoses) -> f64 {
        let w = Weights::paper(0.4);
        Arch::BOTH
            .iter()
            .map(|&a| self.engine.evaluate(a, &[*poses]).unwrap()[0].objective(&w))
            .sum()
    }
}

/// The truth moved by `xi_u` (upper arch) and then the jaw by `xi_j`.
fn moved(truth: &ArchPoses, xi_u: [f64; 6], xi_j: [f64; 6]) -> ArchPoses {
    let u = Pose::exp(&Vector6::from(xi_u));
    let j = Pose::exp(&Vector6::from(xi_j));
    ArchPoses {
        upper: u.compose(&truth.upper),
        lower: u.compose(&j).compose(&truth.lower),
    }
}

/// How far the samples look for their edges in the test of the energy's value: about twice
/// the offsets' largest motion (1-2 px).
const REACH_PX: f64 = 3.0;

/// The smooth energy is Σ c·length·ρ(d) along the drawn edges; as ε → 0 it grows to the area
/// between drawn and segmented edges weighted by what it costs: the pixel-count energy (zero at
/// the truth) within a sixth, less what the count charges to the other arch where a silhouette
/// is drawn over it (`edge_terms::cost`). The rest is the offset read along the normal: where a
/// mask's edge meets the model's at an angle, or the notches between teeth give a sample
/// another tooth's edge, it is not the exact area between them.
#[test]
fn the_smooth_energy_converges_to_the_pixel_count_as_its_width_goes_to_zero() {
    let f = Fixture::new();
    assert_eq!(f.counted(&f.truth), 0.0);
    // The arches moved 1-2 px four ways; the second moves the upper arch's edge over the
    // lower arch in every camera, which hides the lower's label from it: the count charges
    // those pixels to the lower arch, the smooth energy leaves them out.
    let offsets = [
        ([0.0, 0.0, 0.0, 0.4, 0.0, 0.0], [0.0; 6], 0.15),
        ([0.0, 0.004, 0.0, 0.0, -0.3, 0.2], [0.0; 6], 0.4),
        ([0.0; 6], [-0.006, 0.0, 0.0, 0.0, 0.3, 0.0], 0.15),
        (
            [0.003, 0.0, -0.002, 0.2, 0.2, 0.0],
            [0.0, 0.004, 0.0, -0.2, 0.0, 0.0],
            0.15,
        ),
    ];
    let mut off = Vec::new();
    for (xi_u, xi_j, _) in offsets {
        let poses = moved(&f.truth, xi_u, xi_j);
        let counted = f.counted(&poses);
        let samples = f.samples(&poses);
        let still = [Vector6::zeros(); 2];
        let smooth: Vec<f64> = [1.0, 0.3, 0.1, 0.01]
            .iter()
            .map(|&eps| f.sums(&samples, still, REACH_PX, eps).energy)
            .collect();
        eprintln!("counted {counted:.1}, smooth at ε = 1, 0.3, 0.1, 0.01 px: {smooth:.1?}");
        assert!(smooth.windows(2).all(|w| w[1] >= w[0]), "{smooth:?}");
        off.push((smooth[smooth.len() - 1] - counted) / counted);
    }
    eprintln!("relative differences {off:.3?}");
    for (d, (_, _, bound)) in off.iter().zip(offsets) {
        assert!(d.abs() < bound, "{off:?}");
    }
    // At the truth the drawn and segmented edges agree, to the odd pixel.
    let samples = f.samples(&f.truth);
    let at_truth = f
        .sums(&samples, [Vector6::zeros(); 2], REACH_PX, 0.01)
        .energy;
    assert!(at_truth < 0.02 * f.counted(&moved(&f.truth, offsets[0].0, offsets[0].1)));
}

/// −g, the normal equations' right-hand side, is the smooth energy's gradient as
/// Gauss-Newton linearises it: each sample moves along its normal by `nᵀJ·ξ`. Against central
/// differences ([`gradient_and_differences`]) the two point the same way, and no component is
/// off by more than a tenth of the gradient's length. They are not equal: off the truth a
/// mask's edge meets the model's at an angle, so a sample sliding along its own edge finds the
/// mask's a little nearer or farther, which the linearisation leaves out.
#[test]
fn the_gradient_is_the_smooth_energy_s_derivative() {
    let f = Fixture::new();
    let poses = moved(
        &f.truth,
        [0.003, -0.002, 0.0, 0.3, -0.2, 0.1],
        [-0.004, 0.0, 0.002, 0.0, 0.2, -0.1],
    );
    let samples = f.samples(&poses);
    let q = EdgeQuery {
        samples: &samples,
        cameras: &[0, 1, 2],
        moved: [Vector6::zeros(); 2],
        params: EdgeParams {
            reach_px: 4.0,
            smoothing_px: 0.5,
            weights: Weights::paper(0.4),
            level: 0,
        },
    };
    let (analytic, differences) = gradient_and_differences(&f.engine, &q).unwrap();
    let cosine = analytic.dot(&differences) / (analytic.norm() * differences.norm());
    let worst = (analytic - differences).amax() / analytic.norm();
    eprintln!(
        "per step: −g {:.2?}\n central differences {:.2?}\n cosine {cosine:.4}, worst component {worst:.3} of the length",
        analytic.as_slice(),
        differences.as_slice()
    );
    assert!(
        cosine > 0.98 && worst < 0.1,
        "cosine {cosine}, worst {worst}"
    );
}
