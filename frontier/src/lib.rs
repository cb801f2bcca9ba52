//! Sparse voxel occupancy mapping, incremental frontiers, viewpoints and dynamic clusters.
#![forbid(unsafe_code)]
#![deny(missing_docs)]

mod error;
mod frontier;
mod grid;
mod map;
mod raycast;
mod viewpoint;

pub use error::{FrontierError, Result};
pub use frontier::{Cluster, ClusterId, FrontierConfig, FrontierDelta, Frontiers};
pub use grid::{Bounds, Cell, Grid, MAX_CELLS_PER_AXIS};
pub use map::{CellBox, CellChange, CellState, FrameUpdate, MapConfig, VoxelMap};
pub use viewpoint::{
    ElevationBand, FieldOfView, Omnidirectional, Plan, Target, ViewpointConfig, cell_visible,
    plan_targets, sample_candidates, viewpoint_valid, visibility_ratio,
};

/// The README's example, compiled and run as a doctest.
#[cfg(doctest)]
#[doc = include_str!("../README.md")]
pub struct ReadmeDoctests;
