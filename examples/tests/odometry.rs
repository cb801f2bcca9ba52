//! The odometry against the simulator's ground truth.
#![allow(clippy::unwrap_used)]

use fu_mpc_examples::lidar::{LidarNoise, LidarSim};
use fu_mpc_examples::odometry::{NavState, Odometry, OdometryConfig};
use fu_mpc_examples::scene::Scene;
use fu_mpc_examples::uav::{ImuNoise, ImuSample, ImuSim, body_rate, flat_attitude};
use lidar_kinematics::{AngleSample, EncoderConfig, KinematicChain, LidarSensor};
use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};

/// A flight path: position, velocity, acceleration and yaw over time.
trait Path {
    fn position(t: f64) -> Vector3<f64>;
    fn velocity(t: f64) -> Vector3<f64>;
    fn acceleration(t: f64) -> Vector3<f64>;
    fn yaw(t: f64) -> f64;

    fn attitude(t: f64) -> UnitQuaternion<f64> {
        flat_attitude(&Self::acceleration(t), Self::yaw(t))
    }

    fn pose(t: f64) -> Isometry3<f64> {
        Isometry3::from_parts(Translation3::from(Self::position(t)), Self::attitude(t))
    }
}

/// A horizontal circle of radius 1.5 m at 1 m/s in the small scene's left room, yawing slowly.
struct Circle;

impl Circle {
    const C: [f64; 3] = [3.0, 3.0, 1.5];
    const R: f64 = 1.5;
    const W: f64 = 1.0 / 1.5;
}

impl Path for Circle {
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

    fn yaw(t: f64) -> f64 {
        0.3 * t
    }
}

/// Straight along the x axis at 1 m/s, 1.5 m up, in the middle of a corridor.
struct Straight;

impl Path for Straight {
    fn position(t: f64) -> Vector3<f64> {
        Vector3::new(85.0 + t, 1.5, 1.5)
    }

    fn velocity(_: f64) -> Vector3<f64> {
        Vector3::x()
    }

    fn acceleration(_: f64) -> Vector3<f64> {
        Vector3::zeros()
    }

    fn yaw(_: f64) -> f64 {
        0.0
    }
}

/// Flies the circle for `seconds`; returns the largest position error of the odometry at the
/// frame ends \[m\].
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
    let errors = fly_path::<Circle>(
        &scene,
        seconds,
        lidar_noise,
        imu_noise,
        config,
        Vector3::zeros(),
    );
    errors.iter().map(|e| e.0.norm()).fold(0.0, f64::max)
}

/// The IMU samples of frame `k` of path `P`, at 200 Hz in [k/10, (k + 1)/10).
fn frame_imu<P: Path>(imu: &mut ImuSim, k: u64) -> Vec<ImuSample> {
    (0..20u64)
        .map(|i| {
            // Times as exact ratios, so frame ends and IMU ticks coincide.
            let t = (20 * k + i) as f64 / 200.0;
            let h = 1e-4;
            let rate = body_rate(&P::attitude(t - h), &P::attitude(t + h), 2.0 * h);
            imu.sample(t, &P::attitude(t), &P::acceleration(t), &rate)
        })
        .collect()
}

/// The encoder's angles across frame `k`, every millisecond.
fn frame_angles(encoder: &EncoderConfig, motor: impl Fn(f64) -> f64, k: u64) -> Vec<AngleSample> {
    (0..=100u64)
        .map(|i| {
            let t = (100 * k + i) as f64 / 1000.0;
            AngleSample::new(t, encoder.quantise(motor(t)).unwrap())
        })
        .collect()
}

/// Flies path `P` through `scene` for `seconds` with the motor at 100 deg/s, the odometry
/// starting with `velocity_error` in its velocity; returns its position and velocity errors
/// (estimate − truth) at every frame end \[m, m/s\].
fn fly_path<P: Path>(
    scene: &Scene,
    seconds: f64,
    lidar_noise: LidarNoise,
    imu_noise: ImuNoise,
    config: OdometryConfig,
    velocity_error: Vector3<f64>,
) -> Vec<(Vector3<f64>, Vector3<f64>)> {
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
            position: P::position(0.0),
            velocity: P::velocity(0.0) + velocity_error,
            attitude: P::attitude(0.0),
        },
    );
    let mut points = Vec::new();
    let mut errors = Vec::new();
    let frames = (seconds * 10.0).round() as u64;
    for k in 0..frames {
        let t0 = k as f64 / 10.0;
        for s in frame_imu::<P>(&mut imu, k) {
            odo.push_imu(&s).unwrap();
        }
        lidar
            .frame(&world, k, t0, P::pose, motor, &mut points)
            .unwrap();
        let angles = frame_angles(&encoder, motor, k);
        let t1 = (k + 1) as f64 / 10.0;
        odo.process_frame(t1, &points, &angles).unwrap();
        errors.push((
            odo.state().position - P::position(t1),
            odo.state().velocity - P::velocity(t1),
        ));
    }
    errors
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

