//! A window over frames (a fixed-lag smoother): each frame's poses settled together with the
//! `frames` before and after it, so that segmentation noise that changes from frame to frame
//! averages out where the motion says it must.
//!
//! Each frame's estimate comes with the information its masks gave Gauss-Newton about it
//! (the normal matrix of its edges, in the increments [ξ_u; ξ_j] that move both arches and the
//! jaw): its energy, to second order about the estimate. The window minimises the sum of
//! those quadratics plus priors on two accelerations: the head's (the upper arch's second
//! difference over consecutive frames) and the jaw's (the lower arch's pose relative to the
//! upper's), each measured as in the solver's motion prior (displacement at the arch's centre,
//! rotation at an arch's radius, mm). How fast a head moves differs from take to take by more
//! than an order of magnitude, so the head's weight is learned from the frames around each
//! frame ([`head_weight`]). The jaw moves fast and turns sharply where an exercise
//! changes direction, and a capture may be filmed (or read) at a rate its motion outruns, so
//! both priors are robust: Cauchy's loss, quadratic up to about `acceleration_scale_mm` and
//! flattening beyond, minimised by reweighting (a few linear solves a frame). A real turn then
//! costs the prior little and is not bent toward a smooth path. A frame
//! without information (no masks, or found afresh) holds its poses and the others see it as
//! fixed. A frame's output is final once the `frames` after it are tracked.

use nalgebra::{DMatrix, DVector, Matrix6, SMatrix, SVector, Vector3, Vector6};

use super::prior::centre;
use super::search::RADIUS_MM;
use crate::arch::{Arch, ArchPoses};
use crate::capture::Capture;
use crate::energy::smooth::Matrix12;
use crate::geometry::Pose;

/// The window's settings (`window` in the settings).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct WindowSettings {
    /// Frames on each side of a frame that settle it (0: each frame as tracked). A frame's
    /// output is final this many frames later.
    pub frames: usize,
    /// The weight of the head's acceleration (per mm² of the upper arch's second difference,
    /// against the frames' edge information: pixel lengths per pixel of offset); with
    /// `head_from_motion`, the most it may be.
    pub head_acceleration: f64,
    /// Weigh the head's acceleration by how the head moves in the frames around each frame
    /// and how much the frames scatter about that motion, rather than by one weight for
    /// every take: a head held still gets `head_acceleration`, one that moves gets less.
    pub head_from_motion: bool,
    /// The weight of the jaw's acceleration (per mm² of the second difference of the lower
    /// arch's pose relative to the upper's), as `head_acceleration`'s. 0: none.
    pub jaw_acceleration: f64,
    /// Accelerations (mm, at an arch's centre and radius) beyond this are weighed less and less
    /// (Cauchy's loss): a real fast movement is not bent to the prior. 0: quadratic throughout.
    pub acceleration_scale_mm: f64,
}

impl Default for WindowSettings {
    fn default() -> Self {
        WindowSettings {
            frames: 6,
            head_acceleration: 1e4,
            head_from_motion: true,
            jaw_acceleration: 500.0,
            acceleration_scale_mm: 0.5,
        }
    }
}

impl WindowSettings {
    pub fn is_default(&self) -> bool {
        *self == WindowSettings::default()
    }

    pub fn validate(&self, rules: &crate::settings::Rules) -> crate::error::Result<()> {
        rules.count("frames", self.frames as u64, 0, 100)?;
        rules.number("head_acceleration", self.head_acceleration, 0.0, 1e12)?;
        rules.number("jaw_acceleration", self.jaw_acceleration, 0.0, 1e12)?;
        rules.number(
            "acceleration_scale_mm",
            self.acceleration_scale_mm,
            0.0,
            1e3,
        )
    }
}

/// The window as a run uses it: its settings, and each arch's centre in its model frame,
/// where the priors measure the arches' motion (a scan's own origin may lie anywhere). The
/// default measures them at the models' origins.
#[derive(Debug, Clone, Default)]
pub struct Window {
    pub settings: WindowSettings,
    pub centres: [Vector3<f64>; 2],
}

