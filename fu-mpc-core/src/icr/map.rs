//! The map state of iCR: cell positions and the prior information Y₀ = Σ₀⁻¹, diagonal or dense.

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::cholesky::llt;
use faer::{Mat, MatRef, Par};
use nalgebra::Point3;

use crate::Result;
use crate::error::{CoreError, invalid, too_large};

/// The prior information of the map cells.
#[derive(Debug, Clone)]
pub(crate) enum Prior {
    /// Independent cells: the diagonal of Y₀.
    Diagonal(Vec<f64>),
    /// A dense Y₀ = Σ₀⁻¹.
    Dense(Mat<f64>),
}

/// The cells of a map and the prior information over their values (m ~ N(μ₀, Σ₀), Y₀ = Σ₀⁻¹),
/// eq. (11) with the measurement model H = I of the paper's evaluation.
///
/// The diagonal prior is the paper's; [`InformationMap::squared_exponential`] builds a
/// correlated prior for small maps, which the reward handles by a dense Cholesky
/// factorisation.
///
/// # Example
/// ```
/// use fu_mpc_core::icr::InformationMap;
/// use nalgebra::Point3;
///
/// let cells: Vec<Point3<f64>> = (0..10).map(|i| Point3::new(f64::from(i), 0.0, 0.0)).collect();
/// let map = InformationMap::diagonal(cells, vec![0.01; 10]).unwrap(); // Σ₀ = 100 I
/// assert_eq!(map.len(), 10);
/// assert!((map.log_det_prior().unwrap() - 10.0 * 0.01f64.ln()).abs() < 1e-12);
/// ```
#[derive(Debug, Clone)]
pub struct InformationMap {
    cells: Vec<Point3<f64>>,
    pub(crate) prior: Prior,
}

fn check_cells(cells: &[Point3<f64>]) -> Result<()> {
    if cells.is_empty() {
        return Err(CoreError::Empty { what: "map cells" });
    }
    if !cells.iter().all(|p| p.iter().all(|v| v.is_finite())) {
        return Err(CoreError::NonFinite {
            what: "cell position",
        });
    }
    Ok(())
}

impl InformationMap {
    /// Most cells of a dense prior ([`InformationMap::squared_exponential`]): 16,384, whose
    /// n × n covariance takes 2 GiB.
    pub const MAX_DENSE_CELLS: usize = 1 << 14;

    /// Independent cells with prior information `information[j]` = 1/σ₀ⱼ² (the paper's
    /// Σ₀ = diag(100) is 0.01 everywhere).
    ///
    /// # Errors
    /// [`CoreError::Empty`] for no cells, [`CoreError::NonFinite`] for a bad position,
    /// [`CoreError::LengthMismatch`], and [`CoreError::InvalidConfig`] for information that is
    /// not positive and finite.
    pub fn diagonal(cells: Vec<Point3<f64>>, information: Vec<f64>) -> Result<Self> {
        check_cells(&cells)?;
        if information.len() != cells.len() {
            return Err(CoreError::LengthMismatch {
                what: "prior information",
                expected: cells.len(),
                found: information.len(),
            });
        }
        if let Some(&bad) = information.iter().find(|y| !(y.is_finite() && **y > 0.0)) {
            return invalid("prior information", bad, "must be positive and finite");
        }
        Ok(Self {
            cells,
            prior: Prior::Diagonal(information),
        })
    }

