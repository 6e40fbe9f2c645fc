//! Least-squares rigid fit of two point sets (Kabsch/Umeyama without scale).

use nalgebra::{Matrix3, Vector3};

use super::Pose;

#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RigidFitError {
    #[error("a rigid fit needs at least three point pairs, got {0}")]
    TooFewPoints(usize),
    #[error("the two point lists differ in length ({0} and {1})")]
    LengthMismatch(usize, usize),
    #[error("the points are collinear or coincident; the rotation is not determined")]
    Degenerate,
}

/// The rigid motion `b_from_a` minimising Σ |b_i − (R a_i + t)|².
pub fn fit_rigid(a: &[Vector3<f64>], b: &[Vector3<f64>]) -> Result<Pose, RigidFitError> {
    if a.len() != b.len() {
        return Err(RigidFitError::LengthMismatch(a.len(), b.len()));
    }
    if a.len() < 3 {
        return Err(RigidFitError::TooFewPoints(a.len()));
    }
    let n = a.len() as f64;
    let ca = a.iter().sum::<Vector3<f64>>() / n;
    let cb = b.iter().sum::<Vector3<f64>>() / n;
    let h: Matrix3<f64> = a
        .iter()
        .zip(b)
        .map(|(p, q)| (q - cb) * (p - ca).transpose())
        .sum();
    let svd = h.svd(true, true);
    let (u, vt) = (
        svd.u.ok_or(RigidFitError::Degenerate)?,
        svd.v_t.ok_or(RigidFitError::Degenerate)?,
    );
    let s = svd.singular_values;
    let mut sorted = [s[0], s[1], s[2]];
    sorted.sort_by(f64::total_cmp);
    if sorted[1] <= 1e-9 * sorted[2].max(1e-300) {
        return Err(RigidFitError::Degenerate);
    }
    let d = (u * vt).determinant().signum();
    let r = u * Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, d)) * vt;
    let rotation = nalgebra::Rotation3::from_matrix_unchecked(r);
    Ok(Pose::new(rotation, cb - rotation * ca))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn recovers_a_known_motion() {
        let truth = Pose::from_euler_tuple(&[0.4, -0.2, 2.9, 10.0, -4.0, 150.0]);
        let a = vec![
            Vector3::new(0.0, 0.0, 0.0),
            Vector3::new(10.0, 0.0, 1.0),
            Vector3::new(0.0, 8.0, -2.0),
            Vector3::new(-5.0, 3.0, 6.0),
        ];
        let b: Vec<_> = a.iter().map(|p| truth.transform_point(p)).collect();
        let fit = fit_rigid(&a, &b).unwrap();
        let (r, t) = fit.distance_to(&truth);
        assert!(r < 1e-10 && t < 1e-9, "{r} {t}");
    }

    #[test]
    fn rejects_collinear_and_short_input() {
        let a = vec![Vector3::zeros(), Vector3::x(), Vector3::x() * 2.0];
        assert_eq!(fit_rigid(&a, &a).unwrap_err(), RigidFitError::Degenerate);
        assert_eq!(
            fit_rigid(&a[..2], &a[..2]).unwrap_err(),
            RigidFitError::TooFewPoints(2)
        );
    }
}
