//! Deskewing a static scene seen under a known constant-velocity motion returns the scene.
//!
//! The body moves with constant world-frame velocity and constant body-frame angular
//! velocity (so linear interpolation and slerp between samples are exact) while the motor
//! turns at constant speed. Points are generated in the LiDAR frame at their own times from
//! known world points; deskewing must return the world points to 1e-9 m.
// A failed unwrap is a failed test.
#![allow(clippy::unwrap_used)]

use lidar_kinematics::{
    AngleSample, DeskewTarget, Deskewer, Extrinsics, KinematicChain, KinematicsError, PoseSample,
    TimedPoint, angle::wrap_to_two_pi, interpolate_pose, so3,
};
use nalgebra::{Isometry3, Point3, Translation3, Vector3};
use proptest::prelude::*;

#[derive(Debug)]
struct Motion {
    p0: Vector3<f64>,
    v: Vector3<f64>,
    rot0: Vector3<f64>,
    omega_body: Vector3<f64>,
    theta0: f64,
    motor_speed: f64,
}

impl Motion {
    fn body(&self, t: f64) -> Isometry3<f64> {
        Isometry3::from_parts(
            Translation3::from(self.p0 + self.v * t),
            so3::exp(&self.rot0) * so3::exp(&(self.omega_body * t)),
        )
    }

    fn theta(&self, t: f64) -> f64 {
        self.theta0 + self.motor_speed * t
    }
}

fn vec3(r: f64) -> impl Strategy<Value = Vector3<f64>> {
    nalgebra::proptest::vector(-r..r, nalgebra::Const::<3>)
}

fn motion() -> impl Strategy<Value = Motion> {
    (
        vec3(20.0),
        vec3(3.0),
        vec3(3.0),
        vec3(2.0),
        -10.0f64..10.0,
        -12.0f64..12.0,
    )
        .prop_map(|(p0, v, rot0, omega_body, theta0, motor_speed)| Motion {
            p0,
            v,
            rot0,
            omega_body,
            theta0,
            motor_speed,
        })
}

fn extrinsics() -> impl Strategy<Value = Extrinsics> {
    (vec3(0.1), vec3(3.0), vec3(0.2), vec3(3.0)).prop_map(|(t1, r1, t2, r2)| {
        Extrinsics::try_new(Isometry3::new(t1, r1), Isometry3::new(t2, r2)).unwrap()
    })
}

const FRAME: f64 = 0.1;

