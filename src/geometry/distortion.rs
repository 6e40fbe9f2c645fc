//! Lens models as OpenCV defines them, on normalised image coordinates (x, y) = (X/Z, Y/Z):
//!
//! - [`Distortion::OpenCv`]: `cv::projectPoints`' model, radial as a ratio of polynomials
//!   (k1, k2, k3 over k4, k5, k6: the rational model), tangential (p1, p2) and thin prism
//!   (s1..s4). The classic five coefficients are this with the rest zero.
//! - [`Distortion::Fisheye`]: `cv::fisheye` (Kannala-Brandt), θd = θ(1 + k1θ² + k2θ⁴ + k3θ⁶ +
//!   k4θ⁸) with θ the angle off the axis; (x, y) is scaled by θd / r.

/// A camera's lens.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Distortion {
    /// OpenCV order: k1, k2, p1, p2, k3, k4, k5, k6, s1, s2, s3, s4.
    OpenCv([f64; 12]),
    /// k1, k2, k3, k4.
    Fisheye([f64; 4]),
}

impl Default for Distortion {
    fn default() -> Self {
        Distortion::NONE
    }
}

/// How far out lens limits are looked for: r = 20 is 87° off the axis.
const R_MAX: f64 = 20.0;

impl Distortion {
    /// The pinhole: no distortion.
    pub const NONE: Distortion = Distortion::OpenCv([0.0; 12]);

    /// OpenCV's classic (k1, k2, p1, p2, k3).
    pub fn brown(k: [f64; 5]) -> Distortion {
        let mut all = [0.0; 12];
        all[..5].copy_from_slice(&k);
        Distortion::OpenCv(all)
    }

    /// From a camera file's list: 4, 5, 8, 12 or 14 OpenCV coefficients (14 only with the
    /// tilt terms zero), or 4 fisheye ones. `Err` says what is wrong.
    pub fn from_coefficients(values: &[f64], fisheye: bool) -> Result<Distortion, String> {
        if fisheye {
            return match values {
                [k1, k2, k3, k4] => Ok(Distortion::Fisheye([*k1, *k2, *k3, *k4])),
                _ => Err(format!(
                    "the fisheye model has 4 coefficients (k1, k2, k3, k4), found {}",
                    values.len()
                )),
            };
        }
        match values.len() {
            4 | 5 | 8 | 12 => {
                let mut all = [0.0; 12];
                all[..values.len()].copy_from_slice(values);
                Ok(Distortion::OpenCv(all))
            }
            14 if values[12] == 0.0 && values[13] == 0.0 => {
                Distortion::from_coefficients(&values[..12], false)
            }
            14 => Err("the tilted-sensor terms (τx, τy) are not supported".into()),
            n => Err(format!(
                "expected 4, 5, 8, 12 or 14 OpenCV coefficients (k1, k2, p1, p2[, k3[, k4, k5, k6[, s1, s2, s3, s4]]]), found {n}"
            )),
        }
    }

    /// The coefficients as a camera file lists them (the OpenCV model's trailing zeros cut
    /// back to the shortest of its lengths 5, 8 and 12; none for the pinhole).
    pub fn coefficients(&self) -> Vec<f64> {
        match self {
            Distortion::Fisheye(k) => k.to_vec(),
            Distortion::OpenCv(k) => {
                let used = k.iter().rposition(|&v| v != 0.0).map_or(0, |i| i + 1);
                let len = [0, 5, 8, 12].into_iter().find(|&n| n >= used).unwrap_or(12);
                k[..len].to_vec()
            }
        }
    }

    pub fn is_fisheye(&self) -> bool {
        matches!(self, Distortion::Fisheye(_))
    }

    /// Whether projection differs from the pinhole's (the fisheye always does).
    pub fn is_some(&self) -> bool {
        match self {
            Distortion::OpenCv(k) => k.iter().any(|&v| v != 0.0),
            Distortion::Fisheye(_) => true,
        }
    }

