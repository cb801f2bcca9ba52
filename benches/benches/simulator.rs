//! Benchmarks of the simulator (`fu-mpc-examples`).
//!
//! Targets (the simulator issue): one simulated LiDAR frame of 20,000 rays ≤ 5 ms (the ray
//! casts alone, and a whole Mid-360 frame with per-point poses and range noise, in the
//! Spatial Maze); one odometry update on such a frame ≤ 5 ms (deskew, registration against a
//! local map built from 20 earlier frames, map update).
//!
//! Run with `cargo bench -p fu-mpc-benches --bench simulator`.
#![allow(clippy::unwrap_used, clippy::print_stderr)]

use std::hint::black_box;

use criterion::{BatchSize, Criterion, criterion_group, criterion_main};
use fu_mpc_examples::lidar::{LidarNoise, LidarSim};
use fu_mpc_examples::odometry::{NavState, Odometry, OdometryConfig};
use fu_mpc_examples::scene::Scene;
use fu_mpc_examples::uav::{ImuNoise, ImuSim};
use fu_mpc_examples::world::World;
use lidar_kinematics::{AngleSample, KinematicChain, LidarSensor};
use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};

/// `n` directions spread evenly over the sphere (Fibonacci lattice).
fn sphere(n: u32) -> Vec<Vector3<f64>> {
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    (0..n)
        .map(|i| {
            let z = 1.0 - 2.0 * (f64::from(i) + 0.5) / f64::from(n);
            let r = (1.0 - z * z).sqrt();
            let a = golden * f64::from(i);
            Vector3::new(r * a.cos(), r * a.sin(), z)
        })
        .collect()
}

/// Times casting every ray of `dirs` from `origin` with `cast`, counting the hits.
fn bench_casts(
    c: &mut Criterion,
    name: &str,
    dirs: &[Vector3<f64>],
    origin: &Point3<f64>,
    cast: impl Fn(&Point3<f64>, &Vector3<f64>) -> Option<f64>,
) {
    c.bench_function(name, |b| {
        b.iter(|| {
            let hits = dirs
                .iter()
                .filter(|d| cast(black_box(origin), d).is_some())
                .count();
            black_box(hits)
        });
    });
}

fn bench_rays(c: &mut Criterion) {
    let scene = Scene::maze(1);
    let world = scene.world().unwrap();
    let dirs = sphere(20_000);
    let origin = scene.start;
    bench_casts(c, "world_20k_ray_casts_maze", &dirs, &origin, |o, d| {
        world.cast_ray(o, d, 40.0)
    });
    bench_casts(
        c,
        "world_20k_ray_casts_maze_parry",
        &dirs,
        &origin,
        |o, d| world.cast_ray_parry(o, d, 40.0),
    );
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

/// 20,000 ray casts in the shared `apartment.pcd` scene as a voxel world (0.1 m voxels), from
/// the clearest of a few points near its middle: the world's DDA grid against parry3d's voxel
/// shape. Skipped with a message when `../shared/data/scenes` is absent.
fn bench_voxel_rays(c: &mut Criterion) {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../shared/data/scenes/apartment.pcd");
    let Ok(cloud) = fu_mpc_examples::cloud_io::load_pcd(&path) else {
        eprintln!(
            "skipping the voxel-world bench: {} not found",
            path.display()
        );
        return;
    };
    let world = World::from_points(&cloud, 0.1).unwrap();
    let lo = cloud
        .iter()
        .fold(Point3::from(Vector3::repeat(f64::INFINITY)), |m, p| {
            m.inf(p)
        });
    let hi = cloud
        .iter()
        .fold(Point3::from(Vector3::repeat(f64::NEG_INFINITY)), |m, p| {
            m.sup(p)
        });
    let mid = nalgebra::center(&lo, &hi);
    let origin = (0..64)
        .map(|i| {
            let f = f64::from(i);
            mid + Vector3::new((f * 0.7).sin() * 4.0, (f * 1.3).cos() * 3.0, 0.0)
        })
        .max_by(|a, b| world.distance(a).total_cmp(&world.distance(b)))
        .unwrap();
    let dirs = sphere(20_000);
    bench_casts(
        c,
        "world_20k_ray_casts_apartment_voxels_dda",
        &dirs,
        &origin,
        |o, d| world.cast_ray(o, d, 40.0),
    );
    bench_casts(
        c,
        "world_20k_ray_casts_apartment_voxels_parry",
        &dirs,
        &origin,
        |o, d| world.cast_ray_parry(o, d, 40.0),
    );
}

/// One odometry update in the maze, after 20 frames of a straight flight at 2 m/s.
fn bench_odometry(c: &mut Criterion) {
    let scene = Scene::maze(1);
    let world = scene.world().unwrap();
    let chain = KinematicChain::default();
    let mut lidar = LidarSim::new(LidarSensor::mid360(), chain, LidarNoise::default(), 1);
    let start = scene.start;
    let v = Vector3::new(2.0, 0.0, 0.0);
    let pose = move |t: f64| {
        Isometry3::from_parts(
            Translation3::from(start.coords + v * t),
            UnitQuaternion::identity(),
        )
    };
    let omega = 100f64.to_radians();
    let angle = move |t: f64| omega * t;
    let mut imu = ImuSim::new(ImuNoise::default(), 200.0, 2);
    let mut odo = Odometry::new(
        chain,
        OdometryConfig::default(),
        NavState {
            time: 0.0,
            position: start.coords,
            velocity: v,
            attitude: UnitQuaternion::identity(),
        },
    );
    let mut frame = |odo: &mut Odometry, k: u64| {
        let mut pts = Vec::new();
        for i in 0..20u64 {
            let t = (20 * k + i) as f64 / 200.0;
            let s = imu.sample(
                t,
                &UnitQuaternion::identity(),
                &Vector3::zeros(),
                &Vector3::zeros(),
            );
            odo.push_imu(&s).unwrap();
        }
        lidar
            .frame(&world, k, k as f64 / 10.0, pose, angle, &mut pts)
            .unwrap();
        let angles: Vec<AngleSample> = (0..=100u64)
            .map(|j| {
                let t = (100 * k + j) as f64 / 1000.0;
                AngleSample::new(t, angle(t))
            })
            .collect();
        (pts, angles)
    };
    for k in 0..20u64 {
        let (pts, angles) = frame(&mut odo, k);
        odo.process_frame((k + 1) as f64 / 10.0, &pts, &angles)
            .unwrap();
    }
    let (pts, angles) = frame(&mut odo, 20);
    c.bench_function("odometry_update_mid360_20k_maze", |b| {
        b.iter_batched(
            || odo.clone(),
            |mut o| black_box(o.process_frame(2.1, &pts, &angles).unwrap().map_points),
            BatchSize::LargeInput,
        );
    });
}

criterion_group!(
    benches,
    bench_rays,
    bench_voxel_rays,
    bench_frame,
    bench_odometry
);
criterion_main!(benches);