impl Window {
    pub fn new(settings: &WindowSettings, capture: &Capture) -> Window {
        Window {
            settings: settings.clone(),
            centres: [centre(capture, Arch::Upper), centre(capture, Arch::Lower)],
        }
    }
}

/// One frame as tracked.
#[derive(Debug, Clone, Copy)]
pub struct Estimate {
    pub poses: ArchPoses,
    pub information: Option<Matrix12>,
}

/// Where a frame's information stands for "fixed".
const FIXED: f64 = 1e12;

/// IRLS rounds of the robust acceleration terms: each re-weighs the terms by their residuals
/// at the last round's solution.
const ROBUST_ROUNDS: usize = 4;

/// One prior on a second difference over the window: values `x[k]` (increments from frame
/// t's pose), the map `jac[k]` from frame k's increment (at `column` in its 12) to `x[k]`'s,
/// and the metric that turns an increment into mm.
struct Acceleration {
    x: Vec<Vector6<f64>>,
    jac: Vec<Matrix6<f64>>,
    column: usize,
    metric: Matrix6<f64>,
    weight: f64,
}

impl Acceleration {
    /// The second difference centred on k (mm), which is linear in the increments: its value
    /// at none, and the map from each of frames k−1, k and k+1's increments.
    fn linearised(&self, k: usize) -> (Vector6<f64>, [(usize, Matrix6<f64>); 3]) {
        let r0 = self.metric * (self.x[k - 1] - 2.0 * self.x[k] + self.x[k + 1]);
        let blocks = [(k - 1, 1.0), (k, -2.0), (k + 1, 1.0)]
            .map(|(i, c)| (i, self.metric * self.jac[i] * c));
        (r0, blocks)
    }
}

/// Frame `t`'s poses settled with its neighbours in `estimates` (as many of the window's as
/// there are).
pub fn settled(estimates: &[Estimate], t: usize, window: &Window) -> ArchPoses {
    let s = &window.settings;
    let own = estimates[t];
    if s.frames == 0
        || own.information.is_none()
        || (s.head_acceleration <= 0.0 && s.jaw_acceleration <= 0.0)
    {
        return own.poses;
    }
    let first = t.saturating_sub(s.frames);
    let last = (t + s.frames).min(estimates.len() - 1);
    let span = &estimates[first..=last];
    let n = span.len();
    if n < 3 {
        return own.poses;
    }
    let mut information = DMatrix::<f64>::zeros(12 * n, 12 * n);
    for (k, e) in span.iter().enumerate() {
        let info = e
            .information
            .unwrap_or_else(|| Matrix12::identity() * FIXED);
        information
            .view_mut((12 * k, 12 * k), (12, 12))
            .copy_from(&info);
    }
    let mut priors = Vec::new();
    // The upper arch of every frame relative to frame t's, in world axes, measured at its
    // centre.
    let here = own.poses.upper;
    if s.head_acceleration > 0.0 {
        priors.push(Acceleration {
            x: span
                .iter()
                .map(|e| e.poses.upper.compose(&here.inverse()).log())
                .collect(),
            jac: vec![Matrix6::identity(); n],
            column: 0,
            metric: metric(&here.transform_point(&window.centres[0])),
            weight: if s.head_from_motion {
                // A whole window's frames up to the last one in it, where the take has them:
                // at the take's end the window is cut short, and a fit to half of it would
                // weigh the head by its noise.
                let fitted = &estimates[last.saturating_sub(2 * s.frames)..=last];
                head_weight(fitted, &here, &window.centres[0], s.head_acceleration)
            } else {
                s.head_acceleration
            },
        });
    }
    // The jaw (the lower arch in the upper's frame) of every frame relative to frame t's, in
    // the upper arch's axes: ξ_j moves frame k's jaw by Ad(upper_k⁻¹)·ξ_j.
    if s.jaw_acceleration > 0.0 {
        let jaw_here = own.poses.jaw();
        priors.push(Acceleration {
            x: span
                .iter()
                .map(|e| e.poses.jaw().compose(&jaw_here.inverse()).log())
                .collect(),
            jac: span
                .iter()
                .map(|e| e.poses.upper.inverse().adjoint())
                .collect(),
            column: 6,
            metric: metric(&jaw_here.transform_point(&window.centres[1])),
            weight: s.jaw_acceleration,
        });
    }
    let mut delta = DVector::<f64>::zeros(12 * n);
    let rounds = if s.acceleration_scale_mm > 0.0 {
        ROBUST_ROUNDS
    } else {
        1
    };
    for _ in 0..rounds {
        let mut h = information.clone();
        let mut g = DVector::<f64>::zeros(12 * n);
        for p in &priors {
            for k in 1..n - 1 {
                let (r0, blocks) = p.linearised(k);
                // Cauchy's weight on the residual's length at the last round's solution.
                let robust = if s.acceleration_scale_mm > 0.0 {
                    let r = blocks.iter().fold(r0, |r, (i, b)| {
                        r + b * delta.fixed_rows::<6>(12 * i + p.column)
                    });
                    1.0 / (1.0 + (r.norm() / s.acceleration_scale_mm).powi(2))
                } else {
                    1.0
                };
                let w = p.weight * robust;
                for (j, bj) in &blocks {
                    for (i, bi) in &blocks {
                        let mut view = h.view_mut((12 * j + p.column, 12 * i + p.column), (6, 6));
                        view += w * (bj.transpose() * bi);
                    }
                    let mut gj = g.rows_mut(12 * j + p.column, 6);
                    gj -= w * bj.transpose() * r0;
                }
            }
        }
        let Some(chol) = h.cholesky() else {
            return own.poses;
        };
        delta = chol.solve(&g);
    }
    let k = t - first;
    let xi_u = Pose::exp(&delta.fixed_rows::<6>(12 * k).into_owned());
    let xi_j = Pose::exp(&delta.fixed_rows::<6>(12 * k + 6).into_owned());
    ArchPoses {
        upper: xi_u.compose(&own.poses.upper),
        lower: xi_u.compose(&xi_j).compose(&own.poses.lower),
    }
}

