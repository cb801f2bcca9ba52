//! The rotation group SO(3): hat and vee, exponential and logarithm, left Jacobian.
//!
//! Rotations are [`UnitQuaternion<f64>`]; tangent vectors φ ∈ ℝ³ are rotation
//! vectors (axis × angle, radians). Every function is accurate near the
//! identity (Taylor series for small θ = ‖φ‖) and near θ = π.
//!
//! The left Jacobian J_l(φ) is defined by
//! exp(φ + δ) ≈ exp(J_l(φ) δ) · exp(φ) for small δ.
//!
//! # Example
//! ```
//! use lidar_kinematics::so3;
//! use nalgebra::Vector3;
//!
//! let phi = Vector3::new(0.3, -1.2, 2.0);
//! let q = so3::exp(&phi);
//! assert!((so3::log(&q) - phi).norm() < 1e-12);
//! let j = so3::left_jacobian(&phi);
//! assert!((j * so3::left_jacobian_inv(&phi) - nalgebra::Matrix3::identity()).norm() < 1e-12);
//! ```

use nalgebra::{Matrix3, Quaternion, UnitQuaternion, Vector3};

use crate::series;

/// The skew-symmetric matrix φ̂ with φ̂ v = φ × v.
///
/// # Example
/// ```
/// use lidar_kinematics::so3;
/// use nalgebra::Vector3;
/// let (a, b) = (Vector3::new(1.0, 2.0, 3.0), Vector3::new(-2.0, 0.5, 1.0));
/// assert_eq!(so3::hat(&a) * b, a.cross(&b));
/// ```
#[inline]
pub fn hat(phi: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::new(
        0.0, -phi.z, phi.y, //
        phi.z, 0.0, -phi.x, //
        -phi.y, phi.x, 0.0,
    )
}

/// The inverse of [`hat`]: the vector of the skew-symmetric part of `m`.
///
/// For a skew-symmetric `m` this is exact; otherwise it returns the vector of
/// (m − mᵀ)/2.
///
/// # Example
/// ```
/// use lidar_kinematics::so3;
/// use nalgebra::Vector3;
/// let v = Vector3::new(0.1, -0.2, 0.3);
/// assert_eq!(so3::vee(&so3::hat(&v)), v);
/// ```
#[inline]
pub fn vee(m: &Matrix3<f64>) -> Vector3<f64> {
    Vector3::new(
        0.5 * (m[(2, 1)] - m[(1, 2)]),
        0.5 * (m[(0, 2)] - m[(2, 0)]),
        0.5 * (m[(1, 0)] - m[(0, 1)]),
    )
}

/// The exponential map: the rotation by angle ‖φ‖ about φ/‖φ‖.
///
/// # Example
/// ```
/// use lidar_kinematics::so3;
/// use nalgebra::Vector3;
/// let q = so3::exp(&Vector3::new(0.0, 0.0, std::f64::consts::FRAC_PI_2));
/// assert!((q * Vector3::x() - Vector3::y()).norm() < 1e-15);
/// ```
pub fn exp(phi: &Vector3<f64>) -> UnitQuaternion<f64> {
    let mut theta = phi.norm();
    let scale = phi.amax();
    if theta.is_infinite() && scale.is_finite() {
        // ‖φ‖ above about 1.3e154: its square overflows, the norm itself does not.
        theta = scale * (phi / scale).norm();
    }
    let half = 0.5 * theta;
    // sin(θ/2)/θ, with its series for small θ.
    let k = if theta < 1e-4 {
        0.5 - theta * theta / 48.0
    } else {
        half.sin() / theta
    };
    let v = phi * k;
    UnitQuaternion::new_unchecked(Quaternion::new(half.cos(), v.x, v.y, v.z))
}

/// The logarithm map: the rotation vector φ with ‖φ‖ ∈ [0, π] and `exp(φ) = q`.
///
/// At exactly θ = π the two opposite rotation vectors are equally valid; the
/// one in the direction of the quaternion's vector part (with w ≥ 0) is returned.
///
/// # Example
/// ```
/// use lidar_kinematics::so3;
/// use nalgebra::{UnitQuaternion, Vector3};
/// let q = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 0.25);
/// assert!((so3::log(&q) - Vector3::new(0.0, 0.0, 0.25)).norm() < 1e-15);
/// ```
pub fn log(q: &UnitQuaternion<f64>) -> Vector3<f64> {
    let (mut w, mut v) = (q.w, q.imag());
    // q and −q are the same rotation; choose w ≥ 0 so θ ≤ π.
    if w < 0.0 {
        w = -w;
        v = -v;
    }
    let n = v.norm();
    // θ / n = 2 atan2(n, w) / n, with its series when n ≪ w (then w ≈ 1).
    let k = if n < 1e-8 * w {
        let x2 = n * n / (w * w);
        2.0 / w * (1.0 - x2 / 3.0)
    } else {
        2.0 * n.atan2(w) / n
    };
    v * k
}

