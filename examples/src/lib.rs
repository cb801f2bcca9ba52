//! The simulator the FU-MPC explorer flies in, and the metrics of the paper's evaluation.
//!
//! This crate is the project's test bench, not a library to publish: it may read and write
//! files. Today it holds the trajectory metrics ([`metrics`]), the world queries over parry3d
//! ([`world`]), PCD scene loading ([`cloud_io`]) and generated scenes with their explorable
//! space ([`scene`]), the simulated LiDAR ([`lidar`]), and the UAV's flat attitude and IMU
//! ([`uav`]), point-to-plane registration ([`registration`]) and the LiDAR-inertial odometry built on
//! it ([`odometry`]), a whole flight along a fixed route ([`flight`]), and the iCR paper's
//! 2-D experiment ([`icr2d`]); the explorer follows.
#![forbid(unsafe_code)]
#![deny(missing_docs)]

mod box_grid;
pub mod cloud_io;
pub mod explorer;
pub mod flight;
pub mod icr2d;
pub mod lidar;
pub mod metrics;
mod mission;
pub mod odometry;
pub mod plot;
pub mod registration;
pub mod report;
pub mod rng;
pub mod scene;
pub mod setup;
pub mod uav;
pub mod world;
