//! Reports of an exploration run: the summary (JSON and one screen of text) and the pictures.

use std::path::Path;

use nalgebra::Point3;
use serde_json::{Value, json};

use crate::explorer::{ExploreLog, ModuleTimes};
use crate::metrics::{Alignment, ApeStats, MetricsError, ape, trajectory_length};
use crate::plot::{Canvas, LinePlot, PALETTE, Series};

/// Mean, largest and count of one module's per-call milliseconds.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ModuleStats {
    /// Mean \[ms\].
    pub mean_ms: f64,
    /// Largest \[ms\].
    pub max_ms: f64,
    /// Calls.
    pub calls: usize,
}

impl ModuleStats {
    fn of(v: &[f64]) -> Self {
        // Call counts are far below 2^53.
        #[allow(clippy::cast_precision_loss)]
        let mean_ms = if v.is_empty() {
            0.0
        } else {
            v.iter().sum::<f64>() / v.len() as f64
        };
        Self {
            mean_ms,
            max_ms: v.iter().copied().fold(0.0, f64::max),
            calls: v.len(),
        }
    }

    fn total_s(v: &[f64]) -> f64 {
        v.iter().sum::<f64>() / 1e3
    }
}

/// The metrics of one run, as the paper's tables report them.
#[derive(Debug, Clone, PartialEq)]
pub struct Report {
    /// Scene name.
    pub scene: String,
    /// Controller name.
    pub controller: String,
    /// Seed.
    pub seed: u64,
    /// Whether the run ended with no reachable frontier left.
    pub finished: bool,
    /// Whether beams that returned nothing cleared the map along them.
    pub clear_no_return: bool,
    /// Why the harness stopped the run early, if it did.
    pub aborted: Option<&'static str>,
    /// Simulated time at the end \[s\].
    pub exploration_time_s: f64,
    /// Length of the true trajectory \[m\].
    pub trajectory_length_m: f64,
    /// Final coverage (0..1), if measured.
    pub coverage: Option<f64>,
    /// APE after SE(3) alignment \[m\].
    pub ape: ApeStats,
    /// APE without alignment \[m\].
    pub ape_unaligned: ApeStats,
    /// Least distance to the world \[m\].
    pub min_clearance_m: f64,
    /// Collisions.
    pub collisions: usize,
    /// Wall time of the run \[s\].
    pub wall_time_s: f64,
    /// Trajectories planned.
    pub trajectories: usize,
    /// Frontier clusters left at the end.
    pub clusters_left: usize,
    /// Per-module timings: lidar, odometry, mapping, planning, scan, fisher.
    pub modules: Vec<(&'static str, ModuleStats)>,
    /// Share of the wall time spent in the scan controller (including Fisher rebuilds).
    pub scan_share: f64,
}

impl Report {
    /// The report of `log`, run on `scene` with `seed` in `wall_time_s`.
    ///
    /// # Errors
    /// [`MetricsError`] for a log with fewer than three poses.
    pub fn new(
        scene: &str,
        seed: u64,
        log: &ExploreLog,
        wall_time_s: f64,
    ) -> Result<Self, MetricsError> {
        let (truth, est) = positions(log);
        let t: &ModuleTimes = &log.timings;
        let modules = vec![
            ("lidar", ModuleStats::of(&t.lidar)),
            ("odometry", ModuleStats::of(&t.odometry)),
            ("mapping", ModuleStats::of(&t.mapping)),
            ("planning", ModuleStats::of(&t.planning)),
            ("scan", ModuleStats::of(&t.scan)),
            ("fisher", ModuleStats::of(&t.fisher)),
        ];
        let scan_s = ModuleStats::total_s(&t.scan) + ModuleStats::total_s(&t.fisher);
        Ok(Self {
            scene: scene.to_string(),
            controller: log.controller.clone(),
            seed,
            finished: log.finished,
            clear_no_return: log.clear_on_no_return,
            aborted: log.aborted,
            exploration_time_s: log.exploration_time,
            trajectory_length_m: trajectory_length(&truth),
            coverage: log.coverage.last().map(|&(_, c)| c),
            ape: ape(&truth, &est, Alignment::Se3)?,
            ape_unaligned: ape(&truth, &est, Alignment::None)?,
            min_clearance_m: log.min_clearance,
            collisions: log.collisions,
            wall_time_s,
            trajectories: log.trajectories,
            clusters_left: log.clusters_left,
            modules,
            scan_share: scan_s / wall_time_s.max(1e-9),
        })
    }

