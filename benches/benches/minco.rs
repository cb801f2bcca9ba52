//! Benchmarks of `minco` on the reference problem: W_i = (i, sin i, cos i), rest at both
//! ends, all T_i = 1.
//!
//! `solve_energy_grad` is one coefficient solve plus energy and gradient propagation. Targets
//! (half of GCOPTER's C++ on the same machine): s=3: M=10 ≤ 1.9 µs, M=100 ≤ 20.2 µs,
//! M=1000 ≤ 213 µs; s=4: M=10 ≤ 3.5 µs, M=100 ≤ 36.8 µs, M=1000 ≤ 375 µs; s=2: M=100 ≤ 8.7 µs.
//!
//! Run with `cargo bench -p fu-mpc-benches --bench minco`.

use std::hint::black_box;

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use minco::{Minco, Optimizer, OptimizerConfig};

fn point(i: usize) -> [f64; 3] {
    let x = i as f64;
    [x, x.sin(), x.cos()]
}

fn bench_order<const S: usize>(c: &mut Criterion, pieces: &[usize]) {
    let mut g = c.benchmark_group(format!("minco_s{S}"));
    for &m in pieces {
        let mut head = [[0.0; 3]; S];
        let mut tail = [[0.0; 3]; S];
        head[0] = point(0);
        tail[0] = point(m);
        let q: Vec<[f64; 3]> = (1..m).map(point).collect();
        let t = vec![1.0; m];
        let Ok(mut problem) = Minco::<S, 3>::new(m) else {
            continue;
        };
        let (mut gc, mut gt) = (vec![[0.0; 3]; 2 * S * m], vec![0.0; m]);
        let (mut gq, mut gtt) = (vec![[0.0; 3]; m - 1], vec![0.0; m]);
        g.bench_function(BenchmarkId::new("solve_energy_grad", m), |b| {
            b.iter(|| {
                problem
                    .solve(black_box(&head), &tail, black_box(&q), black_box(&t))
                    .ok();
                gc.fill([0.0; 3]);
                gt.fill(0.0);
                let j = problem
                    .add_energy_partials(&mut gc, &mut gt)
                    .unwrap_or(f64::NAN);
                problem.propagate_gradient(&gc, &gt, &mut gq, &mut gtt).ok();
                black_box((j, &gq, &gtt));
            });
        });
    }
    g.finish();
}

/// One full optimisation of a 10-piece trajectory (9 inner path points, v_max = 3 m/s,
/// a_max = 3 m/s²). Target: ≤ 2 ms.
fn bench_optimize(c: &mut Criterion) {
    let path: Vec<[f64; 3]> = (1..10)
        .map(|i| {
            let x = f64::from(i);
            [1.5 * x, 1.2 * (0.7 * x).sin(), 1.0 + 0.3 * (0.5 * x).cos()]
        })
        .collect();
    let rest = |p: [f64; 3]| [p, [0.0; 3], [0.0; 3]];
    let (start, goal) = (rest([0.0, 0.0, 1.3]), rest([15.0, 0.0, 1.0]));
    let cfg = OptimizerConfig::default();
    c.bench_function("minco_optimize_10_pieces", |b| {
        b.iter(|| {
            let Ok(mut opt) = Optimizer::<3, 3>::new(cfg, black_box(start), goal, black_box(&path))
            else {
                return;
            };
            black_box(opt.optimize().ok());
        });
    });
}

fn bench_minco(c: &mut Criterion) {
    bench_order::<2>(c, &[100]);
    bench_order::<3>(c, &[10, 100, 1000]);
    bench_order::<4>(c, &[10, 100, 1000]);
}

criterion_group!(benches, bench_minco, bench_optimize);
criterion_main!(benches);