    /// A correlated prior: Σ₀ᵢⱼ = s² exp(−‖pᵢ − pⱼ‖² / (2ℓ²)) + ε δᵢⱼ (a squared-exponential
    /// kernel over the cell positions, `variance` s², `length_scale` ℓ \[m\], `jitter` ε), and
    /// Y₀ = Σ₀⁻¹ by Cholesky. O(n³) time and n² memory: meant for maps of up to a few thousand
    /// cells, and refused above [`InformationMap::MAX_DENSE_CELLS`].
    ///
    /// # Errors
    /// As [`InformationMap::diagonal`] for the cells; [`CoreError::InvalidConfig`] for more
    /// than [`InformationMap::MAX_DENSE_CELLS`] cells, a
    /// non-positive variance or length scale or a negative jitter;
    /// [`CoreError::NotPositiveDefinite`] if Σ₀ is singular in floating point (raise the
    /// jitter), [`CoreError::NonFinite`] if its inverse overflows (a variance near the
    /// smallest floats).
    pub fn squared_exponential(
        cells: Vec<Point3<f64>>,
        variance: f64,
        length_scale: f64,
        jitter: f64,
    ) -> Result<Self> {
        check_cells(&cells)?;
        if cells.len() > Self::MAX_DENSE_CELLS {
            return too_large(
                "cells",
                cells.len(),
                "at most MAX_DENSE_CELLS for a dense prior",
            );
        }
        if !(variance.is_finite() && variance > 0.0) {
            return invalid("variance", variance, "must be positive and finite");
        }
        if !(length_scale.is_finite() && length_scale > 0.0) {
            return invalid("length_scale", length_scale, "must be positive and finite");
        }
        if !(jitter.is_finite() && jitter >= 0.0) {
            return invalid("jitter", jitter, "must be non-negative and finite");
        }
        let n = cells.len();
        let scale = -0.5 / (length_scale * length_scale);
        let sigma = Mat::from_fn(n, n, |i, j| {
            let k = variance * ((cells[i] - cells[j]).norm_squared() * scale).exp();
            if i == j { k + jitter } else { k }
        });
        let y0 = spd_inverse(sigma, "prior covariance")?;
        Ok(Self {
            cells,
            prior: Prior::Dense(y0),
        })
    }

    /// A dense prior from a covariance Σ₀ given row by row (n × n, symmetric).
    ///
    /// # Errors
    /// As [`InformationMap::squared_exponential`]; [`CoreError::LengthMismatch`] for a matrix
    /// of the wrong size, [`CoreError::NonFinite`] for non-finite entries or an inverse that
    /// overflows.
    pub fn dense_covariance(cells: Vec<Point3<f64>>, covariance: &[f64]) -> Result<Self> {
        check_cells(&cells)?;
        let n = cells.len();
        if covariance.len() != n * n {
            return Err(CoreError::LengthMismatch {
                what: "prior covariance",
                expected: n * n,
                found: covariance.len(),
            });
        }
        if !covariance.iter().all(|v| v.is_finite()) {
            return Err(CoreError::NonFinite {
                what: "prior covariance",
            });
        }
        // Symmetrised, so a tiny asymmetry from the caller's arithmetic does no harm (halved
        // first: entries near f64::MAX do not overflow).
        let sigma = Mat::from_fn(n, n, |i, j| {
            0.5 * covariance[i * n + j] + 0.5 * covariance[j * n + i]
        });
        let y0 = spd_inverse(sigma, "prior covariance")?;
        Ok(Self {
            cells,
            prior: Prior::Dense(y0),
        })
    }

    /// Number of cells n.
    pub fn len(&self) -> usize {
        self.cells.len()
    }

    /// Always false: a map has at least one cell.
    pub fn is_empty(&self) -> bool {
        self.cells.is_empty()
    }

    /// The cell positions p⁽ʲ⁾ \[m\].
    pub fn cells(&self) -> &[Point3<f64>] {
        &self.cells
    }

    /// Whether the prior is dense.
    pub fn is_dense(&self) -> bool {
        matches!(self.prior, Prior::Dense(_))
    }

    /// The diagonal of Y₀.
    pub fn prior_diagonal(&self) -> Vec<f64> {
        match &self.prior {
            Prior::Diagonal(d) => d.clone(),
            Prior::Dense(y) => (0..y.nrows()).map(|i| y[(i, i)]).collect(),
        }
    }

    /// Adds measured information to the diagonal of Y₀ (the EIF update Y ← Y + M of eq. (6)
    /// with a diagonal M), e.g. after executing a control.
    ///
    /// # Errors
    /// [`CoreError::LengthMismatch`], [`CoreError::InvalidConfig`] for negative or
    /// non-finite information, or [`CoreError::NonFinite`] when a sum would overflow (Y₀ is
    /// then left as it was).
    pub fn add_information(&mut self, m: &[f64]) -> Result<()> {
        if m.len() != self.cells.len() {
            return Err(CoreError::LengthMismatch {
                what: "information update",
                expected: self.cells.len(),
                found: m.len(),
            });
        }
        if let Some(&bad) = m.iter().find(|v| !(v.is_finite() && **v >= 0.0)) {
            return invalid("information update", bad, "must be non-negative and finite");
        }
        // Checked before anything changes: a sum that overflows leaves Y₀ as it was.
        let overflows = match &self.prior {
            Prior::Diagonal(d) => d.iter().zip(m).any(|(y, v)| !(y + v).is_finite()),
            Prior::Dense(y) => (0..m.len()).any(|i| !(y[(i, i)] + m[i]).is_finite()),
        };
        if overflows {
            return Err(CoreError::NonFinite {
                what: "prior information after the update",
            });
        }
        match &mut self.prior {
            Prior::Diagonal(d) => d.iter_mut().zip(m).for_each(|(y, v)| *y += v),
            Prior::Dense(y) => (0..m.len()).for_each(|i| y[(i, i)] += m[i]),
        }
        Ok(())
    }

