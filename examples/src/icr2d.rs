//! The iCR paper's Section IV experiment: active occupancy mapping in 2-D with four strategies.
//!
//! Two seeded floor plans of rooms and corridors at the paper's sizes (Environment A
//! 14.46 m × 20.04 m, B 17.37 m × 17.43 m), a robot on SE(2) moving at v = 1.5 m/s with the
//! triangular field of view of height 3 m and 60° opening, κ = 0.5, K = 5, Σ₀ = 100 I, μ₀ = 0,
//! measurements ±1 for occupied/free cells in view, and the EIF update of eq. (6) per cell
//! (H = I, diagonal information). The robot, as in the paper, ignores occlusion and may pass
//! through walls; it is kept inside the map's bounds.
//!
//! Strategies: iCR from random initial yaw rates (ω ~ U[−π/10, π/10]), iCR from a
//! frontier-facing initialisation, the frontier-facing controls alone, and a random policy
//! (ω ~ U[−π/3, π/3]).

use std::f64::consts::PI;
use std::io::Write;
use std::path::Path;

use fu_mpc_core::CoreError;
use fu_mpc_core::icr::{Icr, IcrConfig, InformationMap, Triangle};
use nalgebra::{Isometry3, Point3, Vector3, Vector6};

use crate::rng::Rng;

/// Cell size of the generated maps \[m\].
pub const RESOLUTION: f64 = 0.2;
/// Forward speed \[m/s\].
pub const SPEED: f64 = 1.5;
/// Largest yaw rate any strategy commands \[rad/s\].
pub const MAX_YAW_RATE: f64 = PI / 3.0;

/// An occupancy grid: `occupied[y * width + x]`, cell centres at ((x + ½) r, (y + ½) r).
#[derive(Debug, Clone)]
pub struct GridMap {
    /// Cells along x.
    pub width: usize,
    /// Cells along y.
    pub height: usize,
    /// Occupancy of each cell.
    pub occupied: Vec<bool>,
}

impl GridMap {
    /// A floor plan of `size_x` × `size_y` metres: outer walls, rooms by recursive division with
    /// a door in every wall, and a corridor 1.6 m wide along the longer axis, seeded.
    pub fn floor_plan(size_x: f64, size_y: f64, seed: u64) -> Self {
        // Sizes are tens of metres at 0.2 m cells.
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        let (width, height) = (
            (size_x / RESOLUTION).round() as usize,
            (size_y / RESOLUTION).round() as usize,
        );
        let mut map = Self {
            width,
            height,
            occupied: vec![false; width * height],
        };
        for x in 0..width {
            map.set(x, 0);
            map.set(x, height - 1);
        }
        for y in 0..height {
            map.set(0, y);
            map.set(width - 1, y);
        }
        let mut rng = Rng::new(seed);
        map.divide(1, 1, width - 2, height - 2, &mut rng, 0);
        // The corridor: a free band through the middle of the longer side.
        let band = 8; // 1.6 m
        if width >= height {
            let y0 = height / 2 - band / 2;
            for x in 1..width - 1 {
                for y in y0..y0 + band {
                    map.occupied[y * width + x] = false;
                }
                map.set(x, y0 - 1);
                map.set(x, y0 + band);
            }
            // Doors from the corridor into the rooms on both sides.
            for x in (4..width - 4).step_by(18) {
                for dx in 0..5 {
                    map.occupied[(y0 - 1) * width + x + dx] = false;
                    map.occupied[(y0 + band) * width + x + dx] = false;
                }
            }
        } else {
            let x0 = width / 2 - band / 2;
            for y in 1..height - 1 {
                for x in x0..x0 + band {
                    map.occupied[y * width + x] = false;
                }
                map.set(x0 - 1, y);
                map.set(x0 + band, y);
            }
            for y in (4..height - 4).step_by(18) {
                for dy in 0..5 {
                    map.occupied[(y + dy) * width + x0 - 1] = false;
                    map.occupied[(y + dy) * width + x0 + band] = false;
                }
            }
        }
        map
    }

