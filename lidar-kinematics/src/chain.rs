//! The kinematic chain LiDAR → motor → motor base → body → world, eqs. (1)–(2), and the
//! scan direction (14).
//!
//! Frames (FU-MPC Section III-B): world 𝓕^W, body 𝓕^B, motor base 𝓕^MB, LiDAR 𝓕^L.
//! The motor turns the LiDAR about the z axis of 𝓕^MB by the angle θ, eq. (2), so
//!
//! r^W = R_B^W (R_MB^B (R_M^MB(θ) (R_L^M r^L + r_L^M)) + r_MB^B) + r_B^W.   eq. (1)
//!
//! # Example
//! ```
//! use lidar_kinematics::{Extrinsics, KinematicChain};
//! use nalgebra::{Isometry3, Point3, Vector3};
//!
//! # fn main() -> Result<(), lidar_kinematics::KinematicsError> {
//! // LiDAR 5 cm out along the motor's x axis; motor base 10 cm in front of the body.
//! let chain = KinematicChain::new(Extrinsics::try_new(
//!     Isometry3::translation(0.05, 0.0, 0.0),
//!     Isometry3::translation(0.10, 0.0, 0.0),
//! )?);
//! let body = Isometry3::translation(1.0, 2.0, 3.0);
//! let p = chain.lidar_to_world(&body, std::f64::consts::FRAC_PI_2, &Point3::new(1.0, 0.0, 0.0))?;
//! // A quarter turn sends the LiDAR's x axis along the body's y axis.
//! assert!((p - Point3::new(1.10, 3.05, 3.0)).norm() < 1e-12);
//! # Ok(()) }
//! ```

use nalgebra::{Isometry3, Matrix3, Point3, Translation3, Unit, UnitQuaternion, Vector3};

use crate::error::{KinematicsError, Result, check_finite, check_pose};
use crate::trig::{in_fast_range, sin_cos, sin_cos_reduced};

/// The constant extrinsics of eq. (1): the LiDAR in the motor frame and the motor base in the body.
///
/// Valid by construction: finite translations and unit rotations.
///
/// # Example
/// ```
/// use lidar_kinematics::Extrinsics;
/// use nalgebra::{Isometry3, Vector3};
/// let ok = Extrinsics::try_new(Isometry3::identity(), Isometry3::translation(0.1, 0.0, -0.05));
/// assert!(ok.is_ok());
/// let bad = Extrinsics::try_new(Isometry3::translation(f64::NAN, 0.0, 0.0), Isometry3::identity());
/// assert!(bad.is_err());
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Extrinsics {
    lidar_in_motor: Isometry3<f64>,
    motor_base_in_body: Isometry3<f64>,
}

impl Extrinsics {
    /// Validates and builds the extrinsics (R_L^M, r_L^M) and (R_MB^B, r_MB^B).
    ///
    /// # Errors
    /// [`KinematicsError::NonFinite`] for non-finite entries,
    /// [`KinematicsError::NotUnitRotation`] for a quaternion whose norm is not 1 (to 1e-6).
    pub fn try_new(
        lidar_in_motor: Isometry3<f64>,
        motor_base_in_body: Isometry3<f64>,
    ) -> Result<Self> {
        check_pose(&lidar_in_motor, "LiDAR-in-motor extrinsic")?;
        check_pose(&motor_base_in_body, "motor-base-in-body extrinsic")?;
        Ok(Self {
            lidar_in_motor,
            motor_base_in_body,
        })
    }

    /// Both extrinsics the identity: all four frames share an origin at θ = 0.
    pub fn identity() -> Self {
        Self {
            lidar_in_motor: Isometry3::identity(),
            motor_base_in_body: Isometry3::identity(),
        }
    }

    /// The LiDAR's pose in the motor frame, (R_L^M, r_L^M).
    pub fn lidar_in_motor(&self) -> &Isometry3<f64> {
        &self.lidar_in_motor
    }

    /// The motor base's pose in the body frame, (R_MB^B, r_MB^B).
    pub fn motor_base_in_body(&self) -> &Isometry3<f64> {
        &self.motor_base_in_body
    }
}

impl Default for Extrinsics {
    fn default() -> Self {
        Self::identity()
    }
}

/// The motor rotation R_M^MB(θ) of eq. (2): a rotation by θ \[rad\] about z.
///
/// # Example
/// ```
/// use lidar_kinematics::motor_rotation;
/// use nalgebra::Vector3;
/// let r = motor_rotation(std::f64::consts::PI);
/// assert!((r * Vector3::x() + Vector3::x()).norm() < 1e-15);
/// ```
pub fn motor_rotation(theta: f64) -> UnitQuaternion<f64> {
    UnitQuaternion::from_axis_angle(&Vector3::z_axis(), theta)
}

