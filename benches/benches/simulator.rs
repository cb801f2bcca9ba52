//! Benchmarks of the simulator (`fu-mpc-examples`).
//!
//! Target (the simulator issue): one simulated LiDAR frame of 20,000 rays ≤ 5 ms. Today this
//! measures the world's ray casts for such a frame in the Spatial Maze.
//!
//! Run with `cargo bench -p fu-mpc-benches --bench simulator`.
#![allow(clippy::unwrap_used)]

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use fu_mpc_examples::scene::Scene;
use nalgebra::Vector3;

fn bench_rays(c: &mut Criterion) {
    let scene = Scene::maze(1);
    let world = scene.world().unwrap();
    let n = 20_000u32;
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    let dirs: Vec<Vector3<f64>> = (0..n)
        .map(|i| {
            let z = 1.0 - 2.0 * (f64::from(i) + 0.5) / f64::from(n);
            let r = (1.0 - z * z).sqrt();
            let a = golden * f64::from(i);
            Vector3::new(r * a.cos(), r * a.sin(), z)
        })
        .collect();
    let origin = scene.start;
    c.bench_function("world_20k_ray_casts_maze", |b| {
        b.iter(|| {
            let mut hits = 0usize;
            for d in &dirs {
                if world.cast_ray(black_box(&origin), d, 40.0).is_some() {
                    hits += 1;
                }
            }
            black_box(hits)
        });
    });
}

criterion_group!(benches, bench_rays);
criterion_main!(benches);