    fn set(&mut self, x: usize, y: usize) {
        self.occupied[y * self.width + x] = true;
    }

    /// Recursive division of the free box [x, x + w) × [y, y + h) into rooms of at least 3 m.
    fn divide(&mut self, x: usize, y: usize, w: usize, h: usize, rng: &mut Rng, depth: usize) {
        let min = 15; // 3 m
        if depth > 6 || (w < 2 * min && h < 2 * min) {
            return;
        }
        let vertical = if w >= 2 * min && h >= 2 * min {
            w >= h
        } else {
            w >= 2 * min
        };
        // Offsets in cells of small rooms; the draw is in [0, 1).
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        let pick =
            |rng: &mut Rng, span: usize| min + (rng.unit() * (span - 2 * min) as f64) as usize;
        if vertical {
            let cut = x + pick(rng, w);
            let door = y + 1 + pick_door(rng, h);
            for yy in y..y + h {
                if !(door..door + 5).contains(&yy) {
                    self.set(cut, yy);
                }
            }
            self.divide(x, y, cut - x, h, rng, depth + 1);
            self.divide(cut + 1, y, x + w - cut - 1, h, rng, depth + 1);
        } else {
            let cut = y + pick(rng, h);
            let door = x + 1 + pick_door(rng, w);
            for xx in x..x + w {
                if !(door..door + 5).contains(&xx) {
                    self.set(xx, cut);
                }
            }
            self.divide(x, y, w, cut - y, rng, depth + 1);
            self.divide(x, cut + 1, w, y + h - cut - 1, rng, depth + 1);
        }
    }

    /// Cell centres (z = 0), row by row.
    pub fn cells(&self) -> Vec<Point3<f64>> {
        (0..self.width * self.height)
            .map(|i| {
                let (x, y) = (i % self.width, i / self.width);
                // Grid indices are far below 2^53.
                #[allow(clippy::cast_precision_loss)]
                Point3::new(
                    (x as f64 + 0.5) * RESOLUTION,
                    (y as f64 + 0.5) * RESOLUTION,
                    0.0,
                )
            })
            .collect()
    }

    /// Size along x and y \[m\].
    pub fn extent(&self) -> (f64, f64) {
        // Grid sizes are far below 2^53.
        #[allow(clippy::cast_precision_loss)]
        (
            self.width as f64 * RESOLUTION,
            self.height as f64 * RESOLUTION,
        )
    }
}

/// A door position in a wall of `span` cells (5 cells wide).
fn pick_door(rng: &mut Rng, span: usize) -> usize {
    // A fraction of a small span.
    #[allow(
        clippy::cast_possible_truncation,
        clippy::cast_sign_loss,
        clippy::cast_precision_loss
    )]
    let d = (rng.unit() * span.saturating_sub(7) as f64) as usize;
    d
}

/// One of the four strategies of the experiment.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Strategy {
    /// iCR from random initial yaw rates.
    Icr,
    /// iCR from the frontier-facing controls.
    IcrFrontier,
    /// The frontier-facing controls alone.
    Frontier,
    /// Random yaw rates.
    Random,
}

impl Strategy {
    /// All four, in the column order of the CSV files.
    pub const ALL: [Strategy; 4] = [Self::Icr, Self::IcrFrontier, Self::Frontier, Self::Random];

    /// The CSV column name.
    pub fn name(self) -> &'static str {
        match self {
            Self::Icr => "icr",
            Self::IcrFrontier => "icr_frontier",
            Self::Frontier => "frontier",
            Self::Random => "random",
        }
    }
}

/// The outcome of one episode.
#[derive(Debug, Clone)]
pub struct Episode {
    /// log det Y after each step (index 0: the prior).
    pub log_det: Vec<f64>,
    /// Final information per cell.
    pub information: Vec<f64>,
    /// Final mean per cell.
    pub mean: Vec<f64>,
    /// Robot positions (x, y) \[m\].
    pub path: Vec<(f64, f64)>,
}

