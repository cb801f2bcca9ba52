//! A banded matrix with an in-place sparse LU factorisation without pivoting.
//!
//! Storage is row-major within the band: row `i` holds columns `i − b ..= i + b`
//! contiguously. The MINCO matrix is far sparser than its band (each row touches at most
//! two pieces, and most entries stay zero through the elimination), so
//! [`BandMatrix::analyze`] computes the non-zero structure of the factors once, by a
//! symbolic elimination, and the numeric factorisation and the solves visit only those
//! entries. The structure depends only on the orders and the number of pieces, not on the
//! durations, so one analysis serves every later solve.
//!
//! The MINCO matrix has a non-zero diagonal and is factorised without pivoting, as in the
//! reference implementation; a zero or non-finite pivot is reported as an error.

/// What a factor entry is, for the numeric factorisation.
#[derive(Debug, Clone, Copy)]
enum Kind {
    /// L(i, j): divided by the pivot of column j.
    Lower(usize),
    /// U(i, i): the pivot of row i.
    Pivot(usize),
    /// U(i, j), j > i.
    Upper,
}

/// One entry of the factors and the end of its dot-product pairs.
#[derive(Debug, Clone, Copy)]
struct Target {
    idx: usize,
    kind: Kind,
    end: usize,
}

/// A square band matrix of size `n` with `b` sub- and super-diagonals.
#[derive(Debug, Clone)]
pub(crate) struct BandMatrix {
    n: usize,
    b: usize,
    data: Vec<f64>,
    inv_diag: Vec<f64>,
    /// Columns j > k with U(k, j) ≠ 0, for row k: `u_col[u_start[k]..u_start[k + 1]]`.
    u_start: Vec<usize>,
    u_col: Vec<usize>,
    /// Rows i > k with L(i, k) ≠ 0, for column k.
    lc_start: Vec<usize>,
    lc_row: Vec<usize>,
    /// Columns j < i with L(i, j) ≠ 0, for row i.
    lr_start: Vec<usize>,
    lr_col: Vec<usize>,
    /// The numeric factorisation as a flat program (Doolittle, row by row): every entry of
    /// the factors in the order it is computed, with the (L, U) index pairs of its dot product
    /// `pairs[previous end..end]`. Each entry is written once, so no update chain runs
    /// through memory.
    targets: Vec<Target>,
    pairs: Vec<(usize, usize)>,
    /// Entries that are zero in A but not in its factors: reset before each refill.
    fill_in: Vec<usize>,
}

impl BandMatrix {
    /// A zero matrix with an empty structure; fill it, then call [`BandMatrix::analyze`].
    pub(crate) fn new(n: usize, b: usize) -> Self {
        Self {
            n,
            b,
            data: vec![0.0; n * (2 * b + 1)],
            inv_diag: vec![0.0; n],
            u_start: vec![0; n + 1],
            u_col: Vec::new(),
            lc_start: vec![0; n + 1],
            lc_row: Vec::new(),
            lr_start: vec![0; n + 1],
            lr_col: Vec::new(),
            targets: Vec::new(),
            pairs: Vec::new(),
            fill_in: Vec::new(),
        }
    }

    /// Resets the entries a factorisation wrote: the structural non-zeros of A are
    /// overwritten by the caller's next fill, the fill-in is zeroed here. Before the first
    /// [`BandMatrix::analyze`] everything is zeroed.
    pub(crate) fn reset(&mut self) {
        if self.targets.is_empty() {
            self.data.fill(0.0);
        } else {
            for &k in &self.fill_in {
                self.data[k] = 0.0;
            }
        }
    }

    /// Size n.
    pub(crate) fn len(&self) -> usize {
        self.n
    }

    #[inline(always)]
    fn base(&self, i: usize) -> usize {
        // (i, j) lives at base(i) + j.
        i * (2 * self.b + 1) + self.b - i
    }

    /// Sets (i, j); requires |i − j| ≤ b and i, j < n.
    #[inline(always)]
    pub(crate) fn set(&mut self, i: usize, j: usize, v: f64) {
        let k = self.base(i) + j;
        self.data[k] = v;
    }

    #[cfg(test)]
    pub(crate) fn get(&self, i: usize, j: usize) -> f64 {
        if j + self.b < i || j > i + self.b || i >= self.n || j >= self.n {
            0.0
        } else {
            self.data[self.base(i) + j]
        }
    }

