//! Sparse voxel occupancy mapping, incremental frontiers, viewpoints and dynamic clusters.
//!
//! Everything between "a new LiDAR frame arrived" and "here are the representative viewpoints
//! to visit", after Section IV-A of FU-MPC (equations (4)–(6)):
//!
//! - [`VoxelMap`]: sparse blocks of log-odds cells inside fixed [`Bounds`], frame insertion by
//!   3-D DDA returning the changed cells ([`FrameUpdate`]), state, line-of-sight and clearance
//!   queries;
//! - [`Frontiers`]: known-free cells with an unknown face neighbour, kept up to date from each
//!   [`FrameUpdate`], grouped into [`Cluster`]s (26-connected, split along the principal axis,
//!   with centre, axes, normal into free space, score and box);
//! - [`plan_targets`]: viewpoints in the hemisphere of each cluster's normal, the visibility
//!   ratio (4) through a caller's [`FieldOfView`], visible regions (5), dynamic clusters by the
//!   merge cost (6), one [`Target`] per dynamic cluster.
//!
//! # Example
//! ```
//! use frontier::{Bounds, CellState, FrontierConfig, Frontiers, MapConfig, VoxelMap};
//! use nalgebra::{Point3, Vector3};
//!
//! # fn main() -> Result<(), frontier::FrontierError> {
//! let bounds = Bounds::new(Point3::new(0.0, 0.0, 0.0), Point3::new(10.0, 10.0, 3.0))?;
//! let mut map = VoxelMap::new(bounds, MapConfig::default())?;
//! let mut frontiers = Frontiers::new(FrontierConfig::default())?;
//! // A wall 3 m ahead, seen through a narrow fan of rays.
//! let origin = Point3::new(2.0, 5.0, 1.5);
//! let points: Vec<_> = (-10..=10)
//!     .map(|i| Point3::new(5.05, 5.0 + 0.1 * f64::from(i), 1.5))
//!     .collect();
//! let update = map.insert_frame(&origin, &points)?;
//! assert_eq!(map.state(&Point3::new(5.05, 5.0, 1.5)), CellState::Occupied);
//! frontiers.update(&map, &update);
//! // The sides of the fan border unknown space.
//! assert!(frontiers.frontier_len() > 0);
//! # Ok(()) }
//! ```
#![forbid(unsafe_code)]
#![deny(missing_docs)]

mod error;
mod frontier;
mod grid;
mod map;
mod owners;
mod raycast;
mod viewpoint;

pub use error::{FrontierError, Result};
pub use frontier::{Cluster, ClusterId, FrontierConfig, FrontierDelta, Frontiers};
pub use grid::{Bounds, Cell, Grid, MAX_CELLS_PER_AXIS};
pub use map::{CellBox, CellChange, CellState, FrameUpdate, MAX_BLOCKS, MapConfig, VoxelMap};
pub use viewpoint::{
    ElevationBand, FieldOfView, MAX_CANDIDATES, Omnidirectional, Plan, Target, ViewpointConfig,
    cell_visible, plan_targets, plan_targets_among, sample_candidates, viewpoint_valid,
    visibility_ratio,
};

/// The README's example, compiled and run as a doctest.
#[cfg(doctest)]
#[doc = include_str!("../README.md")]
pub struct ReadmeDoctests;
