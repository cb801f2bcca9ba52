//! Finite inputs at the edges of the floats: the right answer or a typed error, never NaN
//! passed on as a number.
#![allow(clippy::unwrap_used)]

use core::f64::consts::{FRAC_PI_4, PI};

use lidar_kinematics::{
    AngleSample, DeskewTarget, Deskewer, FieldOfView, KinematicChain, KinematicsError, LidarSensor,
    MotorLimits, MotorModel, MotorState, NonRepetitivePattern, PoseSample, RangeLimits,
    SpinningPattern, TimedPoint, angle, so3,
};
use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};

/// Directions whose squared length under- or overflows are still directions.
#[test]
fn fields_of_view_take_any_non_zero_length() {
    let band = FieldOfView::band(-0.1, 0.1).unwrap();
    for x in [1.0, 1e155, 1e300, f64::MAX, 1e-162, 1e-300, 5e-324] {
        assert!(band.contains(&Vector3::new(x, 0.0, 0.0)), "{x}");
        assert!(!band.contains(&Vector3::new(0.0, 0.0, x)), "{x} up");
    }
    assert!(!band.contains(&Vector3::zeros()));
    assert!(!band.contains(&Vector3::new(f64::NAN, 0.0, 0.0)));
    let far = LidarSensor::new(
        SpinningPattern::try_new(vec![0.0], 360, 0.1).unwrap(),
        RangeLimits::try_new(0.0, 1e300).unwrap(),
    )
    .with_field_of_view(band);
    assert!(far.sees_in_lidar_frame(&Point3::new(1e160, 0.0, 0.0)));
    assert!(far.sees_in_lidar_frame(&Point3::new(1e-170, 0.0, 0.0)));
    assert!(!far.sees_in_lidar_frame(&Point3::new(1e160, 0.0, 1e160)));
    assert!(!far.sees_in_lidar_frame(&Point3::new(f64::MAX, 0.0, 0.0)));
    assert!(!far.sees_in_lidar_frame(&Point3::origin()));
}

/// A rotation vector whose squared norm overflows still gives a unit quaternion.
#[test]
fn exp_of_a_huge_rotation_vector_is_a_rotation() {
    for x in [1.3e154, 1.35e154, 1e300, f64::MAX] {
        let q = so3::exp(&Vector3::new(x, 0.0, 0.0));
        assert!(q.coords.iter().all(|v| v.is_finite()), "{x}");
        assert!((q.norm() - 1.0).abs() < 1e-12, "{x}");
    }
}

/// An angle that overflows is an error, and a rollout that would overflow leaves its output
/// as it was.
#[test]
fn motor_angles_that_overflow_are_errors() {
    let model = MotorModel::new(MotorLimits::try_new(-1e308, 1e308, 1e308).unwrap());
    let nonfinite = |r: Result<MotorState, KinematicsError>| {
        matches!(r, Err(KinematicsError::NonFinite { .. }))
    };
    assert!(nonfinite(model.step(
        MotorState::new(1e308, 0.0),
        1e308,
        10.0
    )));
    assert!(nonfinite(model.step_speed(
        MotorState::new(1e308, 0.0),
        1e308,
        10.0
    )));
    assert!(nonfinite(MotorModel::default().step(
        MotorState::new(0.0, 1.0),
        1.0,
        f64::MAX
    )));
    let start = MotorState::new(1e308, 1.0);
    let mut out = [MotorState::new(7.0, 7.0); 4];
    let got = model.rollout_into(start, &[1e308; 3], 1.0, &mut out);
    assert!(matches!(got, Err(KinematicsError::NonFinite { .. })));
    assert_eq!(out, [MotorState::new(7.0, 7.0); 4]);
    // Large but finite: fine.
    let ok = model
        .rollout(MotorState::new(0.0, 0.0), &[1.0; 3], 1e100)
        .unwrap();
    assert!(ok.iter().all(|s| s.theta.is_finite()));
}

/// Poses so far out that composing them with the target frame overflows: an error, as the
/// docs say, not NaN points.
#[test]
fn deskew_into_a_body_frame_that_overflows_is_an_error() {
    let body = Isometry3::from_parts(
        Translation3::new(1.5e308, 1.5e308, 0.0),
        UnitQuaternion::from_euler_angles(0.0, 0.0, FRAC_PI_4),
    );
    let poses = [PoseSample::new(0.0, body), PoseSample::new(1.0, body)];
    let angles = [AngleSample::new(0.0, 0.0), AngleSample::new(1.0, 0.0)];
    let points = [TimedPoint::new(0.5, Point3::new(1.0, 0.0, 0.0))];
    let got = Deskewer::new(KinematicChain::default()).deskew_to_vec(
        &poses,
        &angles,
        &points,
        DeskewTarget::BodyAt(0.5),
    );
    assert!(
        matches!(got, Err(KinematicsError::NonFinite { .. })),
        "{got:?}"
    );
}

/// Beam patterns whose time offsets or phases would overflow are refused.
#[test]
fn patterns_whose_offsets_or_phases_overflow_are_refused() {
    let (lo, hi) = (-0.1, 0.9);
    assert!(NonRepetitivePattern::try_new(20_000, 1e304, 4, lo, hi, 1.0, 61.8).is_err());
    assert!(NonRepetitivePattern::try_new(100, 0.1, 4, lo, hi, f64::MAX, 61.8).is_err());
    assert!(NonRepetitivePattern::try_new(100, 0.1, 4, lo, hi, 1.0, f64::MAX).is_err());
    assert!(NonRepetitivePattern::try_new(20_000, 1e300, 4, lo, hi, 1e6, 1e6).is_ok());
}

/// The shortest rotation between angles whose difference overflows.
#[test]
fn angle_differences_near_the_largest_floats() {
    for (a, b) in [
        (-1e300, f64::MAX),
        (f64::MAX, -f64::MAX),
        (-f64::MAX, 1e308),
    ] {
        let d = angle::difference(a, b);
        assert!(d > -PI && d <= PI, "{a} {b}: {d}");
    }
    assert!(angle::difference(f64::NAN, 0.0).is_nan());
}
