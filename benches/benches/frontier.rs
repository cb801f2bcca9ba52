//! Benchmarks of `frontier`: frame insertion, incremental frontiers, viewpoints and dynamic
//! clusters.
//!
//! Targets (medians on the 2-core reference machine): inserting a 20,000-ray frame of 20 m
//! rays at 0.2 m ≤ 10 ms; the incremental frontier update and re-clustering after such a frame
//! ≤ 3 ms; viewpoint sampling, visibility and dynamic clustering for 50 clusters ≤ 10 ms.
//!
//! Run with `cargo bench -p fu-mpc-benches --bench frontier`. The viewpoint bench explores
//! an office floor with a sensor range of 12 m (59 clusters of at least 20 cells); set
//! `FRONTIER_BENCH_RANGE` (metres) to change the range and with it the cluster count.
#![allow(clippy::unwrap_used, clippy::print_stderr)]

use std::hint::black_box;

use criterion::{BatchSize, Criterion, criterion_group, criterion_main};
use frontier::{
    Bounds, FrontierConfig, Frontiers, MapConfig, Omnidirectional, ViewpointConfig, VoxelMap,
    plan_targets,
};
use fu_mpc_examples::world::World;
use nalgebra::{Point3, Vector3};

/// `n` directions spread evenly over the sphere (Fibonacci lattice).
fn sphere(n: usize) -> Vec<Vector3<f64>> {
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    (0..n)
        .map(|i| {
            let z = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
            let r = (1.0 - z * z).sqrt();
            let a = golden * i as f64;
            Vector3::new(r * a.cos(), r * a.sin(), z)
        })
        .collect()
}

/// An office floor, 40 × 30 × 3 m: outer walls, floor, ceiling, rows of rooms with doors and
/// pillars, as solid boxes.
struct Office {
    world: World,
}

impl Office {
    fn new() -> Self {
        let p = Point3::new;
        let mut boxes = vec![
            (p(-1.0, -1.0, -1.0), p(41.0, 31.0, 0.1)),
            (p(-1.0, -1.0, 2.9), p(41.0, 31.0, 4.0)),
            (p(-1.0, -1.0, -1.0), p(0.1, 31.0, 4.0)),
            (p(39.9, -1.0, -1.0), p(41.0, 31.0, 4.0)),
            (p(-1.0, -1.0, -1.0), p(41.0, 0.1, 4.0)),
            (p(-1.0, 29.9, -1.0), p(41.0, 31.0, 4.0)),
        ];
        // Corridor walls at y = 10 and y = 20 with a door every 8 m; cross walls between rooms.
        for y in [10.0, 20.0] {
            let mut x = 0.0;
            while x < 40.0 {
                boxes.push((p(x, y - 0.1, 0.0), p(x + 6.5, y + 0.1, 3.0)));
                x += 8.0;
            }
        }
        for k in 1..5 {
            let x = 8.0 * f64::from(k) - 0.5;
            boxes.push((p(x - 0.1, 0.0, 0.0), p(x + 0.1, 10.0, 3.0)));
            boxes.push((p(x - 0.1, 20.0, 0.0), p(x + 0.1, 30.0, 3.0)));
        }
        // Pillars in the corridor hall.
        for k in 0..6 {
            let x = 3.0 + 6.5 * f64::from(k);
            boxes.push((p(x, 14.6, 0.0), p(x + 0.6, 15.4, 3.0)));
        }
        Self {
            world: World::from_boxes(&boxes).unwrap(),
        }
    }

    fn frame(&self, o: &Point3<f64>, rays: usize, range: f64) -> Vec<Point3<f64>> {
        sphere(rays)
            .iter()
            .map(|d| o + d * self.world.cast_ray(o, d, range).unwrap_or(range))
            .collect()
    }
}

