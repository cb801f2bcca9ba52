//! Runs the explorer over scenes × controllers × seeds in parallel and writes the paper-style
//! tables and one coverage plot per scene.
//!
//! Run with `cargo run --release -p fu-mpc-examples --bin benchmark -- --scenes small,maze
//! --controllers fu-mpc,fixed:100,rigid-yaw --seeds 1,2 --out DIR`. Each run writes
//! `DIR/runs/SCENE-CONTROLLER-SEED/` (summary, coverage, trajectories, pictures); a run whose
//! `summary.json` exists is not run again, so an interrupted benchmark resumes. At the end
//! `DIR/results.md` holds one table per scene (mean over the seeds) and
//! `DIR/coverage-SCENE.png` the coverage over time of every controller (first seed).

use std::fmt::Write as _;
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::time::Instant;

use clap::Parser;
use fu_mpc_examples::explorer::{ControllerKind, ExplorerConfig, Mission, explore};
use fu_mpc_examples::metrics::{time_to_coverage, write_tum};
use fu_mpc_examples::plot::{LinePlot, PALETTE, Series};
use fu_mpc_examples::report::{Report, say, write_pictures};
use fu_mpc_examples::setup::{clears_no_return, load_scene, parse_band};
use rayon::prelude::*;
use serde_json::Value;

/// Benchmarks the scan controllers: scenes × controllers × seeds.
#[derive(Debug, Parser)]
#[command(version)]
struct Args {
    /// Comma-separated scenes (maze, sinkhole, lavatube, small, FILE.pcd, FILE.ply).
    #[arg(long, default_value = "small", value_delimiter = ',')]
    scenes: Vec<String>,
    /// Comma-separated controllers.
    #[arg(
        long,
        default_value = "fu-mpc,fixed:30,fixed:100,fixed:360,uncertainty,frontier,icr,rigid-yaw",
        value_delimiter = ','
    )]
    controllers: Vec<ControllerKind>,
    /// Comma-separated seeds.
    #[arg(long, default_value = "1", value_delimiter = ',')]
    seeds: Vec<u64>,
    /// Time budget of each run, simulated seconds.
    #[arg(long, default_value_t = 600.0)]
    max_time: f64,
    /// Beams that return nothing clear the map along them up to its range in every scene. By
    /// default they do only in point clouds open to the sky (see `explore --help`). Runs with
    /// it are kept apart (their directories end in `-clear`).
    #[arg(long, conflicts_with = "keep_no_return")]
    clear_no_return: bool,
    /// Beams that return nothing leave the map as it is, even in a cloud open to the sky.
    /// Runs with it are kept apart (their directories end in `-keep`).
    #[arg(long)]
    keep_no_return: bool,
    /// Speed band MIN,MAX of the optimising controllers (fu-mpc, uncertainty, frontier, icr)
    /// in deg/s; by default 30,180. Runs with it are kept apart (their directories end in
    /// `-band_MIN_MAX`).
    #[arg(long, value_parser = parse_band, allow_hyphen_values = true)]
    band: Option<[f64; 2]>,
    /// Runs at once (default: one per core).
    #[arg(long)]
    jobs: Option<usize>,
    /// Output directory.
    #[arg(long, default_value = "out/benchmark")]
    out: PathBuf,
}

fn run_dir(
    out: &Path,
    scene: &str,
    controller: &ControllerKind,
    seed: u64,
    args: &Args,
) -> PathBuf {
    let mut suffix = String::new();
    if args.clear_no_return {
        suffix += "-clear";
    }
    if args.keep_no_return {
        suffix += "-keep";
    }
    if let Some([lo, hi]) = args.band {
        suffix += &format!("-band_{lo}_{hi}");
    }
    let name = format!("{scene}-{controller}-{seed}{suffix}").replace([':', '/', '\\'], "_");
    out.join("runs").join(name)
}

