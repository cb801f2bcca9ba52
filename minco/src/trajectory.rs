//! Piecewise-polynomial trajectories: evaluation, sampling and bounds.

use crate::error::{MincoError, Result};
use crate::poly::eval;

/// A piecewise-polynomial trajectory in `D` dimensions, as produced by [`crate::Minco`].
///
/// Piece i is p_i(τ) = Σ_k c_{i,k} τ^k for local time τ ∈ [0, T_i]; the pieces follow each
/// other, so the trajectory is defined on [0, Σ T_i].
///
/// # Example
/// ```
/// use minco::MinimumJerk;
/// # fn main() -> Result<(), minco::MincoError> {
/// let mut m = MinimumJerk::<1>::new(1)?;
/// m.solve(&[[0.0], [0.0], [0.0]], &[[1.0], [0.0], [0.0]], &[], &[2.0])?;
/// let t = m.trajectory()?;
/// assert_eq!(t.duration(), 2.0);
/// assert!((t.position(1.0)?[0] - 0.5).abs() < 1e-12); // symmetric rest-to-rest motion
/// assert!(t.max_speed(64) > 0.9);
/// # Ok(()) }
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct Trajectory<const D: usize> {
    coeffs_per_piece: usize,
    durations: Vec<f64>,
    starts: Vec<f64>,
    coeffs: Vec<[f64; D]>,
}

impl<const D: usize> Trajectory<D> {
    /// Most samples [`Trajectory::sample`] returns.
    pub const MAX_SAMPLES: usize = 1 << 24;

    /// Most samples per piece [`Trajectory::max_derivative_norm`] takes (the optimiser's
    /// limit on its own sampling); larger counts are treated as this one.
    pub const MAX_SAMPLES_PER_PIECE: usize = 1 << 16;

    pub(crate) fn from_parts(
        coeffs_per_piece: usize,
        durations: Vec<f64>,
        coeffs: Vec<[f64; D]>,
    ) -> Self {
        let mut starts = Vec::with_capacity(durations.len());
        let mut t = 0.0;
        for d in &durations {
            starts.push(t);
            t += d;
        }
        Self {
            coeffs_per_piece,
            durations,
            starts,
            coeffs,
        }
    }

    /// Total duration Σ T_i \[s\].
    pub fn duration(&self) -> f64 {
        self.starts.last().copied().unwrap_or(0.0) + self.durations.last().copied().unwrap_or(0.0)
    }

    /// Number of pieces.
    pub fn piece_count(&self) -> usize {
        self.durations.len()
    }

    /// Piece durations \[s\].
    pub fn durations(&self) -> &[f64] {
        &self.durations
    }

    /// Polynomial degree of each piece (2S − 1).
    pub fn degree(&self) -> usize {
        self.coeffs_per_piece - 1
    }

    /// Coefficients of piece `i`, lowest power first, or `None` if there is no such piece.
    pub fn piece_coefficients(&self, i: usize) -> Option<&[[f64; D]]> {
        if i >= self.piece_count() {
            return None;
        }
        // Checked: a wrapped product would select another piece.
        let n = self.coeffs_per_piece;
        let start = n.checked_mul(i)?;
        self.coeffs.get(start..start.checked_add(n)?)
    }

    /// The piece containing time `t` \[s\] and the local time within it.
    ///
    /// Times at a junction belong to the later piece; the end time belongs to the last piece.
    ///
    /// # Errors
    /// [`MincoError::NonFinite`] for a non-finite time, [`MincoError::Infeasible`] outside [0, duration].
    pub fn locate(&self, t: f64) -> Result<(usize, f64)> {
        if !t.is_finite() {
            return Err(MincoError::NonFinite { what: "time" });
        }
        let total = self.duration();
        if t < 0.0 || t > total || self.durations.is_empty() {
            return Err(MincoError::Infeasible("time outside the trajectory"));
        }
        let i = self.starts.partition_point(|&s| s <= t).saturating_sub(1);
        Ok((i, (t - self.starts[i]).min(self.durations[i])))
    }

