//! Validated asymmetric cost matrices.

use crate::error::{Result, TspError};

/// A square matrix of arc costs c(i, j) ≥ 0, finite; the diagonal is ignored (stored as 0).
///
/// # Example
/// ```
/// use topo_tsp::CostMatrix;
/// let m = CostMatrix::from_rows(&[vec![0.0, 1.0], vec![2.0, 0.0]]).unwrap();
/// assert_eq!(m.len(), 2);
/// assert_eq!(m.cost(1, 0), 2.0);
/// assert!(CostMatrix::from_rows(&[vec![0.0, f64::NAN], vec![1.0, 0.0]]).is_err());
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct CostMatrix {
    n: usize,
    data: Vec<f64>,
}

impl CostMatrix {
    /// Validates and builds a matrix from rows. Diagonal entries are ignored (any value).
    ///
    /// # Errors
    /// [`TspError::Empty`], [`TspError::NotSquare`], or [`TspError::BadCost`] for a NaN,
    /// infinite or negative off-diagonal cost.
    pub fn from_rows(rows: &[Vec<f64>]) -> Result<Self> {
        let n = rows.len();
        if n == 0 {
            return Err(TspError::Empty);
        }
        let mut data = Vec::with_capacity(n * n);
        for (i, row) in rows.iter().enumerate() {
            if row.len() != n {
                return Err(TspError::NotSquare {
                    row: i,
                    found: row.len(),
                    expected: n,
                });
            }
            for (j, &v) in row.iter().enumerate() {
                if i == j {
                    data.push(0.0);
                } else if v.is_finite() && v >= 0.0 {
                    data.push(v);
                } else {
                    return Err(TspError::BadCost {
                        row: i,
                        col: j,
                        value: v,
                    });
                }
            }
        }
        Ok(Self { n, data })
    }

    /// Builds an n × n matrix from a function of (i, j), validated as [`CostMatrix::from_rows`].
    ///
    /// # Errors
    /// As [`CostMatrix::from_rows`].
    pub fn from_fn(n: usize, mut f: impl FnMut(usize, usize) -> f64) -> Result<Self> {
        let mut rows = vec![vec![0.0; n]; n];
        for (i, row) in rows.iter_mut().enumerate() {
            for (j, v) in row.iter_mut().enumerate() {
                *v = f(i, j);
            }
        }
        Self::from_rows(&rows)
    }

    /// Number of nodes n.
    pub fn len(&self) -> usize {
        self.n
    }

    /// Always false: a matrix has at least one node.
    pub fn is_empty(&self) -> bool {
        self.n == 0
    }

    /// The cost of arc (i, j); 0 on the diagonal. Indices must be < n (out of range gives +∞).
    #[inline]
    pub fn cost(&self, i: usize, j: usize) -> f64 {
        if i < self.n && j < self.n {
            self.data[i * self.n + j]
        } else {
            f64::INFINITY
        }
    }

    /// The length of the closed tour visiting `tour` in order and returning to its first node.
    pub fn closed_length(&self, tour: &[usize]) -> f64 {
        if tour.is_empty() {
            return 0.0;
        }
        let mut total: f64 = tour.windows(2).map(|w| self.cost(w[0], w[1])).sum();
        total += self.cost(tour[tour.len() - 1], tour[0]);
        total
    }

    /// The length of the open path visiting `tour` in order (no closing arc).
    pub fn open_length(&self, tour: &[usize]) -> f64 {
        tour.windows(2).map(|w| self.cost(w[0], w[1])).sum()
    }

    /// The matrix of the open tour problem from node 0, eq. (9): every arc into node 0 is free,
    /// so an optimal closed tour of it, cut before its return to 0, is an optimal open path
    /// from node 0 through all nodes.
    pub fn with_free_return_to_start(&self) -> Self {
        let mut m = self.clone();
        for i in 0..self.n {
            m.data[i * self.n] = 0.0;
        }
        m
    }
}

/// Checks that `tour` is a permutation of 0..n starting at node 0.
#[cfg(test)]
pub(crate) fn is_permutation_from_zero(tour: &[usize], n: usize) -> bool {
    if tour.len() != n || tour.first() != Some(&0) {
        return false;
    }
    let mut seen = vec![false; n];
    tour.iter()
        .all(|&v| v < n && !std::mem::replace(&mut seen[v], true))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bad_matrices_are_typed_errors() {
        assert!(matches!(CostMatrix::from_rows(&[]), Err(TspError::Empty)));
        assert!(matches!(
            CostMatrix::from_rows(&[vec![0.0, 1.0], vec![1.0]]),
            Err(TspError::NotSquare { row: 1, .. })
        ));
        assert!(matches!(
            CostMatrix::from_rows(&[vec![0.0, -1.0], vec![1.0, 0.0]]),
            Err(TspError::BadCost { row: 0, col: 1, .. })
        ));
        assert!(matches!(
            CostMatrix::from_rows(&[vec![0.0, 1.0], vec![f64::INFINITY, 0.0]]),
            Err(TspError::BadCost { row: 1, col: 0, .. })
        ));
        // The diagonal may hold anything (TSPLIB sentinels, NaN).
        let m = CostMatrix::from_rows(&[vec![f64::NAN, 1.0], vec![2.0, 9999.0]]).unwrap();
        assert_eq!(m.cost(0, 0), 0.0);
        assert_eq!(m.cost(5, 0), f64::INFINITY);
        assert_eq!(m.closed_length(&[0, 1]), 3.0);
        assert_eq!(m.open_length(&[0, 1]), 1.0);
        assert_eq!(m.with_free_return_to_start().cost(1, 0), 0.0);
        assert!(is_permutation_from_zero(&[0, 1], 2));
        assert!(!is_permutation_from_zero(&[1, 0], 2));
        assert!(!is_permutation_from_zero(&[0, 0], 2));
    }
}
