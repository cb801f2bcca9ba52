//! The crate's error type.

/// Everything that can go wrong in `lidar-kinematics`.
///
/// No function of this crate panics on bad input; each returns one of these
/// variants instead. The variants carry the offending values so a caller can
/// log them without extra bookkeeping.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum KinematicsError {
    /// A pose, angle, time or parameter was NaN or infinite.
    #[error("{what} is not finite")]
    NonFinite {
        /// Which input was not finite.
        what: &'static str,
    },
    /// A rotation given as a quaternion was not of unit norm.
    #[error("{what} is not a unit rotation (quaternion norm {norm})")]
    NotUnitRotation {
        /// Which input was not a rotation.
        what: &'static str,
        /// The quaternion's norm.
        norm: f64,
    },
    /// Motor speed limits with `omega_min > omega_max`.
    #[error(
        "motor speed limits are inverted: omega_min {omega_min} > omega_max {omega_max} [rad/s]"
    )]
    InvertedSpeedLimits {
        /// Lower speed limit [rad/s].
        omega_min: f64,
        /// Upper speed limit [rad/s].
        omega_max: f64,
    },
    /// A negative acceleration limit.
    #[error("motor acceleration limit must be non-negative, got {0} [rad/s^2]")]
    NegativeAccelerationLimit(f64),
    /// A time step that is zero or negative.
    #[error("time step must be positive, got {0} [s]")]
    NonPositiveDt(f64),
    /// An input sequence that must hold at least one element was empty.
    #[error("{what} is empty")]
    Empty {
        /// Which input was empty.
        what: &'static str,
    },
    /// Time-stamped samples whose times do not strictly increase.
    #[error("{what} are not strictly increasing in time at index {index}")]
    Unsorted {
        /// Which samples.
        what: &'static str,
        /// Index of the first sample whose time is not after its predecessor's.
        index: usize,
    },
    /// Two sequences that must have the same length do not.
    #[error("length mismatch for {what}: expected {expected}, found {found}")]
    LengthMismatch {
        /// Which input had the wrong length.
        what: &'static str,
        /// The length it should have had.
        expected: usize,
        /// The length it had.
        found: usize,
    },
    /// A query time outside the span covered by time-stamped samples.
    #[error("time {time} [s] is outside [{start}, {end}] covered by {what}")]
    TimeOutOfRange {
        /// Which samples were queried.
        what: &'static str,
        /// The query time \[s\].
        time: f64,
        /// First sample time \[s\].
        start: f64,
        /// Last sample time \[s\].
        end: f64,
    },
    /// Range limits with `min < 0` or `min >= max`.
    #[error("invalid range limits [{min}, {max}] [m]: need 0 <= min < max")]
    InvalidRange {
        /// Minimum range \[m\].
        min: f64,
        /// Maximum range \[m\].
        max: f64,
    },
    /// A beam pattern, field of view or encoder with impossible parameters.
    #[error("invalid {what}: {reason}")]
    InvalidParameter {
        /// Which parameter.
        what: &'static str,
        /// Why it is invalid.
        reason: &'static str,
    },
}

/// Shorthand for results of this crate.
pub type Result<T, E = KinematicsError> = core::result::Result<T, E>;

/// Returns `Err(NonFinite)` unless `x` is finite.
pub(crate) fn check_finite(x: f64, what: &'static str) -> Result<f64> {
    if x.is_finite() {
        Ok(x)
    } else {
        Err(KinematicsError::NonFinite { what })
    }
}

/// Checks a pose for finite entries and a unit rotation (to 1e-6).
pub(crate) fn check_pose(pose: &nalgebra::Isometry3<f64>, what: &'static str) -> Result<()> {
    let t = &pose.translation.vector;
    let q = pose.rotation.quaternion();
    if !(t.iter().all(|v| v.is_finite()) && q.coords.iter().all(|v| v.is_finite())) {
        return Err(KinematicsError::NonFinite { what });
    }
    let norm = q.norm();
    if (norm - 1.0).abs() > 1e-6 {
        return Err(KinematicsError::NotUnitRotation { what, norm });
    }
    Ok(())
}