/// The head's acceleration weight for a `span` of frames, from the frames themselves (an
/// empirical Bayes estimate): the upper arch's path over the span fitted by a cubic in time
/// (a quadratic's misfit to a head that swings within the span would count as scatter),
/// weighted by each frame's information about the upper arch. The scatter about the fit
/// says what the information is worth in mm (the variance of unit weight, λ, since the edges'
/// errors are correlated and their information is not a calibrated inverse covariance); the
/// fit's curvature, less what the scatter alone would give it, is the head's acceleration. A
/// Gaussian prior on an acceleration of mean square α² per direction weighs λ / α². A head
/// whose acceleration the frames cannot tell from their scatter gets `most`.
fn head_weight(span: &[Estimate], here: &Pose, centre: &Vector3<f64>, most: f64) -> f64 {
    let m = metric(&here.transform_point(centre));
    let Some(m_inv) = m.try_inverse() else {
        return most;
    };
    let mid = (span.len() as f64 - 1.0) / 2.0;
    // Each frame: its place on the path (mm at the arch's centre and radius) and the
    // information about it, with the basis [1, τ, τ², τ³] of the cubic.
    let frames: Vec<(SMatrix<f64, 6, 24>, Matrix6<f64>, Vector6<f64>)> = span
        .iter()
        .enumerate()
        .filter_map(|(k, e)| {
            let info = upper_information(&e.information?);
            let tau = k as f64 - mid;
            let mut basis = SMatrix::<f64, 6, 24>::zeros();
            for (j, c) in [1.0, tau, tau * tau, tau * tau * tau]
                .into_iter()
                .enumerate()
            {
                basis
                    .fixed_view_mut::<6, 6>(0, 6 * j)
                    .copy_from(&(Matrix6::identity() * c));
            }
            let y = m * e.poses.upper.compose(&here.inverse()).log();
            Some((basis, m_inv.transpose() * info * m_inv, y))
        })
        .collect();
    let dof = 6.0 * frames.len() as f64 - 24.0;
    if dof < 1.0 {
        return most;
    }
    let (mut normal, mut rhs) = (SMatrix::<f64, 24, 24>::zeros(), SVector::<f64, 24>::zeros());
    for (p, w, y) in &frames {
        normal += p.transpose() * w * p;
        rhs += p.transpose() * w * y;
    }
    let Some(covariance) = normal.try_inverse() else {
        return most;
    };
    let fit = covariance * rhs;
    let scatter: f64 = frames
        .iter()
        .map(|(p, w, y)| {
            let r = y - p * fit;
            (r.transpose() * w * r)[0]
        })
        .sum::<f64>()
        / dof;
    // At the span's middle (τ = 0) the cubic's second derivative is twice its τ² term.
    let acceleration = 2.0 * fit.fixed_rows::<6>(12);
    let noise = 4.0 * scatter * covariance.fixed_view::<6, 6>(12, 12).trace();
    let signal = acceleration.norm_squared() - noise;
    if signal <= 0.0 {
        return most;
    }
    (6.0 * scatter / signal).min(most)
}