    /// The `k`-th time derivative at time `t` \[s\] (k = 0: position).
    ///
    /// # Errors
    /// As [`Trajectory::locate`].
    pub fn derivative(&self, t: f64, k: usize) -> Result<[f64; D]> {
        let (i, tau) = self.locate(t)?;
        let n = self.coeffs_per_piece;
        Ok(eval(&self.coeffs[n * i..n * (i + 1)], k, tau))
    }

    /// Position at time `t` \[s\].
    ///
    /// # Errors
    /// As [`Trajectory::locate`].
    pub fn position(&self, t: f64) -> Result<[f64; D]> {
        self.derivative(t, 0)
    }

    /// Velocity at time `t` \[s\].
    ///
    /// # Errors
    /// As [`Trajectory::locate`].
    pub fn velocity(&self, t: f64) -> Result<[f64; D]> {
        self.derivative(t, 1)
    }

    /// Acceleration at time `t` \[s\].
    ///
    /// # Errors
    /// As [`Trajectory::locate`].
    pub fn acceleration(&self, t: f64) -> Result<[f64; D]> {
        self.derivative(t, 2)
    }

    /// Positions at t = 0, dt, 2dt, … up to and including the end time.
    ///
    /// # Errors
    /// [`MincoError::InvalidConfig`] unless `dt` is positive and finite and gives at most
    /// [`Trajectory::MAX_SAMPLES`] samples.
    pub fn sample(&self, dt: f64) -> Result<Vec<(f64, [f64; D])>> {
        let total = self.duration();
        let steps = total / dt;
        // floor(steps) + 1 samples on the grid and possibly the end time: at most
        // MAX_SAMPLES when steps < MAX_SAMPLES − 1.
        if !(dt > 0.0 && dt.is_finite() && steps < (Self::MAX_SAMPLES - 1) as f64) {
            return Err(MincoError::InvalidConfig {
                what: "sample step",
                reason: "must be positive, finite, and give at most MAX_SAMPLES samples",
            });
        }
        // At most MAX_SAMPLES, checked above.
        let steps = steps.floor() as usize;
        let mut out = Vec::with_capacity(steps + 2);
        for k in 0..=steps {
            let t = (k as f64 * dt).min(total);
            out.push((t, self.position(t)?));
        }
        if out.last().is_some_and(|(t, _)| *t < total) {
            out.push((total, self.position(total)?));
        }
        Ok(out)
    }

    /// Largest norm of the `k`-th derivative, by dense sampling: `samples_per_piece` + 1
    /// equally spaced points on every piece, ends included. The true maximum can exceed it by
    /// O(h²) of the curvature of the norm between samples; 64 samples per piece is within
    /// ~0.1 % for MINCO pieces.
    ///
    /// `samples_per_piece` is clamped to 1..=[`Trajectory::MAX_SAMPLES_PER_PIECE`].
    pub fn max_derivative_norm(&self, k: usize, samples_per_piece: usize) -> f64 {
        let n = self.coeffs_per_piece;
        let s = samples_per_piece.clamp(1, Self::MAX_SAMPLES_PER_PIECE);
        let mut best = 0.0f64;
        for (i, &t) in self.durations.iter().enumerate() {
            let c = &self.coeffs[n * i..n * (i + 1)];
            for j in 0..=s {
                let v = eval(c, k, t * j as f64 / s as f64);
                best = best.max(v.iter().map(|x| x * x).sum::<f64>());
            }
        }
        best.sqrt()
    }

    /// Largest speed, by dense sampling (see [`Trajectory::max_derivative_norm`]).
    pub fn max_speed(&self, samples_per_piece: usize) -> f64 {
        self.max_derivative_norm(1, samples_per_piece)
    }

    /// Largest acceleration norm, by dense sampling (see [`Trajectory::max_derivative_norm`]).
    pub fn max_acceleration(&self, samples_per_piece: usize) -> f64 {
        self.max_derivative_norm(2, samples_per_piece)
    }

