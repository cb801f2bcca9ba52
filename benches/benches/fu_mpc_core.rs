//! Benchmarks of `fu-mpc-core`.
//!
//! Targets (medians on the 2-core reference machine): one MPC update with N = 20 and the
//! dedicated QP ≤ 20 µs (p99 ≤ 100 µs; the update is timed with both QP back-ends, and
//! includes building its 21 frontier surrogates for 20 targets; it is also timed in closed
//! loop, the motor following each command as on a robot); the Fisher table from 20,000
//! points (K = 10, N_c = 72) ≤ 5 ms (and reported as the explorer builds it: 3,000 points,
//! the Mid-360 on its side on the motor); frontier surrogates for 100 targets × 20 steps × 72
//! knots ≤ 0.5 ms; one iCR iteration (K = 5, 100 × 100 cells) ≤ 1 ms and a 10-iteration iCR
//! plan ≤ 10 ms; the iCR scan controller's update at N = 20 is reported next to FU-MPC's.
//!
//! Run with `cargo bench -p fu-mpc-benches --bench fu_mpc_core`.
#![allow(clippy::unwrap_used, clippy::print_stderr)]

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use fu_mpc_core::icr::{Icr, IcrConfig, IcrScan, IcrScanConfig, InformationMap, Triangle};
use fu_mpc_core::{
    FisherConfig, FisherTable, FrontierTarget, FuMpc, MpcConfig, QpBackend, ScanController,
    ScanInput, UtilityConfig, frontier_surrogates,
};
use lidar_kinematics::{FieldOfView, KinematicChain, LidarSensor, MotorModel, MotorState};
use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};

/// A deterministic pseudo-random sequence in [0, 1).
struct Lcg(u64);

