//! A branch-light `sin_cos` for the per-point hot paths.
//!
//! `f64::sin_cos` calls the platform's `sin` and `cos` separately; on the
//! per-point paths (chain with per-point angles, deskew) those two calls cost
//! more than the rest of the transform. This version reduces the argument by
//! π/2 (Cody–Waite, two-part constant) and evaluates Taylor polynomials on
//! [−π/4, π/4], whose truncation error there is below 1e-17. It agrees with
//! the standard library to a few ulp for |x| ≤ 2^20 rad and falls back to it
//! outside that range and for non-finite input.

use core::f64::consts::FRAC_PI_2;

/// π/2 with its low 20 significand bits cleared: `q * PIO2_HI` is exact for |q| < 2^20.
const PIO2_HI: f64 = f64::from_bits(FRAC_PI_2.to_bits() & !((1u64 << 20) - 1));
/// Low part of the f64 `FRAC_PI_2` (π/2 − f64(π/2) ≈ 6.12e-17).
const PIO2_F64_ERR: f64 = 6.123_233_995_736_766e-17;
/// π/2 − `PIO2_HI`, to double precision.
const PIO2_LO: f64 = (FRAC_PI_2 - PIO2_HI) + PIO2_F64_ERR;
const REDUCE_LIMIT: f64 = 1_048_576.0;
/// Taylor coefficients of (sin r − r)/r³ in powers of r²: (−1)^(j+1)/(2j+3)!.
const SIN: [f64; 7] = [
    -1.0 / 6.0,
    1.0 / 120.0,
    -1.0 / 5040.0,
    1.0 / 362_880.0,
    -1.0 / 39_916_800.0,
    1.0 / 6_227_020_800.0,
    -1.0 / 1_307_674_368_000.0,
];
/// Taylor coefficients of (cos r − 1)/r² in powers of r²: (−1)^(j+1)/(2j+2)!.
const COS: [f64; 8] = [
    -0.5,
    1.0 / 24.0,
    -1.0 / 720.0,
    1.0 / 40_320.0,
    -1.0 / 3_628_800.0,
    1.0 / 479_001_600.0,
    -1.0 / 87_178_291_200.0,
    1.0 / 20_922_789_888_000.0,
];
/// 1.5 · 2^52: adding it rounds any |y| < 2^51 to an integer held in the low mantissa bits.
const ROUND_MAGIC: f64 = 6_755_399_441_055_744.0;

/// Returns `(sin x, cos x)` for any `x`.
#[inline]
pub(crate) fn sin_cos(x: f64) -> (f64, f64) {
    if in_fast_range(x) {
        sin_cos_reduced(x)
    } else {
        sin_cos_slow(x)
    }
}

/// Whether [`sin_cos_reduced`] is accurate for `x` (false for NaN and infinities).
#[inline]
pub(crate) fn in_fast_range(x: f64) -> bool {
    x.abs() < REDUCE_LIMIT
}

#[cold]
#[inline(never)]
fn sin_cos_slow(x: f64) -> (f64, f64) {
    x.sin_cos()
}

/// Returns `(sin x, cos x)`, accurate for [`in_fast_range`] arguments, NaN for non-finite ones.
///
/// Has no branch and no call, so loops over it vectorise; callers check the range once
/// for a whole batch.
#[inline(always)]
pub(crate) fn sin_cos_reduced(x: f64) -> (f64, f64) {
    // Round to the nearest integer by adding 1.5·2^52: `round()` is a libm call on
    // baseline x86-64, this is one add, and the quadrant lands in the low mantissa bits.
    let k = x * core::f64::consts::FRAC_2_PI + ROUND_MAGIC;
    let quadrant = k.to_bits();
    let q = k - ROUND_MAGIC;
    let r = (x - q * PIO2_HI) - q * PIO2_LO;
    let r2 = r * r;
    let r4 = r2 * r2;
    let r8 = r4 * r4;
    // Estrin's scheme: the same Taylor polynomials as Horner's rule with about half the
    // dependency depth, which is what bounds the per-point loops.
    // sin r = r (1 + r² S(r²)), S = −1/3! + r²/5! − … − r¹²/15!
    let s_poly = (SIN[0] + r2 * SIN[1])
        + r4 * (SIN[2] + r2 * SIN[3])
        + r8 * ((SIN[4] + r2 * SIN[5]) + r4 * SIN[6]);
    let s = r + r * r2 * s_poly;
    // cos r = 1 + r² C(r²), C = −1/2! + r²/4! − … + r¹⁴/16!
    let c_poly = (COS[0] + r2 * COS[1])
        + r4 * (COS[2] + r2 * COS[3])
        + r8 * ((COS[4] + r2 * COS[5]) + r4 * (COS[6] + r2 * COS[7]));
    let c = 1.0 + r2 * c_poly;
    // Quadrant q mod 4 → (sin, cos) = (s, c), (c, −s), (−s, −c), (−c, s), chosen without
    // branches so loops over many angles vectorise.
    let odd = quadrant & 1 == 1;
    let (sin, cos) = if odd { (c, s) } else { (s, c) };
    let sin_sign = (quadrant & 2) << 62;
    let cos_sign = (quadrant.wrapping_add(1) & 2) << 62;
    (
        f64::from_bits(sin.to_bits() ^ sin_sign),
        f64::from_bits(cos.to_bits() ^ cos_sign),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn special_values_fall_back() {
        assert!(sin_cos(f64::NAN).0.is_nan());
        assert!(sin_cos(f64::INFINITY).1.is_nan());
        let (s, c) = sin_cos(1e9);
        assert_eq!((s, c), 1e9f64.sin_cos());
    }

    #[test]
    fn quadrant_points() {
        for k in -8..=8 {
            let x = f64::from(k) * FRAC_PI_2;
            let (s, c) = sin_cos(x);
            assert!((s - x.sin()).abs() < 1e-15, "sin at {x}");
            assert!((c - x.cos()).abs() < 1e-15, "cos at {x}");
        }
    }

    proptest! {
        #[test]
        fn matches_std(x in -1.0e5f64..1.0e5) {
            let (s, c) = sin_cos(x);
            prop_assert!((s - x.sin()).abs() <= 4.0 * f64::EPSILON, "sin({x}): {s} vs {}", x.sin());
            prop_assert!((c - x.cos()).abs() <= 4.0 * f64::EPSILON, "cos({x}): {c} vs {}", x.cos());
        }

        #[test]
        fn small_arguments_keep_relative_accuracy(x in -1.0f64..1.0, e in -300i32..0) {
            let x = x * 10f64.powi(e);
            let (s, c) = sin_cos(x);
            prop_assert!((s - x.sin()).abs() <= 2.0 * f64::EPSILON * x.abs());
            prop_assert!((c - x.cos()).abs() <= 2.0 * f64::EPSILON);
        }
    }
}
