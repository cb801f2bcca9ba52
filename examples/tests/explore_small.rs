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
