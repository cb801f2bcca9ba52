//! Periodic piecewise-linear functions on a uniform grid over one revolution.

use core::f64::consts::TAU;

use crate::{CoreError, Result};

/// A 2π-periodic piecewise-linear function with knots at θ_c = 2π c / N_c.
///
/// Both cost terms of FU-MPC, the localisation cost f(θ) of (16) and the per-step frontier
/// surrogates J_k(θ) of (18), are tables of this type: exact at the knots, linear between
/// them, with the slope of the segment as derivative (the right-hand slope at a knot).
///
/// # Example
/// ```
/// use fu_mpc_core::PeriodicPwl;
/// use std::f64::consts::TAU;
///
/// let f = PeriodicPwl::new(vec![0.0, 1.0, 0.0, -1.0]).unwrap();
/// assert_eq!(f.value(TAU / 4.0), 1.0);
/// let (v, slope) = f.eval(TAU / 8.0);
/// assert!((v - 0.5).abs() < 1e-12 && (slope - 4.0 / TAU).abs() < 1e-12);
/// // Periodic, for any real angle.
/// assert!((f.value(TAU / 4.0 - 3.0 * TAU) - 1.0).abs() < 1e-9);
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct PeriodicPwl {
    values: Vec<f64>,
    /// Knots per radian: N_c / 2π.
    scale: f64,
}

impl PeriodicPwl {
    /// A function from its values at N_c uniformly spaced knots starting at θ = 0.
    ///
    /// # Errors
    /// [`CoreError::Empty`] without knots, [`CoreError::NonFinite`] for a NaN or infinite value
    /// or values so far apart (near ±`f64::MAX`) that a slope between knots overflows.
    pub fn new(values: Vec<f64>) -> Result<Self> {
        if values.is_empty() {
            return Err(CoreError::Empty {
                what: "knot values",
            });
        }
        if values.iter().any(|v| !v.is_finite()) {
            return Err(CoreError::NonFinite { what: "knot value" });
        }
        // Knot counts are far below 2^53.
        #[allow(clippy::cast_precision_loss)]
        let scale = values.len() as f64 / TAU;
        let (lo, hi) = values
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), &v| {
                (l.min(v), h.max(v))
            });
        if !((hi - lo) * scale).is_finite() {
            return Err(CoreError::NonFinite {
                what: "knot value slope",
            });
        }
        Ok(Self { values, scale })
    }

    /// Number of knots N_c.
    pub fn len(&self) -> usize {
        self.values.len()
    }

    /// Always `false`: a function has at least one knot.
    pub fn is_empty(&self) -> bool {
        self.values.is_empty()
    }

    /// The knot values.
    pub fn values(&self) -> &[f64] {
        &self.values
    }

    /// The knot values, for refilling a table in place (the crate keeps them finite).
    pub(crate) fn values_mut(&mut self) -> &mut [f64] {
        &mut self.values
    }

    /// The angle of knot `c` \[rad\].
    pub fn knot(&self, c: usize) -> f64 {
        // Knot indices are far below 2^53.
        #[allow(clippy::cast_precision_loss)]
        let c = c as f64;
        c / self.scale
    }

    /// Value and slope at `theta` \[rad\], any real angle. A non-finite angle gives the value at
    /// knot 0 and slope 0.
    #[inline]
    pub fn eval(&self, theta: f64) -> (f64, f64) {
        let n = self.values.len();
        // Knot counts are far below 2^53.
        #[allow(clippy::cast_precision_loss)]
        let nf = n as f64;
        let mut x = theta * self.scale;
        if (-nf..0.0).contains(&x) {
            // One turn either side: the common case of a horizon's angles (the hot path of
            // the MPC).
            x += nf;
        } else if (nf..2.0 * nf).contains(&x) {
            x -= nf;
        } else if !(0.0..nf).contains(&x) {
            // Wrap into [0, n] without fmod or a libm floor.
            let q = x / nf;
            if q.abs() < 1e15 {
                // |q| < 2^53: the truncation is exact, and a step down makes it the floor.
                #[allow(clippy::cast_possible_truncation, clippy::cast_precision_loss)]
                let mut k = q as i64 as f64;
                if k > q {
                    k -= 1.0;
                }
                x -= nf * k;
            } else {
                x = x.rem_euclid(nf);
            }
        }
        if !x.is_finite() {
            if theta.is_finite() {
                // |θ| near f64::MAX: θ N_c / 2π overflowed; one turn's remainder does not.
                return self.eval(theta.rem_euclid(TAU));
            }
            return (self.values[0], 0.0);
        }
        // x ∈ [0, n], so truncation is the floor (no libm call, no integer division in the
        // MPC's hot path); the wrap may round up to n, which is knot 0.
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        let fi = x as usize;
        #[allow(clippy::cast_precision_loss)]
        let t = x - fi as f64;
        let i = if fi >= n { 0 } else { fi };
        let j = if i + 1 >= n { 0 } else { i + 1 };
        let (a, b) = (self.values[i], self.values[j]);
        (a + t * (b - a), (b - a) * self.scale)
    }

    /// Value at `theta` \[rad\].
    #[inline]
    pub fn value(&self, theta: f64) -> f64 {
        self.eval(theta).0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        #[test]
        fn exact_at_knots_periodic_and_linear_between(
            values in proptest::collection::vec(-10.0f64..10.0, 1..80),
            turns in -5i32..5,
            t in 0.0f64..1.0,
        ) {
            let f = PeriodicPwl::new(values.clone()).unwrap();
            let n = values.len();
            for c in 0..n {
                let th = f.knot(c) + f64::from(turns) * TAU;
                prop_assert!((f.value(th) - values[c]).abs() < 1e-9);
            }
            let c = n / 2;
            let th = f.knot(c) + t / f.scale;
            let (v, s) = f.eval(th);
            let want = values[c] + t * (values[(c + 1) % n] - values[c]);
            prop_assert!((v - want).abs() < 1e-9);
            // The slope matches a central difference inside the segment.
            if t > 0.01 && t < 0.99 {
                let h = 1e-6 / f.scale;
                let fd = (f.value(th + h) - f.value(th - h)) / (2.0 * h);
                prop_assert!((fd - s).abs() <= 1e-5 * (1.0 + s.abs()));
            }
        }
    }

    #[test]
    fn far_angles_wrap_like_a_euclidean_remainder() {
        let f = PeriodicPwl::new((0..72).map(|c| f64::from(c).sin()).collect()).unwrap();
        for th in [
            -1e6,
            -12345.678,
            -TAU,
            -1e-300,
            0.0,
            7.5,
            1e6 + 0.25,
            3e14,
            -3e14,
            1e17,
            1e300,
        ] {
            let x = (th * f.scale).rem_euclid(72.0);
            let (i, t) = (x.floor() as usize % 72, x - x.floor());
            let want = f.values[i] + t * (f.values[(i + 1) % 72] - f.values[i]);
            let got = f.value(th);
            // Both wraps are exact (k N_c is an integer below 2^53), so they agree closely.
            assert!((got - want).abs() <= 1e-12, "θ = {th}: {got} vs {want}");
        }
    }

    #[test]
    fn bad_inputs() {
        assert!(PeriodicPwl::new(vec![]).is_err());
        assert!(PeriodicPwl::new(vec![1.0, f64::NAN]).is_err());
        let f = PeriodicPwl::new(vec![2.0, 3.0]).unwrap();
        assert_eq!(f.eval(f64::NAN), (2.0, 0.0));
        assert_eq!(f.eval(f64::INFINITY), (2.0, 0.0));
    }
}
