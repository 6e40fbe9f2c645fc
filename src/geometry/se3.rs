//! Rigid motions: SO(3) and SE(3) with closed-form exp/log maps, the paper's 6-tuple
//! T = (θx, θy, θz, tx, ty, tz) with R = Rz·Ry·Rx, and the relative jaw pose (Eq. 1-3).
//!
//! Tangent vectors are ordered rotation first: `[ω; v]` for se(3), matching the 6-tuple.

use nalgebra::{Matrix3, Rotation3, Vector3, Vector6};

/// Below this angle the exp/log maps switch to Taylor expansions.
const SMALL_ANGLE_RAD: f64 = 1e-4;

/// The skew-symmetric (hat) matrix of `w`, so that `hat(w) * x == w.cross(&x)`.
pub fn hat(w: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::new(0.0, -w.z, w.y, w.z, 0.0, -w.x, -w.y, w.x, 0.0)
}

/// Inverse of [`hat`] for the antisymmetric part of `m`.
fn vee_antisym(m: &Matrix3<f64>) -> Vector3<f64> {
    Vector3::new(
        m[(2, 1)] - m[(1, 2)],
        m[(0, 2)] - m[(2, 0)],
        m[(1, 0)] - m[(0, 1)],
    ) * 0.5
}

/// SO(3) exponential: axis-angle vector to rotation (Rodrigues).
pub fn so3_exp(w: &Vector3<f64>) -> Rotation3<f64> {
    let theta2 = w.norm_squared();
    let theta = theta2.sqrt();
    let k = hat(w);
    let (a, b) = if theta < SMALL_ANGLE_RAD {
        (1.0 - theta2 / 6.0, 0.5 - theta2 / 24.0)
    } else {
        (theta.sin() / theta, (1.0 - theta.cos()) / theta2)
    };
    Rotation3::from_matrix_unchecked(Matrix3::identity() + k * a + k * k * b)
}

/// SO(3) logarithm: rotation to axis-angle vector with angle in [0, π].
/// Stable near 0 (Taylor) and near π (axis from the symmetric part).
pub fn so3_log(r: &Rotation3<f64>) -> Vector3<f64> {
    let m = r.matrix();
    let s_vec = vee_antisym(m); // = sin(θ)·n
    let sin_theta = s_vec.norm();
    let cos_theta = ((m.trace() - 1.0) * 0.5).clamp(-1.0, 1.0);
    let theta = sin_theta.atan2(cos_theta);
    if theta < SMALL_ANGLE_RAD {
        return s_vec * (1.0 + theta * theta / 6.0);
    }
    if cos_theta > 0.0 {
        return s_vec * (theta / sin_theta);
    }
    // θ > π/2: n nᵀ = (sym(R) − cosθ·I) / (1 − cosθ) is well conditioned.
    let sym = (m + m.transpose()) * 0.5;
    let nnt = (sym - Matrix3::identity() * cos_theta) / (1.0 - cos_theta);
    let i = (0..3)
        .max_by(|&a, &b| nnt[(a, a)].total_cmp(&nnt[(b, b)]))
        .unwrap_or(0);
    let mut n = nnt.column(i).into_owned() / nnt[(i, i)].max(1e-300).sqrt();
    n.normalize_mut();
    if n.dot(&s_vec) < 0.0 {
        n = -n;
    }
    n * theta
}

/// Left Jacobian V of SO(3), so that exp([ω; v]).translation = V·v.
fn left_jacobian(w: &Vector3<f64>) -> Matrix3<f64> {
    let theta2 = w.norm_squared();
    let theta = theta2.sqrt();
    let k = hat(w);
    let (b, c) = if theta < SMALL_ANGLE_RAD {
        (0.5 - theta2 / 24.0, 1.0 / 6.0 - theta2 / 120.0)
    } else {
        (
            (1.0 - theta.cos()) / theta2,
            (theta - theta.sin()) / (theta2 * theta),
        )
    };
    Matrix3::identity() + k * b + k * k * c
}