    /// Distorted normalised coordinates of undistorted (x, y).
    pub fn apply(&self, x: f64, y: f64) -> [f64; 2] {
        match self {
            Distortion::OpenCv([k1, k2, p1, p2, k3, k4, k5, k6, s1, s2, s3, s4]) => {
                let r2 = x * x + y * y;
                let radial = (1.0 + r2 * (k1 + r2 * (k2 + r2 * k3)))
                    / (1.0 + r2 * (k4 + r2 * (k5 + r2 * k6)));
                let xy = x * y;
                [
                    x * radial + 2.0 * p1 * xy + p2 * (r2 + 2.0 * x * x) + r2 * (s1 + r2 * s2),
                    y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * xy + r2 * (s3 + r2 * s4),
                ]
            }
            Distortion::Fisheye(k) => {
                let r = (x * x + y * y).sqrt();
                let s = fisheye_scale(k, r);
                [x * s, y * s]
            }
        }
    }

    /// The radial part's image radius at undistorted radius r (tangential and prism terms,
    /// small by nature, left out).
    fn image_radius(&self, r: f64) -> f64 {
        match self {
            Distortion::OpenCv([k1, k2, _, _, k3, k4, k5, k6, ..]) => {
                let r2 = r * r;
                r * (1.0 + r2 * (k1 + r2 * (k2 + r2 * k3)))
                    / (1.0 + r2 * (k4 + r2 * (k5 + r2 * k6)))
            }
            Distortion::Fisheye(k) => r * fisheye_scale(k, r),
        }
    }

    /// The largest r² (undistorted, normalised) up to which the radial image radius keeps
    /// growing with r. Beyond it the model folds back and would map points far outside the
    /// view into the image, so projections stop there. Infinite when it never folds out to
    /// r = 20 (87° off the axis).
    pub fn limit_r2(&self) -> f64 {
        if let Distortion::OpenCv([k1, k2, _, _, k3, k4, k5, k6, ..]) = *self
            && [k4, k5, k6] == [0.0; 3]
        {
            return polynomial_limit_r2(k1, k2, k3);
        }
        // The walk below costs about 1,500 evaluations, and the energy asks for every camera's
        // limit at every candidate pose: remember the last few lenses' (per thread).
        thread_local! {
            static KNOWN: std::cell::RefCell<Vec<(Distortion, f64)>> =
                const { std::cell::RefCell::new(Vec::new()) };
        }
        if let Some(limit) = KNOWN.with(|k| k.borrow().iter().find(|(d, _)| d == self).map(|e| e.1))
        {
            return limit;
        }
        let limit = self.walk_limit_r2();
        KNOWN.with(|k| {
            let mut k = k.borrow_mut();
            if k.len() >= 16 {
                k.clear();
            }
            k.push((*self, limit));
        });
        limit
    }

    /// The rational model (whose denominator may also reach zero) and the fisheye: walk out in
    /// 0.2% steps of r until the radius stops growing, then bisect.
    fn walk_limit_r2(&self) -> f64 {
        let grows = |r: f64| {
            let h = 1e-7 * r.max(1e-3);
            let (a, b) = (self.image_radius(r - h), self.image_radius(r + h));
            b > a && a.is_finite() && b.is_finite() && self.denominator_positive(r + h)
        };
        let mut r = 1e-3;
        while r < R_MAX {
            let next = r * 1.002;
            if !grows(next) {
                let (mut lo, mut hi) = (r, next);
                for _ in 0..60 {
                    let mid = 0.5 * (lo + hi);
                    if grows(mid) {
                        lo = mid;
                    } else {
                        hi = mid;
                    }
                }
                return lo * lo;
            }
            r = next;
        }
        f64::INFINITY
    }

    fn denominator_positive(&self, r: f64) -> bool {
        match self {
            Distortion::OpenCv([_, _, _, _, _, k4, k5, k6, ..]) => {
                let r2 = r * r;
                1.0 + r2 * (k4 + r2 * (k5 + r2 * k6)) > 0.0
            }
            Distortion::Fisheye(_) => true,
        }
    }

    /// The image radius (distorted, normalised) at [`Distortion::limit_r2`]; infinite if the
    /// model never folds.
    pub fn reach(&self) -> f64 {
        let limit = self.limit_r2();
        if limit.is_infinite() {
            f64::INFINITY
        } else {
            self.image_radius(limit.sqrt())
        }
    }
}

