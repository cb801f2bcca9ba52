//! A banded matrix with an in-place LU factorisation without pivoting.
//!
//! Storage is row-major within the band: row `i` holds columns `i − b ..= i + b`
//! contiguously, so every inner loop runs over contiguous memory. The matrix is padded
//! with `b` identity rows and columns so that every loop has the fixed trip count `b`:
//! the kernels are monomorphised for the bandwidths MINCO uses (4, 6, 8) and unroll.
//! The MINCO matrix has a non-zero diagonal and is factorised without pivoting, as in
//! the reference implementation; a zero or non-finite pivot is reported as an error.

/// A square band matrix of size `n` with `b` sub- and super-diagonals.
#[derive(Debug, Clone)]
pub(crate) struct BandMatrix {
    n: usize,
    b: usize,
    data: Vec<f64>,
    inv_diag: Vec<f64>,
}

/// Dispatches a kernel on the bandwidth so that it is compiled for a constant `B`.
macro_rules! with_bandwidth {
    ($b:expr, $f:ident :: <_ $(, $g:ty)*> ($($arg:expr),*)) => {
        match $b {
            4 => $f::<4 $(, $g)*>($($arg),*),
            6 => $f::<6 $(, $g)*>($($arg),*),
            8 => $f::<8 $(, $g)*>($($arg),*),
            _ => $f::<0 $(, $g)*>($($arg),*),
        }
    };
}

impl BandMatrix {
    /// A zero matrix; `b` must be 4, 6 or 8 for the fast kernels (others use a generic path).
    pub(crate) fn new(n: usize, b: usize) -> Self {
        let rows = n + b;
        Self {
            n,
            b,
            data: vec![0.0; rows * (2 * b + 1)],
            inv_diag: vec![0.0; rows],
        }
    }

    /// Rows a right-hand side must have: `n` plus the padding.
    pub(crate) fn padded_len(&self) -> usize {
        self.n + self.b
    }

    #[inline(always)]
    fn idx(&self, i: usize, j: usize) -> usize {
        i * (2 * self.b + 1) + j + self.b - i
    }

    /// Zeroes the matrix and sets the padding to the identity.
    pub(crate) fn clear(&mut self) {
        self.data.fill(0.0);
        for i in self.n..self.n + self.b {
            let k = self.idx(i, i);
            self.data[k] = 1.0;
        }
    }

    /// Sets (i, j); requires |i − j| ≤ b and i, j < n.
    #[inline(always)]
    pub(crate) fn set(&mut self, i: usize, j: usize, v: f64) {
        let k = self.idx(i, j);
        self.data[k] = v;
    }

    #[cfg(test)]
    pub(crate) fn get(&self, i: usize, j: usize) -> f64 {
        if j + self.b < i || j > i + self.b {
            0.0
        } else {
            self.data[self.idx(i, j)]
        }
    }

    /// Factorises in place into L (unit lower) and U; returns the row of a zero or
    /// non-finite pivot on failure.
    pub(crate) fn factorize(&mut self) -> Result<(), usize> {
        let (n, b) = (self.n, self.b);
        with_bandwidth!(b, factorize::<_>(&mut self.data, &mut self.inv_diag, n, b))
    }

    /// Solves A x = b in place; `rhs` has [`BandMatrix::padded_len`] rows, the padding zero.
    pub(crate) fn solve<const D: usize>(&self, rhs: &mut [[f64; D]]) {
        let b = self.b;
        with_bandwidth!(b, solve::<_, D>(&self.data, &self.inv_diag, rhs, b));
    }

    /// Solves Aᵀ x = b in place; `rhs` as for [`BandMatrix::solve`].
    pub(crate) fn solve_transposed<const D: usize>(&self, rhs: &mut [[f64; D]]) {
        let b = self.b;
        with_bandwidth!(
            b,
            solve_transposed::<_, D>(&self.data, &self.inv_diag, rhs, b)
        );
    }
}

/// The bandwidth: the constant `B`, or the runtime `b` when `B = 0` (generic path).
#[inline(always)]
fn bw<const B: usize>(b: usize) -> usize {
    if B == 0 { b } else { B }
}

fn factorize<const B: usize>(
    data: &mut [f64],
    inv_diag: &mut [f64],
    n: usize,
    b: usize,
) -> Result<(), usize> {
    let b = bw::<B>(b);
    let w = 2 * b + 1;
    for k in 0..n {
        let piv = data[k * w + b];
        if !(piv.abs() > f64::MIN_POSITIVE && piv.is_finite()) {
            return Err(k);
        }
        let inv = 1.0 / piv;
        inv_diag[k] = inv;
        // Pivot row k, columns k+1..=k+b, stored divided by the pivot (U = D U' with U'
        // unit upper): the solves then keep the division off their dependency chains.
        let (head, tail) = data.split_at_mut((k + 1) * w);
        let row_k = &mut head[k * w + b + 1..k * w + 2 * b + 1];
        for u in row_k.iter_mut() {
            *u *= inv;
        }
        let row_k = &*row_k;
        for r in 1..=b {
            // Row k + r: column k sits at offset b − r, columns k+1..=k+b follow.
            let base = (r - 1) * w + b - r;
            let a_ik = tail[base];
            tail[base] = a_ik * inv;
            let row_i = &mut tail[base + 1..base + 1 + b];
            for (a, u) in row_i.iter_mut().zip(row_k) {
                *a -= a_ik * u;
            }
        }
    }
    // The padding's pivots are 1.
    for v in &mut inv_diag[n..] {
        *v = 1.0;
    }
    Ok(())
}

