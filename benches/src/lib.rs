//! Criterion benchmarks of the FU-MPC crate family (no library API; see `benches/`).
//!
//! Run all with `cargo bench -p fu-mpc-benches`, one file with
//! `cargo bench -p fu-mpc-benches --bench lidar_kinematics`.
