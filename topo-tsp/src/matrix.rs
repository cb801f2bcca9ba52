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

/// The stored cost of cell (i, j): 0 on the diagonal (whatever was given), else `v` when it is
/// finite and non-negative.
fn entry(i: usize, j: usize, v: f64) -> Result<f64> {
    if i == j {
        Ok(0.0)
    } else if v.is_finite() && v >= 0.0 {
        Ok(v)
    } else {
        Err(TspError::BadCost {
            row: i,
            col: j,
            value: v,
        })
    }
}

impl CostMatrix {
    /// The most nodes a matrix may have: 16 384, whose n² costs take 2 GiB. Larger sizes are
    /// refused before anything is allocated, so a bad size is an error rather than an
    /// allocation failure.
    pub const MAX_LEN: usize = 1 << 14;

    /// [`TspError::TooLarge`] when `n` exceeds [`CostMatrix::MAX_LEN`].
    pub(crate) fn check_len(n: usize) -> Result<()> {
        if n > Self::MAX_LEN {
            return Err(TspError::TooLarge {
                solver: "CostMatrix",
                max: Self::MAX_LEN,
                n,
            });
        }
        Ok(())
    }

    /// Validates and builds a matrix from rows. Diagonal entries are ignored (any value).
    ///
    /// # Errors
    /// [`TspError::Empty`], [`TspError::TooLarge`] for more than [`CostMatrix::MAX_LEN`] rows,
    /// [`TspError::NotSquare`], or [`TspError::BadCost`] for a NaN, infinite or negative
    /// off-diagonal cost.
    pub fn from_rows(rows: &[Vec<f64>]) -> Result<Self> {
        let n = rows.len();
        if n == 0 {
            return Err(TspError::Empty);
        }
        Self::check_len(n)?;
        // Reserve n² only when the rows hold that many costs: short rows must not cost more
        // memory than they occupy before their NotSquare error.
        let mut data = if rows.iter().all(|r| r.len() == n) {
            Vec::with_capacity(n * n)
        } else {
            Vec::new()
        };
        for (i, row) in rows.iter().enumerate() {
            if row.len() != n {
                return Err(TspError::NotSquare {
                    row: i,
                    found: row.len(),
                    expected: n,
                });
            }
            for (j, &v) in row.iter().enumerate() {
                data.push(entry(i, j, v)?);
            }
        }
        Ok(Self { n, data })
    }

    /// Builds an n × n matrix from a function of (i, j), validated as [`CostMatrix::from_rows`].
    /// `f` is called on every (i, j), diagonal included, in row-major order, until a bad cost.
    ///
    /// # Errors
    /// [`TspError::Empty`] for n = 0, [`TspError::TooLarge`] for n > [`CostMatrix::MAX_LEN`]
    /// (before `f` is called), or [`TspError::BadCost`] for the first bad off-diagonal cost.
    ///
    /// # Example
    /// ```
    /// use topo_tsp::{CostMatrix, TspError};
    /// let m = CostMatrix::from_fn(3, |i, j| (i + j) as f64).unwrap();
    /// assert_eq!(m.cost(2, 1), 3.0);
    /// assert!(matches!(
    ///     CostMatrix::from_fn(usize::MAX, |_, _| 1.0),
    ///     Err(TspError::TooLarge { .. })
    /// ));
    /// ```
    pub fn from_fn(n: usize, mut f: impl FnMut(usize, usize) -> f64) -> Result<Self> {
        if n == 0 {
            return Err(TspError::Empty);
        }
        Self::check_len(n)?;
        let mut data = Vec::with_capacity(n * n);
        for i in 0..n {
            for j in 0..n {
                data.push(entry(i, j, f(i, j))?);
            }
        }
        Ok(Self { n, data })
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

    #[test]
    fn oversized_matrices_are_typed_errors() {
        assert!(matches!(
            CostMatrix::from_fn(usize::MAX, |_, _| 1.0),
            Err(TspError::TooLarge { n: usize::MAX, .. })
        ));
        let mut calls = 0;
        assert!(matches!(
            CostMatrix::from_fn(CostMatrix::MAX_LEN + 1, |_, _| {
                calls += 1;
                1.0
            }),
            Err(TspError::TooLarge {
                max: CostMatrix::MAX_LEN,
                ..
            })
        ));
        assert_eq!(calls, 0);
        assert!(matches!(
            CostMatrix::from_fn(0, |_, _| 1.0),
            Err(TspError::Empty)
        ));
        assert!(matches!(
            CostMatrix::from_rows(&vec![Vec::new(); CostMatrix::MAX_LEN + 1]),
            Err(TspError::TooLarge { .. })
        ));
        // Short rows are reported without reserving n² costs first.
        assert!(matches!(
            CostMatrix::from_rows(&vec![Vec::new(); 1000]),
            Err(TspError::NotSquare {
                row: 0,
                found: 0,
                expected: 1000
            })
        ));
        // from_fn and from_rows agree, diagonal included, and report the same first bad cost.
        let f = |i: usize, j: usize| {
            if (i, j) == (2, 1) {
                -1.0
            } else {
                (i * 3 + j) as f64
            }
        };
        let rows: Vec<Vec<f64>> = (0..3).map(|i| (0..3).map(|j| f(i, j)).collect()).collect();
        assert_eq!(CostMatrix::from_fn(3, f), CostMatrix::from_rows(&rows));
        let ok = |i: usize, j: usize| (i * 3 + j) as f64;
        let rows: Vec<Vec<f64>> = (0..3).map(|i| (0..3).map(|j| ok(i, j)).collect()).collect();
        assert_eq!(CostMatrix::from_fn(3, ok), CostMatrix::from_rows(&rows));
    }
}
