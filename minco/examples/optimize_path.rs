//! Optimises a 10-piece trajectory along a wavy path and prints how it went.
//!
//! Run with `cargo run --release -p minco --example optimize_path`.
#![allow(clippy::print_stdout)]

use minco::{MincoError, Optimizer, OptimizerConfig};

fn main() -> Result<(), MincoError> {
    let path: Vec<[f64; 3]> = (1..10)
        .map(|i| {
            let x = f64::from(i);
            [1.5 * x, 1.2 * (0.7 * x).sin(), 1.0 + 0.3 * (0.5 * x).cos()]
        })
        .collect();
    let rest = |p: [f64; 3]| [p, [0.0; 3], [0.0; 3]];
    let cfg = OptimizerConfig::default();
    let mut opt =
        Optimizer::<3, 3>::new(cfg, rest([0.0, 0.0, 1.3]), rest([15.0, 0.0, 1.0]), &path)?;
    let sol = opt.optimize()?;
    let t = &sol.trajectory;
    println!(
        "status {:?} after {} iterations",
        sol.status, sol.iterations
    );
    println!("cost {:.3} (initial {:.3})", sol.cost, sol.initial_cost);
    println!(
        "duration {:.3} s, max speed {:.3} m/s (limit {}), max acceleration {:.3} m/s² (limit {})",
        t.duration(),
        t.max_speed(64),
        cfg.v_max,
        t.max_acceleration(64),
        cfg.a_max
    );
    Ok(())
}
