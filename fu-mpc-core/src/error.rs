//! The crate's error type.

/// Everything that can go wrong in `fu-mpc-core`.
///
/// No function of this crate panics on bad input; each returns one of these variants or a
/// documented fallback.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum CoreError {
    /// A configuration value outside its documented range.
    #[error("invalid configuration: {what} = {value} ({reason})")]
    InvalidConfig {
        /// Which setting.
        what: &'static str,
        /// The value given.
        value: f64,
        /// What the value must satisfy.
        reason: &'static str,
    },
    /// A NaN or infinite input.
    #[error("{what} is not finite")]
    NonFinite {
        /// Which input.
        what: &'static str,
    },
    /// Inputs whose lengths do not agree.
    #[error("length mismatch for {what}: expected {expected}, found {found}")]
    LengthMismatch {
        /// Which input.
        what: &'static str,
        /// Expected length.
        expected: usize,
        /// Actual length.
        found: usize,
    },
    /// An input that must not be empty.
    #[error("{what} must not be empty")]
    Empty {
        /// Which input.
        what: &'static str,
    },
    /// A matrix that must be symmetric positive definite is not (e.g. a prior covariance).
    #[error("{what} is not positive definite")]
    NotPositiveDefinite {
        /// Which matrix.
        what: &'static str,
    },
    /// An error from the kinematic chain or motor model.
    #[error(transparent)]
    Kinematics(#[from] lidar_kinematics::KinematicsError),
}

/// `Result` with [`CoreError`].
pub type Result<T, E = CoreError> = core::result::Result<T, E>;

pub(crate) fn invalid<T>(what: &'static str, value: f64, reason: &'static str) -> Result<T> {
    Err(CoreError::InvalidConfig {
        what,
        value,
        reason,
    })
}

/// [`CoreError::InvalidConfig`] for a count above its limit.
pub(crate) fn too_large<T>(what: &'static str, count: usize, reason: &'static str) -> Result<T> {
    // Counts far above 2^53 round, which an error message can bear.
    #[allow(clippy::cast_precision_loss)]
    invalid(what, count as f64, reason)
}