fn solve<const B: usize, const D: usize>(
    data: &[f64],
    inv_diag: &[f64],
    x: &mut [[f64; D]],
    b: usize,
) {
    let b = bw::<B>(b);
    let w = 2 * b + 1;
    let rows = x.len();
    // L y = rhs. Rows before b only see part of the band: their missing entries are
    // outside the matrix, so start at row b for the fixed-length loop.
    for i in 1..rows.min(b) {
        let mut acc = x[i];
        for j in 0..i {
            let l = data[i * w + j + b - i];
            for d in 0..D {
                acc[d] -= l * x[j][d];
            }
        }
        x[i] = acc;
    }
    for i in b..rows {
        let row = &data[i * w..i * w + b];
        let mut acc = x[i];
        for (l, xj) in row.iter().zip(&x[i - b..i]) {
            for d in 0..D {
                acc[d] -= l * xj[d];
            }
        }
        x[i] = acc;
    }
    // U x = y with U = D U': x_i = y_i / u_ii − Σ_j u'_ij x_j. The padding rows are the
    // identity, so the fixed-length loop starts below them.
    for i in (0..rows - b).rev() {
        let row = &data[i * w + b + 1..i * w + 2 * b + 1];
        let mut acc = x[i];
        for a in &mut acc {
            *a *= inv_diag[i];
        }
        for (u, xj) in row.iter().zip(&x[i + 1..=i + b]) {
            for d in 0..D {
                acc[d] -= u * xj[d];
            }
        }
        x[i] = acc;
    }
}

fn solve_transposed<const B: usize, const D: usize>(
    data: &[f64],
    inv_diag: &[f64],
    x: &mut [[f64; D]],
    b: usize,
) {
    let b = bw::<B>(b);
    let w = 2 * b + 1;
    let rows = x.len();
    // Uᵀ y = rhs with Uᵀ = U'ᵀ D: solve the unit lower U'ᵀ z = rhs by rows of U', then
    // y = D⁻¹ z, which stays off the dependency chain.
    for i in 0..rows - b {
        let zi = x[i];
        let row = &data[i * w + b + 1..i * w + 2 * b + 1];
        for (u, xj) in row.iter().zip(&mut x[i + 1..=i + b]) {
            for d in 0..D {
                xj[d] -= u * zi[d];
            }
        }
        let mut yi = zi;
        for v in &mut yi {
            *v *= inv_diag[i];
        }
        x[i] = yi;
    }
    // Lᵀ x = y, by rows of L (the padding rows of L are zero).
    for i in (b..rows - b).rev() {
        let xi = x[i];
        let row = &data[i * w..i * w + b];
        for (l, xj) in row.iter().zip(&mut x[i - b..i]) {
            for d in 0..D {
                xj[d] -= l * xi[d];
            }
        }
    }
    for i in (1..b.min(rows - b)).rev() {
        let xi = x[i];
        for j in 0..i {
            let l = data[i * w + j + b - i];
            for d in 0..D {
                x[j][d] -= l * xi[d];
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
        /// LU solves agree with a dense solve for random diagonally dominant band matrices.
        #[test]
        fn matches_dense(n in 1usize..40, b in prop_oneof![Just(4usize), Just(6), Just(8), 1usize..5], seed in any::<u64>()) {
            let mut rng = seed;
            let mut next = || {
                rng = rng.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1_442_695_040_888_963_407);
                ((rng >> 11) as f64 / (1u64 << 53) as f64) - 0.5
            };
            let mut band = BandMatrix::new(n, b);
            band.clear();
            let mut dense = DMatrix::zeros(n, n);
            for i in 0..n {
                for j in i.saturating_sub(b)..=(i + b).min(n - 1) {
                    let v = if i == j { 10.0 + next() } else { next() };
                    band.set(i, j, v);
                    dense[(i, j)] = v;
                }
            }
            let mut rhs: Vec<[f64; 2]> = (0..n).map(|_| [next(), next()]).collect();
            let orig = rhs.clone();
            rhs.resize(band.padded_len(), [0.0; 2]);
            let mut x = rhs.clone();
            let mut xt = rhs.clone();
            prop_assert!(band.factorize().is_ok());
            band.solve(&mut x);
            band.solve_transposed(&mut xt);
            let lu = dense.clone().lu();
            let lut = dense.transpose().lu();
            for d in 0..2 {
                let r = nalgebra::DVector::from_iterator(n, orig.iter().map(|v| v[d]));
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
        band.clear();
        band.set(0, 0, 1.0);
        band.set(2, 2, 1.0);
        assert_eq!(band.factorize(), Err(1));
        let mut band = BandMatrix::new(2, 4);
        band.clear();
        band.set(0, 0, f64::NAN);
        assert_eq!(band.factorize(), Err(0));
        assert_eq!(band.get(1, 0), 0.0);
    }
}
