//! Coefficient functions of the SO(3)/SE(3) closed forms, each accurate over
//! [0, π]: a Taylor series in θ² below [`SERIES_BELOW`], the closed form above
//! it, where its cancellation error is a few 1e-14 relative at most (c3 at θ = 1 is the worst).

/// θ below which the series are used. Eleven terms leave a truncation error
/// under 1e-20 there.
pub(crate) const SERIES_BELOW: f64 = 1.0;

/// Σ_j sign_j t2^j c_j by Horner's rule over `coeffs` (lowest power first).
#[inline]
fn horner(t2: f64, coeffs: &[f64]) -> f64 {
    coeffs.iter().rev().fold(0.0, |acc, c| acc * t2 + c)
}

/// Builds `[(-1)^j / (2j + k)!]` for j = 0..N at compile time.
const fn alternating_inverse_factorials<const N: usize>(k: u32) -> [f64; N] {
    let mut out = [0.0; N];
    let mut j = 0;
    while j < N {
        let mut f = 1.0;
        let mut i = 2;
        while i <= 2 * (j as u32) + k {
            f *= i as f64;
            i += 1;
        }
        out[j] = if j % 2 == 0 { 1.0 / f } else { -1.0 / f };
        j += 1;
    }
    out
}

const TERMS: usize = 11;
const A_COEFFS: [f64; TERMS] = alternating_inverse_factorials(2);
const B_COEFFS: [f64; TERMS] = alternating_inverse_factorials(3);
const C2_COEFFS: [f64; TERMS] = alternating_inverse_factorials(4);
/// c3 = Σ_{j≥0} (−1)^j (j + 1) / (2j + 5)! θ^{2j}
const C3_COEFFS: [f64; TERMS] = {
    let base: [f64; TERMS] = alternating_inverse_factorials(5);
    let mut out = [0.0; TERMS];
    let mut j = 0;
    while j < TERMS {
        out[j] = base[j] * (j as f64 + 1.0);
        j += 1;
    }
    out
};
/// d = (1 − (θ/2) cot(θ/2)) / θ²; its series has non-factorial coefficients.
/// Coefficients |B₂ₙ| / (2n)! for n = 1..8 (B₂ₙ the Bernoulli numbers).
const D_COEFFS: [f64; 8] = [
    1.0 / 12.0,
    1.0 / 720.0,
    1.0 / 30_240.0,
    1.0 / 1_209_600.0,
    1.0 / 47_900_160.0,
    691.0 / 1_307_674_368_000.0,
    7.0 / 523_069_747_200.0,
    3617.0 / 10_670_622_842_880_000.0,
];

/// a(θ) = (1 − cos θ) / θ².
#[inline]
pub(crate) fn a(theta: f64) -> f64 {
    if theta < SERIES_BELOW {
        horner(theta * theta, &A_COEFFS)
    } else {
        // 2 sin²(θ/2) avoids the cancellation of 1 − cos θ.
        let s = (0.5 * theta).sin();
        2.0 * s * s / (theta * theta)
    }
}

/// b(θ) = (θ − sin θ) / θ³.
#[inline]
pub(crate) fn b(theta: f64) -> f64 {
    if theta < SERIES_BELOW {
        horner(theta * theta, &B_COEFFS)
    } else {
        (theta - theta.sin()) / (theta * theta * theta)
    }
}

/// c2(θ) = (θ² + 2 cos θ − 2) / (2θ⁴).
#[inline]
pub(crate) fn c2(theta: f64) -> f64 {
    if theta < SERIES_BELOW {
        horner(theta * theta, &C2_COEFFS)
    } else {
        let t2 = theta * theta;
        (t2 + 2.0 * theta.cos() - 2.0) / (2.0 * t2 * t2)
    }
}

/// c3(θ) = (2θ − 3 sin θ + θ cos θ) / (2θ⁵).
#[inline]
pub(crate) fn c3(theta: f64) -> f64 {
    if theta < SERIES_BELOW {
        horner(theta * theta, &C3_COEFFS)
    } else {
        let t2 = theta * theta;
        (2.0 * theta - 3.0 * theta.sin() + theta * theta.cos()) / (2.0 * t2 * t2 * theta)
    }
}

/// d(θ) = 1/θ² − cot(θ/2) / (2θ), the φ̂² coefficient of the inverse left Jacobian.
#[inline]
pub(crate) fn d(theta: f64) -> f64 {
    if theta < 0.5 {
        horner(theta * theta, &D_COEFFS)
    } else {
        let half = 0.5 * theta;
        (1.0 - half * half.cos() / half.sin()) / (theta * theta)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The series and the closed forms agree where both are accurate.
    #[test]
    fn series_and_closed_forms_meet() {
        for &t in &[0.5f64, 0.8, 0.99] {
            let t2 = t * t;
            let close = |x: f64, y: f64| (x - y).abs() < 1e-13 * y.abs().max(1.0);
            assert!(close(a(t), (1.0 - t.cos()) / t2));
            assert!(close(b(t), (t - t.sin()) / (t2 * t)));
            assert!(close(c2(t), (t2 + 2.0 * t.cos() - 2.0) / (2.0 * t2 * t2)));
            assert!(close(
                c3(t),
                (2.0 * t - 3.0 * t.sin() + t * t.cos()) / (2.0 * t2 * t2 * t)
            ));
            let h = 0.5 * t;
            assert!(close(d(t), 1.0 / t2 - h.cos() / h.sin() / (2.0 * t)));
        }
        // The d series below its own switch point, against the closed form at 0.3.
        let t = 0.3f64;
        let h = 0.5 * t;
        let closed = 1.0 / (t * t) - h.cos() / h.sin() / (2.0 * t);
        assert!((horner(t * t, &D_COEFFS) - closed).abs() < 1e-13);
    }

    #[test]
    fn limits_at_zero() {
        assert_eq!(a(0.0), 0.5);
        assert_eq!(b(0.0), 1.0 / 6.0);
        assert_eq!(c2(0.0), 1.0 / 24.0);
        assert_eq!(c3(0.0), 1.0 / 120.0);
        assert_eq!(d(0.0), 1.0 / 12.0);
    }

    #[test]
    fn continuous_across_switch() {
        // The last float below the switch (series) and the switch itself (closed form).
        let below = f64::from_bits(SERIES_BELOW.to_bits() - 1);
        let above = SERIES_BELOW;
        for (name, f) in [("a", a as fn(f64) -> f64), ("b", b), ("c2", c2), ("c3", c3)] {
            let jump = (f(below) - f(above)).abs();
            assert!(jump < 1e-14, "{name} jumps by {jump}");
        }
        assert!((d(f64::from_bits(0.5f64.to_bits() - 1)) - d(0.5)).abs() < 1e-14);
    }
}