    /// Computes the non-zero structure of L and U from the current entries (every entry that
    /// can ever be non-zero must be non-zero now) by a symbolic elimination.
    pub(crate) fn analyze(&mut self) {
        let (n, b) = (self.n, self.b);
        let original: Vec<bool> = self.data.iter().map(|v| *v != 0.0).collect();
        let mut nz = original.clone();
        let w = 2 * b + 1;
        let at = |i: usize, j: usize| i * w + b + j - i;
        // Every pivot is computed (and checked), even one that is zero now.
        for i in 0..n {
            nz[at(i, i)] = true;
        }
        for k in 0..n {
            let end = (k + b).min(n - 1);
            for i in k + 1..=end {
                if nz[at(i, k)] {
                    for j in k + 1..=end {
                        if nz[at(k, j)] {
                            nz[at(i, j)] = true;
                        }
                    }
                }
            }
        }
        let (mut u_col, mut lc_row, mut lr_col) = (Vec::new(), Vec::new(), Vec::new());
        for k in 0..n {
            self.u_start[k] = u_col.len();
            self.lc_start[k] = lc_row.len();
            self.lr_start[k] = lr_col.len();
            let end = (k + b).min(n - 1);
            u_col.extend((k + 1..=end).filter(|&j| nz[at(k, j)]));
            lc_row.extend((k + 1..=end).filter(|&i| nz[at(i, k)]));
            lr_col.extend((k.saturating_sub(b)..k).filter(|&j| nz[at(k, j)]));
        }
        self.u_start[n] = u_col.len();
        self.lc_start[n] = lc_row.len();
        self.lr_start[n] = lr_col.len();
        (self.u_col, self.lc_row, self.lr_col) = (u_col, lc_row, lr_col);

        self.targets.clear();
        self.pairs.clear();
        for i in 0..n {
            let lo = i.saturating_sub(b);
            let hi = (i + b).min(n - 1);
            for j in lo..=hi {
                if !nz[at(i, j)] {
                    continue;
                }
                // a(i, j) = Σ_{k < min(i, j)} L(i, k) U(k, j) + (L(i, j) U(j, j) or U(i, j)).
                let kmin = i.max(j).saturating_sub(b);
                for k in kmin..i.min(j) {
                    if nz[at(i, k)] && nz[at(k, j)] {
                        self.pairs.push((at(i, k), at(k, j)));
                    }
                }
                let kind = match j.cmp(&i) {
                    core::cmp::Ordering::Less => Kind::Lower(j),
                    core::cmp::Ordering::Equal => Kind::Pivot(i),
                    core::cmp::Ordering::Greater => Kind::Upper,
                };
                // An upper entry with an empty dot product is already final.
                if matches!(kind, Kind::Upper)
                    && self.pairs.len() == self.targets.last().map_or(0, |t| t.end)
                {
                    continue;
                }
                self.targets.push(Target {
                    idx: at(i, j),
                    kind,
                    end: self.pairs.len(),
                });
            }
        }
        self.fill_in = (0..nz.len()).filter(|&k| nz[k] && !original[k]).collect();
    }

    /// Factorises in place into L (unit lower) and U = D U' (U' unit upper, stored with D⁻¹);
    /// returns the row of a zero or non-finite pivot on failure. Runs the program built by
    /// [`BandMatrix::analyze`].
    pub(crate) fn factorize(&mut self) -> Result<(), usize> {
        let mut start = 0;
        for t in &self.targets {
            let mut acc = self.data[t.idx];
            for &(l, u) in &self.pairs[start..t.end] {
                acc -= self.data[l] * self.data[u];
            }
            start = t.end;
            self.data[t.idx] = match t.kind {
                Kind::Lower(j) => acc * self.inv_diag[j],
                Kind::Pivot(i) => {
                    if !(acc.abs() > f64::MIN_POSITIVE && acc.is_finite()) {
                        return Err(i);
                    }
                    self.inv_diag[i] = 1.0 / acc;
                    acc
                }
                Kind::Upper => acc,
            };
        }
        // U' = D⁻¹ U: keeps the division off the solves' dependency chains.
        for i in 0..self.n {
            let bi = self.base(i);
            let inv = self.inv_diag[i];
            for &j in &self.u_col[self.u_start[i]..self.u_start[i + 1]] {
                self.data[bi + j] *= inv;
            }
        }
        Ok(())
    }