impl Lcg {
    fn next(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// 20,000 points on the walls, floor and ceiling of a 12 × 8 × 3 m room with pillars.
fn room_cloud(n: usize) -> Vec<Point3<f64>> {
    let mut r = Lcg(7);
    (0..n)
        .map(|_| {
            let (a, b) = (r.next(), r.next());
            match (r.next() * 6.0) as u32 {
                0 => Point3::new(-6.0, 8.0 * a - 4.0, 3.0 * b - 1.5),
                1 => Point3::new(6.0, 8.0 * a - 4.0, 3.0 * b - 1.5),
                2 => Point3::new(12.0 * a - 6.0, -4.0, 3.0 * b - 1.5),
                3 => Point3::new(12.0 * a - 6.0, 4.0, 3.0 * b - 1.5),
                4 => Point3::new(12.0 * a - 6.0, 8.0 * a.sin() * b - 4.0, -1.5),
                _ => {
                    let t = std::f64::consts::TAU * a;
                    Point3::new(2.0 + 0.3 * t.cos(), 1.0 + 0.3 * t.sin(), 3.0 * b - 1.5)
                }
            }
        })
        .collect()
}

fn reference(n: usize, dt: f64) -> Vec<Isometry3<f64>> {
    (0..=n)
        .map(|i| {
            let t = i as f64 * dt;
            Isometry3::from_parts(
                Translation3::new(1.5 * t, 0.3 * t, 0.0),
                UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 0.2 * t),
            )
        })
        .collect()
}

/// The poses at t0, t0 + dt, …, t0 + n dt of a UAV circling the origin at 3 m, 0.9 m/s,
/// facing along its path.
fn circling(n: usize, dt: f64, t0: f64) -> Vec<Isometry3<f64>> {
    (0..=n)
        .map(|i| {
            let a = 0.3 * (t0 + i as f64 * dt);
            Isometry3::from_parts(
                Translation3::new(3.0 * a.cos(), 3.0 * a.sin(), 0.0),
                UnitQuaternion::from_axis_angle(
                    &Vector3::z_axis(),
                    a + std::f64::consts::FRAC_PI_2,
                ),
            )
        })
        .collect()
}

/// `n` targets in a 20 m × 20 m × 2 m box around the reference's start.
fn targets(n: usize) -> Vec<FrontierTarget> {
    targets_in(n, 3, [20.0, 20.0, 2.0])
}

/// `n` seeded targets uniform in a box of the given size centred on the origin.
fn targets_in(n: usize, seed: u64, size: [f64; 3]) -> Vec<FrontierTarget> {
    let mut r = Lcg(seed);
    (0..n)
        .map(|_| FrontierTarget {
            center: Point3::new(
                size[0] * r.next() - 0.5 * size[0],
                size[1] * r.next() - 0.5 * size[1],
                size[2] * r.next() - 0.5 * size[2],
            ),
            score: 100.0 * r.next(),
        })
        .collect()
}

fn sensor() -> LidarSensor {
    LidarSensor::ring16().with_field_of_view(FieldOfView::try_new(-0.6, 0.6, -0.26, 0.26).unwrap())
}

fn bench_fisher(c: &mut Criterion) {
    let chain = KinematicChain::default();
    bench_table(
        c,
        "fisher_table_20k_points_k10_nc72",
        20_000,
        &chain,
        &sensor(),
    );
    // The table as the explorer builds it every second: 3,000 points of the local map, the
    // Mid-360 on its side on the motor (`explorer_chain`), whose full ring sees a point over
    // a long arc of motor angles.
    let chain = fu_mpc_examples::explorer::explorer_chain();
    bench_table(
        c,
        "fisher_table_3k_points_mid360_explorer_mount",
        3_000,
        &chain,
        &LidarSensor::mid360(),
    );
}

/// Times `FisherTable::build` with the default settings on `points` points of the room.
fn bench_table(
    c: &mut Criterion,
    name: &str,
    points: usize,
    chain: &KinematicChain,
    sensor: &LidarSensor,
) {
    let cloud = room_cloud(points);
    let cfg = FisherConfig::default();
    c.bench_function(name, |b| {
        b.iter(|| {
            black_box(
                FisherTable::build(
                    black_box(&cloud),
                    &Isometry3::identity(),
                    chain,
                    sensor,
                    &cfg,
                )
                .unwrap(),
            )
        });
    });
}

/// The surrogates for 100 targets near the UAV, and for 300 spread along a 120 m × 20 m ×
/// 8 m hall (the maze's size) with the UAV near its middle: as in a large map, most of those
/// are beyond the 15 m distance gate.
fn bench_surrogates(c: &mut Criterion) {
    let chain = KinematicChain::default();
    let refs = reference(20, 0.1);
    let cfg = UtilityConfig::default();
    let mut out = Vec::new();
    for (name, t) in [
        ("100_targets", targets(100)),
        (
            "300_spread_targets",
            targets_in(300, 11, [120.0, 20.0, 8.0]),
        ),
    ] {
        c.bench_function(
            &format!("frontier_surrogates_{name}_21_steps_72_knots"),
            |b| {
                b.iter(|| {
                    frontier_surrogates(
                        &chain,
                        black_box(&refs),
                        black_box(&t),
                        &cfg,
                        72,
                        &mut out,
                    )
                    .unwrap();
                    black_box(&out);
                });
            },
        );
    }
}

fn bench_mpc(c: &mut Criterion) {
    let chain = KinematicChain::default();
    let cfg = MpcConfig::default();
    let refs = reference(cfg.horizon, cfg.dt);
    let t = targets(20);
    let table = FisherTable::build(
        &room_cloud(5_000),
        &Isometry3::identity(),
        &chain,
        &sensor(),
        &FisherConfig::default(),
    )
    .unwrap();
    for (name, backend) in [
        ("dedicated", QpBackend::Dedicated),
        ("clarabel", QpBackend::Clarabel),
    ] {
        let mut mpc = FuMpc::new(MpcConfig { backend, ..cfg }, chain).unwrap();
        let mut theta = 0.0;
        // Criterion reports central values; the tail (p99) comes from the same updates, each
        // timed on its own, so it is measured only when this benchmark runs.
        let mut times: Vec<f64> = Vec::new();
        c.bench_function(&format!("fu_mpc_update_n20_{name}"), |b| {
            b.iter_custom(|iters| {
                let mut total = std::time::Duration::ZERO;
                for _ in 0..iters {
                    // A moving motor angle, so warm starts differ between iterations.
                    theta += 0.1;
                    let input = ScanInput {
                        motor: MotorState::new(theta, 1.0),
                        reference: &refs,
                        targets: &t,
                        fisher: Some(&table),
                    };
                    let start = std::time::Instant::now();
                    black_box(mpc.command(black_box(&input)).unwrap());
                    let el = start.elapsed();
                    times.push(el.as_secs_f64() * 1e6);
                    total += el;
                }
                total
            });
        });
        report_tail(&format!("fu_mpc_update_n20_{name}"), &mut times);
    }
    // Closed loop: the motor follows each command and the reference moves on by one step,
    // as in a controller running every Δt, so the shifted previous solution is a warm start
    // that fits (above, the motor state ignores the commands).
    let windows: Vec<Vec<Isometry3<f64>>> = (0..200)
        .map(|s| circling(cfg.horizon, cfg.dt, f64::from(s) * cfg.dt))
        .collect();
    let model = MotorModel::new(cfg.limits);
    // With fewer linearisation steps too: the mean cost of the closed loop's updates says
    // what the time saved costs.
    for (name, iterations) in [("", cfg.iterations), ("_2_iterations", 2)] {
        let cfg = MpcConfig { iterations, ..cfg };
        let mut mpc = FuMpc::new(cfg, chain).unwrap();
        let mut motor = MotorState::new(0.0, 1.0);
        let mut step = 0usize;
        let (mut times, mut cost): (Vec<f64>, f64) = (Vec::new(), 0.0);
        let name = format!("fu_mpc_update_n20_dedicated_closed_loop{name}");
        c.bench_function(&name, |b| {
            b.iter_custom(|iters| {
                let mut total = std::time::Duration::ZERO;
                for _ in 0..iters {
                    let input = ScanInput {
                        motor,
                        reference: &windows[step % windows.len()],
                        targets: &t,
                        fisher: Some(&table),
                    };
                    let start = std::time::Instant::now();
                    let cmd = black_box(mpc.command(black_box(&input)).unwrap());
                    let el = start.elapsed();
                    times.push(el.as_secs_f64() * 1e6);
                    total += el;
                    cost += mpc.solution().cost.total();
                    motor = model.step(motor, cmd.acceleration, cfg.dt).unwrap();
                    step += 1;
                }
                total
            });
        });
        if !times.is_empty() {
            eprintln!("{name}: mean cost {:.4}", cost / times.len() as f64);
        }
        report_tail(&name, &mut times);
    }
}

/// Prints the median and p99 of single update times \[µs\] (criterion reports central values).
fn report_tail(name: &str, times: &mut [f64]) {
    if !times.is_empty() {
        times.sort_by(f64::total_cmp);
        eprintln!(
            "{name}: median {:.1} µs, p99 {:.1} µs over {} updates",
            times[times.len() / 2],
            times[times.len() * 99 / 100],
            times.len()
        );
    }
}

/// The iCR scan controller at N = 20 on the same cloud, reference and sensor as the MPC
/// updates above, so the two are compared in one run.
fn bench_icr_scan(c: &mut Criterion) {
    let cfg = IcrScanConfig::default();
    let refs = reference(cfg.horizon, cfg.dt);
    let mut icr = IcrScan::new(cfg, KinematicChain::default(), sensor()).unwrap();
    icr.set_cloud(&room_cloud(5_000));
    let mut theta = 0.0;
    c.bench_function("icr_scan_update_n20", |b| {
        b.iter(|| {
            theta += 0.1;
            let input = ScanInput {
                motor: MotorState::new(theta, 1.0),
                reference: &refs,
                targets: &[],
                fisher: None,
            };
            black_box(icr.command(black_box(&input)).unwrap())
        });
    });
}

/// iCR on a 100 × 100-cell window (0.1 m cells, Σ₀ = 100 I) with K = 5 and the paper's
/// triangle: one iteration (reward and gradient; target ≤ 1 ms) and a 10-iteration plan
/// (target ≤ 10 ms).
fn bench_icr(c: &mut Criterion) {
    let cells: Vec<Point3<f64>> = (0..10_000)
        .map(|i| {
            Point3::new(
                f64::from(i % 100) * 0.1 - 5.0,
                f64::from(i / 100) * 0.1 - 5.0,
                0.0,
            )
        })
        .collect();
    let map = InformationMap::diagonal(cells, vec![0.01; 10_000]).unwrap();
    let fov = Triangle::new(3.0, 30f64.to_radians()).unwrap();
    let cfg = IcrConfig::default();
    let mut icr = Icr::new(cfg, fov).unwrap();
    let start = Isometry3::translation(-3.0, -1.0, 0.0);
    let u0: Vec<_> = (0..cfg.horizon)
        .map(|k| nalgebra::Vector6::new(1.5, 0.0, 0.0, 0.0, 0.0, 0.1 * f64::from(k as u32)))
        .collect();
    let mut grad = u0.clone();
    c.bench_function("icr_iteration_k5_100x100", |b| {
        b.iter(|| {
            black_box(
                icr.reward_and_gradient(&map, &start, black_box(&u0), &mut grad)
                    .unwrap(),
            )
        });
    });
    c.bench_function("icr_plan_10_iterations_k5_100x100", |b| {
        b.iter(|| {
            let mut u = u0.clone();
            black_box(icr.plan(&map, &start, &mut u).unwrap())
        });
    });
}

criterion_group!(
    benches,
    bench_fisher,
    bench_surrogates,
    bench_mpc,
    bench_icr_scan,
    bench_icr
);
criterion_main!(benches);
