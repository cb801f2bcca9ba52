//! A whole flight in the small scene: route, trajectory, sensors and odometry.
#![allow(clippy::unwrap_used)]

use fu_mpc_examples::flight::{FlightConfig, fly, out_and_back_route, route_trajectory};
use fu_mpc_examples::metrics::{Alignment, ape, trajectory_length};
use fu_mpc_examples::scene::Scene;

#[test]
fn a_flight_through_the_small_scene_is_tracked_and_repeatable() {
    let scene = Scene::small(1);
    let world = scene.world().unwrap();
    let config = FlightConfig::default();
    let route = out_and_back_route(&(&scene).into(), &world, &config).unwrap();
    assert!(route.len() >= 3);
    assert_eq!(route.first(), route.last());
    let traj = route_trajectory(&route, &config, 0.35).unwrap();
    // The trajectory goes out and back, several metres, within the speed limit.
    assert!(traj.duration() > 3.0);
    let log = fly(&world, &traj, &config, 3).unwrap();
    let (truth, est) = log.positions();
    assert!(trajectory_length(&truth) > 5.0);
    assert_eq!(log.collisions, 0);
    assert!(log.min_clearance >= config.radius);
    let stats = ape(&truth, &est, Alignment::None).unwrap();
    assert!(stats.rmse < 0.05, "APE RMSE {} m", stats.rmse);
    assert!(!log.map.is_empty());
    // The UAV tracks the plan in the estimated frame: the true path leaves the plan by about
    // the odometry's error, no more.
    let true_off = truth
        .iter()
        .zip(&log.plan)
        .map(|(x, y)| (x - y).norm())
        .fold(0.0, f64::max);
    assert!(
        true_off > 0.0 && true_off < 0.05,
        "{true_off} m off the plan"
    );
    // The same seed gives the same flight.
    let again = fly(&world, &traj, &config, 3).unwrap();
    assert_eq!(again.estimate, log.estimate);
}

/// With noiseless sensors (and an encoder without latency) the odometry reproduces the truth
/// to a centimetre (RMSE; at most 2 cm at any frame) over 119 m of maze.
#[test]
fn noiseless_odometry_over_100_m_of_maze_is_within_a_centimetre() {
    let scene = Scene::maze(1);
    let world = scene.world().unwrap();
    let config = FlightConfig {
        reach: 50.0,
        lidar_noise: fu_mpc_examples::lidar::LidarNoise { range_std: 0.0 },
        imu_noise: fu_mpc_examples::uav::ImuNoise {
            acc_noise: 0.0,
            gyro_noise: 0.0,
            acc_bias_walk: 0.0,
            gyro_bias_walk: 0.0,
        },
        encoder: lidar_kinematics::EncoderConfig::try_new(1 << 16, 0.0).unwrap(),
        ..FlightConfig::default()
    };
    let route = out_and_back_route(&(&scene).into(), &world, &config).unwrap();
    let traj = route_trajectory(&route, &config, 0.35).unwrap();
    let log = fly(&world, &traj, &config, 1).unwrap();
    let (truth, est) = log.positions();
    let length = trajectory_length(&truth);
    assert!(length > 100.0, "{length} m");
    let stats = ape(&truth, &est, Alignment::None).unwrap();
    assert!(
        stats.rmse < 0.01 && stats.max < 0.02,
        "RMSE {} m, largest error {} m over {length} m",
        stats.rmse,
        stats.max
    );
}