/// The experiment's iCR settings: K = 5, κ = 0.5, σ = 1, τ = 0.5 s, ten iterations on the yaw
/// rate, |ω| ≤ π/3.
pub fn icr_config() -> IcrConfig {
    let mut max_control = [f64::INFINITY; 6];
    max_control[5] = MAX_YAW_RATE;
    IcrConfig {
        horizon: 5,
        tau: 0.5,
        sigma: 1.0,
        kappa: 0.5,
        iterations: 10,
        step: [0.0, 0.0, 0.0, 0.0, 0.0, 0.02],
        max_control,
    }
}

/// Runs one episode of `steps` steps of `strategy` on `map` from the map's centre.
///
/// # Errors
/// Errors of the iCR planner (none for a valid map).
pub fn run_episode(
    map: &GridMap,
    strategy: Strategy,
    steps: usize,
    seed: u64,
) -> Result<Episode, CoreError> {
    let cfg = icr_config();
    let fov = Triangle::new(3.0, 30f64.to_radians())?;
    let mut icr = Icr::new(cfg, fov)?;
    let cells = map.cells();
    let n = cells.len();
    let mut info_map = InformationMap::diagonal(cells.clone(), vec![0.01; n])?;
    let mut info = vec![0.01; n];
    let mut mean = vec![0.0; n];
    let mut rng = Rng::new(seed);
    let (sx, sy) = map.extent();
    let mut pose = Isometry3::new(Vector3::new(0.5 * sx, 0.5 * sy, 0.0), Vector3::zeros());
    let mut log_det = vec![info.iter().map(|y: &f64| y.ln()).sum::<f64>()];
    let mut path = vec![(pose.translation.x, pose.translation.y)];
    let mut m = vec![0.0; n];
    let k = cfg.horizon;
    for _ in 0..steps {
        let mut u: Vec<Vector6<f64>> = match strategy {
            Strategy::Icr => (0..k)
                .map(|_| yaw_control(rng.range(-PI / 10.0, PI / 10.0)))
                .collect(),
            Strategy::IcrFrontier | Strategy::Frontier => {
                frontier_controls(map, &info, &pose, k, cfg.tau)
            }
            Strategy::Random => (0..k)
                .map(|_| yaw_control(rng.range(-PI / 3.0, PI / 3.0)))
                .collect(),
        };
        if matches!(strategy, Strategy::Icr | Strategy::IcrFrontier) {
            icr.plan(&info_map, &pose, &mut u)?;
        }
        // Execute the first control, then keep the robot inside the map.
        pose *= lidar_kinematics::se3::exp(&(u[0] * cfg.tau));
        pose.translation.x = pose.translation.x.clamp(0.0, sx);
        pose.translation.y = pose.translation.y.clamp(0.0, sy);
        path.push((pose.translation.x, pose.translation.y));
        // Measure: V⁻¹ of eq. (21) as information, z = ±1 for the cells inside the triangle.
        icr.information_at(&info_map, &pose, &mut m)?;
        let inv = pose.inverse();
        for j in 0..n {
            if m[j] <= 0.0 {
                continue;
            }
            let q = inv * cells[j];
            let inside = fov.sdf2(&nalgebra::Vector2::new(q.x, q.y)).0 <= 0.0;
            let z = if inside {
                if map.occupied[j] { 1.0 } else { -1.0 }
            } else {
                mean[j] // no measurement: the prior mean
            };
            // EIF with H = I, eq. (6): Y ← Y + M, μ ← (Y μ + M z) / (Y + M).
            let y_new = info[j] + m[j];
            mean[j] = (info[j] * mean[j] + m[j] * z) / y_new;
            info[j] = y_new;
        }
        info_map.add_information(&m)?;
        log_det.push(info.iter().map(|y| y.ln()).sum());
    }
    Ok(Episode {
        log_det,
        information: info,
        mean,
        path,
    })
}

