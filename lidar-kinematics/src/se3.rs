//! The rigid-motion group SE(3): hat and vee, exponential and logarithm, left Jacobian, adjoint.
//!
//! Poses are [`Isometry3<f64>`]. Twists are [`Vector6<f64>`] ordered
//! **ξ = [v; ω]**: translational part first, rotational part last — the
//! ordering of the iCR paper's control u = [v; ω]. The hat operator maps
//! ξ to the 4 × 4 matrix `[[ω̂, v], [0, 0]]`.
//!
//! The left Jacobian 𝒥_l(ξ) is defined by
//! exp(ξ + δ) ≈ exp(𝒥_l(ξ) δ) · exp(ξ), so that (iCR Lemma 1)
//! ∂exp(τû)/∂uᵢ = τ (𝒥_l(τu) eᵢ)^ exp(τû).
//!
//! # Example
//! ```
//! use lidar_kinematics::se3;
//! use nalgebra::Vector6;
//!
//! let xi = Vector6::new(1.0, -0.5, 0.2, 0.1, 0.4, -2.5);
//! let pose = se3::exp(&xi);
//! assert!((se3::log(&pose) - xi).norm() < 1e-12);
//! ```

use nalgebra::{Isometry3, Matrix3, Matrix4, Matrix6, Translation3, Vector3, Vector6};

use crate::{series, so3};

/// Splits a twist into its translational part v and rotational part ω.
#[inline]
fn split(xi: &Vector6<f64>) -> (Vector3<f64>, Vector3<f64>) {
    (xi.fixed_rows::<3>(0).into(), xi.fixed_rows::<3>(3).into())
}

/// The 4 × 4 matrix ξ̂ = `[[ω̂, v], [0, 0]]` of the twist ξ = [v; ω].
///
/// # Example
/// ```
/// use lidar_kinematics::se3;
/// use nalgebra::Vector6;
/// let m = se3::hat(&Vector6::new(1.0, 2.0, 3.0, 0.0, 0.0, 0.5));
/// assert_eq!(m[(0, 3)], 1.0);
/// assert_eq!(m[(1, 0)], 0.5);
/// ```
pub fn hat(xi: &Vector6<f64>) -> Matrix4<f64> {
    let (v, w) = split(xi);
    let mut m = Matrix4::zeros();
    m.fixed_view_mut::<3, 3>(0, 0).copy_from(&so3::hat(&w));
    m.fixed_view_mut::<3, 1>(0, 3).copy_from(&v);
    m
}

/// The inverse of [`hat`]: reads v from the last column and ω from the skew-symmetric part
/// of the upper-left block (the bottom row is ignored).
///
/// # Example
/// ```
/// use lidar_kinematics::se3;
/// use nalgebra::Vector6;
/// let xi = Vector6::new(1.0, 2.0, 3.0, 0.1, 0.2, 0.3);
/// assert_eq!(se3::vee(&se3::hat(&xi)), xi);
/// ```
pub fn vee(m: &Matrix4<f64>) -> Vector6<f64> {
    let w = so3::vee(&m.fixed_view::<3, 3>(0, 0).into_owned());
    Vector6::new(m[(0, 3)], m[(1, 3)], m[(2, 3)], w.x, w.y, w.z)
}

/// The coupling block Q(v, ω) of the SE(3) left Jacobian.
fn q_block(v: &Vector3<f64>, w: &Vector3<f64>) -> Matrix3<f64> {
    let theta = w.norm();
    let (vh, wh) = (so3::hat(v), so3::hat(w));
    let wv = wh * vh;
    let vw = vh * wh;
    let wvw = wv * wh;
    vh * 0.5
        + (wv + vw + wvw) * series::b(theta)
        + (wh * wv + vw * wh - wvw * 3.0) * series::c2(theta)
        + (wvw * wh + wh * wvw) * series::c3(theta)
}

