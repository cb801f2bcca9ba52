//! Benchmarks of `topo-tsp`: open asymmetric tours of exploration size.
//!
//! Targets (medians on a 2-core machine): n = 30 in ≤ 2 ms, n = 100 in ≤ 30 ms, open tour
//! from node 0, with the budget a replanning explorer uses (`SolverConfig::fast`: n trials,
//! LKH's default). The instances are random points in a 40 m × 40 m × 6 m box with the
//! transition cost (7) as arc cost plus a seeded asymmetric detour.
//!
//! `solve_open_fast` is that budget; `solve_open` is the default automatic budget (2n trials at
//! least, continued while the best tour still improves), tuned for TSPLIB optima; `bound` is
//! the Held–Karp ascent and the α-nearness candidates alone, the fixed part of every solve.
//!
//! `graph_2000_nodes` builds a topological graph of 2,000 nodes (random in a 100 m × 40 m ×
//! 8 m box, a third of them at one height as sampled viewpoints are) with a 6 m connection
//! radius and free space everywhere: the neighbour search and the edge bookkeeping alone.
//!
//! Run with `cargo bench -p fu-mpc-benches --bench topo_tsp`.

use std::hint::black_box;

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use topo_tsp::{
    BoundConfig, CostMatrix, SolverConfig, TopoGraph, alpha_candidates, held_karp_bound,
    solve_open, transition_cost,
};

fn instance(n: usize, seed: u64) -> Option<CostMatrix> {
    let mut s = seed;
    let mut next = move || {
        s = s
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        (s >> 11) as f64 / (1u64 << 53) as f64
    };
    let pts: Vec<[f64; 3]> = (0..n)
        .map(|_| [40.0 * next(), 40.0 * next(), 6.0 * next()])
        .collect();
    let detour: Vec<f64> = (0..n * n).map(|_| 2.0 * next()).collect();
    CostMatrix::from_fn(n, |i, j| {
        transition_cost(&[pts[i], pts[j]], 3.0) + detour[i * n + j]
    })
    .ok()
}

fn bench_open_tours(c: &mut Criterion) {
    let mut g = c.benchmark_group("open_atsp");
    g.sample_size(20);
    for n in [30usize, 100] {
        let Some(m) = instance(n, 42) else { continue };
        let cfg = SolverConfig::default();
        g.bench_function(BenchmarkId::new("solve_open", n), |b| {
            b.iter(|| black_box(solve_open(black_box(&m), &cfg, || false).ok()));
        });
        let fast = SolverConfig::fast();
        g.bench_function(BenchmarkId::new("solve_open_fast", n), |b| {
            b.iter(|| black_box(solve_open(black_box(&m), &fast, || false).ok()));
        });
        let open = m.with_free_return_to_start();
        g.bench_function(BenchmarkId::new("bound", n), |b| {
            b.iter(|| {
                let hk = held_karp_bound(black_box(&open), &BoundConfig::default()).ok();
                black_box(hk.and_then(|hk| alpha_candidates(&open, &hk.pi, 10).ok()))
            });
        });
    }
    g.finish();
}

fn bench_graph(c: &mut Criterion) {
    let mut s = 7u64;
    let mut next = move || {
        s = s
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        (s >> 11) as f64 / (1u64 << 53) as f64
    };
    let pts: Vec<[f64; 3]> = (0..2000)
        .map(|i| {
            let z = if i % 3 == 0 { 2.5 } else { 8.0 * next() };
            [100.0 * next(), 40.0 * next(), z]
        })
        .collect();
    let free = |_: &[f64; 3], _: &[f64; 3]| true;
    c.bench_function("graph_2000_nodes", |b| {
        b.iter(|| {
            let mut g = TopoGraph::new();
            for p in &pts {
                black_box(g.add_node(*p, 6.0, &free).ok());
            }
            black_box(g.len())
        });
    });
}

criterion_group!(benches, bench_open_tours, bench_graph);
criterion_main!(benches);
