//! One motor revolution and one deskewed LiDAR frame, printed as tables.
//!
//! A UAV flies at 2 m/s while yawing through a 20 m × 10 m × 4 m room; a 16-ring LiDAR
//! lies on its side on a motor that spins it about the UAV's forward axis. The program
//! 1. spins the motor up with the acceleration model (11)–(12) and prints the scan
//!    direction (14) over one full revolution;
//! 2. simulates one 0.1 s frame (each beam at its own time, pose and motor angle), reads
//!    the motor through a 12-bit encoder, deskews the frame, and prints some of its points
//!    in the world frame with the deskew error against the ground truth.
//!
//! Run with `cargo run --release -p lidar-kinematics --example revolution`.
#![allow(clippy::print_stdout)]

use std::error::Error;
use std::f64::consts::{FRAC_PI_2, TAU};

use lidar_kinematics::{
    AngleSample, DeskewTarget, Deskewer, Encoder, EncoderConfig, Extrinsics, KinematicChain,
    LidarSensor, MotorLimits, MotorModel, MotorState, PoseSample, TimedPoint,
};
use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};

/// Room half-extents [m], centred on the origin.
const ROOM: [f64; 3] = [10.0, 5.0, 2.0];

/// Distance along a unit ray from a point inside the room to its walls.
fn cast_in_room(origin: &Point3<f64>, dir: &Vector3<f64>) -> f64 {
    (0..3)
        .filter(|&i| dir[i].abs() > 1e-12)
        .map(|i| {
            let wall = ROOM[i].copysign(dir[i]);
            (wall - origin[i]) / dir[i]
        })
        .fold(f64::INFINITY, f64::min)
}

/// The UAV's true pose: 2 m/s along x, 0.3 rad/s yaw, 1.5 m above the room centre.
fn body_at(t: f64) -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::new(-3.0 + 2.0 * t, 0.5, 0.0),
        UnitQuaternion::from_euler_angles(0.0, 0.0, 0.3 * t),
    )
}