    /// This trajectory followed by `next`: `next`'s pieces after this one's, so the result
    /// lasts `self.duration() + next.duration()` and at time `self.duration() + t` is where
    /// `next` is at `t`.
    ///
    /// # Example
    /// ```
    /// use minco::MinimumJerk;
    /// # fn main() -> Result<(), minco::MincoError> {
    /// // Two moves from rest to rest: along x, then along y, stopping at the corner.
    /// let rest = |x: f64, y: f64| [[x, y], [0.0; 2], [0.0; 2]];
    /// let mut m = MinimumJerk::<2>::new(1)?;
    /// m.solve(&rest(0.0, 0.0), &rest(2.0, 0.0), &[], &[2.0])?;
    /// let first = m.trajectory()?;
    /// m.solve(&rest(2.0, 0.0), &rest(2.0, 1.0), &[], &[1.5])?;
    /// let both = first.then(&m.trajectory()?)?;
    /// assert_eq!(both.duration(), 3.5);
    /// assert_eq!(both.velocity(2.0)?, [0.0, 0.0]);
    /// assert!((both.position(3.5)?[1] - 1.0).abs() < 1e-12);
    /// # Ok(()) }
    /// ```
    ///
    /// # Errors
    /// [`MincoError::LengthMismatch`] when the two are of different degrees, and
    /// [`MincoError::Infeasible`] when `next` does not start where this one ends (to 1e-9 of
    /// the size of the coordinates), or either point is not finite; velocities and higher
    /// derivatives need not join.
    pub fn then(&self, next: &Trajectory<D>) -> Result<Self> {
        if next.coeffs_per_piece != self.coeffs_per_piece {
            return Err(MincoError::LengthMismatch {
                what: "coefficients per piece (degree + 1)",
                expected: self.coeffs_per_piece,
                found: next.coeffs_per_piece,
            });
        }
        if self.durations.is_empty() {
            return Ok(next.clone());
        }
        if next.durations.is_empty() {
            return Ok(self.clone());
        }
        let end = self.position(self.duration())?;
        let start = next.position(0.0)?;
        let size = end.iter().chain(&start).fold(1.0f64, |m, v| m.max(v.abs()));
        // Written so that a NaN fails the test; an infinite size would pass anything.
        let joins = size.is_finite()
            && end
                .iter()
                .zip(&start)
                .all(|(a, b)| (a - b).abs() <= 1e-9 * size);
        if !joins {
            return Err(MincoError::Infeasible(
                "the next trajectory does not start where this one ends",
            ));
        }
        let mut durations = self.durations.clone();
        durations.extend_from_slice(&next.durations);
        let mut coeffs = self.coeffs.clone();
        coeffs.extend_from_slice(&next.coeffs);
        Ok(Self::from_parts(self.coeffs_per_piece, durations, coeffs))
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use crate::{MinimumJerk, MinimumSnap};

    /// No index past the last piece has coefficients, however large.
    #[test]
    fn piece_coefficients_out_of_range_is_none() {
        let mut m = MinimumSnap::<1>::new(2).unwrap();
        let rest = |p: f64| [[p], [0.0], [0.0], [0.0]];
        m.solve(&rest(0.0), &rest(2.0), &[[1.0]], &[1.0, 1.0])
            .unwrap();
        let t = m.trajectory().unwrap();
        assert_eq!(t.piece_coefficients(0).map(<[_]>::len), Some(8));
        assert_eq!(t.piece_coefficients(1).map(<[_]>::len), Some(8));
        assert_eq!(t.piece_coefficients(2), None);
        assert_eq!(t.piece_coefficients(usize::MAX), None);
        // 8 · (2^(bits−3) + 1) wraps to 8, the start of piece 1.
        assert_eq!(t.piece_coefficients((1 << (usize::BITS - 3)) + 1), None);
    }

    /// A joined trajectory is each part in turn, to the bit; parts of other degrees or that
    /// do not meet are errors.
    #[test]
    fn then_plays_one_trajectory_after_the_other() {
        let mut m = MinimumJerk::<2>::new(2).unwrap();
        let rest = |x: f64, y: f64| [[x, y], [0.0; 2], [0.0; 2]];
        m.solve(&rest(0.0, 0.0), &rest(3.0, 1.0), &[[1.0, 2.0]], &[1.0, 2.0])
            .unwrap();
        let a = m.trajectory().unwrap();
        let mut one = MinimumJerk::<2>::new(1).unwrap();
        one.solve(&rest(3.0, 1.0), &rest(-1.0, 4.0), &[], &[2.5])
            .unwrap();
        let b = one.trajectory().unwrap();
        let ab = a.then(&b).unwrap();
        assert_eq!(ab.piece_count(), 3);
        assert_eq!(ab.duration(), 5.5);
        // Up to the junction, which belongs to the later piece.
        for i in 0..30 {
            let t = f64::from(i) / 10.0;
            assert_eq!(ab.position(t).unwrap(), a.position(t).unwrap(), "{t}");
        }
        for i in 0..=25 {
            let t = f64::from(i) / 10.0;
            let (x, y) = (ab.derivative(3.0 + t, 1).unwrap(), b.velocity(t).unwrap());
            assert!(
                (x[0] - y[0]).abs() < 1e-12 && (x[1] - y[1]).abs() < 1e-12,
                "{t}"
            );
        }
        assert_eq!(ab.position(5.5).unwrap(), b.position(2.5).unwrap());
        // Not where `a` ends.
        let c = b.then(&b);
        assert!(matches!(c, Err(crate::MincoError::Infeasible(_))), "{c:?}");
        // Another degree.
        let mut snap = MinimumSnap::<2>::new(1).unwrap();
        let rest4 = |x: f64, y: f64| [[x, y], [0.0; 2], [0.0; 2], [0.0; 2]];
        snap.solve(&rest4(-1.0, 4.0), &rest4(0.0, 0.0), &[], &[1.0])
            .unwrap();
        let d = b.then(&snap.trajectory().unwrap());
        assert!(
            matches!(d, Err(crate::MincoError::LengthMismatch { .. })),
            "{d:?}"
        );
    }

    /// Parts with a NaN or infinite end or start do not meet; a part without pieces
    /// leaves the other as it is.
    #[test]
    fn then_rejects_parts_that_are_not_finite_and_keeps_empty_ones_out() {
        // Degree 1 (two coefficients per piece): p(t) = c0 + c1 t over one second.
        let line =
            |c0: [f64; 2], c1: [f64; 2]| super::Trajectory::from_parts(2, vec![1.0], vec![c0, c1]);
        let a = line([0.0, 0.0], [1.0, 0.0]);
        for bad in [f64::NAN, f64::INFINITY] {
            let b = line([1.0, bad], [0.0, 1.0]);
            assert!(matches!(a.then(&b), Err(crate::MincoError::Infeasible(_))));
            assert!(matches!(b.then(&a), Err(crate::MincoError::Infeasible(_))));
        }
        let empty = super::Trajectory::<2>::from_parts(2, Vec::new(), Vec::new());
        assert_eq!(a.then(&empty).unwrap().position(1.0).unwrap(), [1.0, 0.0]);
        assert_eq!(empty.then(&a).unwrap().duration(), 1.0);
    }

    /// Sample counts above the cap cost no more than the cap and give its result.
    #[test]
    fn max_derivative_norm_caps_the_sample_count() {
        let mut m = MinimumJerk::<2>::new(2).unwrap();
        let rest = |x: f64| [[x, 0.0], [0.0; 2], [0.0; 2]];
        m.solve(&rest(0.0), &rest(3.0), &[[1.0, 1.0]], &[1.0, 2.0])
            .unwrap();
        let t = m.trajectory().unwrap();
        let cap = super::Trajectory::<2>::MAX_SAMPLES_PER_PIECE;
        let capped = t.max_speed(cap);
        assert!(capped > 0.0);
        assert_eq!(t.max_speed(usize::MAX).to_bits(), capped.to_bits());
        assert_eq!(
            t.max_acceleration(usize::MAX).to_bits(),
            t.max_acceleration(cap).to_bits()
        );
        assert_eq!(
            t.max_derivative_norm(3, cap + 1).to_bits(),
            t.max_derivative_norm(3, cap).to_bits()
        );
        // Ordinary counts are untouched: 0 still means 1.
        assert_eq!(t.max_speed(0).to_bits(), t.max_speed(1).to_bits());
    }
}
