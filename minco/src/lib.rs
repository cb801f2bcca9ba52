//! MINCO: minimum-control-effort piecewise-polynomial trajectories with O(M) gradients.
//!
//! A trajectory of M polynomial pieces of degree 2S − 1 (S = 2, 3, 4: minimum acceleration,
//! jerk, snap) through inner waypoints q_1..q_{M−1} with durations T_1..T_M minimises the
//! control effort
//!
//! J = Σ_i ∫₀^{T_i} ‖p_i^(S)(t)‖² dt
//!
//! for fixed head and tail states. Its coefficients solve a banded linear system
//! A(T) c = b(q, head, tail) (Wang et al., "Geometrically constrained trajectory
//! optimization for multicopters", T-RO 2022), so any cost K(c, T) can be differentiated
//! with respect to q and T in O(M) by one adjoint solve. That is what makes MINCO
//! trajectories cheap to optimise; the FU-MPC system uses them for its local references.
//!
//! The system is not solved as it stands: each piece is written in Hermite form through its
//! end states, which leaves only the derivatives 1..S−1 at each junction unknown, and those
//! solve a symmetric positive-definite block-tridiagonal system with (S−1) × (S−1) blocks.
//! Its block LDLᵀ serves the solve and the adjoint alike.
//!
//! - [`Minco`] (with [`MinimumAcceleration`], [`MinimumJerk`], [`MinimumSnap`]): set up once,
//!   solve for new (q, T) without allocating, energy and gradients;
//! - [`Trajectory`]: evaluation, sampling and speed/acceleration bounds;
//! - [`Optimizer`]: a GCOPTER-style optimiser (waypoints and durations by L-BFGS with a
//!   Lewis–Overton line search, soft speed/acceleration/corridor penalties) that turns a path
//!   into a dynamically feasible trajectory.
//!
//! # Example
//! ```
//! use minco::MinimumSnap;
//!
//! # fn main() -> Result<(), minco::MincoError> {
//! // Three pieces through two waypoints, at rest at both ends.
//! let mut m = MinimumSnap::<3>::new(3)?;
//! let rest = |p: [f64; 3]| [p, [0.0; 3], [0.0; 3], [0.0; 3]];
//! m.solve(&rest([0.0; 3]), &rest([3.0, 0.0, 1.0]), &[[1.0, 1.0, 0.5], [2.0, 1.0, 1.0]], &[1.0; 3])?;
//! let (energy, grad_q, grad_t) = m.energy_gradient()?;
//! assert!(energy > 0.0);
//! // Stretching time lowers the effort.
//! assert!(grad_t.iter().all(|g| *g < 0.0));
//! assert_eq!(grad_q.len(), 2);
//! # Ok(()) }
//! ```
#![forbid(unsafe_code)]
#![deny(missing_docs)]
#![warn(rustdoc::broken_intra_doc_links)]

mod error;
mod hermite;
mod lbfgs;
mod minco;
mod optimizer;
mod poly;
mod trajectory;

pub use error::{MincoError, Result};
pub use lbfgs::Status;
pub use minco::{Minco, MinimumAcceleration, MinimumJerk, MinimumSnap};
pub use optimizer::{Optimizer, OptimizerConfig, Solution};
pub use trajectory::Trajectory;

/// The README's example, compiled and run as a doctest.
#[cfg(doctest)]
#[doc = include_str!("../README.md")]
pub struct ReadmeDoctests;

/// Helpers shared by the unit tests.
#[cfg(test)]
pub(crate) mod test_util {
    /// A seeded uniform generator on [0, 1) (an LCG: enough for test inputs).
    pub(crate) fn uniform(seed: u64) -> impl FnMut() -> f64 {
        let mut rng = seed;
        move || {
            rng = rng
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            (rng >> 11) as f64 / (1u64 << 53) as f64
        }
    }

    /// ‖numeric − analytic‖ and ‖numeric‖ of two gradients.
    pub(crate) fn gradient_error(numeric: &[f64], analytic: &[f64]) -> (f64, f64) {
        let err = numeric
            .iter()
            .zip(analytic)
            .map(|(a, b)| (a - b).powi(2))
            .sum::<f64>()
            .sqrt();
        let norm = numeric.iter().map(|a| a * a).sum::<f64>().sqrt();
        (err, norm)
    }

    /// Checks the first `split` entries (waypoints) and the rest (durations) separately to
    /// `1e-6` relative, so a large waypoint gradient cannot hide a wrong duration gradient.
    pub(crate) fn check_gradient_blocks(
        numeric: &[f64],
        analytic: &[f64],
        split: usize,
    ) -> Result<(), proptest::test_runner::TestCaseError> {
        check_gradient_blocks_with_noise(numeric, analytic, split, &[])
    }

    /// [`check_gradient_blocks`] allowing, on top, each numeric entry's own rounding error
    /// `noise[k]` (a central difference of a cost f with step h cannot resolve better than
    /// about ε|f|/h: a block of small entries beside a large cost needs it). Missing entries
    /// count as 0.
    pub(crate) fn check_gradient_blocks_with_noise(
        numeric: &[f64],
        analytic: &[f64],
        split: usize,
        noise: &[f64],
    ) -> Result<(), proptest::test_runner::TestCaseError> {
        for (what, range) in [("waypoints", 0..split), ("durations", split..numeric.len())] {
            let (err, norm) = gradient_error(&numeric[range.clone()], &analytic[range.clone()]);
            let floor = range
                .map(|k| noise.get(k).copied().unwrap_or(0.0).powi(2))
                .sum::<f64>()
                .sqrt();
            proptest::prop_assert!(
                err <= 1e-6 * norm.max(1e-12) + floor,
                "{what}: gradient error {err} vs norm {norm} (rounding floor {floor})\nnumeric {numeric:?}\nanalytic {analytic:?}"
            );
        }
        Ok(())
    }
}