/// One run, written into its directory.
fn run_one(
    scene_spec: &str,
    controller: ControllerKind,
    seed: u64,
    args: &Args,
    dir: &Path,
) -> Result<String, Box<dyn std::error::Error + Send + Sync>> {
    let mut config = ExplorerConfig {
        controller,
        max_time: args.max_time,
        ..ExplorerConfig::default()
    };
    if let Some([lo, hi]) = args.band {
        config = config.with_band(lo, hi)?;
    }
    let scene = load_scene(
        scene_spec,
        seed,
        config.flight.height,
        config.map.resolution,
        None,
    )?;
    config.clear_on_no_return = clears_no_return(args.clear_no_return, args.keep_no_return, &scene);
    let mission = Mission {
        world: &scene.world,
        min: scene.area.min,
        max: scene.area.max,
        start: scene.area.start,
        explorable: Some(&scene.explorable),
    };
    let clock = Instant::now();
    let log = explore(&mission, &config, seed, |_| {})?;
    let report = Report::new(&scene.name, seed, &log, clock.elapsed().as_secs_f64())?;
    std::fs::create_dir_all(dir)?;
    let mut csv = BufWriter::new(File::create(dir.join("coverage.csv"))?);
    writeln!(csv, "time_s,coverage")?;
    for (t, c) in &log.coverage {
        writeln!(csv, "{t:.1},{c:.5}")?;
    }
    csv.flush()?;
    write_tum(
        &mut BufWriter::new(File::create(dir.join("gt.tum"))?),
        &log.times,
        &log.truth,
    )?;
    write_tum(
        &mut BufWriter::new(File::create(dir.join("est.tum"))?),
        &log.times,
        &log.estimate,
    )?;
    write_pictures(dir, &log)?;
    // The summary last: its presence marks the run as done.
    std::fs::write(
        dir.join("summary.json"),
        format!("{}\n", serde_json::to_string_pretty(&report.json())?),
    )?;
    Ok(report.screen())
}

fn read_coverage(path: &Path) -> Vec<(f64, f64)> {
    std::fs::read_to_string(path)
        .unwrap_or_default()
        .lines()
        .skip(1)
        .filter_map(|l| {
            let (t, c) = l.split_once(',')?;
            Some((t.parse().ok()?, 100.0 * c.parse::<f64>().ok()?))
        })
        .collect()
}

