//! End-to-end: the complete explorer on the small scene.
#![allow(clippy::unwrap_used)]

use fu_mpc_examples::explorer::{ControllerKind, ExplorerConfig, Mission, explore};
use fu_mpc_examples::report::Report;
use fu_mpc_examples::scene::Scene;

fn run(controller: ControllerKind) -> (fu_mpc_examples::explorer::ExploreLog, Report) {
    let scene = Scene::small(1);
    let world = scene.world().unwrap();
    let explorable = scene.explorable(0.2);
    let mission = Mission {
        world: &world,
        min: scene.min,
        max: scene.max,
        start: scene.start,
        explorable: Some(&explorable),
    };
    let config = ExplorerConfig {
        controller,
        max_time: 120.0,
        ..ExplorerConfig::default()
    };
    let log = explore(&mission, &config, 7, |_| {}).unwrap();
    let report = Report::new("small", 7, &log, 1.0).unwrap();
    (log, report)
}

#[test]
fn fu_mpc_explores_the_small_scene_and_repeats_itself() {
    let (log, report) = run(ControllerKind::FuMpc);
    assert!(report.finished, "{}", report.screen());
    let coverage = report.coverage.unwrap();
    assert!(coverage >= 0.95, "{}", report.screen());
    assert_eq!(report.collisions, 0, "{}", report.screen());
    assert!(report.min_clearance_m > 0.25, "{}", report.screen());
    assert!(report.ape.rmse < 0.2, "{}", report.screen());
    // The coverage only grows.
    assert!(log.coverage.windows(2).all(|w| w[1].1 >= w[0].1));
    // The same seed gives the same run.
    let (again, _) = run(ControllerKind::FuMpc);
    assert_eq!(log.times, again.times);
    assert_eq!(log.truth, again.truth);
    assert_eq!(log.estimate, again.estimate);
    assert_eq!(log.coverage, again.coverage);
    assert_eq!(log.motor_speed, again.motor_speed);
}

/// A room open to the sky, explored with beams that return nothing clearing the map: it
/// finishes, with the space under the open top seen, sooner than without them.
#[test]
fn a_room_open_to_the_sky_is_explored_with_misses_clearing_the_map() {
    use fu_mpc_examples::scene::Explorable;
    use fu_mpc_examples::world::World;
    use nalgebra::Point3;
    let p = Point3::new;
    let world = World::from_boxes(&[
        (p(-1.0, -1.0, -1.0), p(9.0, 7.0, 0.0)),
        (p(-1.0, -1.0, 0.0), p(0.0, 7.0, 3.0)),
        (p(8.0, -1.0, 0.0), p(9.0, 7.0, 3.0)),
        (p(-1.0, -1.0, 0.0), p(9.0, 0.0, 3.0)),
        (p(-1.0, 6.0, 0.0), p(9.0, 7.0, 3.0)),
        // A dividing wall with a way round it.
        (p(4.0, 0.0, 0.0), p(4.2, 4.0, 3.0)),
    ])
    .unwrap();
    let (min, max, start) = (p(0.0, 0.0, 0.0), p(8.0, 6.0, 3.0), p(2.0, 3.0, 1.5));
    let explorable = Explorable::from_fn(min, max, &start, 0.2, |q| world.closer_than(q, 0.05));
    let mission = Mission {
        world: &world,
        min,
        max,
        start,
        explorable: Some(&explorable),
    };
    let run = |clear_on_no_return: bool| {
        let config = ExplorerConfig {
            max_time: 120.0,
            clear_on_no_return,
            ..ExplorerConfig::default()
        };
        let log = explore(&mission, &config, 3, |_| {}).unwrap();
        Report::new("open room", 3, &log, 1.0).unwrap()
    };
    let report = run(true);
    assert!(report.finished, "{}", report.screen());
    assert!(report.coverage.unwrap() >= 0.95, "{}", report.screen());
    assert_eq!(report.collisions, 0, "{}", report.screen());
    // Without the misses only rays that meet a wall clear the space under the open top: the
    // same room takes longer.
    let without = run(false);
    assert!(
        report.exploration_time_s < without.exploration_time_s,
        "{}\n{}",
        report.screen(),
        without.screen()
    );
}
