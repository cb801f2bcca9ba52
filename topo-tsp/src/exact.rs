//! Exact solvers for small instances: Held–Karp dynamic programming and brute force.
//!
//! They exist to check heuristics against the true optimum on small cases.

use crate::error::{Result, TspError};
use crate::matrix::CostMatrix;

/// A tour: node order starting at node 0, and its length.
#[derive(Debug, Clone, PartialEq)]
pub struct Tour {
    /// Visiting order, a permutation of 0..n starting at 0.
    pub order: Vec<usize>,
    /// Length of the tour (closed or open, as the producing function says).
    pub length: f64,
}

/// Largest n for [`held_karp`].
pub const HELD_KARP_MAX: usize = 13;
/// Largest n for [`brute_force`].
pub const BRUTE_FORCE_MAX: usize = 9;

/// The optimal closed tour by Held–Karp dynamic programming, O(2ⁿ n²), for n ≤ 13.
///
/// Ties are broken toward smaller node indices, so the result is deterministic. When every
/// tour's length overflows (costs near `f64::MAX`), the order 0, 1, …, n − 1 with length ∞.
///
/// # Errors
/// [`TspError::TooLarge`] for n > 13.
///
/// # Example
/// ```
/// use topo_tsp::{CostMatrix, held_karp};
/// let m = CostMatrix::from_fn(4, |i, j| if (i + 1) % 4 == j { 1.0 } else { 5.0 }).unwrap();
/// let t = held_karp(&m).unwrap();
/// assert_eq!(t.order, vec![0, 1, 2, 3]);
/// assert_eq!(t.length, 4.0);
/// ```
pub fn held_karp(m: &CostMatrix) -> Result<Tour> {
    let n = m.len();
    if n > HELD_KARP_MAX {
        return Err(TspError::TooLarge {
            solver: "Held-Karp",
            max: HELD_KARP_MAX,
            n,
        });
    }
    if n <= 2 {
        let order: Vec<usize> = (0..n).collect();
        let length = m.closed_length(&order);
        return Ok(Tour { order, length });
    }
    // Subsets of nodes 1..n−1 as bit masks; dp[mask][j] = shortest path 0 → … → j through mask.
    let k = n - 1;
    let full = (1usize << k) - 1;
    let mut dp = vec![f64::INFINITY; (1 << k) * k];
    let mut parent = vec![usize::MAX; (1 << k) * k];
    for j in 0..k {
        dp[(1 << j) * k + j] = m.cost(0, j + 1);
    }
    for mask in 1..=full {
        for j in 0..k {
            if mask & (1 << j) == 0 {
                continue;
            }
            let here = dp[mask * k + j];
            if !here.is_finite() {
                continue;
            }
            for nxt in 0..k {
                if mask & (1 << nxt) != 0 {
                    continue;
                }
                let nm = mask | (1 << nxt);
                let cand = here + m.cost(j + 1, nxt + 1);
                if cand < dp[nm * k + nxt] {
                    dp[nm * k + nxt] = cand;
                    parent[nm * k + nxt] = j;
                }
            }
        }
    }
    let (mut best, mut last) = (f64::INFINITY, 0);
    for j in 0..k {
        let total = dp[full * k + j] + m.cost(j + 1, 0);
        if total < best {
            best = total;
            last = j;
        }
    }
    if !best.is_finite() {
        // Every tour's length overflows (costs near f64::MAX): all are equally long, and the
        // search kept no parents; the first order, as the brute force would give.
        let order: Vec<usize> = (0..n).collect();
        return Ok(Tour {
            length: m.closed_length(&order),
            order,
        });
    }
    let mut order = Vec::with_capacity(n);
    let (mut mask, mut j) = (full, last);
    while j != usize::MAX {
        order.push(j + 1);
        let p = parent[mask * k + j];
        mask &= !(1 << j);
        j = p;
    }
    order.push(0);
    order.reverse();
    Ok(Tour {
        length: m.closed_length(&order),
        order,
    })
}

/// The optimal closed tour by enumerating all (n − 1)! orders, for n ≤ 9.
///
/// # Errors
/// [`TspError::TooLarge`] for n > 9.
pub fn brute_force(m: &CostMatrix) -> Result<Tour> {
    let n = m.len();
    if n > BRUTE_FORCE_MAX {
        return Err(TspError::TooLarge {
            solver: "brute force",
            max: BRUTE_FORCE_MAX,
            n,
        });
    }
    let mut rest: Vec<usize> = (1..n).collect();
    let mut best = Tour {
        order: (0..n).collect(),
        length: m.closed_length(&(0..n).collect::<Vec<_>>()),
    };
    // Heap's algorithm over the nodes after 0.
    let mut c = vec![0usize; rest.len()];
    let mut i = 0;
    while i < rest.len() {
        if c[i] < i {
            if i % 2 == 0 {
                rest.swap(0, i);
            } else {
                rest.swap(c[i], i);
            }
            let mut order = Vec::with_capacity(n);
            order.push(0);
            order.extend_from_slice(&rest);
            let len = m.closed_length(&order);
            if len < best.length {
                best = Tour { order, length: len };
            }
            c[i] += 1;
            i = 0;
        } else {
            c[i] = 0;
            i += 1;
        }
    }
    Ok(best)
}

/// The optimal open path from node 0 through all nodes (eq. (9)), by Held–Karp on the matrix
/// with free arcs into node 0; the returned length is the open length.
///
/// # Errors
/// As [`held_karp`].
pub fn held_karp_open(m: &CostMatrix) -> Result<Tour> {
    let t = held_karp(&m.with_free_return_to_start())?;
    Ok(Tour {
        length: m.open_length(&t.order),
        order: t.order,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn matrix(n: usize, seed: u64) -> CostMatrix {
        crate::test_util::random_matrix(n, seed, 100)
    }

    proptest! {
        #[test]
        fn held_karp_equals_brute_force(n in 1usize..=8, seed in any::<u64>()) {
            let m = matrix(n, seed);
            let hk = held_karp(&m).unwrap();
            let bf = brute_force(&m).unwrap();
            prop_assert_eq!(hk.length, bf.length);
            prop_assert!(crate::matrix::is_permutation_from_zero(&hk.order, n));
            prop_assert_eq!(hk.length, m.closed_length(&hk.order));
        }

        #[test]
        fn open_tour_is_no_longer_than_any_open_path(n in 2usize..=7, seed in any::<u64>()) {
            let m = matrix(n, seed);
            let open = held_karp_open(&m).unwrap();
            let bf = brute_force(&m.with_free_return_to_start()).unwrap();
            prop_assert_eq!(open.length, m.open_length(&bf.order));
        }
    }

    #[test]
    fn limits_and_tiny_instances() {
        assert!(matches!(
            held_karp(&matrix(14, 1)),
            Err(TspError::TooLarge { .. })
        ));
        assert!(matches!(
            brute_force(&matrix(10, 1)),
            Err(TspError::TooLarge { .. })
        ));
        let one = matrix(1, 3);
        assert_eq!(held_karp(&one).unwrap().order, vec![0]);
        assert_eq!(brute_force(&one).unwrap().length, 0.0);
        let two = CostMatrix::from_rows(&[vec![0.0, 2.0], vec![5.0, 0.0]]).unwrap();
        assert_eq!(held_karp(&two).unwrap().length, 7.0);
        assert_eq!(held_karp_open(&two).unwrap().length, 2.0);
    }
}
