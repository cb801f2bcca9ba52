//! Angle wrapping and unwrapping for motor angles.
//!
//! Motor angles in this crate are radians and may be *unwrapped* (growing
//! without bound while the motor spins) or *wrapped* to a 2π interval, as
//! encoders report them. These helpers convert between the two.
//!
//! # Example
//! ```
//! use lidar_kinematics::angle;
//! use std::f64::consts::PI;
//! let mut a = [0.0, 3.0, -3.0, 0.0]; // wrapped readings of a motor turning positively
//! angle::unwrap_in_place(&mut a);
//! assert!((a[2] - (2.0 * PI - 3.0)).abs() < 1e-15);
//! assert!((a[3] - 2.0 * PI).abs() < 1e-15);
//! ```

use core::f64::consts::{PI, TAU};

/// Wraps an angle to (−π, π]. Non-finite input gives NaN.
///
/// # Example
/// ```
/// use lidar_kinematics::angle::wrap_to_pi;
/// assert!((wrap_to_pi(7.0) - (7.0 - std::f64::consts::TAU)).abs() < 1e-15);
/// ```
#[inline]
pub fn wrap_to_pi(a: f64) -> f64 {
    let w = (a + PI).rem_euclid(TAU) - PI;
    // rem_euclid gives [−π, π); map −π to π.
    if w <= -PI { w + TAU } else { w }
}

/// Wraps an angle to [0, 2π). Non-finite input gives NaN.
///
/// # Example
/// ```
/// use lidar_kinematics::angle::wrap_to_two_pi;
/// assert!((wrap_to_two_pi(-1.0) - (std::f64::consts::TAU - 1.0)).abs() < 1e-15);
/// ```
#[inline]
pub fn wrap_to_two_pi(a: f64) -> f64 {
    let w = a.rem_euclid(TAU);
    // rem_euclid may round up to exactly 2π for tiny negative input.
    if w >= TAU { 0.0 } else { w }
}

/// The signed shortest rotation from `from` to `to`, in (−π, π] (NaN for a non-finite
/// angle).
///
/// # Example
/// ```
/// use lidar_kinematics::angle::difference;
/// assert!((difference(3.0, -3.0) - (std::f64::consts::TAU - 6.0)).abs() < 1e-15);
/// ```
#[inline]
pub fn difference(from: f64, to: f64) -> f64 {
    let d = to - from;
    if d.is_infinite() && from.is_finite() && to.is_finite() {
        // Angles near ±f64::MAX whose difference overflows: each wrapped first.
        return wrap_to_pi(wrap_to_pi(to) - wrap_to_pi(from));
    }
    wrap_to_pi(d)
}

/// The unwrapped angle closest to `previous` that equals `wrapped` modulo 2π.
///
/// Correct whenever the true motion between the two readings is less than π.
///
/// # Example
/// ```
/// use lidar_kinematics::angle::unwrap_next;
/// let a = unwrap_next(6.2, 0.1);
/// assert!((a - (std::f64::consts::TAU + 0.1)).abs() < 1e-12);
/// ```
#[inline]
pub fn unwrap_next(previous: f64, wrapped: f64) -> f64 {
    previous + difference(previous, wrapped)
}

/// Unwraps a sequence of angle readings in place, keeping the first one as it is.
///
/// Correct whenever consecutive readings differ by less than π of true motion.
pub fn unwrap_in_place(angles: &mut [f64]) {
    for i in 1..angles.len() {
        angles[i] = unwrap_next(angles[i - 1], angles[i]);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        #[test]
        fn wrap_to_pi_range_and_congruence(a in -1e4f64..1e4) {
            let w = wrap_to_pi(a);
            prop_assert!(w > -PI && w <= PI);
            let k = ((a - w) / TAU).round();
            prop_assert!((a - w - k * TAU).abs() < 1e-9);
        }

        #[test]
        fn wrap_to_two_pi_range(a in -1e4f64..1e4) {
            let w = wrap_to_two_pi(a);
            prop_assert!((0.0..TAU).contains(&w));
        }

        /// Unwrapping the wrapped samples of a smooth motion recovers it.
        #[test]
        fn unwrap_recovers_motion(start in -10.0f64..10.0, steps in proptest::collection::vec(-3.0f64..3.0, 1..50)) {
            let mut truth = vec![start];
            for s in &steps {
                let last = truth[truth.len() - 1];
                truth.push(last + s);
            }
            let mut wrapped: Vec<f64> = truth.iter().map(|&a| wrap_to_pi(a)).collect();
            wrapped[0] = truth[0];
            unwrap_in_place(&mut wrapped);
            for (u, t) in wrapped.iter().zip(&truth) {
                prop_assert!((u - t).abs() < 1e-9);
            }
        }
    }

    #[test]
    fn edges() {
        assert_eq!(wrap_to_pi(PI), PI);
        assert_eq!(wrap_to_pi(-PI), PI);
        assert!(wrap_to_pi(f64::NAN).is_nan());
        assert!(wrap_to_two_pi(f64::INFINITY).is_nan());
        assert_eq!(wrap_to_two_pi(-1e-300), 0.0);
    }
}