fn mean(v: &[f64]) -> f64 {
    // Seed counts are small.
    #[allow(clippy::cast_precision_loss)]
    let n = v.len().max(1) as f64;
    v.iter().sum::<f64>() / n
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args = Args::parse();
    if let Some(j) = args.jobs {
        rayon::ThreadPoolBuilder::new()
            .num_threads(j.max(1))
            .build_global()?;
    }
    let mut runs = Vec::new();
    for scene in &args.scenes {
        for controller in &args.controllers {
            for &seed in &args.seeds {
                runs.push((scene.clone(), *controller, seed));
            }
        }
    }
    let todo: Vec<_> = runs
        .iter()
        .filter(|(s, c, seed)| {
            !run_dir(&args.out, s, c, *seed, &args)
                .join("summary.json")
                .exists()
        })
        .collect();
    say(format_args!(
        "{} runs, {} already done, {} to run",
        runs.len(),
        runs.len() - todo.len(),
        todo.len()
    ));
    let failures: Vec<String> = todo
        .par_iter()
        .filter_map(|(scene, controller, seed)| {
            let dir = run_dir(&args.out, scene, controller, *seed, &args);
            match run_one(scene, *controller, *seed, &args, &dir) {
                Ok(screen) => {
                    say(&screen);
                    None
                }
                Err(e) => Some(format!("{scene} / {controller} / {seed}: {e}")),
            }
        })
        .collect();
    for f in &failures {
        say(format_args!("FAILED {f}"));
    }
    // The tables, from every summary on disk.
    let mut md = String::from("# Benchmark results\n\n");
    writeln!(
        md,
        "Means over seeds {:?}; time budget {} s. Exploration time and trajectory length are \
         averaged over finished runs only (— when none finished); the time to 99 % coverage \
         over the runs that reached it (how many in brackets).{}{}\n",
        args.seeds,
        args.max_time,
        if args.clear_no_return {
            " Beams that return nothing clear the map along them in every scene \
             (`--clear-no-return`)."
        } else if args.keep_no_return {
            " Beams that return nothing leave the map as it is in every scene \
             (`--keep-no-return`)."
        } else {
            " Beams that return nothing clear the map along them only in point clouds open \
             to the sky."
        },
        args.band.map_or(String::new(), |[lo, hi]| format!(
            " The optimising controllers keep the motor within {lo}–{hi} deg/s (`--band`)."
        ))
    )?;
    for scene_spec in &args.scenes {
        let mut plot = LinePlot {
            title: format!("COVERAGE: {scene_spec}"),
            x_label: "TIME (S)".into(),
            y_label: "COVERAGE (%)".into(),
            series: Vec::new(),
            y_range: Some((0.0, 100.0)),
        };
        writeln!(md, "## {scene_spec}\n")?;
        md += "| controller | finished | exploration time (s) | 99 % seen at (s) | trajectory length (m) | coverage (%) | APE RMSE (m) | APE mean (m) | APE max (m) | collisions | real-time factor |\n";
        md += "|---|---|---|---|---|---|---|---|---|---|---|\n";
        for (ci, controller) in args.controllers.iter().enumerate() {
            let dirs: Vec<PathBuf> = args
                .seeds
                .iter()
                .map(|&seed| run_dir(&args.out, scene_spec, controller, seed, &args))
                .collect();
            let summaries: Vec<Value> = dirs
                .iter()
                .filter_map(|dir| {
                    let text = std::fs::read_to_string(dir.join("summary.json")).ok()?;
                    serde_json::from_str(&text).ok()
                })
                .collect();
            if summaries.is_empty() {
                continue;
            }
            let f = |v: &Value, k: &str| v.get(k).and_then(Value::as_f64).unwrap_or(f64::NAN);
            let done: Vec<&Value> = summaries
                .iter()
                .filter(|v| v.get("finished").and_then(Value::as_bool) == Some(true))
                .collect();
            let all = |k: &str| mean(&summaries.iter().map(|v| f(v, k)).collect::<Vec<_>>());
            let fin = |k: &str| {
                if done.is_empty() {
                    "—".to_string()
                } else {
                    format!(
                        "{:.1}",
                        mean(&done.iter().map(|v| f(v, k)).collect::<Vec<_>>())
                    )
                }
            };
            let collisions: f64 = summaries.iter().map(|v| f(v, "collisions")).sum();
            // The time to 99 % from each run's coverage series, over the runs that got there.
            let at99: Vec<f64> = dirs
                .iter()
                .filter_map(|dir| time_to_coverage(&read_coverage(&dir.join("coverage.csv")), 99.0))
                .collect();
            let at99 = if at99.is_empty() {
                "—".to_string()
            } else {
                format!("{:.1} ({}/{})", mean(&at99), at99.len(), summaries.len())
            };
            writeln!(
                md,
                "| {controller} | {}/{} | {} | {at99} | {} | {:.1} | {:.3} | {:.3} | {:.3} | {collisions} | {:.1} |",
                done.len(),
                summaries.len(),
                fin("exploration_time_s"),
                fin("trajectory_length_m"),
                100.0 * all("coverage"),
                all("ape_rmse_m"),
                all("ape_mean_m"),
                all("ape_max_m"),
                all("realtime_factor"),
            )?;
            if let Some(dir) = dirs.first() {
                plot.series.push(Series {
                    label: controller.to_string(),
                    color: PALETTE[ci % PALETTE.len()],
                    points: read_coverage(&dir.join("coverage.csv")),
                });
            }
        }
        md += "\n";
        let name = Path::new(scene_spec)
            .file_stem()
            .map_or_else(|| scene_spec.clone(), |s| s.to_string_lossy().into_owned());
        plot.render(1000, 600)
            .write(&args.out.join(format!("coverage-{name}.png")))?;
    }
    std::fs::write(args.out.join("results.md"), &md)?;
    say(&md);
    if failures.is_empty() {
        Ok(())
    } else {
        Err(format!("{} runs failed", failures.len()).into())
    }
}
