//! Small polynomial helpers shared by the solver and the trajectory.

/// Highest number of coefficients per piece (order s = 4: degree 7).
pub(crate) const MAX_COEFFS: usize = 8;

/// `FALLING[d][k]` = k! / (k − d)! for k ≥ d, else 0: the factor of t^(k−d) in d/dt^d t^k.
pub(crate) const FALLING: [[f64; MAX_COEFFS]; MAX_COEFFS] = {
    let mut t = [[0.0; MAX_COEFFS]; MAX_COEFFS];
    let mut d = 0;
    while d < MAX_COEFFS {
        let mut k = d;
        while k < MAX_COEFFS {
            let mut f = 1.0;
            let mut j = k - d + 1;
            while j <= k {
                f *= j as f64;
                j += 1;
            }
            t[d][k] = f;
            k += 1;
        }
        d += 1;
    }
    t
};

/// Powers t^0..t^7 of `t`: enough for every degree and energy exponent of S ≤ 4.
#[inline(always)]
pub(crate) fn powers(t: f64) -> [f64; MAX_COEFFS] {
    let mut p = [1.0; MAX_COEFFS];
    for k in 1..MAX_COEFFS {
        p[k] = p[k - 1] * t;
    }
    p
}

/// The `deriv`-th derivative at `t` of the polynomial with coefficient rows `c` (lowest first).
#[inline]
pub(crate) fn eval<const D: usize>(c: &[[f64; D]], deriv: usize, t: f64) -> [f64; D] {
    let mut out = [0.0; D];
    // Horner over k = n−1 down to deriv.
    for k in (deriv..c.len()).rev() {
        let f = FALLING[deriv][k];
        for d in 0..D {
            out[d] = out[d] * t + f * c[k][d];
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn falling_factorials() {
        assert_eq!(FALLING[0][5], 1.0);
        assert_eq!(FALLING[1][5], 5.0);
        assert_eq!(FALLING[3][5], 60.0);
        assert_eq!(FALLING[5][5], 120.0);
        assert_eq!(FALLING[6][5], 0.0);
    }

    #[test]
    fn eval_matches_expansion() {
        // p(t) = 1 + 2t + 3t², p' = 2 + 6t, p'' = 6
        let c = [[1.0], [2.0], [3.0]];
        assert_eq!(eval(&c, 0, 2.0), [17.0]);
        assert_eq!(eval(&c, 1, 2.0), [14.0]);
        assert_eq!(eval(&c, 2, 2.0), [6.0]);
        assert_eq!(eval(&c, 3, 2.0), [0.0]);
        assert_eq!(powers(2.0)[4], 16.0);
    }
}
