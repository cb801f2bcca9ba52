//! Inputs at the edges of the floats and counts: typed errors, never NaN passed on as a
//! number or a panic.
#![allow(clippy::unwrap_used)]

use minco::{MincoError, MinimumJerk, MinimumSnap, Optimizer, OptimizerConfig, Trajectory};

/// Durations whose powers over- or underflow are bad durations, not an effort of NaN.
#[test]
fn durations_whose_powers_overflow_are_refused() {
    let mut jerk = MinimumJerk::<1>::new(1).unwrap();
    let (head, tail) = ([[0.0], [0.0], [0.0]], [[1.0], [0.0], [0.0]]);
    for t in [1e62, 1e70, 1e-60] {
        let got = jerk.solve(&head, &tail, &[], &[t]);
        assert!(matches!(got, Err(MincoError::BadDuration { .. })), "{t}");
    }
    jerk.solve(&head, &tail, &[], &[1e30]).unwrap();
    assert!(jerk.energy().is_finite());
    let mut snap = MinimumSnap::<1>::new(1).unwrap();
    let (head, tail) = ([[0.0]; 4], [[1.0], [0.0], [0.0], [0.0]]);
    let got = snap.solve(&head, &tail, &[], &[1e-40]);
    assert!(matches!(got, Err(MincoError::BadDuration { .. })));
    snap.solve(&head, &tail, &[], &[1e-20]).unwrap();
    assert!(snap.energy().is_finite());
}

/// A sample step that would give more than `MAX_SAMPLES` samples is refused, counting the
/// grid's first sample and the end time.
#[test]
fn sampling_stays_within_its_limit() {
    let mut jerk = MinimumJerk::<1>::new(1).unwrap();
    jerk.solve(&[[0.0], [0.0], [0.0]], &[[1.0], [0.0], [0.0]], &[], &[1.0])
        .unwrap();
    let traj: Trajectory<1> = jerk.trajectory().unwrap();
    let max = Trajectory::<1>::MAX_SAMPLES as f64;
    for dt in [1.0 / max, 1.0 / (max - 1.0)] {
        assert!(traj.sample(dt).is_err(), "{dt}");
    }
    assert_eq!(traj.sample(0.25).unwrap().len(), 5);
}

/// A path of `usize::MAX` (zero-sized) points is a configuration error, not an overflow.
#[test]
fn a_path_too_long_to_count_is_an_error() {
    let path = vec![[0.0f64; 0]; usize::MAX];
    let got = Optimizer::<3, 0>::new(OptimizerConfig::default(), [[]; 3], [[]; 3], &path);
    assert!(matches!(got, Err(MincoError::InvalidConfig { .. })));
}

/// A path whose segments' first durations overflow is named as such up front, not later as a
/// bad decision vector.
#[test]
fn segments_too_long_for_the_speed_limit_are_refused() {
    let rest = [[0.0; 3]; 3];
    let mut tail = rest;
    tail[0] = [1.0, 0.0, 0.0];
    let far = [[1e300, 0.0, 0.0]];
    let got = Optimizer::<3, 3>::new(OptimizerConfig::default(), rest, tail, &far);
    assert!(
        matches!(got, Err(MincoError::InvalidConfig { .. })),
        "{got:?}"
    );
    let slow = OptimizerConfig::default().with_limits(1e-308, 2.0);
    let got = Optimizer::<3, 3>::new(slow, rest, tail, &[[0.5, 0.0, 0.0]]);
    assert!(
        matches!(got, Err(MincoError::InvalidConfig { .. })),
        "{got:?}"
    );
    assert!(
        Optimizer::<3, 3>::new(OptimizerConfig::default(), rest, tail, &[[0.5, 0.0, 0.0]]).is_ok()
    );
}

/// Durations short enough that the squared coefficients overflow, though every power of T is
/// in range: the effort reads ∞, not NaN.
#[test]
fn an_effort_that_overflows_is_infinite() {
    let mut snap = MinimumSnap::<1>::new(1).unwrap();
    let (head, tail) = ([[0.0]; 4], [[1.0], [0.0], [0.0], [0.0]]);
    for t in [1e-30, 1e-24, 1e-23] {
        snap.solve(&head, &tail, &[], &[t]).unwrap();
        assert_eq!(snap.energy(), f64::INFINITY, "{t}");
    }
    snap.solve(&head, &tail, &[], &[1.0]).unwrap();
    assert!(snap.energy().is_finite() && snap.energy() > 0.0);
}