fn yaw_control(omega: f64) -> Vector6<f64> {
    Vector6::new(SPEED, 0.0, 0.0, 0.0, 0.0, omega)
}

/// Controls that turn toward the frontier of the largest unexplored region: the unexplored
/// cells (information still at most twice the prior) are split into 4-connected regions, and
/// the robot heads for the cell of the largest region's frontier nearest to it.
pub fn frontier_controls(
    map: &GridMap,
    info: &[f64],
    pose: &Isometry3<f64>,
    k: usize,
    tau: f64,
) -> Vec<Vector6<f64>> {
    let target = frontier_target(map, info, pose);
    let mut heading = pose.rotation.euler_angles().2;
    let mut p = (pose.translation.x, pose.translation.y);
    (0..k)
        .map(|_| {
            let w = match target {
                Some((tx, ty)) => {
                    let bearing = (ty - p.1).atan2(tx - p.0);
                    let err = (bearing - heading + PI).rem_euclid(2.0 * PI) - PI;
                    (err / tau).clamp(-MAX_YAW_RATE, MAX_YAW_RATE)
                }
                None => 0.0,
            };
            heading += w * tau;
            p.0 += SPEED * tau * heading.cos();
            p.1 += SPEED * tau * heading.sin();
            yaw_control(w)
        })
        .collect()
}

fn frontier_target(map: &GridMap, info: &[f64], pose: &Isometry3<f64>) -> Option<(f64, f64)> {
    let (w, h) = (map.width, map.height);
    let unknown = |i: usize| info[i] <= 0.02;
    let mut label = vec![usize::MAX; w * h];
    let mut sizes = Vec::new();
    let mut stack = Vec::new();
    for start in 0..w * h {
        if !unknown(start) || label[start] != usize::MAX {
            continue;
        }
        let id = sizes.len();
        let mut size = 0;
        label[start] = id;
        stack.push(start);
        while let Some(c) = stack.pop() {
            size += 1;
            let (x, y) = (c % w, c / w);
            let mut visit = |nx: usize, ny: usize| {
                let j = ny * w + nx;
                if unknown(j) && label[j] == usize::MAX {
                    label[j] = id;
                    stack.push(j);
                }
            };
            if x > 0 {
                visit(x - 1, y);
            }
            if x + 1 < w {
                visit(x + 1, y);
            }
            if y > 0 {
                visit(x, y - 1);
            }
            if y + 1 < h {
                visit(x, y + 1);
            }
        }
        sizes.push(size);
    }
    let largest = (0..sizes.len()).max_by_key(|&i| sizes[i])?;
    let (px, py) = (pose.translation.x, pose.translation.y);
    let mut best: Option<(f64, (f64, f64))> = None;
    for c in 0..w * h {
        if label[c] != largest {
            continue;
        }
        let (x, y) = (c % w, c / w);
        let touches_known = (x > 0 && !unknown(c - 1))
            || (x + 1 < w && !unknown(c + 1))
            || (y > 0 && !unknown(c - w))
            || (y + 1 < h && !unknown(c + w));
        // The whole region counts when nothing is known yet.
        if !touches_known && sizes[largest] < w * h {
            continue;
        }
        // Grid indices are far below 2^53.
        #[allow(clippy::cast_precision_loss)]
        let (cx, cy) = ((x as f64 + 0.5) * RESOLUTION, (y as f64 + 0.5) * RESOLUTION);
        let d = (cx - px).hypot(cy - py);
        if best.is_none_or(|(bd, _)| d < bd) {
            best = Some((d, (cx, cy)));
        }
    }
    best.map(|(_, p)| p)
}

