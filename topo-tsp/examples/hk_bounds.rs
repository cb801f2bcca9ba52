//! Prints the Held–Karp lower bound of TSPLIB instances next to their published optima.
//!
//! Run with `cargo run --release -p topo-tsp --example hk_bounds -- ../shared/data/tsplib`.
#![allow(clippy::print_stdout, clippy::print_stderr)]

use std::process::ExitCode;
use std::time::Instant;

use topo_tsp::{BoundConfig, held_karp_bound, parse_tsplib};

fn main() -> ExitCode {
    let Some(dir) = std::env::args().nth(1) else {
        eprintln!("usage: hk_bounds DIR (with optima.tsv and NAME.atsp files)");
        return ExitCode::FAILURE;
    };
    let Ok(optima) = std::fs::read_to_string(format!("{dir}/optima.tsv")) else {
        eprintln!("cannot read {dir}/optima.tsv");
        return ExitCode::FAILURE;
    };
    println!(
        "{:<10} {:>5} {:>10} {:>12} {:>8} {:>9}",
        "name", "n", "optimum", "lower bound", "gap %", "ms"
    );
    for line in optima.lines() {
        let cols: Vec<&str> = line.split('\t').collect();
        let (Some(name), Some(opt)) = (
            cols.first(),
            cols.get(2).and_then(|v| v.trim().parse::<f64>().ok()),
        ) else {
            continue;
        };
        let Ok(text) = std::fs::read_to_string(format!("{dir}/{name}.atsp")) else {
            eprintln!("cannot read {name}.atsp");
            continue;
        };
        let inst = match parse_tsplib(&text) {
            Ok(i) => i,
            Err(e) => {
                eprintln!("{name}: {e}");
                continue;
            }
        };
        let start = Instant::now();
        let Ok(lb) = held_karp_bound(&inst.matrix, &BoundConfig::default()) else {
            continue;
        };
        let ms = start.elapsed().as_secs_f64() * 1e3;
        println!(
            "{:<10} {:>5} {:>10} {:>12.1} {:>8.3} {:>9.1}",
            name,
            inst.matrix.len(),
            opt,
            lb.lower_bound,
            100.0 * (opt - lb.lower_bound) / opt,
            ms
        );
    }
    ExitCode::SUCCESS
}