/// The exponential map: the pose reached by following the twist ξ = [v; ω] for unit time.
///
/// # Example
/// ```
/// use lidar_kinematics::se3;
/// use nalgebra::{Vector3, Vector6};
/// // A pure translation.
/// let pose = se3::exp(&Vector6::new(1.0, 2.0, 3.0, 0.0, 0.0, 0.0));
/// assert_eq!(pose.translation.vector, Vector3::new(1.0, 2.0, 3.0));
/// ```
pub fn exp(xi: &Vector6<f64>) -> Isometry3<f64> {
    let (v, w) = split(xi);
    let t = so3::left_jacobian(&w) * v;
    Isometry3::from_parts(Translation3::from(t), so3::exp(&w))
}

/// The logarithm map: the twist ξ = [v; ω] with ‖ω‖ ≤ π and `exp(ξ) = pose`.
///
/// # Example
/// ```
/// use lidar_kinematics::se3;
/// use nalgebra::{Isometry3, Vector3};
/// let pose = Isometry3::new(Vector3::new(1.0, 0.0, 0.0), Vector3::new(0.0, 0.0, 0.5));
/// assert!((se3::exp(&se3::log(&pose)).to_homogeneous() - pose.to_homogeneous()).norm() < 1e-14);
/// ```
pub fn log(pose: &Isometry3<f64>) -> Vector6<f64> {
    let w = so3::log(&pose.rotation);
    let v = so3::left_jacobian_inv(&w) * pose.translation.vector;
    Vector6::new(v.x, v.y, v.z, w.x, w.y, w.z)
}

/// The left Jacobian 𝒥_l(ξ) = `[[J_l(ω), Q(v, ω)], [0, J_l(ω)]]` (6 × 6, ordering [v; ω]).
///
/// # Example
/// ```
/// use lidar_kinematics::se3;
/// use nalgebra::{Matrix6, Vector6};
/// assert_eq!(se3::left_jacobian(&Vector6::zeros()), Matrix6::identity());
/// ```
pub fn left_jacobian(xi: &Vector6<f64>) -> Matrix6<f64> {
    let (v, w) = split(xi);
    let j = so3::left_jacobian(&w);
    let mut out = Matrix6::zeros();
    out.fixed_view_mut::<3, 3>(0, 0).copy_from(&j);
    out.fixed_view_mut::<3, 3>(3, 3).copy_from(&j);
    out.fixed_view_mut::<3, 3>(0, 3).copy_from(&q_block(&v, &w));
    out
}

/// The inverse left Jacobian `[[J⁻¹, −J⁻¹ Q J⁻¹], [0, J⁻¹]]`; finite for ‖ω‖ < 2π.
///
/// # Example
/// ```
/// use lidar_kinematics::se3;
/// use nalgebra::{Matrix6, Vector6};
/// let xi = Vector6::new(0.5, -1.0, 2.0, 0.3, 2.9, 0.1);
/// let e = se3::left_jacobian(&xi) * se3::left_jacobian_inv(&xi) - Matrix6::identity();
/// assert!(e.norm() < 1e-12);
/// ```
pub fn left_jacobian_inv(xi: &Vector6<f64>) -> Matrix6<f64> {
    let (v, w) = split(xi);
    let ji = so3::left_jacobian_inv(&w);
    let mut out = Matrix6::zeros();
    out.fixed_view_mut::<3, 3>(0, 0).copy_from(&ji);
    out.fixed_view_mut::<3, 3>(3, 3).copy_from(&ji);
    out.fixed_view_mut::<3, 3>(0, 3)
        .copy_from(&(-ji * q_block(&v, &w) * ji));
    out
}

/// The adjoint Ad_T = `[[R, t̂ R], [0, R]]`, with T exp(ξ) T⁻¹ = exp(Ad_T ξ).
///
/// # Example
/// ```
/// use lidar_kinematics::se3;
/// use nalgebra::{Isometry3, Vector3, Vector6};
/// let t = Isometry3::new(Vector3::new(1.0, 2.0, 3.0), Vector3::new(0.1, 0.2, 0.3));
/// let xi = Vector6::new(0.1, 0.0, 0.2, 0.0, 0.3, 0.0);
/// let lhs = (t * se3::exp(&xi) * t.inverse()).to_homogeneous();
/// let rhs = se3::exp(&(se3::adjoint(&t) * xi)).to_homogeneous();
/// assert!((lhs - rhs).norm() < 1e-12);
/// ```
pub fn adjoint(pose: &Isometry3<f64>) -> Matrix6<f64> {
    let r = pose.rotation.to_rotation_matrix().into_inner();
    let mut out = Matrix6::zeros();
    out.fixed_view_mut::<3, 3>(0, 0).copy_from(&r);
    out.fixed_view_mut::<3, 3>(3, 3).copy_from(&r);
    out.fixed_view_mut::<3, 3>(0, 3)
        .copy_from(&(so3::hat(&pose.translation.vector) * r));
    out
}