/// Writes an RGB image as PNG.
///
/// # Errors
/// I/O and encoding errors.
pub fn write_png(path: &Path, width: usize, height: usize, rgb: &[u8]) -> std::io::Result<()> {
    let file = std::io::BufWriter::new(std::fs::File::create(path)?);
    let (w, h) = (
        u32::try_from(width).map_err(std::io::Error::other)?,
        u32::try_from(height).map_err(std::io::Error::other)?,
    );
    let mut enc = png::Encoder::new(file, w, h);
    enc.set_color(png::ColorType::Rgb);
    enc.set_depth(png::BitDepth::Eight);
    let mut writer = enc.write_header().map_err(std::io::Error::other)?;
    writer
        .write_image_data(rgb)
        .map_err(std::io::Error::other)?;
    writer.finish().map_err(std::io::Error::other)
}

/// The thresholded occupancy map (black occupied, white free, grey unknown) beside the
/// information map (log Y, blue to orange), with the path in red on the left, flipped so +y is
/// up, each cell drawn as 4 × 4 pixels.
pub fn episode_image(map: &GridMap, ep: &Episode) -> (usize, usize, Vec<u8>) {
    let (w, h, small) = episode_image_cells(map, ep);
    let f = 4;
    let mut img = vec![0u8; w * h * f * f * 3];
    for y in 0..h * f {
        for x in 0..w * f {
            let (o, i) = ((y * w * f + x) * 3, ((y / f) * w + x / f) * 3);
            img[o..o + 3].copy_from_slice(&small[i..i + 3]);
        }
    }
    (w * f, h * f, img)
}

fn episode_image_cells(map: &GridMap, ep: &Episode) -> (usize, usize, Vec<u8>) {
    let (w, h) = (map.width, map.height);
    let (iw, ih) = (2 * w + 4, h);
    let mut img = vec![255u8; iw * ih * 3];
    let (lo, hi) = ep
        .information
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), y| {
            (a.min(y.ln()), b.max(y.ln()))
        });
    let span = (hi - lo).max(1e-9);
    for y in 0..h {
        for x in 0..w {
            let j = y * w + x;
            let row = h - 1 - y;
            let occ = match ep.mean[j] {
                m if m > 0.0 => 0u8,
                m if m < 0.0 => 255u8,
                _ => 128u8,
            };
            let o = (row * iw + x) * 3;
            img[o..o + 3].copy_from_slice(&[occ; 3]);
            // A value in [0, 255].
            #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
            let v = (((ep.information[j].ln() - lo) / span) * 255.0).round() as u8;
            let o = (row * iw + w + 4 + x) * 3;
            img[o..o + 3].copy_from_slice(&[v, v / 2, 255 - v]);
        }
    }
    for &(px, py) in &ep.path {
        // Positions inside the map.
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        let (x, y) = (
            ((px / RESOLUTION) as usize).min(w - 1),
            ((py / RESOLUTION) as usize).min(h - 1),
        );
        let o = ((h - 1 - y) * iw + x) * 3;
        img[o..o + 3].copy_from_slice(&[220, 30, 30]);
    }
    (iw, ih, img)
}

