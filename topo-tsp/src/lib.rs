//! Global sequencing for exploration: a topological graph of free space, the topology-aware
//! transition cost, and open asymmetric TSP tools.
//!
//! This crate implements the global planning layer of FU-MPC (Section IV-B): paths on a
//! topological graph of free space, the transition cost (7)
//!
//! d_ij = Σ_l (‖x_{l+1} − x_l‖ + 0.5 |z_{l+1} − z_l|) / (v_max / 2)
//!
//! along the graph path between viewpoints, the heading term (8) on arcs out of the current
//! odometry node, and the cost matrix of the open tour (9).
//!
//! - [`TopoGraph`]: nodes connected within a radius when the caller's [`FreeSpace`] check passes
//!   (neighbour search in a spatial hash), temporary per-cycle nodes, A* and Dijkstra;
//! - [`transition_cost`], [`heading_cost`], [`cost_matrix`];
//! - [`CostMatrix`]: a validated asymmetric matrix, with the open-tour reduction
//!   ([`CostMatrix::with_free_return_to_start`]);
//! - exact solvers for checking heuristics: [`held_karp`] (n ≤ 13) and [`brute_force`] (n ≤ 9);
//! - [`parse_tsplib`]: TSPLIB ATSP/TSP text (explicit matrices and EUC_2D);
//! - [`held_karp_bound`]: the Held–Karp lower bound by subgradient optimisation over 1-trees of
//!   the symmetric transform, and [`alpha_candidates`]: α-nearness candidate lists;
//! - [`solve`] and [`solve_open`]: a seeded heuristic ATSP solver on the α-nearness candidates
//!   and, when it is tight, the assignment relaxation (2-opt, Or-opt and a variable-depth search
//!   over sequential pure 5-opt basic moves with don't-look bits, iterated with double-bridge
//!   kicks and restarts), budgets by trials and by a caller-supplied stop predicate. With
//!   default settings it reaches 17 of the 19 TSPLIB ATSP optima (see the README).
//!
//! # Example
//! ```
//! use topo_tsp::{CostConfig, TopoGraph, cost_matrix, held_karp_open};
//!
//! # fn main() -> Result<(), topo_tsp::TspError> {
//! let free = |_: &[f64; 3], _: &[f64; 3]| true;
//! let mut g = TopoGraph::new();
//! for x in 0..5 {
//!     g.add_node([f64::from(x) * 2.0, 0.0, 1.0], 2.5, &free)?;
//! }
//! let odom = g.add_temporary_node([0.5, 0.0, 1.0], 2.5, &free)?;
//! let views = [g.add_temporary_node([8.0, 0.5, 1.0], 2.5, &free)?, g.add_temporary_node([4.0, 0.5, 1.0], 2.5, &free)?];
//! let m = cost_matrix(&g, odom, &views, [1.0, 0.0, 0.0], &CostConfig::default())?;
//! let tour = held_karp_open(&m)?;
//! assert_eq!(tour.order, vec![0, 2, 1]); // the nearer viewpoint first
//! g.clear_temporary();
//! # Ok(()) }
//! ```
#![forbid(unsafe_code)]
#![deny(missing_docs)]
#![warn(rustdoc::broken_intra_doc_links)]

mod assignment;
mod bound;
mod cost;
mod error;
mod exact;
mod graph;
mod matrix;
mod solver;
mod tsplib;

pub use bound::{BoundConfig, HeldKarpBound, alpha_candidates, held_karp_bound};
pub use cost::{CostConfig, cost_matrix, heading_cost, transition_cost};
pub use error::{Result, TspError};
pub use exact::{BRUTE_FORCE_MAX, HELD_KARP_MAX, Tour, brute_force, held_karp, held_karp_open};
pub use graph::{FreeSpace, GraphPath, NodeId, ShortestPaths, TopoGraph};
pub use matrix::CostMatrix;
pub use solver::{Solution, SolverConfig, solve, solve_open};
pub use tsplib::{ProblemKind, TsplibInstance, parse_tsplib};

/// The README's example, compiled and run as a doctest.
#[cfg(doctest)]
#[doc = include_str!("../README.md")]
pub struct ReadmeDoctests;

/// Helpers shared by the unit tests.
#[cfg(test)]
pub(crate) mod test_util {
    use crate::CostMatrix;

    /// A seeded random n × n matrix with integer costs in 0..modulus.
    pub(crate) fn random_matrix(n: usize, seed: u64, modulus: u64) -> CostMatrix {
        let mut s = seed;
        CostMatrix::from_fn(n, |_, _| {
            s = s
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            ((s >> 40) % modulus) as f64
        })
        .unwrap()
    }
}
