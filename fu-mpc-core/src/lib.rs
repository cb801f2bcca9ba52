//! Frontier- and uncertainty-aware MPC for a motorized LiDAR.
//!
//! The receding-horizon scan controller of FU-MPC (Section V, equations (10)–(21)):
//! [`predict_into`] predicts the scanning process along the UAV's reference,
//! [`FisherTable`] scores each motor angle by the localisation cost tr(F⁻¹) of the surface
//! normals it sees, [`frontier_surrogates`] scores it by the frontiers it sees, and [`FuMpc`]
//! chooses the motor's angular accelerations under its speed and acceleration limits.
//! [`FixedSpeed`], the single-term variants of [`FuMpc`] and the information-theoretic
//! [`icr::IcrScan`] are the baselines, all behind the [`ScanController`] trait; [`icr`] also
//! holds the iCR planner over SE(3) control sequences.
//!
//! # Example
//! ```
//! use fu_mpc_core::{FixedSpeed, FuMpc, MpcConfig, ScanController, ScanInput};
//! use lidar_kinematics::{KinematicChain, MotorState};
//! use nalgebra::Isometry3;
//!
//! # fn main() -> Result<(), fu_mpc_core::CoreError> {
//! let config = MpcConfig::default();
//! let reference = vec![Isometry3::identity(); config.horizon + 1];
//! let input = ScanInput { motor: MotorState::new(0.0, 1.0), reference: &reference, targets: &[], fisher: None };
//! let mut controllers: Vec<Box<dyn ScanController>> = vec![
//!     Box::new(FuMpc::new(config, KinematicChain::default())?),
//!     Box::new(FixedSpeed::new(100f64.to_radians(), config.limits, config.dt)?),
//! ];
//! for c in &mut controllers {
//!     let cmd = c.command(&input)?;
//!     assert!(cmd.acceleration.abs() <= config.limits.u_max(), "{}", c.name());
//! }
//! # Ok(()) }
//! ```
#![forbid(unsafe_code)]
#![deny(missing_docs)]

mod active_set;
mod controller;
mod error;
mod fastmath;
mod fisher;
mod fov_gap;
pub mod icr;
mod knn;
mod mpc;
mod predict;
mod pwl;
mod qp;
mod utility;

pub use controller::{FixedSpeed, ScanCommand, ScanController, ScanInput, ScanStatus};
pub use error::{CoreError, Result};
pub use fisher::{FisherConfig, FisherTable, least_eigen};
pub use mpc::{CostTerms, FuMpc, MpcConfig, MpcSolution, QpBackend};
pub use predict::{PredictedStep, predict_into};
pub use pwl::PeriodicPwl;
pub use utility::{FrontierTarget, UtilityConfig, frontier_surrogates};

/// Most steps a controller's horizon may have: 500 (50 s at the default Δt). The dedicated QP
/// solver stores about 7N² numbers per proximal level, 14 MB each at this size.
pub const MAX_HORIZON: usize = 500;

/// Most knots a cost table may have (motor angles 0.022° apart): settings above it would only
/// cost memory, N_c numbers per table.
pub const MAX_KNOTS: usize = 1 << 14;

/// Most iterations a solver's settings may ask for.
pub const MAX_ITERATIONS: usize = 100_000;

/// The README's example, compiled and run as a doctest.
#[cfg(doctest)]
#[doc = include_str!("../README.md")]
pub struct ReadmeDoctests;