#[test]
fn a_featureless_corridor_lets_the_odometry_drift_along_its_axis() {
    // A 200 m corridor, 3 m wide and high: its ends are beyond the LiDAR's range from the
    // middle, so nothing constrains motion along x.
    let corridor = Scene {
        name: "corridor".into(),
        min: Point3::new(0.0, 0.0, 0.0),
        max: Point3::new(200.0, 3.0, 3.0),
        start: Point3::new(85.0, 1.5, 1.5),
        boxes: vec![
            (Point3::new(-1.0, -1.0, -1.0), Point3::new(201.0, 4.0, 0.0)),
            (Point3::new(-1.0, -1.0, 3.0), Point3::new(201.0, 4.0, 4.0)),
            (Point3::new(-1.0, -1.0, 0.0), Point3::new(201.0, 0.0, 3.0)),
            (Point3::new(-1.0, 3.0, 0.0), Point3::new(201.0, 4.0, 3.0)),
            (Point3::new(-1.0, 0.0, 0.0), Point3::new(0.0, 3.0, 3.0)),
            (Point3::new(200.0, 0.0, 0.0), Point3::new(201.0, 3.0, 3.0)),
        ],
    };
    let errors = fly_path::<Straight>(
        &corridor,
        20.0,
        LidarNoise::default(),
        ImuNoise::default(),
        OdometryConfig::default(),
        Vector3::zeros(),
    );
    let rms = |k: usize| {
        (errors.iter().map(|e| e.0[k] * e.0[k]).sum::<f64>() / errors.len() as f64).sqrt()
    };
    let (x, y, z) = (rms(0), rms(1), rms(2));
    assert!(x > 3.0 * y.max(z), "RMS error x {x} m, y {y} m, z {z} m");
    assert!(y < 0.05 && z < 0.05, "RMS error y {y} m, z {z} m");
}

#[test]
fn the_filter_corrects_a_wrong_initial_velocity() {
    // The odometry starts 0.3 m/s off: only the registration's position corrections, through
    // the filter's position–velocity covariance, can reveal it.
    let errors = fly_path::<Circle>(
        &Scene::small(1),
        6.0,
        LidarNoise::default(),
        ImuNoise::default(),
        OdometryConfig::default(),
        Vector3::new(0.3, -0.2, 0.0),
    );
    let (first, last) = (errors[0].1.norm(), errors[errors.len() - 1].1.norm());
    assert!(first > 0.2, "the error is there at first: {first} m/s");
    assert!(last < 0.03, "velocity error after 6 s: {last} m/s");
    // Uncorrected, the error would reach 0.36 m/s × 6 s ≈ 2.2 m.
    let worst = errors.iter().map(|e| e.0.norm()).fold(0.0, f64::max);
    assert!(worst < 0.25, "largest position error {worst} m");
}

/// Beams without a return are deskewed exactly as returns are, and change neither the
/// estimate nor the local map.
#[test]
fn misses_are_deskewed_like_returns_and_change_nothing_else() {
    // A floor and two walls under an open sky.
    let world = fu_mpc_examples::world::World::from_boxes(&[
        (
            Point3::new(-20.0, -20.0, -1.0),
            Point3::new(20.0, 20.0, 0.0),
        ),
        (Point3::new(8.0, -20.0, 0.0), Point3::new(9.0, 20.0, 4.0)),
        (Point3::new(-20.0, 7.0, 0.0), Point3::new(20.0, 8.0, 4.0)),
    ])
    .unwrap();
    let chain = KinematicChain::default();
    let mut lidar =
        LidarSim::new(LidarSensor::mid360(), chain, LidarNoise::default(), 7).with_misses(true);
    let mut imu = ImuSim::new(ImuNoise::default(), 200.0, 9);
    let encoder = EncoderConfig::try_new(1 << 16, 0.0).unwrap();
    let motor = |t: f64| 100f64.to_radians() * t;
    let start = NavState {
        time: 0.0,
        position: Circle::position(0.0),
        velocity: Circle::velocity(0.0),
        attitude: Circle::attitude(0.0),
    };
    let mut with = Odometry::new(chain, OdometryConfig::default(), start);
    let mut without = with.clone();
    let mut as_returns = with.clone();
    let mut points = Vec::new();
    for k in 0..5u64 {
        let t0 = k as f64 / 10.0;
        for s in frame_imu::<Circle>(&mut imu, k) {
            for odo in [&mut with, &mut without, &mut as_returns] {
                odo.push_imu(&s).unwrap();
            }
        }
        lidar
            .frame(&world, k, t0, Circle::pose, motor, &mut points)
            .unwrap();
        let misses = lidar.misses().to_vec();
        assert!(misses.len() > 1_000, "{}", misses.len());
        let angles = frame_angles(&encoder, motor, k);
        let t1 = (k + 1) as f64 / 10.0;
        // The deskew of the frame before this one's registration: the same poses for all.
        let mut combined = points.clone();
        combined.extend_from_slice(&misses);
        as_returns.process_frame(t1, &combined, &angles).unwrap();
        with.process_frame_with_misses(t1, &points, &misses, &angles)
            .unwrap();
        without.process_frame(t1, &points, &angles).unwrap();
        assert_eq!(with.last_misses(), &as_returns.last_scan()[points.len()..]);
        assert_eq!(with.last_scan(), without.last_scan());
        assert_eq!(with.state().pose(), without.state().pose());
        assert_eq!(with.map_len(), without.map_len());
        assert!(without.last_misses().is_empty());
        // Keep the third odometry on the same track: only its deskew is compared.
        as_returns = with.clone();
    }
}
