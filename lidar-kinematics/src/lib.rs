//! Kinematics of a LiDAR that spins on a motor mounted on a UAV.
//!
//! This crate is the geometric base of the FU-MPC crate family. A point measured
//! in the LiDAR frame reaches the world frame through the chain (FU-MPC eq. (1))
//!
//! r^W = R_B^W (R_MB^B (R_M^MB(θ) (R_L^M r^L + r_L^M)) + r_MB^B) + r_B^W,
//!
//! where θ is the motor angle, R_M^MB(θ) a rotation about the motor base's z axis
//! (eq. (2)) and the two extrinsics are constant. The crate provides:
//!
//! - [`so3`] and [`se3`]: hat/vee, exp/log, left Jacobians (and the SE(3) adjoint),
//!   accurate near the identity and near a half turn; twists are ordered [v; ω];
//! - [`KinematicChain`]: eq. (1) for single points and batches, at one motor angle or per point,
//!   and the scan direction d^W of eq. (14);
//! - [`MotorModel`]: the speed-commanded model (3) and the acceleration-commanded model
//!   (11)–(12) with saturation, one step or a rollout; [`angle`] helpers; an [`Encoder`] model;
//! - [`LidarSensor`]: beam patterns as data (spinning multi-ring and Mid-360-like
//!   non-repetitive), range limits, field of view and a visibility gate;
//! - [`Deskewer`]: per-point motion compensation of a frame.
//!
//! Everything is `f64` and nalgebra. Nothing panics on bad input: NaN or infinite
//! poses, angles and times, inverted limits, non-positive time steps, unsorted or
//! empty samples and mismatched lengths return a [`KinematicsError`].
//!
//! # Example
//! ```
//! use lidar_kinematics::{Extrinsics, KinematicChain, MotorLimits, MotorModel, MotorState};
//! use nalgebra::{Isometry3, Point3, UnitQuaternion, Vector3};
//!
//! # fn main() -> Result<(), lidar_kinematics::KinematicsError> {
//! // The LiDAR sits on its side on the motor; the motor base is 12 cm ahead of the body.
//! let chain = KinematicChain::new(Extrinsics::try_new(
//!     Isometry3::rotation(Vector3::new(std::f64::consts::FRAC_PI_2, 0.0, 0.0)),
//!     Isometry3::translation(0.12, 0.0, 0.0),
//! )?);
//! let motor = MotorModel::new(MotorLimits::try_new(-6.0, 6.0, 10.0)?);
//!
//! // Spin up for half a second, then map a return 8 m along the LiDAR's x axis.
//! let states = motor.rollout(MotorState::default(), &[10.0; 5], 0.1)?;
//! let theta = states[5].theta;
//! let body = Isometry3::from_parts(Vector3::new(0.0, 0.0, 1.5).into(), UnitQuaternion::identity());
//! let p = chain.lidar_to_world(&body, theta, &Point3::new(8.0, 0.0, 0.0))?;
//! let d = chain.scan_direction(&body.rotation, theta)?;
//! // The return lies along the scan direction, offset by the lever arm.
//! assert!(((p - body.translation.vector - Vector3::new(0.12, 0.0, 0.0)).coords - d.into_inner() * 8.0).norm() < 1e-12);
//! # Ok(()) }
//! ```
#![forbid(unsafe_code)]
#![deny(missing_docs)]
#![warn(rustdoc::broken_intra_doc_links)]

pub mod angle;
mod chain;
mod deskew;
mod encoder;
mod error;
mod motor;
pub mod se3;
mod sensor;
mod series;
pub mod so3;
mod trig;

pub use chain::{Extrinsics, KinematicChain, motor_rotation};
pub use deskew::{AngleSample, DeskewTarget, Deskewer, PoseSample, TimedPoint, interpolate_pose};
pub use encoder::{Encoder, EncoderConfig, EncoderReading};
pub use error::{KinematicsError, Result};
pub use motor::{MotorLimits, MotorModel, MotorState};
pub use sensor::{
    Beam, BeamPattern, FieldOfView, Frame, LidarSensor, MAX_POINTS_PER_FRAME, NonRepetitivePattern,
    RangeLimits, SpinningPattern, VisibilityGate,
};

/// The README's example, compiled and run as a doctest.
#[cfg(doctest)]
#[doc = include_str!("../README.md")]
pub struct ReadmeDoctests;
