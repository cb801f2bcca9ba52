//! The odometry against the simulator's ground truth.
#![allow(clippy::unwrap_used)]

use fu_mpc_examples::lidar::{LidarNoise, LidarSim};
use fu_mpc_examples::odometry::{NavState, Odometry, OdometryConfig};
use fu_mpc_examples::scene::Scene;
use fu_mpc_examples::uav::{ImuNoise, ImuSim, body_rate, flat_attitude};
use lidar_kinematics::{AngleSample, EncoderConfig, KinematicChain, LidarSensor};
use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};

/// A horizontal circle of radius 1.5 m at 1 m/s in the small scene's left room, yawing slowly.
struct Circle;

impl Circle {
    const C: [f64; 3] = [3.0, 3.0, 1.5];
    const R: f64 = 1.5;
    const W: f64 = 1.0 / 1.5;

    fn position(t: f64) -> Vector3<f64> {
        let (s, c) = (Self::W * t).sin_cos();
        Vector3::new(
            Self::C[0] + Self::R * c,
            Self::C[1] + Self::R * s,
            Self::C[2],
        )
    }

    fn velocity(t: f64) -> Vector3<f64> {
        let (s, c) = (Self::W * t).sin_cos();
        Vector3::new(-s, c, 0.0) * Self::R * Self::W
    }

    fn acceleration(t: f64) -> Vector3<f64> {
        let (s, c) = (Self::W * t).sin_cos();
        -Vector3::new(c, s, 0.0) * Self::R * Self::W * Self::W
    }

    fn attitude(t: f64) -> UnitQuaternion<f64> {
        flat_attitude(&Self::acceleration(t), 0.3 * t)
    }

    fn pose(t: f64) -> Isometry3<f64> {
        Isometry3::from_parts(Translation3::from(Self::position(t)), Self::attitude(t))
    }
}

/// Flies the circle for `seconds` with the motor at 100 deg/s; returns the largest position
/// error of the odometry at the frame ends \[m\].
fn fly(seconds: f64, lidar_noise: LidarNoise, imu_noise: ImuNoise) -> f64 {
    fly_with(seconds, lidar_noise, imu_noise, OdometryConfig::default())
}

fn fly_with(
    seconds: f64,
    lidar_noise: LidarNoise,
    imu_noise: ImuNoise,
    config: OdometryConfig,
) -> f64 {
    let scene = Scene::small(1);
    let world = scene.world().unwrap();
    let chain = KinematicChain::default();
    let mut lidar = LidarSim::new(LidarSensor::mid360(), chain, lidar_noise, 7);
    let mut imu = ImuSim::new(imu_noise, 200.0, 9);
    let encoder = EncoderConfig::try_new(1 << 16, 0.0).unwrap();
    let omega = 100f64.to_radians();
    let motor = |t: f64| omega * t;
    let mut odo = Odometry::new(
        chain,
        config,
        NavState {
            time: 0.0,
            position: Circle::position(0.0),
            velocity: Circle::velocity(0.0),
            attitude: Circle::attitude(0.0),
        },
    );
    let mut points = Vec::new();
    let mut worst: f64 = 0.0;
    let frames = (seconds * 10.0).round() as u64;
    for k in 0..frames {
        // Times as exact ratios, so frame ends and IMU ticks coincide.
        let t0 = k as f64 / 10.0;
        // IMU samples in [t0, t0 + 0.1).
        for i in 0..20u64 {
            let t = (20 * k + i) as f64 / 200.0;
            let h = 1e-4;
            let rate = body_rate(&Circle::attitude(t - h), &Circle::attitude(t + h), 2.0 * h);
            let s = imu.sample(t, &Circle::attitude(t), &Circle::acceleration(t), &rate);
            odo.push_imu(&s).unwrap();
        }
        lidar
            .frame(&world, k, t0, Circle::pose, motor, &mut points)
            .unwrap();
        let angles: Vec<AngleSample> = (0..=100u64)
            .map(|i| {
                let t = (100 * k + i) as f64 / 1000.0;
                AngleSample::new(t, encoder.quantise(motor(t)).unwrap())
            })
            .collect();
        let t1 = (k + 1) as f64 / 10.0;
        odo.process_frame(t1, &points, &angles).unwrap();
        let err = (odo.state().position - Circle::position(t1)).norm();
        worst = worst.max(err);
    }
    worst
}

#[test]
fn noiseless_odometry_follows_the_truth() {
    let worst = fly(
        10.0,
        LidarNoise { range_std: 0.0 },
        ImuNoise {
            acc_noise: 0.0,
            gyro_noise: 0.0,
            acc_bias_walk: 0.0,
            gyro_bias_walk: 0.0,
        },
    );
    assert!(worst < 0.01, "largest position error {worst} m");
}

#[test]
fn registration_removes_the_imu_drift() {
    let worst = fly(10.0, LidarNoise::default(), ImuNoise::default());
    assert!(worst < 0.05, "largest position error {worst} m");
    // The same flight on the IMU alone (no registration iterations) drifts much further.
    let mut cfg = OdometryConfig::default();
    cfg.registration.iterations = 0;
    let dead_reckoning = fly_with(10.0, LidarNoise::default(), ImuNoise::default(), cfg);
    assert!(
        dead_reckoning > 0.1,
        "dead reckoning stayed within {dead_reckoning} m"
    );
}
