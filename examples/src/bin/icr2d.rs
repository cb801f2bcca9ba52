//! The iCR paper's Section IV experiment on two generated floor plans.
//!
//! Run with `cargo run --release -p fu-mpc-examples --bin icr2d -- --out DIR [--steps N] [--seed S]`.
//! Writes, per environment E ∈ {A, B}: `DIR/logdet_E.csv` (header
//! `step,icr,icr_frontier,frontier,random`), `DIR/logdet_E.png` (the four curves: iCR blue,
//! iCR + frontier green, frontier cyan, random red) and `DIR/map_E_<strategy>.png` (the
//! thresholded occupancy map with the path, beside the information map), and prints one JSON
//! line per environment with the final log det of each strategy.

use std::path::PathBuf;

use fu_mpc_examples::icr2d::{
    GridMap, Strategy, episode_image, log_det_plot, run_episode, write_csv, write_png,
};
use fu_mpc_examples::report::say;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut out: Option<PathBuf> = None;
    let mut steps = 925usize;
    let mut seed = 1u64;
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--out" => out = args.next().map(PathBuf::from),
            "--steps" => {
                steps = args
                    .next()
                    .and_then(|s| s.parse().ok())
                    .ok_or("--steps needs a number")?;
            }
            "--seed" => {
                seed = args
                    .next()
                    .and_then(|s| s.parse().ok())
                    .ok_or("--seed needs a number")?;
            }
            _ => return Err("usage: icr2d --out DIR [--steps N] [--seed S]".into()),
        }
    }
    let out = out.ok_or("usage: icr2d --out DIR [--steps N] [--seed S]")?;
    std::fs::create_dir_all(&out)?;
    for (name, sx, sy, map_seed) in [("A", 14.46, 20.04, seed), ("B", 17.37, 17.43, seed + 1)] {
        let map = GridMap::floor_plan(sx, sy, map_seed);
        let mut curves = Vec::new();
        let mut finals = Vec::new();
        for strategy in Strategy::ALL {
            let ep = run_episode(&map, strategy, steps, seed)?;
            let (w, h, img) = episode_image(&map, &ep);
            write_png(
                &out.join(format!("map_{name}_{}.png", strategy.name())),
                w,
                h,
                &img,
            )?;
            finals.push(format!(
                "\"{}\":{:.1}",
                strategy.name(),
                ep.log_det[ep.log_det.len() - 1]
            ));
            curves.push(ep.log_det);
        }
        write_csv(&out.join(format!("logdet_{name}.csv")), &curves)?;
        let (w, h, img) = log_det_plot(&curves);
        write_png(&out.join(format!("logdet_{name}.png")), w, h, &img)?;
        say(format_args!(
            "{{\"environment\":\"{name}\",\"cells\":{},\"steps\":{steps},{}}}",
            map.occupied.len(),
            finals.join(",")
        ));
    }
    Ok(())
}