/// θd / r of the fisheye model (1 on the axis).
fn fisheye_scale(k: &[f64; 4], r: f64) -> f64 {
    if r < 1e-12 {
        return 1.0;
    }
    let t = r.atan();
    let t2 = t * t;
    t * (1.0 + t2 * (k[0] + t2 * (k[1] + t2 * (k[2] + t2 * k[3])))) / r
}

/// The limit of the polynomial radial model r·(1 + k1 r² + k2 r⁴ + k3 r⁶), found exactly.
fn polynomial_limit_r2(k1: f64, k2: f64, k3: f64) -> f64 {
    // d(image radius)/dr as a cubic in t = r²; it is 1 at t = 0.
    let (a, b, c) = (3.0 * k1, 5.0 * k2, 7.0 * k3);
    let slope = |t: f64| 1.0 + t * (a + t * (b + t * c));
    let t_max = R_MAX * R_MAX;
    // Between the cubic's turning points it is monotonic: find the first stretch where
    // it reaches zero, then bisect there.
    let mut points = [0.0, t_max, t_max, t_max];
    let (qa, qb, qc) = (3.0 * c, 2.0 * b, a);
    let turning: [f64; 2] = if qa != 0.0 {
        let disc = qb * qb - 4.0 * qa * qc;
        let sq = disc.max(0.0).sqrt();
        [(-qb - sq) / (2.0 * qa), (-qb + sq) / (2.0 * qa)]
    } else if qb != 0.0 {
        [-qc / qb; 2]
    } else {
        [t_max; 2]
    };
    for (slot, t) in points[2..].iter_mut().zip(turning) {
        if t > 0.0 && t < t_max {
            *slot = t;
        }
    }
    points.sort_by(f64::total_cmp);
    for w in points.windows(2) {
        let (mut lo, mut hi) = (w[0], w[1]);
        if slope(hi) > 0.0 {
            continue;
        }
        for _ in 0..100 {
            let mid = 0.5 * (lo + hi);
            if slope(mid) > 0.0 {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        return lo;
    }
    f64::INFINITY
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_numeric_limit_agrees_with_the_exact_one() {
        // A rational model whose denominator is 1 + 0·r² walks the numeric path.
        for k in [[-0.5, 0.0, 0.0], [-0.3, 0.05, -0.01], [-0.12, 0.05, -0.01]] {
            let exact = polynomial_limit_r2(k[0], k[1], k[2]);
            let mut all = [0.0; 12];
            (all[0], all[1], all[4], all[5]) = (k[0], k[1], k[2], 1e-300);
            let numeric = Distortion::OpenCv(all).limit_r2();
            assert!(
                (numeric - exact).abs() < 1e-6 * exact,
                "{k:?}: {numeric} against {exact}"
            );
        }
    }

    #[test]
    fn fisheye_folds_where_theta_d_peaks() {
        // θd = θ(1 − θ²/3) peaks at θ = 1.
        let d = Distortion::Fisheye([-1.0 / 3.0, 0.0, 0.0, 0.0]);
        let r = d.limit_r2().sqrt();
        assert!((r.atan() - 1.0).abs() < 1e-6, "{}", r.atan());
        // An equidistant lens (all zero) never folds before 87°.
        assert_eq!(Distortion::Fisheye([0.0; 4]).limit_r2(), f64::INFINITY);
    }

    #[test]
    fn coefficients_round_trip() {
        let d = Distortion::from_coefficients(&[0.1, 0.0, 0.0, 0.0, 0.0, 0.2, 0.0, 0.0], false)
            .unwrap();
        assert_eq!(d.coefficients().len(), 8);
        assert_eq!(
            Distortion::brown([0.1, 0.0, 0.0, 0.0, 0.0]).coefficients(),
            vec![0.1, 0.0, 0.0, 0.0, 0.0]
        );
        assert!(Distortion::NONE.coefficients().is_empty());
        assert!(Distortion::from_coefficients(&[0.0; 6], false).is_err());
        assert!(Distortion::from_coefficients(&[0.0; 5], true).is_err());
        let mut tilt = [0.0; 14];
        tilt[13] = 0.01;
        assert!(
            Distortion::from_coefficients(&tilt, false)
                .unwrap_err()
                .contains("tilted")
        );
    }
}
