//! Viewpoints, visibility and dynamic clusters on the room scene.
#![allow(clippy::unwrap_used)]

mod common;

use frontier::{
    Bounds, ElevationBand, FrontierConfig, Frontiers, MapConfig, Omnidirectional, ViewpointConfig,
    VoxelMap, cell_visible, plan_targets, plan_targets_among, viewpoint_valid, visibility_ratio,
};
use nalgebra::Point3;

fn explored(origins: &[Point3<f64>], range: f64) -> (VoxelMap, Frontiers) {
    let scene = common::room();
    let bounds = Bounds::new(Point3::new(0.0, 0.0, 0.0), Point3::new(12.0, 8.0, 3.0)).unwrap();
    let cfg = MapConfig {
        max_range: range,
        ..Default::default()
    };
    let mut map = VoxelMap::new(bounds, cfg).unwrap();
    let mut f = Frontiers::new(FrontierConfig::default()).unwrap();
    for o in origins {
        let u = map.insert_frame(o, &scene.scan(o, 180, 40, 12.0)).unwrap();
        f.update(&map, &u);
    }
    (map, f)
}

#[test]
fn representatives_are_valid_and_see_every_member() {
    let (map, f) = explored(
        &[Point3::new(2.0, 2.0, 1.5), Point3::new(3.0, 5.0, 1.2)],
        4.0,
    );
    let n_clusters = f.clusters().count();
    assert!(n_clusters >= 3, "{n_clusters}");
    let cfg = ViewpointConfig {
        visibility_samples: 0,
        sensor_range: 4.0,
        ..Default::default()
    };
    let uav = Point3::new(3.0, 5.0, 1.2);
    let plan = plan_targets(&map, &f, &uav, &Omnidirectional, |_| true, &cfg).unwrap();
    assert!(!plan.targets.is_empty());
    // Merging never increases the number of targets.
    assert!(plan.targets.len() + plan.unviewable.len() <= n_clusters);
    let members: usize = plan.targets.iter().map(|t| t.members.len()).sum();
    assert_eq!(members + plan.unviewable.len(), n_clusters);
    for t in &plan.targets {
        assert!(viewpoint_valid(&map, &t.viewpoint, &cfg, &|_: &Point3<
            f64,
        >| true));
        assert!(map.clearance(&t.viewpoint, 1.0) >= cfg.safety_distance);
        for id in &t.members {
            let cl = f.cluster(*id).unwrap();
            let r = visibility_ratio(&map, cl, &t.viewpoint, &Omnidirectional, &cfg);
            assert!(r >= cfg.min_visibility, "ratio {r} for {id:?}");
        }
        assert!(t.seen_cells > 0);
    }
    // The same inputs give the same plan, on one thread as on several.
    let again = plan_targets(&map, &f, &uav, &Omnidirectional, |_| true, &cfg).unwrap();
    assert_eq!(plan, again);
    for threads in [1, 3] {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        let other = pool
            .install(|| plan_targets(&map, &f, &uav, &Omnidirectional, |_| true, &cfg))
            .unwrap();
        assert_eq!(plan, other, "{threads} threads");
    }
    // The sampled visibility gives the same plan on any number of threads too.
    let sampled = ViewpointConfig {
        visibility_samples: 8,
        ..cfg.clone()
    };
    let one = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap()
        .install(|| plan_targets(&map, &f, &uav, &Omnidirectional, |_| true, &sampled))
        .unwrap();
    let many = plan_targets(&map, &f, &uav, &Omnidirectional, |_| true, &sampled).unwrap();
    assert_eq!(one, many);
    // A reachability test that rejects everything leaves every cluster unviewable.
    let none = plan_targets(&map, &f, &uav, &Omnidirectional, |_| false, &cfg).unwrap();
    assert!(none.targets.is_empty());
    assert_eq!(none.unviewable.len(), n_clusters);
    // A narrower field of view cannot see more.
    let band = ElevationBand {
        min: -0.1,
        max: 0.1,
    };
    let narrow = plan_targets(&map, &f, &uav, &band, |_| true, &cfg).unwrap();
    assert!(narrow.unviewable.len() >= plan.unviewable.len());
    // Over every cluster, the subset form is the same plan; over a subset, only its members.
    let all: Vec<_> = f.clusters().collect();
    let among = plan_targets_among(&map, &all, &uav, &Omnidirectional, |_| true, &cfg).unwrap();
    assert_eq!(among, plan);
    let some = &all[..all.len() / 2];
    let part = plan_targets_among(&map, some, &uav, &Omnidirectional, |_| true, &cfg).unwrap();
    let chosen: Vec<_> = some.iter().map(|c| c.id()).collect();
    let members: usize = part.targets.iter().map(|t| t.members.len()).sum();
    assert_eq!(members + part.unviewable.len(), some.len());
    assert!(
        part.targets
            .iter()
            .flat_map(|t| t.members.iter())
            .chain(part.unviewable.iter())
            .all(|id| chosen.contains(id))
    );
}

