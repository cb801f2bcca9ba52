//! Explores a scene with the complete FU-MPC system in the simulator and reports the paper's
//! metrics.
//!
//! Run with `cargo run --release -p fu-mpc-examples --bin explore -- --scene small --out DIR`.
//! Writes `DIR/summary.json`, `DIR/coverage.csv`, the trajectories `DIR/gt.tum` and
//! `DIR/est.tum`, and the pictures `DIR/coverage.png`, `DIR/motor_speed.png`, `DIR/ape.png` and
//! `DIR/map_top.png`; prints a one-screen summary.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::PathBuf;
use std::time::Instant;

use clap::Parser;
use fu_mpc_examples::explorer::{ControllerKind, ExplorerConfig, Mission, explore};
use fu_mpc_examples::metrics::write_tum;
use fu_mpc_examples::report::{Report, say, write_pictures};
use fu_mpc_examples::setup::{clears_no_return, load_scene, parse_band};
use indicatif::{ProgressBar, ProgressStyle};
use nalgebra::Point3;

/// Explores a scene with a motorized-LiDAR UAV and reports time, distance, coverage and
/// localisation error.
#[derive(Debug, Parser)]
#[command(version)]
struct Args {
    /// Scene: maze, sinkhole, lavatube, small, or a FILE.pcd / FILE.ply point cloud.
    #[arg(long, default_value = "maze")]
    scene: String,
    /// Scan controller: fu-mpc, fixed:<deg/s>, uncertainty, frontier, icr or rigid-yaw.
    #[arg(long, default_value = "fu-mpc")]
    controller: ControllerKind,
    /// Seed of the scene generator and of the sensor noise.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Time budget of the exploration, simulated seconds.
    #[arg(long, default_value_t = 600.0)]
    max_time: f64,
    /// Start position X,Y,Z in metres. By default the scene's start; for point clouds the
    /// clearest point of a 0.5 m grid near 1.5 m above the cloud's lowest point.
    #[arg(long, value_parser = parse_point)]
    start: Option<Point3<f64>>,
    /// Output directory.
    #[arg(long, default_value = "out/explore")]
    out: PathBuf,
    /// Beams that return nothing clear the map along them up to its range. By default only in
    /// point clouds open to the sky (no ceiling: fewer than half of the cloud's 0.5 m columns
    /// reach within 0.5 m of its top); this turns it on for every scene.
    #[arg(long, conflicts_with = "keep_no_return")]
    clear_no_return: bool,
    /// Beams that return nothing leave the map as it is, even in a cloud open to the sky.
    #[arg(long)]
    keep_no_return: bool,
    /// Speed band MIN,MAX of the optimising controllers (fu-mpc, uncertainty, frontier, icr)
    /// in deg/s; by default 30,180. Fixed speeds and rigid-yaw ignore it.
    #[arg(long, value_parser = parse_band, allow_hyphen_values = true)]
    band: Option<[f64; 2]>,
    /// No progress bar.
    #[arg(long)]
    quiet: bool,
}

fn parse_point(s: &str) -> Result<Point3<f64>, String> {
    let v: Vec<f64> = s
        .split(',')
        .map(|x| x.trim().parse::<f64>().map_err(|e| e.to_string()))
        .collect::<Result<_, _>>()?;
    match v[..] {
        [x, y, z] if v.iter().all(|c| c.is_finite()) => Ok(Point3::new(x, y, z)),
        _ => Err(format!("expected X,Y,Z in metres, got {s:?}")),
    }
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args = Args::parse();
    let mut config = ExplorerConfig {
        controller: args.controller,
        max_time: args.max_time,
        ..ExplorerConfig::default()
    };
    if let Some([lo, hi]) = args.band {
        config = config.with_band(lo, hi)?;
    }
    let scene = load_scene(
        &args.scene,
        args.seed,
        config.flight.height,
        config.map.resolution,
        args.start,
    )?;
    config.clear_on_no_return = clears_no_return(args.clear_no_return, args.keep_no_return, &scene);
    if config.clear_on_no_return && !args.clear_no_return {
        say(format_args!(
            "{} is open to the sky: beams that return nothing clear the map along them \
             (--keep-no-return to leave it)",
            scene.name
        ));
    }
    std::fs::create_dir_all(&args.out)?;
    let mission = Mission {
        world: &scene.world,
        min: scene.area.min,
        max: scene.area.max,
        start: scene.area.start,
        explorable: Some(&scene.explorable),
    };
    let bar = if args.quiet {
        ProgressBar::hidden()
    } else {
        ProgressBar::new(1000)
    };
    bar.set_style(
        ProgressStyle::with_template(
            "{spinner} [{elapsed_precise}] coverage {bar:30} {percent:>3}% {msg}",
        )?
        .progress_chars("=> "),
    );
    let clock = Instant::now();
    let log = explore(&mission, &config, args.seed, |p| {
        if let Some(c) = p.coverage {
            // Coverage is in [0, 1]: the per-mille count fits u64.
            #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
            bar.set_position((c * 1000.0).round() as u64);
        }
        bar.set_message(format!("sim {:6.1} s, {} targets", p.time, p.targets));
    })?;
    let wall = clock.elapsed().as_secs_f64();
    bar.finish_and_clear();
    let report = Report::new(&scene.name, args.seed, &log, wall)?;
    std::fs::write(
        args.out.join("summary.json"),
        format!("{}\n", serde_json::to_string_pretty(&report.json())?),
    )?;
    let mut csv = BufWriter::new(File::create(args.out.join("coverage.csv"))?);
    writeln!(csv, "time_s,coverage")?;
    for (t, c) in &log.coverage {
        writeln!(csv, "{t:.1},{c:.5}")?;
    }
    csv.flush()?;
    write_tum(
        &mut BufWriter::new(File::create(args.out.join("gt.tum"))?),
        &log.times,
        &log.truth,
    )?;
    write_tum(
        &mut BufWriter::new(File::create(args.out.join("est.tum"))?),
        &log.times,
        &log.estimate,
    )?;
    write_pictures(&args.out, &log)?;
    say(report.screen());
    say(format_args!("wrote {}", args.out.display()));
    Ok(())
}