/// The pose `exp(ξ)` as a 4 × 4 homogeneous matrix (a convenience for matrix-form derivations).
///
/// # Example
/// ```
/// use lidar_kinematics::se3;
/// use nalgebra::{Matrix4, Vector6};
/// assert_eq!(se3::exp_matrix(&Vector6::zeros()), Matrix4::identity());
/// ```
pub fn exp_matrix(xi: &Vector6<f64>) -> Matrix4<f64> {
    exp(xi).to_homogeneous()
}

#[cfg(test)]
mod tests {
    use super::*;
    use core::f64::consts::PI;
    use nalgebra::UnitQuaternion;
    use proptest::prelude::*;

    fn twist(angle: impl Strategy<Value = f64>) -> impl Strategy<Value = Vector6<f64>> {
        (
            nalgebra::proptest::vector(-3.0f64..3.0, nalgebra::Const::<3>),
            crate::so3::tests::rotation_vector(angle),
        )
            .prop_map(|(v, w)| Vector6::new(v.x, v.y, v.z, w.x, w.y, w.z))
    }

    fn interesting_angle() -> impl Strategy<Value = f64> {
        prop_oneof![
            0.0f64..PI - 1e-6,
            (-15i32..-1).prop_map(|e| 10f64.powi(e)),
            (-10i32..-2).prop_map(|e| PI - 10f64.powi(e)),
        ]
    }

    proptest! {
        #[test]
        fn log_of_exp_is_identity(xi in twist(interesting_angle())) {
            let back = log(&exp(&xi));
            prop_assert!((back - xi).norm() < 1e-11 * xi.norm().max(1.0), "xi {xi:?} back {back:?}");
        }

        #[test]
        fn exp_of_log_is_identity(
            t in nalgebra::proptest::vector(-10.0f64..10.0, nalgebra::Const::<3>),
            rot in crate::so3::tests::rotation_vector(interesting_angle()),
        ) {
            let pose = Isometry3::from_parts(Translation3::from(t), UnitQuaternion::from_scaled_axis(rot));
            let back = exp(&log(&pose));
            prop_assert!((back.to_homogeneous() - pose.to_homogeneous()).norm() < 1e-11);
        }

        /// The matrix exponential series agrees with the closed form.
        #[test]
        fn exp_matches_matrix_series(xi in twist(0.0f64..PI)) {
            let m = hat(&xi);
            let mut term = Matrix4::identity();
            let mut sum = Matrix4::identity();
            for k in 1..60 {
                term = term * m / f64::from(k);
                sum += term;
            }
            prop_assert!((sum - exp_matrix(&xi)).norm() < 1e-10);
        }

        /// Lemma 1 of iCR: ∂exp(ξ̂)/∂ξᵢ = (𝒥_l(ξ) eᵢ)^ exp(ξ̂), by central differences.
        #[test]
        fn left_jacobian_matches_finite_differences(xi in twist(interesting_angle())) {
            let j = left_jacobian(&xi);
            let e_xi = exp_matrix(&xi);
            let h = 1e-6;
            for i in 0..6 {
                let e = Vector6::ith(i, h);
                let fd = (exp_matrix(&(xi + e)) - exp_matrix(&(xi - e))) / (2.0 * h);
                let analytic = hat(&j.column(i).into_owned()) * e_xi;
                prop_assert!((fd - analytic).norm() < 1e-7, "column {i}: {}", (fd - analytic).norm());
            }
        }

        #[test]
        fn inverse_left_jacobian_is_inverse(xi in twist(interesting_angle())) {
            let e = left_jacobian(&xi) * left_jacobian_inv(&xi) - Matrix6::identity();
            prop_assert!(e.norm() < 1e-10, "residual {}", e.norm());
        }
    }
}
