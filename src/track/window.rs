//! A window over frames (a fixed-lag smoother): each frame's poses settled together with the
//! `frames` before and after it, so that segmentation noise that changes from frame to frame
//! averages out where the head's motion says it must.
//!
//! Each frame's estimate comes with the information its masks gave Gauss-Newton about it
//! (the normal matrix of its edges, in the increments [ξ_u; ξ_j] that move both arches and the
//! jaw): its energy, to second order about the estimate. The window minimises the sum of
//! those quadratics plus a prior on the head's acceleration: the upper arch's second
//! difference over consecutive frames, measured as in the solver's motion prior (displacement
//! at the arch's centre, rotation at an arch's radius, mm). The jaw is left to each frame's
//! masks (it moves fast; its acceleration is no smaller than the masks' noise), but it gains
//! from the head: where the edges pin the lower arch in the world, a steadier upper arch makes
//! a truer jaw. The problem is linear in the increments; one solve per frame. A frame without
//! information (no masks, or found afresh) holds its poses and the others see it as fixed. A
//! frame's output is final once the `frames` after it are tracked.

use nalgebra::{DMatrix, DVector, Matrix6, Vector6};

use super::search::RADIUS_MM;
use crate::arch::ArchPoses;
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
    /// against the frames' edge information: pixel lengths per pixel of offset).
    pub head_acceleration: f64,
}

impl Default for WindowSettings {
    fn default() -> Self {
        WindowSettings {
            frames: 6,
            head_acceleration: 1e3,
        }
    }
}

impl WindowSettings {
    pub fn is_default(&self) -> bool {
        *self == WindowSettings::default()
    }

    pub fn validate(&self, rules: &crate::settings::Rules) -> crate::error::Result<()> {
        rules.count("frames", self.frames as u64, 0, 100)?;
        rules.number("head_acceleration", self.head_acceleration, 0.0, 1e12)
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

/// Frame `t`'s poses settled with its neighbours in `estimates` (as many of the window's as
/// there are).
pub fn settled(estimates: &[Estimate], t: usize, s: &WindowSettings) -> ArchPoses {
    let own = estimates[t];
    if s.frames == 0 || own.information.is_none() || s.head_acceleration <= 0.0 {
        return own.poses;
    }
    let first = t.saturating_sub(s.frames);
    let last = (t + s.frames).min(estimates.len() - 1);
    let window = &estimates[first..=last];
    let n = window.len();
    if n < 3 {
        return own.poses;
    }
    let mut h = DMatrix::<f64>::zeros(12 * n, 12 * n);
    let mut g = DVector::<f64>::zeros(12 * n);
    for (k, e) in window.iter().enumerate() {
        let info = e
            .information
            .unwrap_or_else(|| Matrix12::identity() * FIXED);
        h.view_mut((12 * k, 12 * k), (12, 12)).copy_from(&info);
    }
    // The upper arch of every frame relative to frame t's, and the metric at its centre.
    let here = own.poses.upper;
    let u: Vec<Vector6<f64>> = window
        .iter()
        .map(|e| e.poses.upper.compose(&here.inverse()).log())
        .collect();
    let m = metric(&here.translation);
    for k in 1..n - 1 {
        let r = m * (u[k - 1] - 2.0 * u[k] + u[k + 1]);
        for (j, c) in [(k - 1, 1.0), (k, -2.0), (k + 1, 1.0)] {
            let mj = m * c;
            for (i, ci) in [(k - 1, 1.0), (k, -2.0), (k + 1, 1.0)] {
                let block = s.head_acceleration * (mj.transpose() * (m * ci));
                let mut view = h.view_mut((12 * j, 12 * i), (6, 6));
                view += block;
            }
            let mut gj = g.rows_mut(12 * j, 6);
            gj -= s.head_acceleration * mj.transpose() * r;
        }
    }
    let Some(chol) = h.cholesky() else {
        return own.poses;
    };
    let delta = chol.solve(&g);
    let k = t - first;
    let xi_u = Pose::exp(&delta.fixed_rows::<6>(12 * k).into_owned());
    let xi_j = Pose::exp(&delta.fixed_rows::<6>(12 * k + 6).into_owned());
    ArchPoses {
        upper: xi_u.compose(&own.poses.upper),
        lower: xi_u.compose(&xi_j).compose(&own.poses.lower),
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
        let s = WindowSettings::default();
        let settled_nod = |e: &[Estimate], t: usize| settled(e, t, &s).upper.to_euler_tuple()[0];
        let nod = settled_nod(&noisy, 6);
        assert!(nod.abs() < 0.002, "the middle frame still nods {nod} rad");
        // Held far more sharply than the prior holds the head's acceleration (1e3 per mm²,
        // about 1e6 per rad² at an arch's radius): the poses stay where the frames put them.
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
            let p = settled(&moving, t, &WindowSettings::default());
            let (r, d) = p.upper.distance_to(&moving[t].poses.upper);
            assert!(r < 1e-6 && d < 1e-6, "frame {t}: moved {d} mm, {r} rad");
        }
    }
}
