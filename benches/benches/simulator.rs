//! Benchmarks of the simulator (`fu-mpc-examples`).
//!
//! Target (the simulator issue): one simulated LiDAR frame of 20,000 rays ≤ 5 ms: the ray
//! casts alone, and a whole Mid-360 frame with per-point poses and range noise, in the
//! Spatial Maze.
//!
//! Run with `cargo bench -p fu-mpc-benches --bench simulator`.
#![allow(clippy::unwrap_used)]

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use fu_mpc_examples::lidar::{LidarNoise, LidarSim};
use fu_mpc_examples::scene::Scene;
use lidar_kinematics::{KinematicChain, LidarSensor};
use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};

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

fn bench_frame(c: &mut Criterion) {
    let scene = Scene::maze(1);
    let world = scene.world().unwrap();
    let mut lidar = LidarSim::new(
        LidarSensor::mid360(),
        KinematicChain::default(),
        LidarNoise::default(),
        1,
    );
    let start = scene.start;
    let pose = move |t: f64| {
        Isometry3::from_parts(
            Translation3::from(start.coords + Vector3::new(2.0 * t, 0.0, 0.0)),
            UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 0.2 * t),
        )
    };
    let angle = |t: f64| 100f64.to_radians() * t;
    let mut out = Vec::new();
    let mut index = 0;
    c.bench_function("lidar_frame_mid360_20k_maze", |b| {
        b.iter(|| {
            index += 1;
            lidar
                .frame(&world, index, 0.0, pose, angle, &mut out)
                .unwrap();
            black_box(out.len())
        });
    });
}

criterion_group!(benches, bench_rays, bench_frame);
criterion_main!(benches);