/// Samples of the motion: poses at 200 Hz, wrapped encoder angles at 1 kHz.
fn samples(m: &Motion) -> (Vec<PoseSample>, Vec<AngleSample>) {
    let poses = (0..=20)
        .map(|k| {
            let t = f64::from(k) * 0.005;
            PoseSample::new(t, m.body(t))
        })
        .collect();
    let angles = (0..=100)
        .map(|k| {
            let t = f64::from(k) * 0.001;
            AngleSample::new(t, wrap_to_two_pi(m.theta(t)))
        })
        .collect();
    (poses, angles)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    #[test]
    fn deskew_returns_the_static_scene(
        m in motion(),
        ext in extrinsics(),
        scene in proptest::collection::vec(vec3(40.0), 1..200),
        times in proptest::collection::vec(0.0f64..=FRAME, 200),
        reverse in any::<bool>(),
    ) {
        let chain = KinematicChain::new(ext);
        let world: Vec<Point3<f64>> = scene.into_iter().map(Point3::from).collect();
        let mut points: Vec<TimedPoint> = world
            .iter()
            .zip(&times)
            .map(|(w, &t)| TimedPoint::new(t, chain.world_to_lidar(&m.body(t), m.theta(t), w).unwrap()))
            .collect();
        let mut expected = world;
        if reverse {
            // Points out of time order must give the same answer.
            points.reverse();
            expected.reverse();
        }
        let (poses, angles) = samples(&m);
        let mut deskewer = Deskewer::new(chain);

        let out = deskewer.deskew_to_vec(&poses, &angles, &points, DeskewTarget::World).unwrap();
        for (o, w) in out.iter().zip(&expected) {
            prop_assert!((o - w).norm() < 1e-9, "world error {}", (o - w).norm());
        }

        let end = m.body(FRAME);
        let out = deskewer.deskew_to_vec(&poses, &angles, &points, DeskewTarget::BodyAt(FRAME)).unwrap();
        for (o, w) in out.iter().zip(&expected) {
            let b = end.inverse_transform_point(w);
            prop_assert!((o - b).norm() < 1e-9, "body error {}", (o - b).norm());
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    /// A point's deskew depends on that point alone, bit for bit: deskewing each point on its
    /// own gives the whole frame's answer, whatever the order, with many points exactly on the
    /// sample times where two spans meet. So a frame may be deskewed in chunks.
    #[test]
    fn each_point_is_deskewed_as_in_the_whole_frame(
        m in motion(),
        ext in extrinsics(),
        picks in proptest::collection::vec((0u32..3, 0u32..=100, 0.0f64..=FRAME, vec3(30.0)), 1..150),
    ) {
        let chain = KinematicChain::new(ext);
        let points: Vec<TimedPoint> = picks
            .iter()
            .map(|&(kind, k, t, p)| {
                let t = match kind {
                    // On a pose sample's time, on an angle sample's time, or anywhere.
                    0 => f64::from(k / 5) * 0.005,
                    1 => f64::from(k) * 0.001,
                    _ => t,
                };
                TimedPoint::new(t, Point3::from(p))
            })
            .collect();
        let (poses, angles) = samples(&m);
        let mut deskewer = Deskewer::new(chain);
        for target in [DeskewTarget::World, DeskewTarget::BodyAt(0.05)] {
            let whole = deskewer.deskew_to_vec(&poses, &angles, &points, target).unwrap();
            for (p, w) in points.iter().zip(&whole) {
                let alone = deskewer.deskew_to_vec(&poses, &angles, &[*p], target).unwrap();
                prop_assert_eq!(alone[0], *w, "point at {} s", p.time);
            }
        }
    }
}

/// Without deskew (one pose for the whole frame) the same scene is smeared: the test above is not trivially satisfied.
#[test]
fn ignoring_motion_would_fail() {
    let m = Motion {
        p0: Vector3::zeros(),
        v: Vector3::new(3.0, 0.0, 0.0),
        rot0: Vector3::zeros(),
        omega_body: Vector3::new(0.0, 0.0, 1.0),
        theta0: 0.0,
        motor_speed: 6.0,
    };
    let chain = KinematicChain::default();
    let w = Point3::new(10.0, 5.0, 1.0);
    let t = 0.03;
    let p = chain.world_to_lidar(&m.body(t), m.theta(t), &w).unwrap();
    let naive = chain
        .lidar_to_world(&m.body(0.0), m.theta(0.0), &p)
        .unwrap();
    assert!((naive - w).norm() > 0.1);
}

#[test]
fn bad_input_is_a_typed_error() {
    use KinematicsError as E;
    let mut d = Deskewer::new(KinematicChain::default());
    let poses = [
        PoseSample::new(0.0, Isometry3::identity()),
        PoseSample::new(0.1, Isometry3::identity()),
    ];
    let angles = [AngleSample::new(0.0, 0.0), AngleSample::new(0.1, 1.0)];
    let pts = [TimedPoint::new(0.05, Point3::new(1.0, 0.0, 0.0))];
    let w = DeskewTarget::World;

    assert!(d.deskew_to_vec(&poses, &angles, &pts, w).is_ok());
    assert!(matches!(
        d.deskew_to_vec(&[], &angles, &pts, w),
        Err(E::Empty { .. })
    ));
    assert!(matches!(
        d.deskew_to_vec(&poses, &[], &pts, w),
        Err(E::Empty { .. })
    ));
    let unsorted = [poses[1], poses[0]];
    assert!(matches!(
        d.deskew_to_vec(&unsorted, &angles, &pts, w),
        Err(E::Unsorted { index: 1, .. })
    ));
    let duplicate = [poses[0], poses[0]];
    assert!(matches!(
        d.deskew_to_vec(&duplicate, &angles, &pts, w),
        Err(E::Unsorted { .. })
    ));
    let nan_time = [PoseSample::new(f64::NAN, Isometry3::identity())];
    assert!(matches!(
        d.deskew_to_vec(&nan_time, &angles, &pts, w),
        Err(E::NonFinite { .. })
    ));
    let nan_pose = [
        poses[0],
        PoseSample::new(0.1, Isometry3::translation(f64::INFINITY, 0.0, 0.0)),
    ];
    assert!(matches!(
        d.deskew_to_vec(&nan_pose, &angles, &pts, w),
        Err(E::NonFinite { .. })
    ));
    let nan_angle = [angles[0], AngleSample::new(0.1, f64::NAN)];
    assert!(matches!(
        d.deskew_to_vec(&poses, &nan_angle, &pts, w),
        Err(E::NonFinite { .. })
    ));
    let late = [TimedPoint::new(0.2, Point3::origin())];
    assert!(matches!(
        d.deskew_to_vec(&poses, &angles, &late, w),
        Err(E::TimeOutOfRange { .. })
    ));
    let nan_point_time = [TimedPoint::new(f64::NAN, Point3::origin())];
    assert!(matches!(
        d.deskew_to_vec(&poses, &angles, &nan_point_time, w),
        Err(E::NonFinite { .. })
    ));
    let short_angles = [AngleSample::new(0.0, 0.0), AngleSample::new(0.04, 0.0)];
    assert!(matches!(
        d.deskew_to_vec(&poses, &short_angles, &pts, w),
        Err(E::TimeOutOfRange {
            what: "motor angle samples",
            ..
        })
    ));
    assert!(matches!(
        d.deskew_to_vec(&poses, &angles, &pts, DeskewTarget::BodyAt(1.0)),
        Err(E::TimeOutOfRange { .. })
    ));
    assert!(matches!(
        d.deskew_to_vec(&poses, &angles, &pts, DeskewTarget::BodyAt(f64::NAN)),
        Err(E::NonFinite { .. })
    ));
    // A BodyAt time needs poses only: outside the angle span but inside the pose span is fine.
    let early_angles = [AngleSample::new(0.0, 0.0), AngleSample::new(0.06, 0.6)];
    assert!(
        d.deskew_to_vec(&poses, &early_angles, &pts, DeskewTarget::BodyAt(0.09))
            .is_ok()
    );
    let mut out = [Point3::origin(); 2];
    assert!(matches!(
        d.deskew(&poses, &angles, &pts, w, &mut out),
        Err(E::LengthMismatch { .. })
    ));
    // A single sample is valid at exactly its own time.
    let one_pose = [poses[0]];
    let one_angle = [angles[0]];
    let at0 = [TimedPoint::new(0.0, Point3::new(1.0, 2.0, 3.0))];
    let out = d.deskew_to_vec(&one_pose, &one_angle, &at0, w).unwrap();
    assert!((out[0] - Point3::new(1.0, 2.0, 3.0)).norm() < 1e-15);
}

/// Finite samples whose interpolation would divide by a vanishing gap or subtract past
/// f64::MAX are typed errors, not NaN output.
#[test]
fn finite_samples_that_would_interpolate_to_nan_are_errors() {
    use KinematicsError as E;
    let mut d = Deskewer::new(KinematicChain::default());
    let poses = [
        PoseSample::new(0.0, Isometry3::identity()),
        PoseSample::new(0.1, Isometry3::identity()),
    ];
    let angles = [AngleSample::new(0.0, 0.0), AngleSample::new(0.1, 1.0)];
    let pts = [TimedPoint::new(0.0, Point3::new(1.0, 0.0, 0.0))];
    let w = DeskewTarget::World;
    let fails = |r: Result<Vec<Point3<f64>>, E>, expected: &str| matches!(r, Err(E::NonFinite { what }) if what == expected);
    let gap = "reciprocal of a gap between sample times";

    // 1 / 5e-324 is infinite, and (t − t0) · ∞ at t = t0 is NaN.
    let tiny = f64::from_bits(1);
    let tiny_poses = [
        PoseSample::new(0.0, Isometry3::identity()),
        PoseSample::new(tiny, Isometry3::translation(1.0, 0.0, 0.0)),
    ];
    let tiny_angles = [AngleSample::new(0.0, 0.0), AngleSample::new(tiny, 1.0)];
    assert!(fails(
        d.deskew_to_vec(&tiny_poses, &tiny_angles, &pts, w),
        gap
    ));
    assert!(fails(d.deskew_to_vec(&poses, &tiny_angles, &pts, w), gap));
    assert!(fails(d.deskew_to_vec(&tiny_poses, &angles, &pts, w), gap));
    assert!(matches!(
        interpolate_pose(&tiny_poses, 0.0),
        Err(E::NonFinite { what }) if what == gap
    ));
    // 1 / gap is finite here but 3 / gap is not.
    let small_angles = [AngleSample::new(0.0, 0.0), AngleSample::new(1e-308, 3.0)];
    assert!(fails(
        d.deskew_to_vec(&poses, &small_angles, &pts, w),
        "motor angle rate between samples"
    ));

    // Finite times whose gap overflows: (t − t0) · 0 with t − t0 = ∞.
    let wide_poses = [
        PoseSample::new(-1e308, Isometry3::identity()),
        PoseSample::new(1e308, Isometry3::identity()),
    ];
    let wide_angles = [AngleSample::new(-1e308, 0.0), AngleSample::new(1e308, 1.0)];
    let late = [TimedPoint::new(0.9e308, Point3::new(1.0, 0.0, 0.0))];
    assert!(fails(
        d.deskew_to_vec(&wide_poses, &wide_angles, &late, w),
        "gap between sample times"
    ));
    assert!(matches!(
        interpolate_pose(&wide_poses, 0.9e308),
        Err(E::NonFinite {
            what: "gap between sample times"
        })
    ));

    // Finite angles whose difference overflows: wrap_to_pi(−∞) is NaN.
    let far_angles = [AngleSample::new(0.0, 1e308), AngleSample::new(0.1, -1e308)];
    assert!(fails(
        d.deskew_to_vec(&poses, &far_angles, &pts, w),
        "step between motor angle samples"
    ));

    // Finite positions whose difference overflows: p0 + (−∞) · 0 is NaN.
    let far_poses = [
        PoseSample::new(0.0, Isometry3::translation(1e308, 0.0, 0.0)),
        PoseSample::new(0.1, Isometry3::translation(-1e308, 0.0, 0.0)),
    ];
    let step = "position step between pose samples";
    assert!(fails(d.deskew_to_vec(&far_poses, &angles, &pts, w), step));
    assert!(matches!(
        interpolate_pose(&far_poses, 0.0),
        Err(E::NonFinite { what }) if what == step
    ));

    // The guards leave ordinary samples alone, also large but representable ones.
    let big = [
        PoseSample::new(1e9, Isometry3::translation(1e300, 0.0, 0.0)),
        PoseSample::new(1e9 + 1e-6, Isometry3::translation(-1e300, 0.0, 0.0)),
    ];
    assert!(interpolate_pose(&big, 1e9).is_ok());
    let out = d.deskew_to_vec(&poses, &angles, &pts, w).unwrap();
    assert!(out[0].coords.iter().all(|v| v.is_finite()));
}