/// An affine map x ↦ m x + t held as a plain matrix, for the batched hot paths.
#[derive(Debug, Clone, Copy)]
struct Affine {
    m: Matrix3<f64>,
    t: Vector3<f64>,
}

impl Affine {
    fn from_isometry(iso: &Isometry3<f64>) -> Self {
        Self {
            m: iso.rotation.to_rotation_matrix().into_inner(),
            t: iso.translation.vector,
        }
    }

    #[inline(always)]
    fn apply(&self, p: &Vector3<f64>) -> Vector3<f64> {
        self.m * p + self.t
    }

    /// Maps `src` into `dst` (equal lengths, checked by the caller).
    fn apply_all(&self, src: &[Point3<f64>], dst: &mut [Point3<f64>]) {
        for (d, s) in dst.iter_mut().zip(src) {
            d.coords = self.apply(&s.coords);
        }
    }
}

/// The kinematic chain of eq. (1) for one set of extrinsics.
///
/// Frames (FU-MPC Section III-B): world 𝓕^W, body 𝓕^B, motor base 𝓕^MB, LiDAR 𝓕^L.
/// The motor turns the LiDAR about the z axis of 𝓕^MB by the angle θ, eq. (2), so
///
/// r^W = R_B^W (R_MB^B (R_M^MB(θ) (R_L^M r^L + r_L^M)) + r_MB^B) + r_B^W.   eq. (1)
///
/// All methods validate their pose and angle arguments and return
/// [`KinematicsError::NonFinite`] or [`KinematicsError::NotUnitRotation`] for bad ones.
/// Point coordinates are data, not checked: a non-finite point maps to a non-finite point.
///
/// # Example
/// ```
/// use lidar_kinematics::{Extrinsics, KinematicChain};
/// use nalgebra::{Isometry3, Point3};
/// # fn main() -> Result<(), lidar_kinematics::KinematicsError> {
/// let chain = KinematicChain::new(Extrinsics::identity());
/// let body = Isometry3::translation(0.0, 0.0, 1.0);
/// let p = Point3::new(2.0, 0.0, 0.0);
/// let w = chain.lidar_to_world(&body, 0.3, &p)?;
/// assert!((chain.world_to_lidar(&body, 0.3, &w)? - p).norm() < 1e-12);
/// # Ok(()) }
/// ```
#[derive(Debug, Clone, Copy)]
pub struct KinematicChain {
    extrinsics: Extrinsics,
    lidar_in_motor: Affine,
}

impl Default for KinematicChain {
    fn default() -> Self {
        Self::new(Extrinsics::identity())
    }
}

impl KinematicChain {
    /// A chain for validated extrinsics.
    pub fn new(extrinsics: Extrinsics) -> Self {
        Self {
            lidar_in_motor: Affine::from_isometry(&extrinsics.lidar_in_motor),
            extrinsics,
        }
    }

    /// The chain's extrinsics.
    pub fn extrinsics(&self) -> &Extrinsics {
        &self.extrinsics
    }

    /// The LiDAR's pose in the body frame at motor angle θ \[rad\]: T_MB^B · R_M^MB(θ) · T_L^M.
    ///
    /// # Errors
    /// [`KinematicsError::NonFinite`] for a non-finite angle.
    pub fn lidar_in_body(&self, theta: f64) -> Result<Isometry3<f64>> {
        check_finite(theta, "motor angle")?;
        let e = &self.extrinsics;
        Ok(e.motor_base_in_body
            * Isometry3::from_parts(Translation3::identity(), motor_rotation(theta))
            * e.lidar_in_motor)
    }

    /// The LiDAR's pose in the world for a body pose T_B^W and motor angle θ \[rad\].
    ///
    /// # Errors
    /// As the type documents for bad poses and angles.
    pub fn lidar_pose(&self, body_pose: &Isometry3<f64>, theta: f64) -> Result<Isometry3<f64>> {
        check_pose(body_pose, "body pose")?;
        Ok(body_pose * self.lidar_in_body(theta)?)
    }

    /// Maps one point from the LiDAR frame to the world frame, eq. (1).
    ///
    /// # Errors
    /// As the type documents for bad poses and angles.
    pub fn lidar_to_world(
        &self,
        body_pose: &Isometry3<f64>,
        theta: f64,
        point: &Point3<f64>,
    ) -> Result<Point3<f64>> {
        Ok(self.lidar_pose(body_pose, theta)? * point)
    }

