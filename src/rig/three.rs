//! What any three-parameter rig offers the tools that drive it (IK, animation in animator
//! units, the page): a pose for three parameters, which of them are valid, and the jaw frame
//! its poses are measured on. The NLPCA rig and the envelope rig both implement it.

use crate::anatomy::motion::MotionFrame;
use crate::geometry::Pose;

pub trait ThreeParameterRig {
    /// What the rig is, in a word or two (for people).
    fn kind(&self) -> &'static str;
    /// The jaw pose (upper_from_lower) for the parameters.
    fn pose(&self, d: &[f64; 3]) -> Pose;
    fn is_valid(&self, d: &[f64; 3]) -> bool;
    /// The nearest valid parameters.
    fn clamp(&self, d: &[f64; 3]) -> [f64; 3];
    /// The valid span of parameter `k` (1: lateral, 2: protrusion) with the others as in `d`;
    /// `None` where no value is valid.
    fn band(&self, d: &[f64; 3], k: usize) -> Option<[f64; 2]>;
    /// The rest bite and jaw axes the animator's units are measured on (`None` when the rig
    /// file lacks them).
    fn motion_frame(&self) -> Option<MotionFrame>;
    /// Parameters spread over the poses the rig was learned from.
    fn spread(&self) -> Vec<[f64; 3]>;
    /// The parameters nearest the rest bite (where solving for animator values starts).
    fn rest_params(&self) -> [f64; 3];
    /// Where a search for animator values may go: the parameters themselves for a rig that
    /// poses any (the NLPCA rig, shown out of range beyond its ranges), the valid ones for a
    /// rig that poses only those (the envelope rig).
    fn clamp_for_search(&self, d: &[f64; 3]) -> [f64; 3] {
        *d
    }
}

/// The parameters whose pose measures `target` (opening °, lateral mm, protrusion mm) on `m`,
/// by damped Gauss-Newton steps from `start` (the Jacobian by central differences); `None` when the
/// rig does not reach them.
pub fn solve_animator<R: ThreeParameterRig + ?Sized>(
    rig: &R,
    m: &MotionFrame,
    target: &[f64; 3],
    start: [f64; 3],
) -> Option<[f64; 3]> {
    let (d, miss) = nearest_animator(rig, m, target, start)?;
    (miss < 1e-3).then_some(d)
}

/// [`solve_animator`]'s search, ended where it got: the parameters and how far their pose's
/// animator values are from `target` (degrees and mm together). `None` only when the steps
/// could not be taken at all.
pub fn nearest_animator<R: ThreeParameterRig + ?Sized>(
    rig: &R,
    m: &MotionFrame,
    target: &[f64; 3],
    start: [f64; 3],
) -> Option<([f64; 3], f64)> {
    let f = |d: &[f64; 3]| -> [f64; 3] {
        let a = m.measure(&rig.pose(d));
        [
            a.opening_deg - target[0],
            a.lateral_mm - target[1],
            a.protrusion_mm - target[2],
        ]
    };
    let mut d = start;
    for _ in 0..50 {
        let r = f(&d);
        let miss = r.iter().map(|v| v * v).sum::<f64>().sqrt();
        if miss < 1e-6 {
            return Some((d, miss));
        }
        let h = 1e-5;
        let mut jac = nalgebra::Matrix3::zeros();
        for k in 0..3 {
            let (mut a, mut b) = (d, d);
            a[k] += h;
            b[k] -= h;
            let (fa, fb) = (f(&a), f(&b));
            for i in 0..3 {
                jac[(i, k)] = (fa[i] - fb[i]) / (2.0 * h);
            }
        }
        // Levenberg's damping keeps the step defined where a parameter has no effect (the
        // envelope's tip, where it is one point wide); elsewhere it is Newton's step. A
        // parameter held at its edge by the step is left out of the next solve, so the others
        // still move (a projected step).
        let mut step = nalgebra::Vector3::zeros();
        for _ in 0..3 {
            let jtj = jac.transpose() * jac;
            let mu = 1e-9 * jtj.diagonal().max().max(1e-12);
            step = (jtj + nalgebra::Matrix3::identity() * mu).try_inverse()?
                * (jac.transpose() * nalgebra::Vector3::from(r));
            let trial: [f64; 3] = std::array::from_fn(|k| d[k] - step[k]);
            let held = rig.clamp_for_search(&trial);
            let stuck: Vec<usize> = (0..3)
                .filter(|&k| held[k] != trial[k] && held[k] == d[k])
                .collect();
            if stuck.is_empty() {
                break;
            }
            for k in stuck {
                jac.set_column(k, &nalgebra::Vector3::zeros());
            }
        }
        // Damped: a full step can leave the region the rig was fitted on.
        let scale = (0.1 / step.norm()).min(1.0);
        let mut next = d;
        for k in 0..3 {
            next[k] -= scale * step[k];
        }
        // A rig that clamps its parameters (the envelope's cube) stalls at its edge: stay
        // on the edge, where the search has come as near as it can.
        let next = rig.clamp_for_search(&next);
        if next == d {
            break;
        }
        d = next;
    }
    let r = f(&d);
    Some((d, r.iter().map(|v| v * v).sum::<f64>().sqrt()))
}
