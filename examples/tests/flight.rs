//! A whole flight in the small scene: route, trajectory, sensors and odometry.
#![allow(clippy::unwrap_used)]

use fu_mpc_examples::flight::{FlightConfig, fly, out_and_back_route, route_trajectory};
use fu_mpc_examples::metrics::{Alignment, ape, trajectory_length};
use fu_mpc_examples::scene::Scene;
use nalgebra::Point3;

#[test]
fn a_flight_through_the_small_scene_is_tracked_and_repeatable() {
    let scene = Scene::small(1);
    let world = scene.world().unwrap();
    let config = FlightConfig::default();
    let route = out_and_back_route(&scene, &world, &config).unwrap();
    assert!(route.len() >= 3);
    assert_eq!(route.first(), route.last());
    let traj = route_trajectory(&route, &config, 0.35).unwrap();
    // The trajectory goes out and back, several metres, within the speed limit.
    assert!(traj.duration() > 3.0);
    let log = fly(&world, &traj, &config, 3).unwrap();
    let truth: Vec<Point3<f64>> = log
        .truth
        .iter()
        .map(|p| p.translation.vector.into())
        .collect();
    let est: Vec<Point3<f64>> = log
        .estimate
        .iter()
        .map(|p| p.translation.vector.into())
        .collect();
    assert!(trajectory_length(&truth) > 5.0);
    assert_eq!(log.collisions, 0);
    assert!(log.min_clearance >= config.radius);
    let stats = ape(&truth, &est, Alignment::None).unwrap();
    assert!(stats.rmse < 0.05, "APE RMSE {} m", stats.rmse);
    assert!(!log.map.is_empty());
    // The same seed gives the same flight.
    let again = fly(&world, &traj, &config, 3).unwrap();
    assert_eq!(again.estimate, log.estimate);
}