    /// Maps one point from the world frame to the LiDAR frame: the inverse of eq. (1).
    ///
    /// # Errors
    /// As the type documents for bad poses and angles.
    pub fn world_to_lidar(
        &self,
        body_pose: &Isometry3<f64>,
        theta: f64,
        point: &Point3<f64>,
    ) -> Result<Point3<f64>> {
        Ok(self
            .lidar_pose(body_pose, theta)?
            .inverse_transform_point(point))
    }

    /// Maps many LiDAR-frame points, all at one motor angle, to the world frame.
    ///
    /// # Errors
    /// [`KinematicsError::LengthMismatch`] unless `src` and `dst` have equal lengths,
    /// and as the type documents for bad poses and angles.
    pub fn lidar_to_world_batch(
        &self,
        body_pose: &Isometry3<f64>,
        theta: f64,
        src: &[Point3<f64>],
        dst: &mut [Point3<f64>],
    ) -> Result<()> {
        check_len("destination points", src.len(), dst.len())?;
        Affine::from_isometry(&self.lidar_pose(body_pose, theta)?).apply_all(src, dst);
        Ok(())
    }

    /// Maps many points, all at one motor angle, from the LiDAR frame to the world frame in place.
    ///
    /// # Errors
    /// As the type documents for bad poses and angles.
    pub fn lidar_to_world_in_place(
        &self,
        body_pose: &Isometry3<f64>,
        theta: f64,
        points: &mut [Point3<f64>],
    ) -> Result<()> {
        let a = Affine::from_isometry(&self.lidar_pose(body_pose, theta)?);
        for p in points.iter_mut() {
            p.coords = a.apply(&p.coords);
        }
        Ok(())
    }

    /// Maps many world-frame points, all at one motor angle, to the LiDAR frame.
    ///
    /// # Errors
    /// [`KinematicsError::LengthMismatch`] unless `src` and `dst` have equal lengths,
    /// and as the type documents for bad poses and angles.
    pub fn world_to_lidar_batch(
        &self,
        body_pose: &Isometry3<f64>,
        theta: f64,
        src: &[Point3<f64>],
        dst: &mut [Point3<f64>],
    ) -> Result<()> {
        check_len("destination points", src.len(), dst.len())?;
        Affine::from_isometry(&self.lidar_pose(body_pose, theta)?.inverse()).apply_all(src, dst);
        Ok(())
    }

    /// Maps LiDAR-frame points to the world frame, each at its own motor angle `thetas[i]`,
    /// all with one body pose (e.g. a frame taken while hovering).
    ///
    /// # Errors
    /// [`KinematicsError::LengthMismatch`] unless all three slices have equal lengths,
    /// [`KinematicsError::NonFinite`] if any angle is not finite (then `dst` is unchanged),
    /// and as the type documents for a bad pose.
    pub fn lidar_to_world_per_point(
        &self,
        body_pose: &Isometry3<f64>,
        thetas: &[f64],
        src: &[Point3<f64>],
        dst: &mut [Point3<f64>],
    ) -> Result<()> {
        check_len("motor angles", src.len(), thetas.len())?;
        check_len("destination points", src.len(), dst.len())?;
        check_pose(body_pose, "body pose")?;
        if thetas.iter().any(|t| !t.is_finite()) {
            return Err(KinematicsError::NonFinite {
                what: "motor angle",
            });
        }
        let body_mb = Affine::from_isometry(&(body_pose * self.extrinsics.motor_base_in_body));
        if thetas.iter().all(|&t| in_fast_range(t)) {
            for ((d, s), &theta) in dst.iter_mut().zip(src).zip(thetas) {
                d.coords = self.motor_point_to(&body_mb, sin_cos_reduced(theta), &s.coords);
            }
        } else {
            for ((d, s), &theta) in dst.iter_mut().zip(src).zip(thetas) {
                d.coords = self.motor_point_to(&body_mb, sin_cos(theta), &s.coords);
            }
        }
        Ok(())
    }

    /// `outer · R_z(θ) · T_L^M · p` for (sin θ, cos θ): the chain from the LiDAR through the
    /// motor to the frame of `outer`.
    #[inline(always)]
    fn motor_point_to(
        &self,
        outer: &Affine,
        sin_cos_theta: (f64, f64),
        p: &Vector3<f64>,
    ) -> Vector3<f64> {
        outer.apply(&self.lidar_to_motor_unchecked(sin_cos_theta, p))
    }