/// What a frame's information says of the upper arch alone (its jaw's increment free): the
/// Schur complement of the jaw's block.
fn upper_information(info: &Matrix12) -> Matrix6<f64> {
    let uu = info.fixed_view::<6, 6>(0, 0).into_owned();
    let uj = info.fixed_view::<6, 6>(0, 6).into_owned();
    match info.fixed_view::<6, 6>(6, 6).into_owned().cholesky() {
        Some(jj) => uu - uj * jj.solve(&uj.transpose()),
        None => uu,
    }
}

/// The map from a world increment [ω; v] to the motion it causes at `centre`: rotation at an
/// arch's radius and displacement (mm).
fn metric(centre: &nalgebra::Vector3<f64>) -> Matrix6<f64> {
    let mut m = Matrix6::zeros();
    m.fixed_view_mut::<3, 3>(0, 0)
        .copy_from(&(nalgebra::Matrix3::identity() * RADIUS_MM));
    m.fixed_view_mut::<3, 3>(3, 0)
        .copy_from(&-crate::geometry::hat(centre));
    m.fixed_view_mut::<3, 3>(3, 3)
        .copy_from(&nalgebra::Matrix3::identity());
    m
}

#[cfg(test)]
mod tests {
    use nalgebra::Vector3;

    use super::*;

    fn at_origins(settings: WindowSettings) -> Window {
        Window {
            settings,
            ..Window::default()
        }
    }

    fn at(x: f64, nod: f64) -> ArchPoses {
        let upper = Pose::from_euler_tuple(&[nod, 0.0, 0.0, x, 0.0, 0.0]);
        ArchPoses {
            upper,
            lower: upper.compose(&Pose::from_translation(Vector3::new(0.0, -10.0, 0.0))),
        }
    }

    #[test]
    fn noise_on_a_weakly_held_direction_averages_out_and_sharp_frames_stay() {
        // The head still; each frame's nod (rotation about x) off by ±0.01 rad in turn, a
        // direction its edges hold weakly; its other directions held sharply.
        let mut weak = Matrix12::identity() * 1e6;
        weak[(0, 0)] = 1e2;
        let noisy: Vec<Estimate> = (0..13)
            .map(|k| Estimate {
                poses: at(0.0, if k % 2 == 0 { 0.01 } else { -0.01 }),
                information: Some(weak),
            })
            .collect();
        let s = at_origins(WindowSettings::default());
        let settled_nod = |e: &[Estimate], t: usize| settled(e, t, &s).upper.to_euler_tuple()[0];
        let nod = settled_nod(&noisy, 6);
        assert!(nod.abs() < 0.002, "the middle frame still nods {nod} rad");
        // Held far more sharply than the prior holds the head's acceleration (1e4 per mm²,
        // about 1e7 per rad² at an arch's radius): the poses stay where the frames put them.
        let sharp: Vec<Estimate> = noisy
            .iter()
            .map(|e| Estimate {
                information: Some(Matrix12::identity() * 1e11),
                ..*e
            })
            .collect();
        let nod = settled_nod(&sharp, 6);
        assert!(
            (nod - 0.01).abs() < 1e-4,
            "a sharp frame moved to {nod} rad"
        );
        // A frame without information holds its poses.
        let mut held = noisy.clone();
        held[6].information = None;
        assert_eq!(settled(&held, 6, &s), held[6].poses);
    }

