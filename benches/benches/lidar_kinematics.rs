//! Benchmarks of `lidar-kinematics` hot paths.
//!
//! Targets (medians on a 2-core machine):
//! - chain transform of 1,000,000 points: ≤ 3 ns per point at one motor angle,
//!   ≤ 10 ns per point with per-point angles;
//! - deskew of a 20,000-point frame: ≤ 0.5 ms.
//!
//! Run with `cargo bench -p fu-mpc-benches --bench lidar_kinematics`.

use std::hint::black_box;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use lidar_kinematics::{
    AngleSample, DeskewTarget, Deskewer, Extrinsics, KinematicChain, LidarSensor, PoseSample,
    TimedPoint,
};
use nalgebra::{Isometry3, Point3, Vector3};

/// A small deterministic generator (SplitMix64) so inputs are the same every run.
struct Rng(u64);

impl Rng {
    fn next_f64(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^= z >> 31;
        (z >> 11) as f64 / (1u64 << 53) as f64
    }

    fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.next_f64()
    }
}

fn chain() -> KinematicChain {
    let ext = Extrinsics::try_new(
        Isometry3::new(
            Vector3::new(0.02, 0.0, 0.05),
            Vector3::new(std::f64::consts::FRAC_PI_2, 0.0, 0.0),
        ),
        Isometry3::new(Vector3::new(0.12, 0.0, -0.03), Vector3::new(0.0, 0.1, 0.0)),
    );
    match ext {
        Ok(e) => KinematicChain::new(e),
        Err(e) => unreachable!("constant extrinsics are valid: {e}"),
    }
}

fn bench_chain(c: &mut Criterion) {
    const N: usize = 1_000_000;
    let mut rng = Rng(7);
    let src: Vec<Point3<f64>> = (0..N)
        .map(|_| {
            Point3::new(
                rng.range(-30.0, 30.0),
                rng.range(-30.0, 30.0),
                rng.range(-5.0, 5.0),
            )
        })
        .collect();
    let thetas: Vec<f64> = (0..N).map(|i| i as f64 * 1e-5).collect();
    let mut dst = vec![Point3::origin(); N];
    let chain = chain();
    let body = Isometry3::new(Vector3::new(1.0, 2.0, 3.0), Vector3::new(0.05, -0.02, 0.7));

    let mut g = c.benchmark_group("chain_1M");
    g.throughput(Throughput::Elements(N as u64));
    g.sample_size(20);
    g.bench_function("one_angle", |b| {
        b.iter(|| {
            chain
                .lidar_to_world_batch(black_box(&body), black_box(0.3), black_box(&src), &mut dst)
                .ok();
            black_box(&dst);
        });
    });
    g.bench_function("per_point_angle", |b| {
        b.iter(|| {
            chain
                .lidar_to_world_per_point(
                    black_box(&body),
                    black_box(&thetas),
                    black_box(&src),
                    &mut dst,
                )
                .ok();
            black_box(&dst);
        });
    });
    g.finish();
}

fn bench_deskew(c: &mut Criterion) {
    let sensor = LidarSensor::mid360();
    let chain = chain();
    let mut rng = Rng(11);
    // 0.1 s frame; body poses at 200 Hz, encoder at 1 kHz, motor at 2π rad/s.
    let poses: Vec<PoseSample> = (0..=20)
        .map(|k| {
            let t = f64::from(k) * 0.005;
            PoseSample::new(
                t,
                Isometry3::new(
                    Vector3::new(2.0 * t, 0.5 * t, 1.5),
                    Vector3::new(0.02 * t, 0.0, 0.8 * t),
                ),
            )
        })
        .collect();
    let angles: Vec<AngleSample> = (0..=100)
        .map(|k| {
            let t = f64::from(k) * 0.001;
            AngleSample::new(
                t,
                lidar_kinematics::angle::wrap_to_two_pi(std::f64::consts::TAU * t),
            )
        })
        .collect();
    let points: Vec<TimedPoint> = sensor
        .pattern()
        .frame(0)
        .map(|b| {
            TimedPoint::new(
                b.time_offset,
                Point3::from(b.direction.into_inner() * rng.range(1.0, 40.0)),
            )
        })
        .collect();
    let mut out = vec![Point3::origin(); points.len()];
    let mut deskewer = Deskewer::new(chain);

    let mut g = c.benchmark_group("deskew");
    g.throughput(Throughput::Elements(points.len() as u64));
    g.bench_function("mid360_frame_20k_world", |b| {
        b.iter(|| {
            deskewer
                .deskew(
                    black_box(&poses),
                    black_box(&angles),
                    black_box(&points),
                    DeskewTarget::World,
                    &mut out,
                )
                .ok();
            black_box(&out);
        });
    });
    g.bench_function("mid360_frame_20k_frame_end_body", |b| {
        b.iter(|| {
            deskewer
                .deskew(
                    black_box(&poses),
                    black_box(&angles),
                    black_box(&points),
                    DeskewTarget::BodyAt(0.1),
                    &mut out,
                )
                .ok();
            black_box(&out);
        });
    });
    g.finish();
}

criterion_group!(benches, bench_chain, bench_deskew);
criterion_main!(benches);
