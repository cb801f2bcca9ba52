//! The crate's error type.

/// Everything that can go wrong in `frontier`.
///
/// No function of this crate panics on bad input; each returns one of these variants or a
/// documented fallback (bad points in a frame are counted and skipped, see
/// [`FrameUpdate`](crate::FrameUpdate)).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum FrontierError {
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
    /// Map bounds that are not finite or whose minimum is not below the maximum on every axis.
    #[error("map bounds must be finite with min < max on every axis")]
    InvalidBounds,
    /// Bounds and resolution that need more cells per axis than a cell index can address.
    #[error("the map needs {cells} cells along an axis; at most {max} are supported")]
    TooManyCells {
        /// Cells needed along the largest axis.
        cells: f64,
        /// The largest supported count.
        max: u32,
    },
    /// Bounds and resolution that need more blocks of 8 × 8 × 8 cells than
    /// [`MAX_BLOCKS`](crate::MAX_BLOCKS): the map keeps a directory entry for every block.
    #[error("the map needs {blocks} blocks of 8 x 8 x 8 cells; at most {max} are supported")]
    TooManyBlocks {
        /// Blocks needed to cover the bounds.
        blocks: u64,
        /// The largest supported count.
        max: u64,
    },
    /// A NaN or infinite input that cannot be skipped (a sensor origin, a query point).
    #[error("{what} is not finite")]
    NonFinite {
        /// Which input.
        what: &'static str,
    },
    /// A sensor origin outside the map bounds.
    #[error("the sensor origin is outside the map bounds")]
    OriginOutsideBounds,
}

/// `Result` with [`FrontierError`].
pub type Result<T, E = FrontierError> = core::result::Result<T, E>;
