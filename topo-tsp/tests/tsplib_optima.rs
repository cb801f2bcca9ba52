//! The solver on the TSPLIB ATSP instances of `../shared/data/tsplib/` (skipped with a message
//! when the folder is absent).
//!
//! Every test uses the default settings (seed 1) and requires the published optimum.
//! `instances_under_100_nodes` runs in CI; `larger_instances` (n ≥ 100) is ignored — run it
//! with `cargo test --release -p topo-tsp --test tsplib_optima -- --ignored`.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::print_stderr)]

use std::path::{Path, PathBuf};

use topo_tsp::{SolverConfig, parse_tsplib, solve};

fn data_dir() -> Option<PathBuf> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/data/tsplib");
    if dir.join("optima.tsv").is_file() {
        Some(dir)
    } else {
        eprintln!(
            "skipping: {} not found (the shared data folder is not beside the project)",
            dir.display()
        );
        None
    }
}

/// (name, n, optimum) rows of optima.tsv.
fn optima(dir: &Path) -> Vec<(String, usize, f64)> {
    std::fs::read_to_string(dir.join("optima.tsv"))
        .unwrap()
        .lines()
        .filter_map(|l| {
            let c: Vec<&str> = l.split('\t').collect();
            Some((
                c.first()?.trim().to_string(),
                c.get(1)?.trim().parse().ok()?,
                c.get(2)?.trim().parse().ok()?,
            ))
        })
        .collect()
}

fn check(dir: &Path, name: &str, n: usize, opt: f64) {
    let text = std::fs::read_to_string(dir.join(format!("{name}.atsp"))).unwrap();
    let inst = parse_tsplib(&text).unwrap();
    let sol = solve(&inst.matrix, &SolverConfig::default(), || false).unwrap();
    let mut seen = vec![false; n];
    assert_eq!(sol.tour.order.len(), n, "{name}");
    assert!(
        sol.tour
            .order
            .iter()
            .all(|&v| !std::mem::replace(&mut seen[v], true)),
        "{name}: not a permutation"
    );
    assert_eq!(
        sol.tour.length,
        inst.matrix.closed_length(&sol.tour.order),
        "{name}"
    );
    assert!(
        sol.tour.length >= opt,
        "{name}: {} below the published optimum {opt}",
        sol.tour.length
    );
    assert!(
        sol.lower_bound <= opt + 1e-6,
        "{name}: bound {} above the optimum {opt}",
        sol.lower_bound
    );
    assert!(
        sol.tour.length <= opt,
        "{name}: {} is {:.3} % above the optimum {opt}",
        sol.tour.length,
        100.0 * (sol.tour.length - opt) / opt
    );
}

#[test]
fn instances_under_100_nodes() {
    let Some(dir) = data_dir() else { return };
    for (name, n, opt) in optima(&dir).into_iter().filter(|r| r.1 < 100) {
        check(&dir, &name, n, opt);
    }
}

#[test]
#[ignore = "seconds in release mode, minutes in debug mode"]
fn larger_instances() {
    let Some(dir) = data_dir() else { return };
    for (name, n, opt) in optima(&dir).into_iter().filter(|r| r.1 >= 100) {
        check(&dir, &name, n, opt);
    }
}