/// A line plot of the four log det curves (colours: iCR blue, iCR + frontier green, frontier
/// cyan, random red — the paper's), 800 × 500 pixels, axes from the data's range.
pub fn log_det_plot(curves: &[Vec<f64>]) -> (usize, usize, Vec<u8>) {
    let (w, h, m) = (800usize, 500usize, 40usize);
    let mut img = vec![255u8; w * h * 3];
    let colours = [[30, 60, 220], [30, 160, 60], [0, 190, 210], [220, 30, 30]];
    let (lo, hi) = curves
        .iter()
        .flatten()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
            (a.min(*v), b.max(*v))
        });
    let span = (hi - lo).max(1e-9);
    let len = curves.iter().map(Vec::len).max().unwrap_or(1).max(2);
    let put = |x: usize, y: usize, c: [u8; 3], img: &mut Vec<u8>| {
        if x < w && y < h {
            let o = (y * w + x) * 3;
            img[o..o + 3].copy_from_slice(&c);
        }
    };
    for x in m..w - m {
        put(x, h - m, [0, 0, 0], &mut img);
    }
    for y in m..h - m {
        put(m, y, [0, 0, 0], &mut img);
    }
    for (curve, c) in curves.iter().zip(colours) {
        // Pixel coordinates of small plots.
        #[allow(
            clippy::cast_possible_truncation,
            clippy::cast_sign_loss,
            clippy::cast_precision_loss
        )]
        let to_px = |i: usize, v: f64| {
            let x = m as f64 + (w - 2 * m) as f64 * i as f64 / (len - 1) as f64;
            let y = (h - m) as f64 - (h - 2 * m) as f64 * (v - lo) / span;
            (x, y)
        };
        for i in 1..curve.len() {
            let (a, b) = (to_px(i - 1, curve[i - 1]), to_px(i, curve[i]));
            let steps = ((b.0 - a.0).abs().max((b.1 - a.1).abs()).ceil() as usize).max(1);
            for s in 0..=steps {
                // Interpolated pixel positions.
                #[allow(
                    clippy::cast_possible_truncation,
                    clippy::cast_sign_loss,
                    clippy::cast_precision_loss
                )]
                let (x, y) = {
                    let t = s as f64 / steps as f64;
                    (
                        (a.0 + (b.0 - a.0) * t).round() as usize,
                        (a.1 + (b.1 - a.1) * t).round() as usize,
                    )
                };
                put(x, y, c, &mut img);
                put(x, y + 1, c, &mut img);
            }
        }
    }
    (w, h, img)
}

/// Writes the curves as CSV with the header `step,icr,icr_frontier,frontier,random`.
///
/// # Errors
/// I/O errors.
pub fn write_csv(path: &Path, curves: &[Vec<f64>]) -> std::io::Result<()> {
    let mut f = std::io::BufWriter::new(std::fs::File::create(path)?);
    writeln!(f, "step,{}", Strategy::ALL.map(Strategy::name).join(","))?;
    let len = curves.iter().map(Vec::len).min().unwrap_or(0);
    for i in 0..len {
        let row: Vec<String> = curves.iter().map(|c| format!("{:.6}", c[i])).collect();
        writeln!(f, "{i},{}", row.join(","))?;
    }
    f.flush()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn floor_plans_have_the_papers_sizes_and_free_space() {
        for (sx, sy) in [(14.46, 20.04), (17.37, 17.43)] {
            let map = GridMap::floor_plan(sx, sy, 7);
            let (ex, ey) = map.extent();
            assert!((ex - sx).abs() <= RESOLUTION && (ey - sy).abs() <= RESOLUTION);
            let free = map.occupied.iter().filter(|o| !**o).count();
            assert!(free > map.occupied.len() / 2, "mostly free space");
            assert!(free < map.occupied.len(), "some walls");
            // Seeded: the same plan twice.
            assert_eq!(map.occupied, GridMap::floor_plan(sx, sy, 7).occupied);
        }
    }

    /// A short episode on a small plan: the information only grows, and iCR gains at least as
    /// much as random motion over the same steps.
    #[test]
    fn short_episodes_gain_information() {
        let map = GridMap::floor_plan(8.0, 6.0, 3);
        let icr = run_episode(&map, Strategy::Icr, 12, 1).unwrap();
        let random = run_episode(&map, Strategy::Random, 12, 1).unwrap();
        let frontier = run_episode(&map, Strategy::Frontier, 12, 1).unwrap();
        for ep in [&icr, &random, &frontier] {
            assert_eq!(ep.log_det.len(), 13);
            assert!(ep.log_det.windows(2).all(|w| w[1] >= w[0]));
            assert!(ep.log_det[12] > ep.log_det[0]);
        }
        assert!(icr.log_det[12] >= random.log_det[12] - 1e-9 * random.log_det[12].abs());
        let (w, h, img) = episode_image(&map, &icr);
        assert_eq!(img.len(), w * h * 3);
        let (w, h, img) = log_det_plot(&[icr.log_det, random.log_det]);
        assert_eq!(img.len(), w * h * 3);
    }
}