    /// log det Y₀.
    ///
    /// # Errors
    /// [`CoreError::NotPositiveDefinite`] if a dense Y₀ has lost definiteness.
    pub fn log_det_prior(&self) -> Result<f64> {
        let zeros = vec![0.0; self.len()];
        self.log_det_with(&zeros, None)
    }

    /// log det(Y₀ + diag(m)), and, into `inv_diag` when given, the diagonal of its inverse.
    pub(crate) fn log_det_with(&self, m: &[f64], inv_diag: Option<&mut [f64]>) -> Result<f64> {
        match &self.prior {
            Prior::Diagonal(d) => {
                let mut total = 0.0;
                match inv_diag {
                    Some(out) => {
                        for ((o, y0), v) in out.iter_mut().zip(d).zip(m) {
                            let y = y0 + v;
                            total += y.ln();
                            *o = 1.0 / y;
                        }
                    }
                    None => {
                        for (y0, v) in d.iter().zip(m) {
                            total += (y0 + v).ln();
                        }
                    }
                }
                Ok(total)
            }
            Prior::Dense(y0) => {
                let n = y0.nrows();
                let mut y = y0.clone();
                for (i, v) in m.iter().enumerate() {
                    y[(i, i)] += v;
                }
                let l = cholesky(y, "information matrix")?;
                let total = 2.0 * (0..n).map(|i| l[(i, i)].ln()).sum::<f64>();
                if let Some(out) = inv_diag {
                    let inv = inverse_from_factor(l.as_ref());
                    for (i, o) in out.iter_mut().enumerate() {
                        *o = inv[(i, i)];
                    }
                }
                Ok(total)
            }
        }
    }
}

/// The lower Cholesky factor of a symmetric positive definite matrix (sequential, so results
/// do not depend on the thread count).
fn cholesky(mut a: Mat<f64>, what: &'static str) -> Result<Mat<f64>> {
    let n = a.nrows();
    let mut mem = MemBuffer::new(llt::factor::cholesky_in_place_scratch::<f64>(
        n,
        Par::Seq,
        Default::default(),
    ));
    llt::factor::cholesky_in_place(
        a.as_mut(),
        Default::default(),
        Par::Seq,
        MemStack::new(&mut mem),
        Default::default(),
    )
    .map_err(|_| CoreError::NotPositiveDefinite { what })?;
    if !(0..n).all(|i| a[(i, i)].is_finite() && a[(i, i)] > 0.0) {
        return Err(CoreError::NotPositiveDefinite { what });
    }
    Ok(a)
}

/// A⁻¹ from the lower Cholesky factor of A (both triangles filled).
fn inverse_from_factor(l: MatRef<'_, f64>) -> Mat<f64> {
    let n = l.nrows();
    let mut out = Mat::zeros(n, n);
    let mut mem = MemBuffer::new(llt::inverse::inverse_scratch::<f64>(n, Par::Seq));
    llt::inverse::inverse(out.as_mut(), l, Par::Seq, MemStack::new(&mut mem));
    for j in 0..n {
        for i in 0..j {
            out[(i, j)] = out[(j, i)];
        }
    }
    out
}