    /// Solves A x = rhs in place (after [`BandMatrix::factorize`]); `rhs` has n rows.
    pub(crate) fn solve<const D: usize>(&self, x: &mut [[f64; D]]) {
        for i in 0..self.n {
            let bi = self.base(i);
            let mut acc = x[i];
            for &j in &self.lr_col[self.lr_start[i]..self.lr_start[i + 1]] {
                let l = self.data[bi + j];
                for d in 0..D {
                    acc[d] -= l * x[j][d];
                }
            }
            x[i] = acc;
        }
        for i in (0..self.n).rev() {
            let bi = self.base(i);
            let mut acc = x[i];
            for a in &mut acc {
                *a *= self.inv_diag[i];
            }
            for &j in &self.u_col[self.u_start[i]..self.u_start[i + 1]] {
                let u = self.data[bi + j];
                for d in 0..D {
                    acc[d] -= u * x[j][d];
                }
            }
            x[i] = acc;
        }
    }

    /// Solves Aᵀ x = rhs in place: U'ᵀ z = rhs, y = D⁻¹ z, then Lᵀ x = y, each by rows of the
    /// stored factors.
    pub(crate) fn solve_transposed<const D: usize>(&self, x: &mut [[f64; D]]) {
        for i in 0..self.n {
            let bi = self.base(i);
            let z = x[i];
            for &j in &self.u_col[self.u_start[i]..self.u_start[i + 1]] {
                let u = self.data[bi + j];
                for d in 0..D {
                    x[j][d] -= u * z[d];
                }
            }
            let mut y = z;
            for v in &mut y {
                *v *= self.inv_diag[i];
            }
            x[i] = y;
        }
        for i in (0..self.n).rev() {
            let bi = self.base(i);
            let xi = x[i];
            for &j in &self.lr_col[self.lr_start[i]..self.lr_start[i + 1]] {
                let l = self.data[bi + j];
                for d in 0..D {
                    x[j][d] -= l * xi[d];
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::DMatrix;
    use proptest::prelude::*;

    proptest! {
        /// LU solves agree with a dense solve for random diagonally dominant band matrices
        /// with random sparsity.
        #[test]
        fn matches_dense(n in 1usize..40, b in 1usize..9, density in 0.2f64..1.0, seed in any::<u64>()) {
            let mut rng = seed;
            let mut next = || {
                rng = rng.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1_442_695_040_888_963_407);
                (rng >> 11) as f64 / (1u64 << 53) as f64
            };
            let mut band = BandMatrix::new(n, b);
            let mut dense = DMatrix::zeros(n, n);
            for i in 0..n {
                for j in i.saturating_sub(b)..=(i + b).min(n - 1) {
                    let v = if i == j { 10.0 + next() } else if next() < density { next() - 0.5 } else { 0.0 };
                    band.set(i, j, v);
                    dense[(i, j)] = v;
                }
            }
            band.analyze();
            let rhs: Vec<[f64; 2]> = (0..n).map(|_| [next(), next()]).collect();
            let mut x = rhs.clone();
            let mut xt = rhs.clone();
            prop_assert!(band.factorize().is_ok());
            band.solve(&mut x);
            band.solve_transposed(&mut xt);
            let lu = dense.clone().lu();
            let lut = dense.transpose().lu();
            for d in 0..2 {
                let r = nalgebra::DVector::from_iterator(n, rhs.iter().map(|v| v[d]));
                let xs = lu.solve(&r).unwrap();
                let xts = lut.solve(&r).unwrap();
                for i in 0..n {
                    prop_assert!((x[i][d] - xs[i]).abs() < 1e-10, "solve {i}");
                    prop_assert!((xt[i][d] - xts[i]).abs() < 1e-10, "transposed {i}");
                }
            }
        }
    }

    #[test]
    fn zero_pivot_is_reported() {
        let mut band = BandMatrix::new(3, 4);
        band.reset();
        band.set(0, 0, 1.0);
        band.set(2, 2, 1.0);
        band.analyze();
        assert_eq!(band.factorize(), Err(1));
        let mut band = BandMatrix::new(2, 4);
        band.set(0, 0, f64::NAN);
        band.set(1, 1, 1.0);
        band.analyze();
        assert_eq!(band.factorize(), Err(0));
        assert_eq!(band.get(1, 0), 0.0);
    }
}