    #[test]
    fn steady_motion_is_not_bent() {
        // The head sliding at constant speed: no acceleration to take out.
        let moving: Vec<Estimate> = (0..13)
            .map(|k| Estimate {
                poses: at(0.5 * k as f64, 0.0),
                information: Some(Matrix12::identity() * 10.0),
            })
            .collect();
        for t in [0, 3, 6, 12] {
            let p = settled(&moving, t, &at_origins(WindowSettings::default()));
            let (r, d) = p.upper.distance_to(&moving[t].poses.upper);
            assert!(r < 1e-6 && d < 1e-6, "frame {t}: moved {d} mm, {r} rad");
        }
    }

    #[test]
    fn a_head_that_swings_is_followed_and_a_still_one_is_held() {
        // Each frame held by its edges about as well as its noise says (±0.02 mm along x, 1e2
        // per mm²).
        let frames = |x: &dyn Fn(f64) -> f64| -> Vec<Estimate> {
            (0..13)
                .map(|k| Estimate {
                    poses: at(x(k as f64) + if k % 2 == 0 { 0.02 } else { -0.02 }, 0.0),
                    information: Some(Matrix12::identity() * 1e2),
                })
                .collect()
        };
        let learned = at_origins(WindowSettings::default());
        let fixed = at_origins(WindowSettings {
            head_from_motion: false,
            ..WindowSettings::default()
        });
        let x_at = |e: &[Estimate], w: &Window| settled(e, 6, w).upper.translation.x;
        // Swinging 3 mm each way over 30 frames, frame 6 at a turn (0.13 mm a frame²).
        let swing = |k: f64| 3.0 * (std::f64::consts::TAU * (k - 6.0) / 30.0).cos();
        let swinging = frames(&swing);
        let (followed, bent) = (
            x_at(&swinging, &learned) - 3.0,
            x_at(&swinging, &fixed) - 3.0,
        );
        assert!(
            followed.abs() < 0.03 && bent.abs() > 0.15,
            "the turn is missed by {followed} mm, by {bent} mm with the fixed weight"
        );
        // Still: the noise cannot be told from motion, and averages out as with the fixed
        // weight.
        let still = frames(&|_| 0.0);
        let x = x_at(&still, &learned);
        assert!(x.abs() < 0.005, "the still head settles {x} mm off");
    }

    /// The head still, the jaw opening by `open[k]` mm (the lower arch lowered), each frame's
    /// jaw held by its edges with `weak` along that direction and sharply along the others.
    fn jaw_frames(open: &[f64], weak: f64) -> Vec<Estimate> {
        let mut info = Matrix12::identity() * 1e6;
        info[(10, 10)] = weak;
        open.iter()
            .map(|y| Estimate {
                poses: ArchPoses {
                    upper: Pose::IDENTITY,
                    lower: Pose::from_translation(Vector3::new(0.0, -10.0 - y, 0.0)),
                },
                information: Some(info),
            })
            .collect()
    }

    fn opening(p: &ArchPoses) -> f64 {
        -10.0 - p.jaw().translation.y
    }

    #[test]
    fn jaw_noise_averages_out() {
        let noisy: Vec<f64> = (0..13)
            .map(|k| if k % 2 == 0 { 0.1 } else { -0.1 })
            .collect();
        let frames = jaw_frames(&noisy, 1e2);
        let y = opening(&settled(&frames, 6, &at_origins(WindowSettings::default())));
        assert!(y.abs() < 0.03, "the middle frame's jaw is still {y} mm off");
        let off = WindowSettings {
            jaw_acceleration: 0.0,
            ..WindowSettings::default()
        };
        let y = opening(&settled(&frames, 6, &at_origins(off)));
        assert!((y - 0.1).abs() < 1e-6, "without the prior it moved to {y}");
    }

