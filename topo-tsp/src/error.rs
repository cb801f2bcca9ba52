//! The crate's error type.

/// Everything that can go wrong in `topo-tsp`.
///
/// No function of this crate panics on bad input; each returns one of these variants.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum TspError {
    /// A cost matrix with no rows.
    #[error("the cost matrix is empty")]
    Empty,
    /// A cost matrix whose rows do not all have n entries.
    #[error("the cost matrix is not square: row {row} has {found} entries, expected {expected}")]
    NotSquare {
        /// Offending row.
        row: usize,
        /// Its length.
        found: usize,
        /// The number of rows.
        expected: usize,
    },
    /// A NaN, infinite or negative cost.
    #[error("cost ({row}, {col}) = {value} is not a finite non-negative number")]
    BadCost {
        /// Row.
        row: usize,
        /// Column.
        col: usize,
        /// The value.
        value: f64,
    },
    /// An instance too large for an exact solver, or for a [`crate::CostMatrix`] (more than
    /// [`crate::CostMatrix::MAX_LEN`] nodes).
    #[error("{solver} handles at most {max} nodes, got {n}")]
    TooLarge {
        /// Which solver, or `"CostMatrix"`.
        solver: &'static str,
        /// Its limit.
        max: usize,
        /// The instance size.
        n: usize,
    },
    /// A node index outside the graph or matrix.
    #[error("node {node} does not exist (size {size})")]
    NoSuchNode {
        /// The index.
        node: usize,
        /// The number of nodes.
        size: usize,
    },
    /// A NaN or infinite coordinate or parameter.
    #[error("{what} is not finite")]
    NonFinite {
        /// Which input.
        what: &'static str,
    },
    /// A setting out of range.
    #[error("invalid setting {what}: {reason}")]
    InvalidConfig {
        /// Which setting.
        what: &'static str,
        /// Why.
        reason: &'static str,
    },
    /// A TSPLIB text that cannot be parsed.
    #[error("TSPLIB parse error at line {line}: {reason}")]
    Parse {
        /// 1-based line number.
        line: usize,
        /// What went wrong.
        reason: String,
    },
}

/// Shorthand for results of this crate.
pub type Result<T, E = TspError> = core::result::Result<T, E>;