#[test]
fn a_cell_behind_the_wall_is_not_visible() {
    // Explore both sides of the dividing wall at x = 6 (door at y ∈ [3.5, 4.5]).
    let (map, _) = explored(
        &[Point3::new(3.0, 1.5, 1.5), Point3::new(9.0, 1.5, 1.5)],
        8.0,
    );
    let cfg = ViewpointConfig::default();
    let behind = map.grid().cell_of(&Point3::new(8.0, 1.5, 1.5)).unwrap();
    let front = map.grid().cell_of(&Point3::new(4.5, 1.5, 1.5)).unwrap();
    let from = Point3::new(3.0, 1.5, 1.5);
    assert!(cell_visible(&map, &from, front, &Omnidirectional, &cfg));
    assert!(!cell_visible(&map, &from, behind, &Omnidirectional, &cfg));
    // Through the door it is seen.
    let door_view = map.grid().cell_of(&Point3::new(8.0, 4.0, 1.5)).unwrap();
    assert!(cell_visible(
        &map,
        &Point3::new(4.0, 4.0, 1.5),
        door_view,
        &Omnidirectional,
        &cfg
    ));
    // Beyond the sensor range nothing is seen.
    let far = ViewpointConfig {
        sensor_range: 1.0,
        ..Default::default()
    };
    assert!(!cell_visible(&map, &from, front, &Omnidirectional, &far));
}

#[test]
fn bad_inputs_are_errors() {
    let (map, f) = explored(&[Point3::new(2.0, 2.0, 1.5)], 4.0);
    let nan = Point3::new(f64::NAN, 0.0, 0.0);
    assert!(
        plan_targets(
            &map,
            &f,
            &nan,
            &Omnidirectional,
            |_| true,
            &ViewpointConfig::default()
        )
        .is_err()
    );
    let bad = [
        ViewpointConfig {
            radii: vec![],
            ..Default::default()
        },
        ViewpointConfig {
            radii: vec![-1.0],
            ..Default::default()
        },
        ViewpointConfig {
            elevations: vec![2.0],
            ..Default::default()
        },
        ViewpointConfig {
            azimuths: 0,
            ..Default::default()
        },
        ViewpointConfig {
            min_visibility: 0.0,
            ..Default::default()
        },
        ViewpointConfig {
            sensor_range: f64::NAN,
            ..Default::default()
        },
        ViewpointConfig {
            alpha: -1.0,
            ..Default::default()
        },
        ViewpointConfig {
            safety_distance: f64::INFINITY,
            ..Default::default()
        },
    ];
    for c in bad {
        assert!(c.validate().is_err(), "{c:?}");
        assert!(
            plan_targets(
                &map,
                &f,
                &Point3::new(2.0, 2.0, 1.5),
                &Omnidirectional,
                |_| true,
                &c
            )
            .is_err()
        );
    }
    // A viewpoint outside the map sees nothing.
    let cl = f.clusters().next().unwrap();
    let out = Point3::new(-5.0, 0.0, 0.0);
    assert_eq!(
        visibility_ratio(
            &map,
            cl,
            &out,
            &Omnidirectional,
            &ViewpointConfig::default()
        ),
        0.0
    );
}