    /// The summary as JSON.
    pub fn json(&self) -> Value {
        let modules: serde_json::Map<String, Value> = self
            .modules
            .iter()
            .map(|(name, s)| {
                (
                    (*name).to_string(),
                    json!({"mean_ms": s.mean_ms, "max_ms": s.max_ms, "calls": s.calls}),
                )
            })
            .collect();
        json!({
            "scene": self.scene,
            "controller": self.controller,
            "seed": self.seed,
            "finished": self.finished,
            "clear_no_return": self.clear_no_return,
            "aborted": self.aborted,
            "exploration_time_s": self.exploration_time_s,
            "trajectory_length_m": self.trajectory_length_m,
            "coverage": self.coverage,
            "ape_rmse_m": self.ape.rmse,
            "ape_mean_m": self.ape.mean,
            "ape_max_m": self.ape.max,
            "ape_unaligned_rmse_m": self.ape_unaligned.rmse,
            "ape_unaligned_mean_m": self.ape_unaligned.mean,
            "ape_unaligned_max_m": self.ape_unaligned.max,
            "min_clearance_m": self.min_clearance_m,
            "collisions": self.collisions,
            "sim_time_s": self.exploration_time_s,
            "wall_time_s": self.wall_time_s,
            "realtime_factor": self.exploration_time_s / self.wall_time_s.max(1e-9),
            "trajectories": self.trajectories,
            "clusters_left": self.clusters_left,
            "scan_share_of_wall": self.scan_share,
            "modules": modules,
        })
    }

