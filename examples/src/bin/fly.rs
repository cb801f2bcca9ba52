//! Flies a fixed route through a scene with the LiDAR, IMU, encoder and odometry running, and
//! measures the odometry against the ground truth.
//!
//! Run with `cargo run --release -p fu-mpc-examples --bin fly -- --scene maze --seed N --out DIR`;
//! `--scene` also takes a PCD or PLY point cloud, flown as occupied 0.1 m voxels from the
//! clearest point 1.5 m above its lowest point.
//! The route goes from the scene's start to the reachable point farthest along x (at most
//! 80 m on) at 1.5 m and back (about 200 m in the maze), at up to 2 m/s, with the motor at 100 deg/s (see
//! `fu_mpc_examples::flight`). Writes `DIR/summary.json`, the trajectories `DIR/gt.tum` and
//! `DIR/est.tum` (so `evo_ape tum gt.tum est.tum` works) and the odometry's final local map
//! `DIR/map.ply`, and prints the summary.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::PathBuf;
use std::time::Instant;

use fu_mpc_examples::cloud_io::{load_pcd, load_ply};
use fu_mpc_examples::flight::{Area, FlightConfig, fly, out_and_back_route, route_trajectory};
use fu_mpc_examples::metrics::{Alignment, ape, trajectory_length, write_tum};
use fu_mpc_examples::report::say;
use fu_mpc_examples::scene::Scene;
use fu_mpc_examples::world::World;

const USAGE: &str =
    "usage: fly [--scene maze|sinkhole|lavatube|small|FILE.pcd|FILE.ply] [--seed N] [--out DIR]";

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut scene_name = "maze".to_string();
    let mut seed = 1u64;
    let mut out = PathBuf::from("out/fly");
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--scene" => scene_name = args.next().ok_or(USAGE)?,
            "--seed" => {
                seed = args
                    .next()
                    .and_then(|s| s.parse().ok())
                    .ok_or("--seed needs a number")?;
            }
            "--out" => out = args.next().map(PathBuf::from).ok_or(USAGE)?,
            _ => return Err(USAGE.into()),
        }
    }
    let config = FlightConfig::default();
    let (name, world, area) = match scene_name.as_str() {
        "maze" | "sinkhole" | "lavatube" | "small" => {
            let scene = match scene_name.as_str() {
                "maze" => Scene::maze(seed),
                "sinkhole" => Scene::sinkhole(seed),
                "lavatube" => Scene::lava_tube(seed),
                _ => Scene::small(seed),
            };
            let area = Area::from(&scene);
            (scene.name.clone(), scene.world()?, area)
        }
        file => {
            // A point-cloud scene: occupied 0.1 m voxels; the start is the clearest point
            // 1.5 m above the cloud's lowest point (see `Area::of_cloud`).
            let path = PathBuf::from(file);
            let cloud = if file.ends_with(".ply") {
                load_ply(&path)?
            } else if file.ends_with(".pcd") {
                load_pcd(&path)?
            } else {
                return Err(USAGE.into());
            };
            let world = World::from_points(&cloud, 0.1)?;
            let area = Area::of_cloud(&cloud, &world, config.height)
                .ok_or("the cloud has no finite point")?;
            let name = path
                .file_stem()
                .map_or_else(|| file.to_string(), |s| s.to_string_lossy().into_owned());
            (name, world, area)
        }
    };
    std::fs::create_dir_all(&out)?;
    let route = out_and_back_route(&area, &world, &config)?;
    let traj = route_trajectory(&route, &config, 0.35)?;
    if std::env::var_os("FLY_DEBUG").is_some() {
        say(format_args!("route {route:?} duration {}", traj.duration()));
    }
    let start = Instant::now();
    let log = fly(&world, &traj, &config, seed)?;
    let wall = start.elapsed().as_secs_f64();
    let (truth, est) = log.positions();
    let raw = ape(&truth, &est, Alignment::None)?;
    let aligned = ape(&truth, &est, Alignment::Se3)?;
    let sim_time = log.times.last().copied().unwrap_or(0.0);
    // Frame counts are small.
    #[allow(clippy::cast_precision_loss)]
    let per_frame_ms = |s: f64| 1e3 * s / log.times.len().max(1) as f64;
    let summary = format!(
        concat!(
            "{{\"scene\":\"{}\",\"seed\":{},\"trajectory_length_m\":{:.3},\"sim_time_s\":{:.3},",
            "\"wall_time_s\":{:.3},\"ape_rmse_m\":{:.4},\"ape_mean_m\":{:.4},\"ape_max_m\":{:.4},",
            "\"ape_unaligned_rmse_m\":{:.4},\"ape_unaligned_mean_m\":{:.4},",
            "\"ape_unaligned_max_m\":{:.4},\"min_clearance_m\":{:.3},\"collisions\":{},",
            "\"frames\":{},\"lidar_frame_ms_mean\":{:.3},\"odometry_update_ms_mean\":{:.3}}}"
        ),
        name,
        seed,
        trajectory_length(&truth),
        sim_time,
        wall,
        aligned.rmse,
        aligned.mean,
        aligned.max,
        raw.rmse,
        raw.mean,
        raw.max,
        log.min_clearance,
        log.collisions,
        log.times.len(),
        per_frame_ms(log.lidar_seconds),
        per_frame_ms(log.odometry_seconds),
    );
    std::fs::write(out.join("summary.json"), format!("{summary}\n"))?;
    write_tum(
        &mut BufWriter::new(File::create(out.join("gt.tum"))?),
        &log.times,
        &log.truth,
    )?;
    write_tum(
        &mut BufWriter::new(File::create(out.join("est.tum"))?),
        &log.times,
        &log.estimate,
    )?;
    let mut ply = BufWriter::new(File::create(out.join("map.ply"))?);
    writeln!(
        ply,
        "ply\nformat ascii 1.0\nelement vertex {}\nproperty float x\nproperty float y\nproperty float z\nend_header",
        log.map.len()
    )?;
    for p in &log.map {
        writeln!(ply, "{:.3} {:.3} {:.3}", p.x, p.y, p.z)?;
    }
    ply.flush()?;
    say(&summary);
    Ok(())
}
