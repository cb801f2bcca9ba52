//! The reference problem: solve, energy and gradient, printed as one JSON line.
//!
//! Points W_i = (i, sin i, cos i) for i = 0..M; the trajectory starts at W_0 and ends at W_M
//! with all higher head and tail derivatives zero, passes q_i = W_i, and every T_i = 1.
//! Prints `{"order":S,"pieces":M,"energy":J,"grad_q1":[x,y,z],"grad_t0":g,"solve_ns":…,"grad_ns":…}`
//! where `grad_q1` is ∂J/∂q_1 (null for M = 1), `grad_t0` is dJ/dT_1, and the times are medians
//! over repeated runs of one solve and of one energy-plus-gradient propagation.
//!
//! Run with `cargo run --release -p minco --example reference -- --order 3 --pieces 100`.
#![allow(clippy::print_stdout, clippy::print_stderr)]

use std::hint::black_box;
use std::process::ExitCode;
use std::time::Instant;

use minco::{Minco, MincoError};

fn point(i: usize) -> [f64; 3] {
    let x = i as f64;
    [x, x.sin(), x.cos()]
}

fn median_ns(mut f: impl FnMut(), runs: usize) -> u128 {
    let mut t: Vec<u128> = (0..runs)
        .map(|_| {
            let start = Instant::now();
            f();
            start.elapsed().as_nanos()
        })
        .collect();
    t.sort_unstable();
    t[t.len() / 2]
}

fn run<const S: usize>(m: usize) -> Result<String, MincoError> {
    let mut head = [[0.0; 3]; S];
    let mut tail = [[0.0; 3]; S];
    head[0] = point(0);
    tail[0] = point(m);
    let q: Vec<[f64; 3]> = (1..m).map(point).collect();
    let t = vec![1.0; m];
    let mut problem = Minco::<S, 3>::new(m)?;
    problem.solve(&head, &tail, &q, &t)?;

    let n = 2 * S * m;
    let (mut gc, mut gt) = (vec![[0.0; 3]; n], vec![0.0; m]);
    let (mut gq, mut gtt) = (vec![[0.0; 3]; m - 1], vec![0.0; m]);
    problem.add_energy_partials(&mut gc, &mut gt)?;
    problem.propagate_gradient(&gc, &gt, &mut gq, &mut gtt)?;
    let energy = problem.energy();

    let runs = (200_000 / m).clamp(200, 20_000);
    let solve_ns = median_ns(
        || {
            problem
                .solve(black_box(&head), &tail, black_box(&q), &t)
                .ok();
        },
        runs,
    );
    let grad_ns = median_ns(
        || {
            gc.fill([0.0; 3]);
            gt.fill(0.0);
            black_box(problem.add_energy_partials(&mut gc, &mut gt).ok());
            problem.propagate_gradient(&gc, &gt, &mut gq, &mut gtt).ok();
            black_box(&gtt);
        },
        runs,
    );
    let grad_q1 = gq.first().map_or("null".to_string(), |g| {
        format!("[{:e},{:e},{:e}]", g[0], g[1], g[2])
    });
    Ok(format!(
        "{{\"order\":{S},\"pieces\":{m},\"energy\":{energy:e},\"grad_q1\":{grad_q1},\"grad_t0\":{:e},\"solve_ns\":{solve_ns},\"grad_ns\":{grad_ns}}}",
        gtt[0]
    ))
}

fn parse_args() -> Result<(usize, usize), String> {
    let mut order = 3;
    let mut pieces = 10;
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        let mut value = |name: &str| -> Result<usize, String> {
            args.next()
                .ok_or(format!("{name} needs a value"))?
                .parse()
                .map_err(|e| format!("{name}: {e}"))
        };
        match a.as_str() {
            "--order" => order = value("--order")?,
            "--pieces" => pieces = value("--pieces")?,
            "-h" | "--help" => return Err("usage: reference [--order 2|3|4] [--pieces M]".into()),
            other => return Err(format!("unknown argument {other}")),
        }
    }
    Ok((order, pieces))
}

fn main() -> ExitCode {
    let result = parse_args().and_then(|(order, pieces)| {
        match order {
            2 => run::<2>(pieces),
            3 => run::<3>(pieces),
            4 => run::<4>(pieces),
            s => Err(MincoError::UnsupportedOrder(s)),
        }
        .map_err(|e| e.to_string())
    });
    match result {
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
