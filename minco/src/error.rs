//! The crate's error type.

/// Everything that can go wrong in `minco`.
///
/// No function of this crate panics on bad input; each returns one of these variants.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum MincoError {
    /// The order is not one of 2 (minimum acceleration), 3 (jerk) or 4 (snap).
    #[error("order s = {0} is not supported: use 2, 3 or 4")]
    UnsupportedOrder(usize),
    /// A trajectory needs at least one piece.
    #[error("a trajectory needs at least one piece")]
    NoPieces,
    /// A dimension of zero.
    #[error("the dimension must be at least 1")]
    ZeroDimension,
    /// A duration that is zero, negative or not finite.
    #[error("duration {index} must be positive and finite, got {value} [s]")]
    BadDuration {
        /// Index of the piece.
        index: usize,
        /// The duration given \[s\].
        value: f64,
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
    /// The linear system is numerically singular (e.g. durations spanning too many orders of magnitude).
    #[error("the MINCO system is numerically singular at junction {junction}")]
    Singular {
        /// Junction (0-based, between pieces `junction` and `junction + 1`) whose pivot block
        /// failed, or 0 when the coefficients overflowed.
        junction: usize,
    },
    /// A gradient was requested before a successful solve.
    #[error("no solved trajectory: call solve first")]
    NotSolved,
    /// An optimiser setting out of range.
    #[error("invalid setting {what}: {reason}")]
    InvalidConfig {
        /// Which setting.
        what: &'static str,
        /// Why it is invalid.
        reason: &'static str,
    },
    /// A request that cannot be met, e.g. a time lookup outside the trajectory.
    #[error("infeasible request: {0}")]
    Infeasible(&'static str),
}

/// Shorthand for results of this crate.
pub type Result<T, E = MincoError> = core::result::Result<T, E>;