/// The inverse of a symmetric positive definite matrix; [`CoreError::NonFinite`] when it
/// overflows (a covariance with entries near the smallest floats).
fn spd_inverse(a: Mat<f64>, what: &'static str) -> Result<Mat<f64>> {
    let l = cholesky(a, what)?;
    let inv = inverse_from_factor(l.as_ref());
    for j in 0..inv.ncols() {
        for i in 0..inv.nrows() {
            if !inv[(i, j)].is_finite() {
                return Err(CoreError::NonFinite {
                    what: "inverse of the prior covariance",
                });
            }
        }
    }
    Ok(inv)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn line(n: usize) -> Vec<Point3<f64>> {
        (0..n)
            .map(|i| Point3::new(i as f64 * 0.3, 0.0, 0.0))
            .collect()
    }

    #[test]
    fn dense_and_diagonal_agree_on_a_diagonal_prior() {
        let n = 12;
        let mut cov = vec![0.0; n * n];
        for i in 0..n {
            cov[i * n + i] = 100.0 / (1.0 + i as f64);
        }
        let dense = InformationMap::dense_covariance(line(n), &cov).unwrap();
        let diag =
            InformationMap::diagonal(line(n), (0..n).map(|i| (1.0 + i as f64) / 100.0).collect())
                .unwrap();
        let m: Vec<f64> = (0..n).map(|i| (i as f64 * 0.7).sin().abs()).collect();
        let (mut a, mut b) = (vec![0.0; n], vec![0.0; n]);
        let la = dense.log_det_with(&m, Some(&mut a)).unwrap();
        let lb = diag.log_det_with(&m, Some(&mut b)).unwrap();
        assert!((la - lb).abs() < 1e-10 * lb.abs().max(1.0), "{la} vs {lb}");
        for (x, y) in a.iter().zip(&b) {
            assert!((x - y).abs() < 1e-12 * y.abs().max(1.0));
        }
    }

    #[test]
    fn dense_inverse_diagonal_matches_nalgebra() {
        let map = InformationMap::squared_exponential(line(15), 4.0, 0.5, 1e-3).unwrap();
        let Prior::Dense(y0) = &map.prior else {
            unreachable!()
        };
        let m: Vec<f64> = (0..15).map(|i| 0.1 * f64::from(i)).collect();
        let mut d = vec![0.0; 15];
        let ld = map.log_det_with(&m, Some(&mut d)).unwrap();
        let y =
            nalgebra::DMatrix::from_fn(15, 15, |i, j| y0[(i, j)] + if i == j { m[i] } else { 0.0 });
        let inv = y.clone().try_inverse().unwrap();
        assert!((ld - y.determinant().ln()).abs() < 1e-8 * ld.abs().max(1.0));
        for i in 0..15 {
            assert!((d[i] - inv[(i, i)]).abs() < 1e-8 * inv[(i, i)].abs());
        }
    }

    #[test]
    fn bad_maps_are_errors() {
        assert!(matches!(
            InformationMap::diagonal(vec![], vec![]),
            Err(CoreError::Empty { .. })
        ));
        assert!(matches!(
            InformationMap::diagonal(vec![Point3::new(f64::NAN, 0.0, 0.0)], vec![1.0]),
            Err(CoreError::NonFinite { .. })
        ));
        assert!(InformationMap::diagonal(line(2), vec![1.0]).is_err());
        assert!(InformationMap::diagonal(line(2), vec![1.0, 0.0]).is_err());
        assert!(InformationMap::squared_exponential(line(3), -1.0, 1.0, 0.0).is_err());
        // Too many cells for a dense prior: refused before the n² allocation.
        let many = line(InformationMap::MAX_DENSE_CELLS + 1);
        assert!(matches!(
            InformationMap::squared_exponential(many, 1.0, 1.0, 0.0),
            Err(CoreError::InvalidConfig { .. })
        ));
        // Two coincident cells and no jitter: Σ₀ is singular.
        let twins = vec![Point3::origin(), Point3::origin()];
        assert!(matches!(
            InformationMap::squared_exponential(twins, 1.0, 1.0, 0.0),
            Err(CoreError::NotPositiveDefinite { .. })
        ));
        assert!(InformationMap::dense_covariance(line(2), &[1.0, 0.0, 0.0]).is_err());
        let mut map = InformationMap::diagonal(line(2), vec![1.0, 1.0]).unwrap();
        assert!(map.add_information(&[1.0, -1.0]).is_err());
        assert!(map.add_information(&[1.0]).is_err());
        map.add_information(&[1.0, 2.0]).unwrap();
        assert_eq!(map.prior_diagonal(), vec![2.0, 3.0]);
    }
}
