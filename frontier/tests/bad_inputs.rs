//! Bad inputs give typed errors or documented fallbacks, never a panic.
#![allow(clippy::unwrap_used)]

use frontier::{
    Bounds, Cell, CellChange, CellState, FrameUpdate, FrontierConfig, FrontierError, Frontiers,
    MAX_BLOCKS, MAX_CANDIDATES, MapConfig, Omnidirectional, ViewpointConfig, VoxelMap,
    cell_visible, plan_targets, sample_candidates, visibility_ratio,
};
use nalgebra::{Point3, Vector3};

fn small_map() -> VoxelMap {
    let b = Bounds::new(Point3::new(0.0, 0.0, 0.0), Point3::new(10.0, 10.0, 3.0)).unwrap();
    VoxelMap::new(b, MapConfig::default()).unwrap()
}

/// A map seen from its middle through a ring of rays, and its frontier.
fn explored() -> (VoxelMap, Frontiers, FrameUpdate) {
    let mut map = small_map();
    let mut f = Frontiers::new(FrontierConfig::default()).unwrap();
    let origin = Point3::new(5.0, 5.0, 1.5);
    let points: Vec<_> = (0..360)
        .map(|i| {
            let a = f64::from(i).to_radians();
            origin + Vector3::new(3.0 * a.cos(), 3.0 * a.sin(), 0.0)
        })
        .collect();
    let u = map.insert_frame(&origin, &points).unwrap();
    f.update(&map, &u);
    (map, f, u)
}

#[test]
fn a_viewpoint_outside_the_map_sees_nothing() {
    let map = small_map();
    let cell = Cell::new(0, 7, 0);
    let infinite = ViewpointConfig {
        sensor_range: f64::INFINITY,
        ..Default::default()
    };
    // Grid coordinates of 1e308 overflow to infinity: the walk used to step out of the grid.
    let far = Point3::new(1e308, 1.5, 0.1);
    assert!(!cell_visible(&map, &far, cell, &Omnidirectional, &infinite));
    let cfg = ViewpointConfig::default();
    for from in [
        far,
        Point3::new(-0.5, 1.5, 0.1),
        Point3::new(f64::NAN, 1.5, 0.1),
        Point3::new(f64::INFINITY, 1.5, 0.1),
    ] {
        assert!(!cell_visible(&map, &from, cell, &Omnidirectional, &cfg));
    }
    // An invalid config sees nothing even from inside the map.
    let inside = Point3::new(1.0, 1.5, 0.1);
    assert!(!cell_visible(
        &map,
        &inside,
        cell,
        &Omnidirectional,
        &infinite
    ));
    // The same query with a valid config is answered as before.
    let near = map.grid().cell_of(&Point3::new(1.5, 1.5, 0.1)).unwrap();
    let unknown_blocks = ViewpointConfig {
        unknown_occludes: true,
        ..Default::default()
    };
    assert!(cell_visible(&map, &inside, near, &Omnidirectional, &cfg));
    let behind = map.grid().cell_of(&Point3::new(2.5, 1.5, 0.1)).unwrap();
    assert!(!cell_visible(
        &map,
        &inside,
        behind,
        &Omnidirectional,
        &unknown_blocks
    ));
    // Cells far outside the grid are out of range, or clamped into the grid when in range.
    for c in [Cell::new(u32::MAX, u32::MAX, u32::MAX), Cell::new(60, 7, 0)] {
        assert!(!cell_visible(&map, &inside, c, &Omnidirectional, &infinite));
        let _ = cell_visible(&map, &inside, c, &Omnidirectional, &cfg);
    }
}

#[test]
fn visibility_ratio_of_an_invalid_config_is_zero() {
    let (map, f, _) = explored();
    let cl = f.clusters().next().unwrap();
    let from = Point3::new(5.0, 5.0, 1.5);
    let cfg = ViewpointConfig::default();
    assert!(visibility_ratio(&map, cl, &from, &Omnidirectional, &cfg) > 0.0);
    let bad = ViewpointConfig {
        sensor_range: f64::INFINITY,
        ..Default::default()
    };
    assert_eq!(
        visibility_ratio(&map, cl, &from, &Omnidirectional, &bad),
        0.0
    );
}