/// Inverse of [`left_jacobian`] in closed form.
fn left_jacobian_inv(w: &Vector3<f64>) -> Matrix3<f64> {
    let theta2 = w.norm_squared();
    let theta = theta2.sqrt();
    let k = hat(w);
    let c = if theta < SMALL_ANGLE_RAD {
        1.0 / 12.0 + theta2 / 720.0
    } else {
        (1.0 - theta * theta.sin() / (2.0 * (1.0 - theta.cos()))) / theta2
    };
    Matrix3::identity() - k * 0.5 + k * k * c
}

/// A rigid motion `x_b = R·x_a + t`, named `b_from_a` where it is stored.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pose {
    pub rotation: Rotation3<f64>,
    pub translation: Vector3<f64>,
}

/// Within this of orthonormal (max |RᵀR − I| entry, |det − 1|) a matrix read from a file is a
/// rotation to rounding, and [`Pose::rotation_from_rows`] keeps it unchanged.
const EXACT_ROTATION_TOL: f64 = 1e-13;

impl Default for Pose {
    fn default() -> Self {
        Self::IDENTITY
    }
}

impl Pose {
    pub const IDENTITY: Pose = Pose {
        rotation: Rotation3::from_matrix_unchecked(Matrix3::new(
            1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0,
        )),
        translation: Vector3::new(0.0, 0.0, 0.0),
    };

    pub fn new(rotation: Rotation3<f64>, translation: Vector3<f64>) -> Self {
        Self {
            rotation,
            translation,
        }
    }

    pub fn from_translation(t: Vector3<f64>) -> Self {
        Self::new(Rotation3::identity(), t)
    }

    pub fn inverse(&self) -> Pose {
        let r_inv = self.rotation.inverse();
        Pose::new(r_inv, -(r_inv * self.translation))
    }

    /// `self ∘ other`: apply `other` first. The product is re-orthonormalised: a tracker
    /// composes poses frame after frame, and unchecked rounding would compound. A product that
    /// is not finite is left as it is: nalgebra's re-orthonormalisation iterates until it
    /// converges, which a NaN never does.
    pub fn compose(&self, other: &Pose) -> Pose {
        let mut rotation = self.rotation * other.rotation;
        if rotation.matrix().iter().all(|v| v.is_finite()) {
            rotation.renormalize();
        }
        Pose::new(
            rotation,
            self.rotation * other.translation + self.translation,
        )
    }

    /// The 4x4 matrix, column-major, as WebGL and glTF take it.
    pub fn column_major(&self) -> [f64; 16] {
        let r = self.rotation.matrix();
        std::array::from_fn(|i| match (i % 4, i / 4) {
            (3, 3) => 1.0,
            (3, _) => 0.0,
            (row, 3) => self.translation[row],
            (row, col) => r[(row, col)],
        })
    }

    pub fn transform_point(&self, p: &Vector3<f64>) -> Vector3<f64> {
        self.rotation * p + self.translation
    }

    /// se(3) exponential of `[ω; v]`.
    pub fn exp(xi: &Vector6<f64>) -> Pose {
        let w = xi.fixed_rows::<3>(0).into_owned();
        let v = xi.fixed_rows::<3>(3).into_owned();
        Pose::new(so3_exp(&w), left_jacobian(&w) * v)
    }

    /// se(3) logarithm, `[ω; v]` with |ω| in [0, π].
    pub fn log(&self) -> Vector6<f64> {
        let w = so3_log(&self.rotation);
        let v = left_jacobian_inv(&w) * self.translation;
        Vector6::new(w.x, w.y, w.z, v.x, v.y, v.z)
    }

    /// The adjoint matrix, `exp(Ad·ξ) = g·exp(ξ)·g⁻¹`, for `[ω; v]` ordering.
    pub fn adjoint(&self) -> nalgebra::Matrix6<f64> {
        let r = *self.rotation.matrix();
        let mut ad = nalgebra::Matrix6::zeros();
        ad.fixed_view_mut::<3, 3>(0, 0).copy_from(&r);
        ad.fixed_view_mut::<3, 3>(3, 3).copy_from(&r);
        ad.fixed_view_mut::<3, 3>(3, 0)
            .copy_from(&(hat(&self.translation) * r));
        ad
    }