/// The left Jacobian J_l(φ) = I + a(θ) φ̂ + b(θ) φ̂², with a = (1 − cos θ)/θ², b = (θ − sin θ)/θ³.
///
/// # Example
/// ```
/// use lidar_kinematics::so3;
/// use nalgebra::{Matrix3, Vector3};
/// assert_eq!(so3::left_jacobian(&Vector3::zeros()), Matrix3::identity());
/// ```
pub fn left_jacobian(phi: &Vector3<f64>) -> Matrix3<f64> {
    let theta = phi.norm();
    let p = hat(phi);
    Matrix3::identity() + p * series::a(theta) + p * p * series::b(theta)
}

/// The inverse left Jacobian J_l⁻¹(φ) = I − φ̂/2 + d(θ) φ̂², d = 1/θ² − cot(θ/2)/(2θ).
///
/// J_l is invertible for θ < 2π; rotation vectors from [`log`] have θ ≤ π.
/// It is singular at θ = 2π, 4π, …: there the result is not finite or, rounded, finite and
/// meaningless; use it only for θ < 2π.
///
/// # Example
/// ```
/// use lidar_kinematics::so3;
/// use nalgebra::{Matrix3, Vector3};
/// let phi = Vector3::new(3.0, 0.1, 0.0); // close to π
/// let e = so3::left_jacobian(&phi) * so3::left_jacobian_inv(&phi) - Matrix3::identity();
/// assert!(e.norm() < 1e-12);
/// ```
pub fn left_jacobian_inv(phi: &Vector3<f64>) -> Matrix3<f64> {
    let theta = phi.norm();
    let p = hat(phi);
    Matrix3::identity() - p * 0.5 + p * p * series::d(theta)
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use core::f64::consts::PI;
    use proptest::prelude::*;

    /// A rotation vector with a random axis and an angle from `angle`.
    pub(crate) fn rotation_vector(
        angle: impl Strategy<Value = f64>,
    ) -> impl Strategy<Value = Vector3<f64>> {
        (
            nalgebra::proptest::vector(-1.0f64..1.0, nalgebra::Const::<3>),
            angle,
        )
            .prop_filter_map("axis too short", |(axis, angle)| {
                let n = axis.norm();
                (n > 1e-3).then(|| axis / n * angle)
            })
    }

    /// Angles that exercise the small-angle series, the switch point and the region near π.
    fn interesting_angle() -> impl Strategy<Value = f64> {
        prop_oneof![
            0.0f64..PI - 1e-6,
            (-15i32..-1).prop_map(|e| 10f64.powi(e)),
            (0.0f64..1.0).prop_map(|s| 1.0 + (s - 0.5) * 1e-6),
            (-12i32..-2).prop_map(|e| PI - 10f64.powi(e)),
        ]
    }

    fn same_rotation(a: &UnitQuaternion<f64>, b: &UnitQuaternion<f64>) -> f64 {
        (a.coords - b.coords)
            .norm()
            .min((a.coords + b.coords).norm())
    }

    proptest! {
        #[test]
        fn log_of_exp_is_identity(phi in rotation_vector(interesting_angle())) {
            let back = log(&exp(&phi));
            prop_assert!((back - phi).norm() <= 1e-13 * phi.norm().max(1.0) + 1e-300,
                "phi {phi:?} back {back:?}");
        }

        #[test]
        fn exp_of_log_is_identity(phi in rotation_vector(interesting_angle())) {
            let q = UnitQuaternion::from_scaled_axis(phi);
            prop_assert!(same_rotation(&exp(&log(&q)), &q) < 1e-14);
        }

        #[test]
        fn exp_matches_nalgebra(phi in rotation_vector(0.0f64..10.0)) {
            prop_assert!(same_rotation(&exp(&phi), &UnitQuaternion::from_scaled_axis(phi)) < 1e-14);
        }

        /// exp(φ + h eᵢ) exp(φ)⁻¹ = exp(h J_l(φ) eᵢ + O(h²)), by central differences.
        #[test]
        fn left_jacobian_matches_finite_differences(phi in rotation_vector(interesting_angle())) {
            let j = left_jacobian(&phi);
            let h = 1e-6;
            let r_inv = exp(&phi).inverse();
            for i in 0..3 {
                let e = Vector3::ith(i, h);
                let plus = log(&(exp(&(phi + e)) * r_inv));
                let minus = log(&(exp(&(phi - e)) * r_inv));
                let fd = (plus - minus) / (2.0 * h);
                prop_assert!((fd - j.column(i)).norm() < 1e-8, "column {i}: fd {fd:?} vs {:?}", j.column(i));
            }
        }

        #[test]
        fn inverse_left_jacobian_is_inverse(phi in rotation_vector(interesting_angle())) {
            let e = left_jacobian(&phi) * left_jacobian_inv(&phi) - Matrix3::identity();
            prop_assert!(e.norm() < 1e-12, "residual {}", e.norm());
        }
    }

    #[test]
    fn log_at_exactly_pi_is_a_half_turn() {
        let q = UnitQuaternion::from_axis_angle(&Vector3::y_axis(), PI);
        let phi = log(&q);
        assert!((phi.norm() - PI).abs() < 1e-15);
        assert!(phi.normalize().cross(&Vector3::y()).norm() < 1e-15);
    }

    #[test]
    fn hat_vee_roundtrip() {
        let v = Vector3::new(-0.4, 7.0, 1e-9);
        assert_eq!(vee(&hat(&v)), v);
        assert_eq!(hat(&v).transpose(), -hat(&v));
    }
}