#[test]
fn too_many_candidates_are_refused() {
    let (map, f, _) = explored();
    let cl = f.clusters().next().unwrap();
    assert_eq!(sample_candidates(cl, &ViewpointConfig::default()).len(), 90);
    let at_limit = ViewpointConfig {
        radii: vec![1.0],
        elevations: vec![0.5],
        azimuths: MAX_CANDIDATES,
        ..Default::default()
    };
    assert!(at_limit.validate().is_ok());
    assert_eq!(sample_candidates(cl, &at_limit).len(), MAX_CANDIDATES);
    let huge = [
        usize::MAX,
        1 << 40,
        MAX_CANDIDATES + 1,
        // Under the azimuth limit, but the product with 3 radii and 3 elevations is not.
        MAX_CANDIDATES / 4,
    ];
    for azimuths in huge {
        let cfg = ViewpointConfig {
            azimuths,
            ..Default::default()
        };
        assert!(
            matches!(cfg.validate(), Err(FrontierError::InvalidConfig { .. })),
            "{azimuths}"
        );
        assert!(sample_candidates(cl, &cfg).is_empty(), "{azimuths}");
        let uav = Point3::new(5.0, 5.0, 1.5);
        assert!(plan_targets(&map, &f, &uav, &Omnidirectional, |_| true, &cfg).is_err());
    }
    // A product that overflows usize.
    let cfg = ViewpointConfig {
        radii: vec![1.0; 1 << 12],
        elevations: vec![0.5; 1 << 12],
        azimuths: MAX_CANDIDATES,
        ..Default::default()
    };
    assert!(cfg.validate().is_err());
    assert!(sample_candidates(cl, &cfg).is_empty());
}

#[test]
fn changes_outside_the_grid_are_ignored() {
    let (map, mut g, u) = explored();
    let cells = g.frontier_cells();
    let ids: Vec<_> = g.all_clusters().map(|c| c.id()).collect();
    let outside = [
        Cell::new(u32::MAX, 0, 0),
        Cell::new(0, u32::MAX, u32::MAX),
        // Keys pack 21 bits per axis: this one would alias cell (5, 1, 0).
        Cell::new((1 << 21) + 5, 0, 0),
        Cell::new(50, 0, 0),
    ];
    let bad = FrameUpdate {
        changed: outside
            .iter()
            .map(|&cell| CellChange {
                cell,
                before: CellState::Unknown,
                after: CellState::Free,
            })
            .collect(),
        ..Default::default()
    };
    let delta = g.update(&map, &bad);
    assert_eq!(delta.examined, 0);
    assert!(delta.added.is_empty() && delta.removed.is_empty());
    assert_eq!(g.frontier_cells(), cells);
    assert_eq!(g.all_clusters().map(|c| c.id()).collect::<Vec<_>>(), ids);
    // Mixed into a real update, they change nothing either.
    let mut a = Frontiers::new(FrontierConfig::default()).unwrap();
    let mut b = Frontiers::new(FrontierConfig::default()).unwrap();
    let mut mixed = u.clone();
    mixed.changed.extend(bad.changed.iter().copied());
    let da = a.update(&map, &u);
    let db = b.update(&map, &mixed);
    assert_eq!(da, db);
    assert_eq!(a.frontier_cells(), b.frontier_cells());
    assert!(a.all_clusters().eq(b.all_clusters()));
}

#[test]
fn bounds_too_large_for_the_block_directory_are_an_error() {
    let cfg = |resolution| MapConfig {
        resolution,
        ..Default::default()
    };
    let b = |x: f64, y: f64, z: f64| {
        Bounds::new(Point3::new(0.0, 0.0, 0.0), Point3::new(x, y, z)).unwrap()
    };
    // 10^6 cells per axis (allowed per axis), 10^18 / 512 blocks in all.
    let huge = VoxelMap::new(b(1e5, 1e5, 1e5), cfg(0.1));
    assert!(
        matches!(huge, Err(FrontierError::TooManyBlocks { max, .. }) if max == MAX_BLOCKS),
        "{huge:?}"
    );
    // 10 km × 10 km × 100 m at 0.2 m: 6250 × 6250 × 63 blocks.
    assert_eq!(
        VoxelMap::new(b(1e4, 1e4, 100.0), cfg(0.2)).err(),
        Some(FrontierError::TooManyBlocks {
            blocks: 6250 * 6250 * 63,
            max: MAX_BLOCKS,
        })
    );
    // Too many cells along one axis is still reported as such.
    assert!(matches!(
        VoxelMap::new(b(1e6, 1.0, 1.0), cfg(0.1)),
        Err(FrontierError::TooManyCells { .. })
    ));
    // The largest scene of the project is far below the limit.
    let scene = VoxelMap::new(b(315.0, 53.5, 27.0), cfg(0.2)).unwrap();
    assert!(scene.memory_bytes() < 1 << 20);
}

/// A point so far out that its squared distance overflows still clears free space up to
/// the range along its direction, as a nearer one beyond the range does.
#[test]
fn far_points_clear_up_to_the_range() {
    let origin = Point3::new(1.0, 5.0, 1.5);
    let mut near = small_map();
    let want = near
        .insert_frame(&origin, &[Point3::new(1e150, 5.0, 1.5)])
        .unwrap();
    assert!(want.free_cells > 1);
    for x in [1e160, 1e200, 1e300, f64::MAX] {
        let mut far = small_map();
        let got = far
            .insert_frame(&origin, &[Point3::new(x, 5.0, 1.5)])
            .unwrap();
        assert_eq!(got.free_cells, want.free_cells, "{x}");
        assert_eq!(got.truncated, 1);
        assert_eq!(
            far.state(&Point3::new(5.0, 5.0, 1.5)),
            CellState::Free,
            "{x}"
        );
    }
}
