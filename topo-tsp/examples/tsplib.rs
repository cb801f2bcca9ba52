//! Solves one TSPLIB instance and prints one JSON line:
//! `{"name":…,"n":…,"length":…,"lower_bound":…,"trials":…,"millis":…}` (the closed tour's length).
//!
//! Run with `cargo run --release -p topo-tsp --example tsplib -- FILE.atsp [--seed S] [--time-limit-ms T]`.
#![allow(clippy::print_stdout, clippy::print_stderr)]

use std::process::ExitCode;
use std::time::{Duration, Instant};

use topo_tsp::{SolverConfig, parse_tsplib, solve};

fn run() -> Result<String, String> {
    let mut args = std::env::args().skip(1);
    let mut file = None;
    let mut cfg = SolverConfig::default();
    let mut limit = None;
    while let Some(a) = args.next() {
        match a.as_str() {
            "--candidates" => {
                cfg.candidates = args
                    .next()
                    .and_then(|v| v.parse().ok())
                    .ok_or("--candidates needs a number")?;
            }
            "--trials" => {
                cfg.max_trials = args
                    .next()
                    .and_then(|v| v.parse().ok())
                    .ok_or("--trials needs a number")?;
            }
            "--seed" => {
                cfg.seed = args
                    .next()
                    .and_then(|v| v.parse().ok())
                    .ok_or("--seed needs a number")?;
            }
            "--time-limit-ms" => {
                let ms: u64 = args
                    .next()
                    .and_then(|v| v.parse().ok())
                    .ok_or("--time-limit-ms needs a number")?;
                limit = Some(Duration::from_millis(ms));
            }
            "-h" | "--help" => return Err(
                "usage: tsplib FILE [--seed S] [--trials N] [--candidates K] [--time-limit-ms T]"
                    .into(),
            ),
            other if file.is_none() => file = Some(other.to_string()),
            other => return Err(format!("unexpected argument {other}")),
        }
    }
    let file = file.ok_or("usage: tsplib FILE [--seed S] [--time-limit-ms T]")?;
    let text = std::fs::read_to_string(&file).map_err(|e| format!("{file}: {e}"))?;
    let inst = parse_tsplib(&text).map_err(|e| format!("{file}: {e}"))?;
    let start = Instant::now();
    let sol = solve(&inst.matrix, &cfg, || {
        limit.is_some_and(|l| start.elapsed() > l)
    })
    .map_err(|e| e.to_string())?;
    let millis = start.elapsed().as_secs_f64() * 1e3;
    Ok(format!(
        "{{\"name\":\"{}\",\"n\":{},\"length\":{},\"lower_bound\":{:.1},\"trials\":{},\"millis\":{:.1}}}",
        inst.name,
        inst.matrix.len(),
        sol.tour.length,
        sol.lower_bound,
        sol.trials,
        millis
    ))
}

fn main() -> ExitCode {
    match run() {
        Ok(line) => {
            println!("{line}");
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}
