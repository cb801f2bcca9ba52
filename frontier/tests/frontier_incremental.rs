//! The incremental frontier equals a from-scratch recomputation after any sequence of frames,
//! its clusters partition the frontier cells and respect the radius limit.
#![allow(clippy::unwrap_used)]

mod common;

use std::collections::BTreeSet;

use frontier::{Bounds, Cell, FrontierConfig, Frontiers, MapConfig, VoxelMap};
use nalgebra::Point3;
use proptest::prelude::*;

proptest! {
    #![proptest_config(ProptestConfig::with_cases(16))]

    #[test]
    fn incremental_equals_rebuild(
        origins in proptest::collection::vec((0.6f64..11.4, 0.6f64..7.4, 0.4f64..2.6), 1..6),
        range in 2.0f64..8.0,
        radius in 0.6f64..3.0,
        rays in 12u32..40,
    ) {
        let scene = common::room();
        let bounds = Bounds::new(Point3::new(0.0, 0.0, 0.0), Point3::new(12.0, 8.0, 3.0)).unwrap();
        let cfg = MapConfig { max_range: range, ..Default::default() };
        let mut map = VoxelMap::new(bounds, cfg).unwrap();
        let fcfg = FrontierConfig { max_cluster_radius: radius, ..Default::default() };
        let mut inc = Frontiers::new(fcfg).unwrap();
        for &(x, y, z) in &origins {
            let o = Point3::new(x, y, z);
            let u = map.insert_frame(&o, &scene.scan(&o, rays, 7, 12.0)).unwrap();
            inc.update(&map, &u);

            let mut full = Frontiers::new(fcfg).unwrap();
            full.rebuild(&map);
            prop_assert_eq!(inc.frontier_cells(), full.frontier_cells());
            // Every tracked cell is a frontier cell of the map.
            for c in inc.frontier_cells() {
                prop_assert!(Frontiers::is_frontier_in(&map, c));
            }
            let mut seen: BTreeSet<Cell> = BTreeSet::new();
            for cl in inc.all_clusters() {
                prop_assert!(cl.radius(map.grid()) <= radius + 1e-9);
                prop_assert!(!cl.cells().is_empty());
                for c in cl.cells() {
                    prop_assert!(seen.insert(*c));
                    prop_assert_eq!(inc.owner(*c), Some(cl.id()));
                }
            }
            prop_assert_eq!(seen.len(), inc.frontier_len());
        }
    }
}