    /// The paper's 6-tuple (θx, θy, θz, tx, ty, tz), R = Rz(θz)·Ry(θy)·Rx(θx).
    pub fn from_euler_tuple(t: &[f64; 6]) -> Pose {
        let rx = Rotation3::from_axis_angle(&Vector3::x_axis(), t[0]);
        let ry = Rotation3::from_axis_angle(&Vector3::y_axis(), t[1]);
        let rz = Rotation3::from_axis_angle(&Vector3::z_axis(), t[2]);
        Pose::new(rz * ry * rx, Vector3::new(t[3], t[4], t[5]))
    }

    /// Inverse of [`Pose::from_euler_tuple`], with θy in [−π/2, π/2].
    pub fn to_euler_tuple(&self) -> [f64; 6] {
        let m = self.rotation.matrix();
        // R = Rz Ry Rx: m20 = −sin θy, m21 = cos θy sin θx, m22 = cos θy cos θx,
        // m10 = sin θz cos θy, m00 = cos θz cos θy.
        let theta_y = (-m[(2, 0)]).clamp(-1.0, 1.0).asin();
        let (theta_x, theta_z) = if m[(2, 0)].abs() < 1.0 - 1e-12 {
            (m[(2, 1)].atan2(m[(2, 2)]), m[(1, 0)].atan2(m[(0, 0)]))
        } else {
            // Gimbal lock (θy = ±π/2): only θx ∓ θz is determined; put it all in θx.
            ((m[(0, 1)] * -m[(2, 0)]).atan2(m[(1, 1)]), 0.0)
        };
        let t = self.translation;
        [theta_x, theta_y, theta_z, t.x, t.y, t.z]
    }

    /// The pose with `delta` added to its 6-tuple (θx, θy, θz, tx, ty, tz): rotations about
    /// the model's origin, translations in the parent frame (the paper's search space).
    pub fn with_euler_offset(&self, delta: &[f64; 6]) -> Pose {
        let mut t = self.to_euler_tuple();
        for (a, d) in t.iter_mut().zip(delta) {
            *a += d;
        }
        Pose::from_euler_tuple(&t)
    }

    /// Re-orthonormalise a 3x3 matrix read from a file (one already orthonormal to rounding is
    /// kept as it is); `None` if it is not a rotation within `tol` (max |RᵀR − I| entry, and
    /// det ≈ +1).
    pub fn rotation_from_rows(rows: &[[f64; 3]; 3], tol: f64) -> Option<Rotation3<f64>> {
        let m = Matrix3::from_fn(|i, j| rows[i][j]);
        let err = (m.transpose() * m - Matrix3::identity()).abs().max();
        // Written so that NaN fails too.
        let is_rotation = err <= tol && (m.determinant() - 1.0).abs() <= tol * 3.0;
        if !is_rotation {
            return None;
        }
        // A matrix orthonormal to rounding (as every pose jawtrack writes is) is kept to the
        // bit, so that a pose written and read back is the same pose: a resumed run goes on
        // from exactly where the interrupted one was.
        if err <= EXACT_ROTATION_TOL && (m.determinant() - 1.0).abs() <= EXACT_ROTATION_TOL {
            return Some(Rotation3::from_matrix_unchecked(m));
        }
        let svd = m.svd(true, true);
        let (u, vt) = (svd.u?, svd.v_t?);
        // The nearest rotation in the Frobenius norm.
        let r = u * vt;
        (r.determinant() > 0.0).then(|| Rotation3::from_matrix_unchecked(r))
    }

    pub fn rotation_rows(&self) -> [[f64; 3]; 3] {
        let m = self.rotation.matrix();
        [
            [m[(0, 0)], m[(0, 1)], m[(0, 2)]],
            [m[(1, 0)], m[(1, 1)], m[(1, 2)]],
            [m[(2, 0)], m[(2, 1)], m[(2, 2)]],
        ]
    }