    /// R_M^MB(θ) T_L^M p: the LiDAR point in the motor base frame, before the motor-base
    /// extrinsic, for the motor angle's (sin θ, cos θ) (no checks; hot paths).
    #[inline(always)]
    pub(crate) fn lidar_to_motor_unchecked(
        &self,
        (s, c): (f64, f64),
        p: &Vector3<f64>,
    ) -> Vector3<f64> {
        let m = self.lidar_in_motor.apply(p);
        // eq. (2)
        Vector3::new(c * m.x - s * m.y, s * m.x + c * m.y, m.z)
    }

    /// The principal scan direction d^W of eq. (14) for a body attitude and motor angle θ \[rad\]:
    /// R_B^W R_MB^B [cos θ, sin θ, 0]ᵀ.
    ///
    /// This is the motor frame's x axis in the world. Eq. (14) leaves out R_L^M: the direction
    /// is where the motor points, whatever way the LiDAR sits on it.
    ///
    /// # Errors
    /// [`KinematicsError::NonFinite`] for a non-finite angle or attitude,
    /// [`KinematicsError::NotUnitRotation`] for a non-unit attitude quaternion.
    ///
    /// # Example
    /// ```
    /// use lidar_kinematics::KinematicChain;
    /// use nalgebra::{UnitQuaternion, Vector3};
    /// # fn main() -> Result<(), lidar_kinematics::KinematicsError> {
    /// let chain = KinematicChain::default();
    /// let yaw90 = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), std::f64::consts::FRAC_PI_2);
    /// let d = chain.scan_direction(&yaw90, 0.0)?;
    /// assert!((d.into_inner() - Vector3::y()).norm() < 1e-15);
    /// # Ok(()) }
    /// ```
    pub fn scan_direction(
        &self,
        body_attitude: &UnitQuaternion<f64>,
        theta: f64,
    ) -> Result<Unit<Vector3<f64>>> {
        check_finite(theta, "motor angle")?;
        check_pose(
            &Isometry3::from_parts(Translation3::identity(), *body_attitude),
            "body attitude",
        )?;
        let (s, c) = sin_cos(theta);
        // eq. (14)
        let d =
            body_attitude * (self.extrinsics.motor_base_in_body.rotation * Vector3::new(c, s, 0.0));
        // A rotated unit vector: unit up to rounding, so it is not renormalised (the tests
        // check the norm).
        Ok(Unit::new_unchecked(d))
    }
}