fn main() -> Result<(), Box<dyn Error>> {
    // The motor spins about the body x axis (its base is pitched down by 90°); the LiDAR's
    // spin axis lies along the motor's x axis so that its rings sweep through the vertical.
    let chain = KinematicChain::new(Extrinsics::try_new(
        Isometry3::rotation(Vector3::new(0.0, -FRAC_PI_2, 0.0)),
        Isometry3::from_parts(
            Translation3::new(0.12, 0.0, -0.05),
            UnitQuaternion::from_euler_angles(0.0, FRAC_PI_2, 0.0),
        ),
    )?);
    let motor = MotorModel::new(MotorLimits::try_new(-TAU, TAU, 4.0 * TAU)?);
    let dt = 0.01;

    // 1. Spin up to 2π rad/s, then one full revolution.
    let spin_up = motor.rollout(MotorState::default(), &[4.0 * TAU; 30], dt)?;
    let mut state = spin_up[spin_up.len() - 1];
    println!(
        "Motor spun up in {:.2} s to {:.3} rad/s",
        30.0 * dt,
        state.omega
    );
    println!();
    println!("One revolution: scan direction d^W (eq. 14), UAV level");
    println!(
        "{:>6} {:>9} {:>8} {:>8} {:>8}",
        "t [s]", "θ [deg]", "d_x", "d_y", "d_z"
    );
    // At 2π rad/s one revolution takes 1 s: twelve steps of 1/12 s are 30° each.
    let step = 1.0 / 12.0;
    for k in 0..=12 {
        let d = chain.scan_direction(&UnitQuaternion::identity(), state.theta)?;
        println!(
            "{:>6.3} {:>9.1} {:>8.3} {:>8.3} {:>8.3}",
            f64::from(k) * step,
            lidar_kinematics::angle::wrap_to_two_pi(state.theta).to_degrees(),
            d.x,
            d.y,
            d.z
        );
        state = motor.step(state, 0.0, step)?;
    }

    // 2. One frame of a 16-ring LiDAR while flying and spinning.
    let sensor = LidarSensor::ring16();
    let frame = sensor.pattern().frame_period();
    let theta_at = |t: f64| 0.4 + TAU * t;
    let mut points = Vec::new();
    let mut truth = Vec::new();
    for beam in sensor.pattern().frame(0) {
        let t = beam.time_offset;
        let lidar = chain.lidar_pose(&body_at(t), theta_at(t))?;
        let dir = lidar.rotation * beam.direction.into_inner();
        let origin = Point3::from(lidar.translation.vector);
        let range = cast_in_room(&origin, &dir);
        if sensor.range().contains(range) {
            let world = origin + dir * range;
            points.push(TimedPoint::new(t, lidar.inverse_transform_point(&world)));
            truth.push(world);
        }
    }
    // Odometry poses at 200 Hz; a 12-bit encoder with 1 ms latency read at 1 kHz.
    let poses: Vec<PoseSample> = (0..=20)
        .map(|k| f64::from(k) * 0.005)
        .map(|t| PoseSample::new(t, body_at(t)))
        .collect();
    let mut encoder = Encoder::new(EncoderConfig::try_new(4096, 1e-3)?);
    let mut angles = Vec::new();
    for k in -2..=101 {
        let t = f64::from(k) * 1e-3;
        encoder.record(t, theta_at(t))?;
        if k >= 0 {
            let reading = encoder.read(t + 1e-3)?; // the reading of the angle at t
            angles.push(AngleSample::new(t, reading.angle));
        }
    }
    let angles = &angles[..=100];
    let mut deskewer = Deskewer::new(chain);
    let world = deskewer.deskew_to_vec(&poses, angles, &points, DeskewTarget::World)?;
    // Without deskew: every point with the frame-start pose and angle.
    let naive: Vec<Point3<f64>> = points
        .iter()
        .map(|p| chain.lidar_to_world(&body_at(0.0), theta_at(0.0), &p.point))
        .collect::<Result<_, _>>()?;

    println!();
    println!(
        "One {} ms frame of a 16-ring LiDAR: {} returns in a {}×{}×{} m room",
        frame * 1e3,
        points.len(),
        2.0 * ROOM[0],
        2.0 * ROOM[1],
        2.0 * ROOM[2]
    );
    println!(
        "{:>7} {:>8} {:>8} {:>8} {:>8} {:>11}",
        "t [ms]", "θ [deg]", "x^W", "y^W", "z^W", "error [mm]"
    );
    let step = (points.len() / 12).max(1);
    for i in (0..points.len()).step_by(step) {
        let p = &world[i];
        println!(
            "{:>7.2} {:>8.1} {:>8.3} {:>8.3} {:>8.3} {:>11.3}",
            points[i].time * 1e3,
            lidar_kinematics::angle::wrap_to_two_pi(theta_at(points[i].time)).to_degrees(),
            p.x,
            p.y,
            p.z,
            (p - truth[i]).norm() * 1e3
        );
    }
    let stats = |pts: &[Point3<f64>]| {
        let errs: Vec<f64> = pts
            .iter()
            .zip(&truth)
            .map(|(a, b)| (a - b).norm())
            .collect();
        let mean = errs.iter().sum::<f64>() / errs.len() as f64;
        (mean, errs.iter().copied().fold(0.0, f64::max))
    };
    let (mean, max) = stats(&world);
    let (naive_mean, naive_max) = stats(&naive);
    println!();
    println!(
        "Deskewed:     mean error {:.2} mm, max {:.2} mm (encoder quantisation: {:.3}°)",
        mean * 1e3,
        max * 1e3,
        360.0 / 4096.0
    );
    println!(
        "Not deskewed: mean error {:.1} mm, max {:.1} mm",
        naive_mean * 1e3,
        naive_max * 1e3
    );
    Ok(())
}
