//! Inline `exp`, `atan2` and `acos` for the frontier surrogates' hot loop.
//!
//! Branch-free (selects only) and inlined, so a loop over targets vectorises, which calls into
//! libm prevent. The kernels are fdlibm's (exp: Remez rational on |r| ≤ ln2/2; atan: odd
//! polynomial on |s| ≤ 7/16), both below one ulp there.

use core::f64::consts::{FRAC_PI_2, FRAC_PI_6, LOG2_E, PI};

/// Smallest argument [`exp_in_range`] accepts: e^x stays a normal number above it.
pub(crate) const EXP_MIN: f64 = -708.0;

/// 1.5 · 2^52: adding it rounds to an integer, no `round` call needed.
const SHIFT: f64 = 6_755_399_441_055_744.0;
/// ln 2 split so that k · LN2_HI is exact for |k| < 2^11.
const LN2_HI: f64 = 0.693_147_180_369_123_8;
const LN2_LO: f64 = 1.908_214_929_270_587_7e-10;
// fdlibm's e_exp.c coefficients.
const P1: f64 = 0.166_666_666_666_666_02;
const P2: f64 = -0.002_777_777_777_701_559_3;
const P3: f64 = 6.613_756_321_437_934e-5;
const P4: f64 = -1.653_390_220_546_525_2e-6;
const P5: f64 = 4.138_136_797_057_238_5e-8;

/// e^x for [`EXP_MIN`] ≤ x ≤ 0 (error ≤ 1 ulp); other inputs give meaningless values, never
/// a panic.
#[inline]
pub(crate) fn exp_in_range(x: f64) -> f64 {
    // kt = SHIFT + k with k = round(x / ln 2); the low bits of kt hold k.
    let kt = x * LOG2_E + SHIFT;
    let kf = kt - SHIFT;
    let hi = x - kf * LN2_HI;
    let lo = kf * LN2_LO;
    let r = hi - lo;
    let t = r * r;
    let c = r - t * (P1 + t * (P2 + t * (P3 + t * (P4 + t * P5))));
    let y = 1.0 - ((lo - (r * c) / (2.0 - c)) - hi);
    // 2^k from its exponent bits: SHIFT's low 12 bits are zero, so they hold k + 1023
    // (in [2, 1023] here) and the shift drops everything above.
    let scale = f64::from_bits(kt.to_bits().wrapping_add(1023) << 52);
    y * scale
}

// fdlibm's s_atan.c coefficients: atan(s) ≈ s − s (AT[0] s² + AT[1] s⁴ + …).
const AT: [f64; 11] = [
    0.333_333_333_333_329_3,
    -0.199_999_999_998_764_83,
    0.142_857_142_725_034_66,
    -0.111_111_104_054_623_56,
    0.090_908_871_334_365_07,
    -0.076_918_762_050_448_3,
    0.066_610_731_373_875_31,
    -0.058_335_701_337_905_735,
    0.049_768_779_946_159_324,
    -0.036_531_572_744_216_916,
    0.016_285_820_115_365_782,
];
/// tan(π/12) = 2 − √3.
const TAN_PI_12: f64 = 0.267_949_192_431_122_8;
const SQRT3: f64 = 1.732_050_807_568_877_2;
/// π/6 − FRAC_PI_6, π/2 − FRAC_PI_2 and π − PI.
const FRAC_PI_6_LO: f64 = -5.360_408_832_255_455e-17;
const FRAC_PI_2_LO: f64 = 6.123_233_995_736_766e-17;
const PI_LO: f64 = 1.224_646_799_147_353_2e-16;

/// atan(s) for |s| ≤ 7/16; even and odd powers split to shorten the dependency chain.
#[inline]
fn atan_poly(s: f64) -> f64 {
    let z = s * s;
    let w = z * z;
    let s1 = z * (AT[0] + w * (AT[2] + w * (AT[4] + w * (AT[6] + w * (AT[8] + w * AT[10])))));
    let s2 = w * (AT[1] + w * (AT[3] + w * (AT[5] + w * (AT[7] + w * AT[9]))));
    s - s * (s1 + s2)
}

/// atan2(y, x) for finite inputs (absolute error < 1e-15), with libm's signs at zeros:
/// atan2(±0, +0) = ±0, atan2(±0, −0) = ±π; NaN in, NaN out.
#[inline]
pub(crate) fn atan2(y: f64, x: f64) -> f64 {
    let ax = x.abs();
    let ay = y.abs();
    // Octant reduction: t = min/max ∈ [0, 1].
    let swap = ay > ax;
    let num = if swap { ax } else { ay };
    let den = if swap { ay } else { ax };
    let t = if den == 0.0 { 0.0 } else { num / den };
    // atan(t) = π/6 + atan((√3 t − 1)/(t + √3)) brings t ∈ (tan(π/12), 1] into the kernel's
    // short range.
    let big = t > TAN_PI_12;
    let s = if big {
        (SQRT3 * t - 1.0) / (t + SQRT3)
    } else {
        t
    };
    let p = atan_poly(s);
    // The π/6, π/2 and π offsets carry their rounding errors (…_LO) separately, so each
    // step rounds once.
    let a = if big {
        FRAC_PI_6 + (p + FRAC_PI_6_LO)
    } else {
        p
    };
    let a = if swap {
        FRAC_PI_2 - (a - FRAC_PI_2_LO)
    } else {
        a
    };
    let a = if x.is_sign_negative() {
        PI - (a - PI_LO)
    } else {
        a
    };
    a.copysign(y)
}