pub(crate) fn check_len(what: &'static str, expected: usize, found: usize) -> Result<()> {
    if expected == found {
        Ok(())
    } else {
        Err(KinematicsError::LengthMismatch {
            what,
            expected,
            found,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn pose() -> impl Strategy<Value = Isometry3<f64>> {
        (
            nalgebra::proptest::vector(-50.0f64..50.0, nalgebra::Const::<3>),
            nalgebra::proptest::vector(-3.0f64..3.0, nalgebra::Const::<3>),
        )
            .prop_map(|(t, r)| Isometry3::new(t, r))
    }

    fn chain() -> impl Strategy<Value = KinematicChain> {
        (pose(), pose()).prop_map(|(a, b)| {
            let small = |p: Isometry3<f64>| {
                Isometry3::from_parts(Translation3::from(p.translation.vector * 0.01), p.rotation)
            };
            KinematicChain::new(Extrinsics::try_new(small(a), small(b)).unwrap())
        })
    }

    fn point() -> impl Strategy<Value = Point3<f64>> {
        nalgebra::proptest::vector(-100.0f64..100.0, nalgebra::Const::<3>).prop_map(Point3::from)
    }

    /// Eq. (1) written out literally, as the reference.
    fn eq1(
        chain: &KinematicChain,
        body: &Isometry3<f64>,
        theta: f64,
        p: &Point3<f64>,
    ) -> Point3<f64> {
        let e = chain.extrinsics();
        let r_lm = e.lidar_in_motor().rotation.to_rotation_matrix();
        let r_mbb = e.motor_base_in_body().rotation.to_rotation_matrix();
        let r_bw = body.rotation.to_rotation_matrix();
        let r_m = motor_rotation(theta).to_rotation_matrix();
        Point3::from(
            r_bw * (r_mbb * (r_m * (r_lm * p.coords + e.lidar_in_motor().translation.vector))
                + e.motor_base_in_body().translation.vector)
                + body.translation.vector,
        )
    }

    proptest! {
        #[test]
        fn world_lidar_world_round_trip(chain in chain(), body in pose(), theta in -50.0f64..50.0, p in point()) {
            let w = chain.lidar_to_world(&body, theta, &p).unwrap();
            prop_assert!((w - eq1(&chain, &body, theta, &p)).norm() < 1e-10);
            let back = chain.world_to_lidar(&body, theta, &w).unwrap();
            prop_assert!((back - p).norm() < 1e-10);
        }

        #[test]
        fn batch_paths_agree(chain in chain(), body in pose(), theta in -50.0f64..50.0,
                             pts in proptest::collection::vec(point(), 0..20)) {
            let mut a = vec![Point3::origin(); pts.len()];
            chain.lidar_to_world_batch(&body, theta, &pts, &mut a).unwrap();
            let thetas = vec![theta; pts.len()];
            let mut b = vec![Point3::origin(); pts.len()];
            chain.lidar_to_world_per_point(&body, &thetas, &pts, &mut b).unwrap();
            let mut c = pts.clone();
            chain.lidar_to_world_in_place(&body, theta, &mut c).unwrap();
            let mut back = vec![Point3::origin(); pts.len()];
            chain.world_to_lidar_batch(&body, theta, &a, &mut back).unwrap();
            for i in 0..pts.len() {
                let r = eq1(&chain, &body, theta, &pts[i]);
                prop_assert!((a[i] - r).norm() < 1e-10);
                prop_assert!((b[i] - r).norm() < 1e-10);
                prop_assert!((c[i] - r).norm() < 1e-10);
                prop_assert!((back[i] - pts[i]).norm() < 1e-10);
            }
        }

        #[test]
        fn scan_direction_is_unit_and_continuous(chain in chain(), body in pose(), theta in -50.0f64..50.0) {
            let d = chain.scan_direction(&body.rotation, theta).unwrap();
            prop_assert!((d.norm() - 1.0).abs() < 1e-12);
            let h = 1e-7;
            let d2 = chain.scan_direction(&body.rotation, theta + h).unwrap();
            // |d(θ+h) − d(θ)| = 2 sin(h/2) ≤ h for a unit circle traced at unit speed.
            prop_assert!((d2.into_inner() - d.into_inner()).norm() <= h * (1.0 + 1e-6));
            // It is the motor frame's x axis in the world.
            let x_m = (body * chain.extrinsics().motor_base_in_body()).rotation * motor_rotation(theta) * Vector3::x();
            prop_assert!((d.into_inner() - x_m).norm() < 1e-12);
        }
    }

    #[test]
    fn bad_input_is_a_typed_error() {
        use KinematicsError as E;
        let chain = KinematicChain::default();
        let nan_pose = Isometry3::translation(f64::NAN, 0.0, 0.0);
        let p = Point3::origin();
        assert!(matches!(
            chain.lidar_to_world(&nan_pose, 0.0, &p),
            Err(E::NonFinite { .. })
        ));
        assert!(matches!(
            chain.lidar_to_world(&Isometry3::identity(), f64::INFINITY, &p),
            Err(E::NonFinite { .. })
        ));
        let mut bad_rot = Isometry3::identity();
        bad_rot.rotation =
            UnitQuaternion::new_unchecked(nalgebra::Quaternion::new(2.0, 0.0, 0.0, 0.0));
        assert!(matches!(
            chain.lidar_pose(&bad_rot, 0.0),
            Err(E::NotUnitRotation { .. })
        ));
        assert!(matches!(
            Extrinsics::try_new(bad_rot, Isometry3::identity()),
            Err(E::NotUnitRotation { .. })
        ));
        let src = [p; 3];
        let mut dst = [p; 2];
        assert!(matches!(
            chain.lidar_to_world_batch(&Isometry3::identity(), 0.0, &src, &mut dst),
            Err(E::LengthMismatch { .. })
        ));
        let mut dst3 = [p; 3];
        assert!(matches!(
            chain.lidar_to_world_per_point(&Isometry3::identity(), &[0.0; 2], &src, &mut dst3),
            Err(E::LengthMismatch { .. })
        ));
        assert!(matches!(
            chain.lidar_to_world_per_point(
                &Isometry3::identity(),
                &[0.0, f64::NAN, 0.0],
                &src,
                &mut dst3
            ),
            Err(E::NonFinite { .. })
        ));
        assert!(matches!(
            chain.scan_direction(&UnitQuaternion::identity(), f64::NAN),
            Err(E::NonFinite { .. })
        ));
    }
}