    #[test]
    fn a_sharp_turn_of_the_jaw_is_bent_less_with_the_robust_loss() {
        // The jaw opening at 2 mm a frame, closing again from frame 6: a turn of 4 mm a
        // frame², far beyond the masks' noise, that the frames hold only weakly.
        let turn: Vec<f64> = (0..13)
            .map(|k| 12.0 - 2.0 * (k as f64 - 6.0).abs())
            .collect();
        let frames = jaw_frames(&turn, 1e2);
        let bent = |scale: f64| {
            let s = WindowSettings {
                acceleration_scale_mm: scale,
                ..WindowSettings::default()
            };
            (opening(&settled(&frames, 6, &at_origins(s))) - 12.0).abs()
        };
        let (robust, quadratic) = (
            bent(WindowSettings::default().acceleration_scale_mm),
            bent(0.0),
        );
        assert!(
            robust < 0.25 * quadratic,
            "the turn is bent by {robust} mm with the robust loss, {quadratic} without"
        );
    }

    #[test]
    fn the_settled_arches_do_not_depend_on_where_the_scans_put_their_origins() {
        // A head that turns and nods, a jaw that opens, both with noise, each frame's nod and
        // opening held weakly. The same motion with each scan's vertices moved (its origin
        // elsewhere: poses composed with the inverse shift, centres moved with the vertices)
        // must settle to the same arches in the world.
        let mut info = Matrix12::identity() * 1e5;
        info[(0, 0)] = 1e3;
        info[(6, 6)] = 1e3;
        let frames: Vec<Estimate> = (0..13)
            .map(|k| {
                let (k, noise) = (k as f64, if k % 2 == 0 { 1.0 } else { -1.0 });
                let upper = Pose::from_euler_tuple(&[
                    0.01 * noise,
                    0.02 * k,
                    0.0,
                    0.3 * k,
                    0.05 * k * k,
                    100.0,
                ]);
                let jaw = Pose::from_euler_tuple(&[
                    -0.03 * k + 0.004 * noise,
                    0.0,
                    0.0,
                    0.0,
                    -12.0 - 0.2 * k,
                    -3.0,
                ]);
                Estimate {
                    poses: ArchPoses {
                        upper,
                        lower: upper.compose(&jaw),
                    },
                    information: Some(info),
                }
            })
            .collect();
        let centres = [
            Vector3::new(0.0, 2.0, -15.0),
            Vector3::new(0.0, -2.0, -12.0),
        ];
        let shifts = [
            Vector3::new(40.0, -30.0, 70.0),
            Vector3::new(-50.0, 20.0, 35.0),
        ];
        let moved: Vec<Estimate> = frames
            .iter()
            .map(|e| Estimate {
                poses: ArchPoses {
                    upper: e.poses.upper.compose(&Pose::from_translation(-shifts[0])),
                    lower: e.poses.lower.compose(&Pose::from_translation(-shifts[1])),
                },
                ..*e
            })
            .collect();
        let settings = WindowSettings::default();
        let here = settled(
            &frames,
            6,
            &Window {
                settings: settings.clone(),
                centres,
            },
        );
        let there = settled(
            &moved,
            6,
            &Window {
                settings,
                centres: [centres[0] + shifts[0], centres[1] + shifts[1]],
            },
        );
        assert!(
            here.upper.distance_to(&frames[6].poses.upper).1 > 0.01,
            "the window did not move the frame"
        );
        for (a, (p, q)) in [(here.upper, there.upper), (here.lower, there.lower)]
            .into_iter()
            .enumerate()
        {
            let off = (p.transform_point(&centres[a])
                - q.transform_point(&(centres[a] + shifts[a])))
            .norm();
            assert!(off < 1e-6, "arch {a}'s centre is {off} mm apart");
        }
    }
}