/// acos(x) for x ∈ [−1, 1] (absolute error < 1e-15); NaN outside.
#[inline]
pub(crate) fn acos(x: f64) -> f64 {
    // (1 − x)(1 + x) rather than 1 − x², which loses the small difference near ±1.
    atan2(((1.0 - x) * (1.0 + x)).sqrt(), x)
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// |a − b| in units of b's last place.
    fn ulps(a: f64, b: f64) -> f64 {
        let ulp = f64::from_bits(b.abs().to_bits() + 1) - b.abs();
        (a - b).abs() / ulp
    }

    #[test]
    fn exp_edges() {
        assert_eq!(exp_in_range(0.0), 1.0);
        assert_eq!(exp_in_range(-0.0), 1.0);
        for x in [
            EXP_MIN,
            -707.5,
            -1e-300,
            -5e-324,
            -0.5 * core::f64::consts::LN_2,
        ] {
            assert!(ulps(exp_in_range(x), x.exp()) <= 1.0, "{x}");
        }
        // Every output near the lower end is still normal.
        assert!(exp_in_range(EXP_MIN).is_normal());
    }

    #[test]
    fn atan2_edges() {
        assert_eq!(atan2(0.0, 1.0).to_bits(), 0f64.to_bits());
        assert_eq!(atan2(-0.0, 1.0).to_bits(), (-0f64).to_bits());
        assert_eq!(atan2(0.0, 0.0).to_bits(), 0f64.to_bits());
        assert_eq!(atan2(-0.0, 0.0).to_bits(), (-0f64).to_bits());
        assert_eq!(atan2(0.0, -0.0).to_bits(), PI.to_bits());
        assert_eq!(atan2(-0.0, -0.0).to_bits(), (-PI).to_bits());
        assert_eq!(atan2(0.0, -1.0).to_bits(), PI.to_bits());
        assert_eq!(atan2(-0.0, -1.0).to_bits(), (-PI).to_bits());
        for (y, x) in [
            (1.0, 0.0),
            (1.0, -0.0),
            (-1.0, 0.0),
            (1.0, 1.0),
            (-1.0, -1.0),
            (1e-300, 1.0),
            (1.0, 1e-300),
            (1e300, -1e-300),
            (TAN_PI_12, 1.0),
            (5e-324, -1.0),
            (5e-324, 5e-324),
            (-1e-310, 3e-310),
            (1e-320, -1e300),
            (f64::MAX, f64::MAX),
            (-f64::MAX, 1.0),
        ] {
            assert!((atan2(y, x) - y.atan2(x)).abs() <= 1e-15, "{y} {x}");
        }
        assert!(ulps(atan2(1e-300, 1.0), 1e-300) <= 1.0);
    }

    #[test]
    fn acos_edges() {
        assert_eq!(acos(1.0), 0.0);
        assert_eq!(acos(-1.0).to_bits(), PI.to_bits());
        assert!(acos(1.0 + 1e-15).is_nan());
        assert!(acos(f64::NAN).is_nan());
        for x in [
            0.0,
            -0.0,
            1.0 - f64::EPSILON,
            -1.0 + f64::EPSILON,
            0.5,
            -0.5,
        ] {
            assert!((acos(x) - x.acos()).abs() <= 1e-15, "{x}");
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(4096))]

        #[test]
        fn exp_matches_std(x in EXP_MIN..=0.0f64, small in -1.0f64..=0.0) {
            // Within one ulp of libm's (itself within about half an ulp).
            prop_assert!(ulps(exp_in_range(x), x.exp()) <= 1.0, "{}", x);
            prop_assert!(ulps(exp_in_range(small), small.exp()) <= 1.0, "{}", small);
        }

        #[test]
        fn atan2_matches_std(
            y in -1e3f64..1e3,
            x in -1e3f64..1e3,
            ey in -300i32..300,
            ex in -300i32..300,
        ) {
            prop_assert!((atan2(y, x) - y.atan2(x)).abs() <= 1e-15, "{} {}", y, x);
            // Widely different magnitudes.
            let (y, x) = (y * 10f64.powi(ey), x * 10f64.powi(ex));
            prop_assert!((atan2(y, x) - y.atan2(x)).abs() <= 1e-15, "{} {}", y, x);
        }

        #[test]
        fn acos_matches_std(x in -1.0f64..=1.0, e in 1.0f64..16.0) {
            prop_assert!((acos(x) - x.acos()).abs() <= 1e-15, "{}", x);
            // Close to ±1, where acos is steepest.
            let near = 1.0 - 10f64.powf(-e);
            prop_assert!((acos(near) - near.acos()).abs() <= 1e-15, "{}", near);
            prop_assert!((acos(-near) - (-near).acos()).abs() <= 1e-15, "{}", -near);
        }
    }
}