    /// Rotation angle of `self.inverse() ∘ other` in radians, and translation distance.
    pub fn distance_to(&self, other: &Pose) -> (f64, f64) {
        let d = self.inverse().compose(other);
        (
            so3_log(&d.rotation).norm(),
            (self.translation - other.translation).norm(),
        )
    }
}

/// The jaw pose of a frame: the lower arch relative to the upper (Eq. 1-3),
/// `upper_from_lower = world_from_upper⁻¹ ∘ world_from_lower`.
pub fn jaw_pose(world_from_upper: &Pose, world_from_lower: &Pose) -> Pose {
    world_from_upper.inverse().compose(world_from_lower)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::lie_suite::{LieGroup, group_axiom_suite};

    #[test]
    fn a_rotation_read_back_from_its_rows_is_the_same_to_the_bit() {
        let a = Pose::from_euler_tuple(&[0.3, -0.2, 0.1, 1.0, 2.0, 3.0]);
        let b = Pose::from_euler_tuple(&[-0.05, 0.4, 0.7, 0.0, 0.0, 0.0]);
        let p = a.compose(&b).compose(&a);
        let read = Pose::rotation_from_rows(&p.rotation_rows(), 1e-6).unwrap();
        assert_eq!(read.matrix(), p.rotation.matrix());
        // Rows off by more than rounding are re-orthonormalised.
        let mut rows = p.rotation_rows();
        rows[0][0] += 1e-9;
        let fixed = Pose::rotation_from_rows(&rows, 1e-6).unwrap();
        let m = fixed.matrix();
        assert!((m.transpose() * m - Matrix3::identity()).abs().max() < 1e-14);
        assert_ne!(m[(0, 0)], rows[0][0]);
    }

    /// Found by hostile input: any non-finite pose reaching `compose` looped for ever in
    /// nalgebra's re-orthonormalisation (bf99878).
    #[test]
    fn composing_a_non_finite_pose_returns() {
        let bad = Pose::new(
            Rotation3::from_matrix_unchecked(Matrix3::from_element(f64::NAN)),
            Vector3::new(f64::INFINITY, 0.0, 0.0),
        );
        let p = bad.compose(&Pose::IDENTITY);
        assert!(p.rotation.matrix()[(0, 0)].is_nan());
        let q = Pose::IDENTITY.compose(&bad);
        assert!(!q.translation.x.is_finite());
    }

    impl LieGroup for Pose {
        type Tangent = Vector6<f64>;
        const NAME: &'static str = "SE(3)";
        fn exp(xi: &Self::Tangent) -> Self {
            Pose::exp(xi)
        }
        fn log(&self) -> Self::Tangent {
            Pose::log(self)
        }
        fn compose(&self, o: &Self) -> Self {
            Pose::compose(self, o)
        }
        fn inverse(&self) -> Self {
            Pose::inverse(self)
        }
        fn identity() -> Self {
            Pose::IDENTITY
        }
        fn adjoint_apply(&self, xi: &Self::Tangent) -> Self::Tangent {
            self.adjoint() * xi
        }
        fn distance(&self, o: &Self) -> f64 {
            let (r, t) = self.distance_to(o);
            r + t
        }
        fn tangent_distance(a: &Self::Tangent, b: &Self::Tangent) -> f64 {
            (a - b).norm()
        }
        fn tangents() -> Vec<Self::Tangent> {
            let pi = std::f64::consts::PI;
            let mut out = vec![
                Vector6::zeros(),
                Vector6::new(1e-9, -2e-9, 0.0, 1.0, 2.0, 3.0),
                Vector6::new(1e-5, 0.0, 3e-6, -4.0, 0.5, 9.0),
                Vector6::new(0.3, -0.2, 0.1, 10.0, -5.0, 2.0),
                Vector6::new(0.0, 0.0, pi - 1e-7, 1.0, 1.0, 1.0),
                Vector6::new(
                    0.0,
                    (pi - 1e-3) / 2f64.sqrt(),
                    (pi - 1e-3) / 2f64.sqrt(),
                    0.0,
                    3.0,
                    -1.0,
                ),
                Vector6::new(1.2, 0.5, -0.7, 0.0, 0.0, -20.0),
            ];
            let n = Vector3::new(1.0, 2.0, -2.0).normalize() * (pi - 1e-10);
            out.push(Vector6::new(n.x, n.y, n.z, 0.5, 0.0, 0.0));
            out
        }
    }

    #[test]
    fn se3_group_axioms() {
        group_axiom_suite::<Pose>();
    }

    #[test]
    fn long_chains_of_compositions_stay_rotations() {
        // Constant-velocity extrapolation, a thousand times: last ∘ before⁻¹ ∘ last.
        let (mut before, mut last) = (
            Pose::IDENTITY,
            Pose::from_euler_tuple(&[0.011, -0.007, 0.013, 0.1, 0.0, 0.2]),
        );
        for _ in 0..1000 {
            let next = last.compose(&before.inverse()).compose(&last);
            (before, last) = (last, next);
        }
        let m = last.rotation.matrix();
        assert!((m.transpose() * m - Matrix3::identity()).abs().max() < 1e-9);
        assert!(Pose::rotation_from_rows(&last.rotation_rows(), 1e-6).is_some());
    }

    #[test]
    fn so3_log_exactly_pi_returns_a_valid_axis() {
        let r = Rotation3::from_axis_angle(&Vector3::y_axis(), std::f64::consts::PI);
        let w = so3_log(&r);
        assert!((w.norm() - std::f64::consts::PI).abs() < 1e-12);
        assert!((so3_exp(&w).matrix() - r.matrix()).abs().max() < 1e-12);
    }

    #[test]
    fn euler_tuple_round_trip_and_order() {
        let t = [0.1, -0.4, 0.7, 1.0, -2.0, 3.0];
        let p = Pose::from_euler_tuple(&t);
        let back = p.to_euler_tuple();
        for i in 0..6 {
            assert!((t[i] - back[i]).abs() < 1e-12, "component {i}");
        }
        // R = Rz·Ry·Rx: rotating x by θz about z alone moves it towards y.
        let pz = Pose::from_euler_tuple(&[0.0, 0.0, 0.5, 0.0, 0.0, 0.0]);
        let x = pz.transform_point(&Vector3::x());
        assert!((x.y - 0.5f64.sin()).abs() < 1e-12);
        let px_then = Pose::from_euler_tuple(&[0.3, 0.2, 0.0, 0.0, 0.0, 0.0]);
        let ry = Rotation3::from_axis_angle(&Vector3::y_axis(), 0.2);
        let rx = Rotation3::from_axis_angle(&Vector3::x_axis(), 0.3);
        assert!((px_then.rotation.matrix() - (ry * rx).matrix()).abs().max() < 1e-12);
    }

    #[test]
    fn jaw_pose_matches_equations_1_to_3() {
        let u = Pose::from_euler_tuple(&[0.1, 0.2, -0.1, 5.0, 1.0, 200.0]);
        let jaw = Pose::from_euler_tuple(&[0.3, 0.0, 0.05, 0.0, -5.0, 2.0]);
        let l = u.compose(&jaw);
        let got = jaw_pose(&u, &l);
        // R = R_Uᵀ R_L, t = R_Uᵀ (t_L − t_U)
        let r = u.rotation.transpose() * l.rotation;
        let t = u.rotation.transpose() * (l.translation - u.translation);
        assert!((got.rotation.matrix() - r.matrix()).abs().max() < 1e-12);
        assert!((got.translation - t).norm() < 1e-12);
        assert!((got.translation - jaw.translation).norm() < 1e-12);
    }

    #[test]
    fn rotation_from_rows_rejects_non_rotations_and_reorthonormalises() {
        assert!(
            Pose::rotation_from_rows(&[[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, -1.0]], 1e-3)
                .is_none()
        );
        assert!(
            Pose::rotation_from_rows(&[[2.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]], 1e-3)
                .is_none()
        );
        let r =
            Pose::rotation_from_rows(&[[1.0, 2e-4, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]], 1e-3)
                .unwrap();
        let m = r.matrix();
        assert!((m.transpose() * m - Matrix3::identity()).abs().max() < 1e-12);
    }
}