    /// One screen of text.
    pub fn screen(&self) -> String {
        let mut s = format!(
            "{} / {} / seed {}: {} after {:.1} s simulated ({:.1} s wall, {:.1}x real time)\n",
            self.scene,
            self.controller,
            self.seed,
            match (self.finished, self.aborted) {
                (true, _) => "finished".to_string(),
                (false, Some(why)) => format!("ABORTED ({why})"),
                (false, None) => "NOT finished".to_string(),
            },
            self.exploration_time_s,
            self.wall_time_s,
            self.exploration_time_s / self.wall_time_s.max(1e-9),
        );
        s += &format!(
            "  coverage {}   trajectory {:.1} m   trajectories {}   clusters left {}\n",
            self.coverage
                .map_or_else(|| "n/a".to_string(), |c| format!("{:.1} %", 100.0 * c)),
            self.trajectory_length_m,
            self.trajectories,
            self.clusters_left,
        );
        s += &format!(
            "  APE rmse/mean/max {:.3}/{:.3}/{:.3} m aligned, {:.3}/{:.3}/{:.3} m as flown\n",
            self.ape.rmse,
            self.ape.mean,
            self.ape.max,
            self.ape_unaligned.rmse,
            self.ape_unaligned.mean,
            self.ape_unaligned.max,
        );
        s += &format!(
            "  min clearance {:.2} m   collisions {}\n  per call (mean/max ms):",
            self.min_clearance_m, self.collisions
        );
        for (name, m) in &self.modules {
            s += &format!(" {name} {:.2}/{:.1}", m.mean_ms, m.max_ms);
        }
        s += &format!(
            "\n  scan control {:.2} % of the wall time",
            100.0 * self.scan_share
        );
        s
    }
}

/// Writes `text` and a newline to standard output, for the programs' summaries. A closed
/// output (a reader such as `head` that stopped early) ends nothing: the run's files are
/// written already, so the program goes on where `println!` would panic.
///
/// # Example
/// ```
/// fu_mpc_examples::report::say("wrote out/explore");
/// ```
pub fn say(text: impl std::fmt::Display) {
    use std::io::Write;
    // A broken pipe behind stdout loses only the echo.
    let _ = writeln!(std::io::stdout().lock(), "{text}");
}

/// The true and estimated positions of a log.
pub fn positions(log: &ExploreLog) -> (Vec<Point3<f64>>, Vec<Point3<f64>>) {
    let at = |poses: &[nalgebra::Isometry3<f64>]| -> Vec<Point3<f64>> {
        poses.iter().map(|p| p.translation.vector.into()).collect()
    };
    (at(&log.truth), at(&log.estimate))
}

/// The top-down picture: occupied cells (darker where more are stacked), the true trajectory
/// in red and the estimate in blue, 50 pixels per metre at most.
pub fn map_picture(log: &ExploreLog) -> Canvas {
    let (truth, est) = positions(log);
    let all = || log.occupied.iter().chain(truth.iter());
    let (mut lo, mut hi) = (
        Point3::new(f64::MAX, f64::MAX, 0.0),
        Point3::new(f64::MIN, f64::MIN, 0.0),
    );
    for p in all() {
        lo = Point3::new(lo.x.min(p.x), lo.y.min(p.y), 0.0);
        hi = Point3::new(hi.x.max(p.x), hi.y.max(p.y), 0.0);
    }
    if lo.x > hi.x {
        (lo, hi) = (Point3::origin(), Point3::new(1.0, 1.0, 0.0));
    }
    let span = (hi - lo).xy().max().max(1.0);
    let scale = (1600.0 / span).min(50.0);
    // Picture sizes are a few thousand pixels.
    #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
    let (w, h) = (
        ((hi.x - lo.x) * scale) as usize + 21,
        ((hi.y - lo.y) * scale) as usize + 21,
    );
    let mut counts = vec![0u16; w * h];
    #[allow(clippy::cast_possible_truncation)]
    let px = |p: &Point3<f64>| {
        (
            ((p.x - lo.x) * scale).round() as i64 + 10,
            (h as i64 - 11) - ((p.y - lo.y) * scale).round() as i64,
        )
    };
    for p in &log.occupied {
        let (x, y) = px(p);
        if let (Ok(x), Ok(y)) = (usize::try_from(x), usize::try_from(y))
            && x < w
            && y < h
        {
            counts[y * w + x] = counts[y * w + x].saturating_add(1);
        }
    }
    let mut c = Canvas::new(w, h);
    let cell = (scale * 0.2).ceil().max(1.0);
    #[allow(clippy::cast_possible_truncation)]
    let r = cell as i64 / 2;
    for y in 0..h {
        for x in 0..w {
            let n = counts[y * w + x];
            if n > 0 {
                #[allow(clippy::cast_possible_truncation)]
                let g = 200u16.saturating_sub(12 * n).max(40) as u8;
                #[allow(clippy::cast_possible_wrap)]
                let (x, y) = (x as i64, y as i64);
                c.fill((x - r, y - r), (x + r, y + r), [g, g, g]);
            }
        }
    }
    for (pts, color) in [(&est, PALETTE[0]), (&truth, PALETTE[1])] {
        for w2 in pts.windows(2) {
            c.line(px(&w2[0]), px(&w2[1]), color, 2);
        }
    }
    if let Some(s) = truth.first() {
        let (x, y) = px(s);
        c.fill((x - 4, y - 4), (x + 4, y + 4), PALETTE[2]);
    }
    c.text(10, 10, "RED: TRUE PATH  BLUE: ESTIMATE", [0, 0, 0], 2);
    c
}

/// Writes `coverage.png`, `motor_speed.png`, `ape.png` and `map_top.png` into `dir`.
///
/// # Errors
/// I/O and encoding errors.
pub fn write_pictures(dir: &Path, log: &ExploreLog) -> std::io::Result<()> {
    let (truth, est) = positions(log);
    let name = log.controller.clone();
    let plot = |title: &str, y_label: &str, points: Vec<(f64, f64)>, y_range| LinePlot {
        title: title.into(),
        x_label: "TIME (S)".into(),
        y_label: y_label.into(),
        series: vec![Series {
            label: name.clone(),
            color: PALETTE[0],
            points,
        }],
        y_range,
    };
    plot(
        "COVERAGE",
        "COVERAGE (%)",
        log.coverage.iter().map(|&(t, c)| (t, 100.0 * c)).collect(),
        Some((0.0, 100.0)),
    )
    .render(900, 500)
    .write(&dir.join("coverage.png"))?;
    plot(
        "MOTOR SPEED",
        "DEG/S",
        log.times
            .iter()
            .zip(&log.motor_speed)
            .map(|(&t, w)| (t, w.to_degrees()))
            .collect(),
        None,
    )
    .render(900, 500)
    .write(&dir.join("motor_speed.png"))?;
    plot(
        "POSITION ERROR AS FLOWN",
        "ERROR (M)",
        log.times
            .iter()
            .zip(truth.iter().zip(&est))
            .map(|(&t, (g, e))| (t, (g - e).norm()))
            .collect(),
        None,
    )
    .render(900, 500)
    .write(&dir.join("ape.png"))?;
    map_picture(log).write(&dir.join("map_top.png"))
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Isometry3;

    fn log(n: usize) -> ExploreLog {
        // Sizes are tiny.
        #[allow(clippy::cast_precision_loss)]
        let truth: Vec<Isometry3<f64>> = (0..n)
            .map(|i| Isometry3::translation(i as f64, 0.0, 1.0))
            .collect();
        let estimate = truth
            .iter()
            .map(|p| Isometry3::translation(0.0, 0.1, 0.0) * p)
            .collect();
        #[allow(clippy::cast_precision_loss)]
        let times = (0..n).map(|i| 0.1 * (i + 1) as f64).collect();
        ExploreLog {
            controller: "fu-mpc".into(),
            finished: true,
            exploration_time: 0.1 * 4.0,
            times,
            truth,
            estimate,
            motor_speed: vec![1.0; n],
            coverage: vec![(0.2, 0.5), (0.4, 0.75)],
            min_clearance: 0.8,
            timings: ModuleTimes {
                scan: vec![1.0, 3.0],
                ..ModuleTimes::default()
            },
            ..ExploreLog::default()
        }
    }

    #[test]
    fn the_summary_holds_the_paper_metrics() {
        let r = Report::new("small", 3, &log(4), 2.0).unwrap();
        assert!((r.trajectory_length_m - 3.0).abs() < 1e-12);
        assert!((r.ape_unaligned.rmse - 0.1).abs() < 1e-12);
        assert!(r.ape.rmse < 1e-9, "alignment removes a constant shift");
        assert_eq!(r.coverage, Some(0.75));
        let scan = r.modules.iter().find(|(n, _)| *n == "scan").unwrap().1;
        assert!((scan.mean_ms - 2.0).abs() < 1e-12 && (scan.max_ms - 3.0).abs() < 1e-12);
        assert!((r.scan_share - 0.002).abs() < 1e-12);
        let j = r.json();
        for key in [
            "scene",
            "controller",
            "seed",
            "finished",
            "clear_no_return",
            "exploration_time_s",
            "trajectory_length_m",
            "coverage",
            "ape_rmse_m",
            "ape_mean_m",
            "ape_max_m",
            "min_clearance_m",
            "collisions",
            "sim_time_s",
            "wall_time_s",
            "modules",
        ] {
            assert!(j.get(key).is_some(), "{key}");
        }
        assert!(r.screen().contains("finished"));
        // Too short a log for the alignment is an error, not a panic.
        assert!(Report::new("small", 3, &log(2), 1.0).is_err());
        // The pictures draw.
        let pic = map_picture(&log(4));
        assert!(pic.width() > 20 && pic.height() > 20);
    }
}
