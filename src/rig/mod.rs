//! The jaw rig (Yang et al., Sections 3 and 5): jaw poses relative to the upper arch, mapped
//! to se(3) (the coordinates and PCA are `anatomy`'s), hierarchical NLPCA, the three-parameter rig with alpha-shape ranges, IK and
//! keyframe animation.

pub mod additive;
pub mod animate;
pub mod coupled;
pub mod eval;
mod file;
pub mod ik;
mod lbfgs;
pub mod model;
mod network;
pub mod nlpca;
pub mod plot;
pub mod ranges;
pub mod three;
pub mod units;

pub use model::{JawRig, RigError, RigSettings};
pub use nlpca::{Nlpca, NlpcaSettings};
pub use three::ThreeParameterRig;
pub use units::AnimatorParams;

/// For the networks' tests: `f`'s gradient (its second value) agrees with central
/// differences of its value at `theta`, each component within 1e-6 relative.
#[cfg(test)]
pub(crate) fn assert_gradient_matches_differences(
    theta: &[f64],
    f: impl Fn(&[f64]) -> (f64, Vec<f64>),
) {
    let (_, g) = f(theta);
    let h = 1e-6;
    for i in 0..theta.len() {
        let (mut p, mut m) = (theta.to_vec(), theta.to_vec());
        p[i] += h;
        m[i] -= h;
        let fd = (f(&p).0 - f(&m).0) / (2.0 * h);
        assert!(
            (fd - g[i]).abs() <= 1e-6 * (1.0 + fd.abs()),
            "parameter {i}: analytic {} vs finite difference {fd}",
            g[i]
        );
    }
}

/// Told, now and then, how far a long step (learning a rig) is.
pub type Progress<'a> = dyn Fn(&str) + Sync + 'a;
