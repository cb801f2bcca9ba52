//! iCR: iterative covariance regulation over SE(3) control sequences (Koga, Asgharivaskasi,
//! Atanasov), and a scan controller built on its differentiable field of view.
//!
//! The module is named after the method, as the paper names it: active mapping by gradient
//! ascent of r(U) = log det Y_K, eq. (8), over a control sequence U on SE(3).
//!
//! - [`Triangle`], [`Cone`]: signed distance functions of a 2-D and a 3-D field of view with
//!   their gradients, eq. (18) and Lemma 2; [`Probit`]: the smoothed step of eq. (20), giving
//!   the differentiable inverse noise V⁻¹_jj of eq. (21);
//! - [`InformationMap`]: the cells and their prior information, diagonal (the paper's) or a
//!   dense squared-exponential prior factorised by faer's Cholesky;
//! - [`Icr`]: the reward, its gradient (Proposition 1) and Algorithm 1;
//! - [`IcrScan`]: a [`ScanController`](crate::ScanController) that chooses the motor's
//!   accelerations by gradient ascent of the log-determinant of the pose information the
//!   LiDAR gathers over the horizon.
//!
//! # Example
//! ```
//! use fu_mpc_core::icr::{Icr, IcrConfig, InformationMap, Triangle};
//! use nalgebra::{Isometry3, Point3, Vector6};
//!
//! # fn main() -> Result<(), fu_mpc_core::CoreError> {
//! let cells: Vec<Point3<f64>> =
//!     (0..400).map(|i| Point3::new(f64::from(i % 20) * 0.25, f64::from(i / 20) * 0.25 - 2.5, 0.0)).collect();
//! let map = InformationMap::diagonal(cells, vec![0.01; 400])?;
//! let mut icr = Icr::new(IcrConfig::default(), Triangle::new(3.0, 30f64.to_radians())?)?;
//! let u = vec![Vector6::new(1.5, 0.0, 0.0, 0.0, 0.0, 0.0); 5];
//! let mut grad = vec![Vector6::zeros(); 5];
//! let r = icr.reward_and_gradient(&map, &Isometry3::identity(), &u, &mut grad)?;
//! assert!(r > map.log_det_prior()?); // looking ahead gains information
//! # Ok(()) }
//! ```

mod fov;
mod map;
mod plan;
mod scan;

pub use fov::{Cone, FovSdf, Probit, Triangle};
pub use map::InformationMap;
pub use plan::{Icr, IcrConfig, IcrReport};
pub use scan::{IcrScan, IcrScanConfig};