fn bench_insert(c: &mut Criterion) {
    let mut g = c.benchmark_group("frontier_insert");
    let bounds = Bounds::new(
        Point3::new(-25.0, -25.0, -25.0),
        Point3::new(25.0, 25.0, 25.0),
    )
    .unwrap();
    let cfg = MapConfig {
        max_range: 25.0,
        ..Default::default()
    };
    let origin = Point3::new(0.1, 0.05, 0.02);
    let frame: Vec<Point3<f64>> = sphere(20_000).iter().map(|d| origin + 20.0 * d).collect();
    let empty = VoxelMap::new(bounds, cfg).unwrap();
    g.bench_function("20k_rays_20m_fresh_map", |b| {
        b.iter_batched(
            || empty.clone(),
            |mut m| black_box(m.insert_frame(&origin, &frame).unwrap().changed.len()),
            BatchSize::LargeInput,
        );
    });
    let mut seen = empty.clone();
    seen.insert_frame(&origin, &frame).unwrap();
    g.bench_function("20k_rays_20m_known_map", |b| {
        b.iter(|| black_box(seen.insert_frame(&origin, &frame).unwrap().changed.len()));
    });
    let known = seen.known_cells();
    let bytes = seen.memory_bytes();
    eprintln!(
        "map memory: {known} known cells in {} blocks, {bytes} bytes of storage: {:.3} bytes per known cell, {:.3} per allocated cell; {} bytes of scratch for the next frame",
        seen.allocated_blocks(),
        bytes as f64 / known as f64,
        bytes as f64 / (seen.allocated_blocks() * 512) as f64,
        seen.scratch_bytes()
    );
    g.finish();
}

/// The office explored along the corridor: (map, frontiers) after `poses` frames.
fn office_state(poses: &[Point3<f64>], range: f64) -> (Office, VoxelMap, Frontiers) {
    let office = Office::new();
    let bounds = Bounds::new(Point3::new(0.0, 0.0, 0.0), Point3::new(40.0, 30.0, 3.0)).unwrap();
    let cfg = MapConfig {
        max_range: range,
        ..Default::default()
    };
    let mut map = VoxelMap::new(bounds, cfg).unwrap();
    let mut f = Frontiers::new(FrontierConfig::default()).unwrap();
    for o in poses {
        let u = map.insert_frame(o, &office.frame(o, 20_000, 20.0)).unwrap();
        f.update(&map, &u);
    }
    (office, map, f)
}

fn bench_frontiers(c: &mut Criterion) {
    let path: Vec<Point3<f64>> = (0..6)
        .map(|k| Point3::new(4.0 + 1.0 * f64::from(k), 15.0, 1.5))
        .collect();
    let (office, mut m2, f) = office_state(&path[..5], 20.0);
    let next = path[5];
    let frame = office.frame(&next, 20_000, 20.0);
    let u = m2.insert_frame(&next, &frame).unwrap();
    let delta = f.clone().update(&m2, &u);
    eprintln!(
        "frontier update: {} changed cells, {} frontier cells, {} clusters before; {} examined, {} clusters removed, {} added",
        u.changed.len(),
        f.frontier_len(),
        f.all_clusters().count(),
        delta.examined,
        delta.removed.len(),
        delta.added.len()
    );
    // The routines return the frontier so that dropping it is not timed: an update in use
    // keeps its state.
    c.bench_function("frontier_update_after_20k_frame", |b| {
        b.iter_batched(
            || f.clone(),
            |mut f| {
                let delta = f.update(&m2, &u);
                black_box((f, delta))
            },
            BatchSize::LargeInput,
        );
    });
    c.bench_function("frontier_rebuild_from_scratch", |b| {
        b.iter_batched(
            || f.clone(),
            |mut f| {
                let delta = f.rebuild(&m2);
                black_box((f, delta))
            },
            BatchSize::LargeInput,
        );
    });
}

fn bench_viewpoints(c: &mut Criterion) {
    let range: f64 = std::env::var("FRONTIER_BENCH_RANGE")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(12.0);
    let path = [Point3::new(4.0, 15.0, 1.5), Point3::new(12.0, 15.0, 1.5)];
    let (_, map, f) = office_state(&path, range);
    let cfg = ViewpointConfig::default();
    let plan = plan_targets(&map, &f, &path[1], &Omnidirectional, |_| true, &cfg).unwrap();
    eprintln!(
        "viewpoints: {} clusters ({} with tiny ones), {} sampled, {} valid, {} targets, {} unviewable",
        f.clusters().count(),
        f.all_clusters().count(),
        plan.sampled,
        plan.valid,
        plan.targets.len(),
        plan.unviewable.len()
    );
    c.bench_function("frontier_plan_targets", |b| {
        b.iter(|| {
            black_box(plan_targets(&map, &f, &path[1], &Omnidirectional, |_| true, &cfg).unwrap())
        });
    });
}

criterion_group!(benches, bench_insert, bench_frontiers, bench_viewpoints);
criterion_main!(benches);
