//! A whole flight without planning: a fixed route through a scene, flown with the LiDAR on
//! its motor, the IMU, the encoder and the odometry running, against the ground truth.
//!
//! The route ([`out_and_back_route`]) goes from the scene's start to the reachable point
//! farthest along x at the start's height and back, along a shortest path that keeps a
//! clearance; [`route_trajectory`] turns it into a MINCO trajectory within speed and
//! acceleration limits. [`fly`] runs the sensors and the odometry along it. The UAV tracks
//! the plan in the *estimated* frame (its yaw fixed at 0): after each odometry update the
//! position controller shifts its target by plan − estimate, and the true position follows
//! through a smooth third-order lag (velocity, acceleration and attitude continuous, so the
//! IMU sees the motion), so the true path differs from the plan by the odometry's error.

use std::cmp::Reverse;
use std::collections::BinaryHeap;
use std::time::Instant;

use lidar_kinematics::{
    AngleSample, Encoder, EncoderConfig, KinematicChain, KinematicsError, LidarSensor, MotorModel,
    MotorState,
};
use minco::{MincoError, Optimizer, OptimizerConfig, Trajectory};
use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};

use crate::lidar::{LidarNoise, LidarSim};
use crate::odometry::{NavState, Odometry, OdometryConfig, OdometryError};
use crate::scene::Scene;
use crate::uav::{ImuNoise, ImuSim, body_rate, flat_attitude};
use crate::world::World;

/// Errors of a flight.
#[derive(Debug, thiserror::Error)]
pub enum FlightError {
    /// No route with the required clearance.
    #[error("no route: {0}")]
    NoRoute(&'static str),
    /// The trajectory optimiser failed.
    #[error(transparent)]
    Minco(#[from] MincoError),
    /// A kinematics error (bad angle or pose).
    #[error(transparent)]
    Kinematics(#[from] KinematicsError),
    /// The odometry failed.
    #[error(transparent)]
    Odometry(#[from] OdometryError),
    /// A setting out of range.
    #[error("flight setting {0} must be positive and finite")]
    InvalidConfig(&'static str),
}

/// Settings of a flight.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FlightConfig {
    /// For point-cloud scenes, the preferred height of the start above the cloud's lowest
    /// point \[m\] (see [`Area::of_cloud`]); default 1.5. Routes fly at the start's height.
    pub height: f64,
    /// Least clearance of the route's grid cells and shortcuts \[m\]; default 0.75.
    pub clearance: f64,
    /// Grid cell of the route search \[m\]; default 0.25.
    pub grid: f64,
    /// How far along x the route may go from the start \[m\]; default 80 (about 200 m out
    /// and back).
    pub reach: f64,
    /// Speed and acceleration limits of the trajectory \[m/s\], \[m/s²\]; default 2 and 2.
    pub v_max: f64,
    /// See `v_max`.
    pub a_max: f64,
    /// Motor speed \[deg/s\]; default 100.
    pub motor_speed_deg: f64,
    /// Radius of the UAV \[m\]: a clearance below it is a collision; default 0.25.
    pub radius: f64,
    /// Mean delay of the position tracking \[s\]: the true position follows the plan
    /// corrected by the odometry's error with this lag (three critically damped poles, so
    /// the true acceleration and attitude stay continuous); default 0.5.
    pub tracking_lag: f64,
    /// Largest shift of the tracking target per odometry update \[m\]; default 0.2.
    pub max_correction: f64,
    /// LiDAR noise.
    pub lidar_noise: LidarNoise,
    /// IMU noise.
    pub imu_noise: ImuNoise,
    /// The motor's encoder.
    pub encoder: EncoderConfig,
    /// The odometry.
    pub odometry: OdometryConfig,
}

impl Default for FlightConfig {
    fn default() -> Self {
        Self {
            height: 1.5,
            clearance: 0.75,
            grid: 0.25,
            reach: 80.0,
            v_max: 2.0,
            a_max: 2.0,
            motor_speed_deg: 100.0,
            radius: 0.25,
            tracking_lag: 0.5,
            max_correction: 0.2,
            lidar_noise: LidarNoise::default(),
            imu_noise: ImuNoise::default(),
            encoder: EncoderConfig::default(),
            odometry: OdometryConfig::default(),
        }
    }
}

/// Where a route may go: the region's bounds and the start \[m\].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Area {
    /// Lower corner.
    pub min: Point3<f64>,
    /// Upper corner.
    pub max: Point3<f64>,
    /// The start; routes fly at its height.
    pub start: Point3<f64>,
}

impl From<&Scene> for Area {
    fn from(s: &Scene) -> Self {
        Self {
            min: s.min,
            max: s.max,
            start: s.start,
        }
    }
}

impl Area {
    /// The area of a point-cloud scene: the cloud's bounding box, and as the start the point
    /// of a 0.5 m grid with the most clearance (counted up to 2 m), preferring heights near
    /// `height` above the cloud's lowest point and then the centre among equals. `None` for a
    /// cloud without finite points.
    pub fn of_cloud(cloud: &[Point3<f64>], world: &World, height: f64) -> Option<Self> {
        let finite = cloud.iter().filter(|p| p.iter().all(|v| v.is_finite()));
        let (min, max) = finite.fold(None, |acc: Option<(Point3<f64>, Point3<f64>)>, p| {
            Some(acc.map_or((*p, *p), |(lo, hi)| (lo.inf(p), hi.sup(p))))
        })?;
        let centre = nalgebra::center(&min, &max);
        let want = min.z + height;
        let mut best: Option<(f64, f64, Point3<f64>)> = None;
        let mut z = min.z + 0.5;
        while z < max.z {
            let mut y = min.y + 0.25;
            while y < max.y {
                let mut x = min.x + 0.25;
                while x < max.x {
                    let p = Point3::new(x, y, z);
                    let clear = world.distance(&p).min(2.0);
                    let off = (z - want).abs() * 10.0 + (p - centre).norm();
                    if best.is_none_or(|(c, o, _)| clear > c || (clear == c && off < o)) {
                        best = Some((clear, off, p));
                    }
                    x += 0.5;
                }
                y += 0.5;
            }
            z += 0.5;
        }
        let (_, _, start) = best?;
        Some(Self { min, max, start })
    }
}

impl FlightConfig {
    /// Checks the settings the route and the flight divide by or step with.
    ///
    /// # Errors
    /// [`FlightError::InvalidConfig`] naming the first setting that is not positive and finite.
    pub fn validate(&self) -> Result<(), FlightError> {
        for (v, what) in [
            (self.grid, "grid"),
            (self.clearance, "clearance"),
            (self.v_max, "v_max"),
            (self.a_max, "a_max"),
            (self.tracking_lag, "tracking_lag"),
            (self.max_correction, "max_correction"),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(FlightError::InvalidConfig(what));
            }
        }
        Ok(())
    }
}

/// A 2-D grid of clearances at one height.
struct Grid {
    origin: Point3<f64>,
    cell: f64,
    nx: usize,
    ny: usize,
    clear: Vec<f64>,
}

impl Grid {
    fn new(area: &Area, world: &World, z: f64, cell: f64) -> Self {
        let ext = area.max - area.min;
        // Scene extents over grid cells of centimetres and more: small counts.
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        let (nx, ny) = (
            (ext.x / cell).floor().max(1.0) as usize,
            (ext.y / cell).floor().max(1.0) as usize,
        );
        let origin = Point3::new(area.min.x, area.min.y, z);
        let mut g = Self {
            origin,
            cell,
            nx,
            ny,
            clear: Vec::with_capacity(nx * ny),
        };
        for y in 0..ny {
            for x in 0..nx {
                let p = g.center(x, y);
                g.clear.push(world.distance(&p));
            }
        }
        g
    }

    fn center(&self, x: usize, y: usize) -> Point3<f64> {
        // Grid indices are small.
        #[allow(clippy::cast_precision_loss)]
        let (fx, fy) = (x as f64, y as f64);
        self.origin + Vector3::new((fx + 0.5) * self.cell, (fy + 0.5) * self.cell, 0.0)
    }

    fn cell_of(&self, p: &Point3<f64>) -> Option<(usize, usize)> {
        let g = (p - self.origin) / self.cell;
        // Checked against the grid before the casts.
        #[allow(
            clippy::cast_possible_truncation,
            clippy::cast_sign_loss,
            clippy::cast_precision_loss
        )]
        ((g.x >= 0.0 && g.y >= 0.0 && g.x < self.nx as f64 && g.y < self.ny as f64)
            .then(|| (g.x as usize, g.y as usize)))
    }

    /// Shortest 8-connected path between two cells through cells of clearance ≥ `min`; the
    /// step cost grows near obstacles so the path keeps to the middle of passages.
    fn path(&self, from: usize, to: usize, min: f64) -> Option<Vec<usize>> {
        let n = self.nx * self.ny;
        let mut dist = vec![u64::MAX; n];
        let mut prev = vec![usize::MAX; n];
        let mut heap = BinaryHeap::new();
        dist[from] = 0;
        heap.push(Reverse((0u64, from)));
        while let Some(Reverse((d, i))) = heap.pop() {
            if i == to {
                break;
            }
            if d > dist[i] {
                continue;
            }
            let (x, y) = (i % self.nx, i / self.nx);
            for (dx, dy) in [
                (-1, -1),
                (0, -1),
                (1, -1),
                (-1, 0),
                (1, 0),
                (-1, 1),
                (0, 1),
                (1, 1),
            ] {
                let (Some(x2), Some(y2)) = (x.checked_add_signed(dx), y.checked_add_signed(dy))
                else {
                    continue;
                };
                if x2 >= self.nx || y2 >= self.ny {
                    continue;
                }
                let j = x2 + self.nx * y2;
                let c = self.clear[j];
                if c < min {
                    continue;
                }
                let len = if dx != 0 && dy != 0 { 1.414 } else { 1.0 };
                // Millimetre-scale integer costs keep the search exact and deterministic.
                #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
                let step = (1000.0 * len * self.cell * (1.0 + 1.0 / c.max(1e-3))) as u64;
                let nd = d + step;
                if nd < dist[j] {
                    dist[j] = nd;
                    prev[j] = i;
                    heap.push(Reverse((nd, j)));
                }
            }
        }
        if dist[to] == u64::MAX {
            return None;
        }
        let mut path = vec![to];
        while let Some(&last) = path.last() {
            if last == from {
                break;
            }
            path.push(prev[last]);
        }
        path.reverse();
        Some(path)
    }
}

/// Whether the segment keeps a clearance of at least `min` (sampled every 5 cm).
fn segment_clear(world: &World, a: &Point3<f64>, b: &Point3<f64>, min: f64) -> bool {
    let d = b - a;
    // Route segments are metres long.
    #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
    let steps = ((d.norm() / 0.05).ceil() as usize).max(1);
    (0..=steps).all(|k| {
        #[allow(clippy::cast_precision_loss)]
        let s = k as f64 / steps as f64;
        world.distance(&(a + d * s)) >= min
    })
}

/// The route from the area's start to the reachable point farthest along x (at most
/// `config.reach` beyond the start), at the start's height, and back: a shortest grid path with clearance ≥ `config.clearance`, shortened
/// greedily while straight segments keep that clearance. Waypoints include both ends.
///
/// # Errors
/// [`FlightError::NoRoute`] when the start has too little clearance or nothing is reachable.
pub fn out_and_back_route(
    area: &Area,
    world: &World,
    config: &FlightConfig,
) -> Result<Vec<Point3<f64>>, FlightError> {
    config.validate()?;
    if !area
        .start
        .iter()
        .chain(area.min.iter())
        .chain(area.max.iter())
        .all(|v| v.is_finite())
    {
        return Err(FlightError::NoRoute("the area is not finite"));
    }
    let z = area.start.z;
    let grid = Grid::new(area, world, z, config.grid);
    let start = area.start;
    let (sx, sy) = grid
        .cell_of(&start)
        .ok_or(FlightError::NoRoute("start outside the scene"))?;
    let s = sx + grid.nx * sy;
    if grid.clear[s] < config.clearance {
        return Err(FlightError::NoRoute("too little clearance at the start"));
    }
    // Reachable cells from the start, then the farthest along x (clearest on ties).
    let min = config.clearance;
    let mut seen = vec![false; grid.nx * grid.ny];
    let mut stack = vec![s];
    seen[s] = true;
    let mut goal = s;
    while let Some(i) = stack.pop() {
        let (x, y) = (i % grid.nx, i / grid.nx);
        let gx = goal % grid.nx;
        let within = grid.center(x, y).x <= start.x + config.reach;
        if within && (x > gx || (x == gx && grid.clear[i] > grid.clear[goal])) {
            goal = i;
        }
        for (dx, dy) in [(-1, 0), (1, 0), (0, -1), (0, 1)] {
            let (Some(x2), Some(y2)) = (x.checked_add_signed(dx), y.checked_add_signed(dy)) else {
                continue;
            };
            if x2 < grid.nx && y2 < grid.ny {
                let j = x2 + grid.nx * y2;
                if !seen[j] && grid.clear[j] >= min {
                    seen[j] = true;
                    stack.push(j);
                }
            }
        }
    }
    if goal == s {
        return Err(FlightError::NoRoute("nothing reachable from the start"));
    }
    let path = grid
        .path(s, goal, min)
        .ok_or(FlightError::NoRoute("no path to the far end"))?;
    let cells: Vec<Point3<f64>> = path
        .iter()
        .map(|&i| grid.center(i % grid.nx, i / grid.nx))
        .collect();
    let mut out = vec![start];
    let mut i = 0;
    while i + 1 < cells.len() {
        // The farthest cell still in straight view with the clearance.
        let from = *out.last().unwrap_or(&start);
        let mut j = i + 1;
        while j + 1 < cells.len() && segment_clear(world, &from, &cells[j + 1], min) {
            j += 1;
        }
        out.push(cells[j]);
        i = j;
    }
    // And back along the same way.
    let back: Vec<Point3<f64>> = out.iter().rev().skip(1).copied().collect();
    out.extend(back);
    Ok(out)
}

/// A minimum-jerk trajectory from rest to rest through the route's waypoints, kept within
/// `corridor` \[m\] of its segments and within the speed and acceleration limits.
///
/// # Errors
/// [`FlightError::NoRoute`] for fewer than two waypoints; optimiser errors.
pub fn route_trajectory(
    route: &[Point3<f64>],
    config: &FlightConfig,
    corridor: f64,
) -> Result<Trajectory<3>, FlightError> {
    let (Some(first), Some(last)) = (route.first(), route.last()) else {
        return Err(FlightError::NoRoute("empty route"));
    };
    if route.len() < 2 {
        return Err(FlightError::NoRoute("a route needs two waypoints"));
    }
    let rest = |p: &Point3<f64>| [[p.x, p.y, p.z], [0.0; 3], [0.0; 3]];
    let inner: Vec<[f64; 3]> = route[1..route.len() - 1]
        .iter()
        .map(|p| [p.x, p.y, p.z])
        .collect();
    let mut cfg = OptimizerConfig::default().with_limits(config.v_max, config.a_max);
    cfg.corridor_radius = Some(corridor);
    // Hold the waypoints: free ones let an out-and-back route collapse onto its start.
    cfg.waypoint_weight = 1e4;
    let mut opt = Optimizer::<3, 3>::new(cfg, rest(first), rest(last), &inner)?;
    Ok(opt.optimize()?.trajectory)
}

/// What a flight recorded.
#[derive(Debug, Clone, Default)]
pub struct FlightLog {
    /// Frame end times \[s\].
    pub times: Vec<f64>,
    /// True body poses at the frame ends.
    pub truth: Vec<Isometry3<f64>>,
    /// Odometry poses at the frame ends.
    pub estimate: Vec<Isometry3<f64>>,
    /// Planned positions at the frame ends.
    pub plan: Vec<Point3<f64>>,
    /// Least distance from the true position to the world, at the IMU rate \[m\].
    pub min_clearance: f64,
    /// Times the clearance fell below the UAV's radius.
    pub collisions: usize,
    /// The odometry's local map at the end, in the world frame.
    pub map: Vec<Point3<f64>>,
    /// Wall time spent simulating LiDAR frames \[s\] (instrumentation only: nothing in the
    /// flight depends on it).
    pub lidar_seconds: f64,
    /// Wall time spent in the odometry's frame updates \[s\].
    pub odometry_seconds: f64,
}

/// The true motion: the plan shifted by an offset that follows the tracking controller's
/// target as a critically damped third-order system: three poles of time constant `tau / 3`,
/// so the mean delay is `tau`, as for a first-order lag of time constant `tau`.
///
/// The controller tracks the plan in the *estimated* frame: after each odometry update it
/// moves its target offset by plan − estimate, and the UAV's true position follows. The offset's
/// position, velocity and acceleration stay continuous when the target moves
/// ([`Tracking::retarget`]): the IMU, which measures only acceleration and body rate, then sees
/// all of the true motion. (A first-order lag jumps the velocity at every retarget and a
/// second-order one the acceleration, hence the attitude: motions no IMU reports, which a
/// filter trusting its IMU cannot follow.)
#[derive(Debug, Clone, Copy)]
pub(crate) struct Tracking {
    /// Time of the last retarget \[s\].
    pub(crate) t0: f64,
    start: [Vector3<f64>; 3],
    target: Vector3<f64>,
    tau: f64,
}

impl Tracking {
    /// No offset, at rest, from `t0`, with a mean delay of `tau` \[s\].
    pub(crate) fn at_rest(t0: f64, tau: f64) -> Self {
        Self {
            t0,
            start: [Vector3::zeros(); 3],
            target: Vector3::zeros(),
            tau,
        }
    }

    /// From `t` on, the offset moves toward `target`, starting from its position, velocity and
    /// acceleration at `t`.
    pub(crate) fn retarget(&self, t: f64, target: Vector3<f64>) -> Self {
        Self {
            t0: t,
            start: self.offset(t),
            target,
            tau: self.tau,
        }
    }

    /// Offset, its rate and its acceleration at `t` (≥ `t0`): x = x* + q(s) e^(−s/T) with
    /// s = t − t0, T = τ/3 and q(s) = A + B s + C s², whose coefficients match the position,
    /// velocity and acceleration at the last retarget.
    pub(crate) fn offset(&self, t: f64) -> [Vector3<f64>; 3] {
        let s = (t - self.t0).max(0.0);
        let k = 3.0 / self.tau; // 1/T
        let e = (-s * k).exp();
        let [x0, v0, a0] = self.start;
        let a = x0 - self.target;
        let b = v0 + a * k;
        let c = (a0 + b * (2.0 * k) - a * (k * k)) * 0.5;
        let q = a + b * s + c * (s * s);
        let dq = b + c * (2.0 * s);
        let ddq = c * 2.0;
        [
            self.target + q * e,
            (dq - q * k) * e,
            (ddq - dq * (2.0 * k) + q * (k * k)) * e,
        ]
    }
}

/// The true state at `t`: position, velocity, acceleration.
fn actual(
    traj: &Trajectory<3>,
    track: &Tracking,
    t: f64,
) -> Result<[Vector3<f64>; 3], FlightError> {
    let plan = planned(traj, t)?;
    let off = track.offset(t);
    Ok([plan[0] + off[0], plan[1] + off[1], plan[2] + off[2]])
}

impl FlightLog {
    /// The true and the estimated positions at the frame ends.
    pub fn positions(&self) -> (Vec<Point3<f64>>, Vec<Point3<f64>>) {
        let at = |poses: &[Isometry3<f64>]| -> Vec<Point3<f64>> {
            poses.iter().map(|p| p.translation.vector.into()).collect()
        };
        (at(&self.truth), at(&self.estimate))
    }
}

/// The planned state at `t`: position, velocity, acceleration.
fn planned(traj: &Trajectory<3>, t: f64) -> Result<[Vector3<f64>; 3], FlightError> {
    let t = t.clamp(0.0, traj.duration());
    Ok([
        Vector3::from(traj.position(t)?),
        Vector3::from(traj.velocity(t)?),
        Vector3::from(traj.acceleration(t)?),
    ])
}

/// Flies `traj` through `world` with the sensors and the odometry; the flight lasts the
/// trajectory's duration rounded up to whole 0.1 s frames.
///
/// # Errors
/// Trajectory, kinematics or odometry errors.
pub fn fly(
    world: &World,
    traj: &Trajectory<3>,
    config: &FlightConfig,
    seed: u64,
) -> Result<FlightLog, FlightError> {
    config.validate()?;
    let chain = KinematicChain::default();
    let sensor = LidarSensor::mid360();
    let mut lidar = LidarSim::new(sensor, chain, config.lidar_noise, seed);
    let mut imu = ImuSim::new(config.imu_noise, 200.0, seed.wrapping_add(1));
    let motor = MotorModel::new(lidar_kinematics::MotorLimits::default());
    let mut encoder = Encoder::new(config.encoder);
    let omega = config.motor_speed_deg.to_radians();
    let mut track = Tracking::at_rest(0.0, config.tracking_lag);
    let attitude = |track: &Tracking, t: f64| -> Result<UnitQuaternion<f64>, FlightError> {
        Ok(flat_attitude(&actual(traj, track, t)?[2], 0.0))
    };
    let pose = |track: &Tracking, t: f64| -> Result<Isometry3<f64>, FlightError> {
        Ok(Isometry3::from_parts(
            Translation3::from(actual(traj, track, t)?[0]),
            attitude(track, t)?,
        ))
    };
    let [p0, v0, _] = actual(traj, &track, 0.0)?;
    let mut odo = Odometry::new(
        chain,
        config.odometry,
        NavState {
            time: 0.0,
            position: p0,
            velocity: v0,
            attitude: attitude(&track, 0.0)?,
        },
    );
    let mut log = FlightLog {
        min_clearance: f64::INFINITY,
        ..FlightLog::default()
    };
    let mut motor_state = MotorState::new(0.0, 0.0);
    encoder.record(0.0, 0.0)?;
    let mut motor_samples: Vec<(f64, f64)> = vec![(0.0, 0.0)];
    let mut points = Vec::new();
    let mut angles: Vec<AngleSample> = Vec::with_capacity(101);
    let mut body_samples: Vec<Isometry3<f64>> = Vec::with_capacity(101);
    let latency = config.encoder.latency();
    // The first report: the angle at time 0, read one latency later.
    angles.push(AngleSample::new(0.0, encoder.read(latency)?.angle));
    let mut inside = false;
    // Frame and tick counts are small; times are exact ratios so ticks and frame ends meet.
    #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
    let frames = (traj.duration() * 10.0).ceil() as u64;
    #[allow(clippy::cast_precision_loss)]
    for k in 0..frames {
        let t0 = k as f64 / 10.0;
        let t1 = (k + 1) as f64 / 10.0;
        // Motor and encoder at 1 kHz over the frame; each read reports the angle one latency
        // earlier. The last read of the previous frame starts this frame's angles.
        motor_samples.drain(..motor_samples.len() - 1);
        angles.drain(..angles.len().saturating_sub(1));
        for j in 1..=100u64 {
            let t = (100 * k + j) as f64 / 1000.0;
            motor_state = motor.step_speed(motor_state, omega, 1e-3)?;
            encoder.record(t, motor_state.theta)?;
            motor_samples.push((t, motor_state.theta));
            if t - latency > 0.0 {
                let r = encoder.read(t)?;
                angles.push(AngleSample::new(t - latency, r.angle));
            }
        }
        let motor_angle = |t: f64| {
            let i = motor_samples
                .partition_point(|&(ti, _)| ti <= t)
                .clamp(1, motor_samples.len() - 1);
            let ((ta, a), (tb, b)) = (motor_samples[i - 1], motor_samples[i]);
            a + (b - a) * (t - ta) / (tb - ta)
        };
        // IMU at 200 Hz.
        for i in 0..20u64 {
            let t = (20 * k + i) as f64 / 200.0;
            let h = 1e-4;
            let rate = body_rate(
                &attitude(&track, (t - h).max(track.t0))?,
                &attitude(&track, t + h)?,
                t + h - (t - h).max(track.t0),
            );
            let [p, _, a] = actual(traj, &track, t)?;
            let s = imu.sample(t, &attitude(&track, t)?, &a, &rate);
            odo.push_imu(&s)?;
            let c = world.distance(&Point3::from(p));
            log.min_clearance = log.min_clearance.min(c);
            let now_inside = c < config.radius;
            if now_inside && !inside {
                log.collisions += 1;
            }
            inside = now_inside;
        }
        // The body pose every millisecond of the frame, interpolated for each beam's time
        // (the trajectory is smooth: the interpolation error is far below a micrometre).
        body_samples.clear();
        for j in 0..=100u64 {
            body_samples.push(pose(&track, (100 * k + j) as f64 / 1000.0)?);
        }
        let body = |t: f64| {
            let s = ((t - t0) * 1000.0).clamp(0.0, 100.0);
            // Clamped into [0, 100], so the cast is exact.
            #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
            let i = (s.floor() as usize).min(99);
            let f = s - i as f64;
            let (a, b) = (&body_samples[i], &body_samples[i + 1]);
            Isometry3::from_parts(
                Translation3::from(a.translation.vector.lerp(&b.translation.vector, f)),
                a.rotation.nlerp(&b.rotation, f),
            )
        };
        let clock = Instant::now();
        lidar.frame(world, k, t0, body, motor_angle, &mut points)?;
        log.lidar_seconds += clock.elapsed().as_secs_f64();
        let clock = Instant::now();
        odo.process_frame(t1, &points, &angles)?;
        log.odometry_seconds += clock.elapsed().as_secs_f64();
        let truth = pose(&track, t1)?;
        log.times.push(t1);
        log.truth.push(truth);
        log.estimate.push(odo.state().pose());
        // The controller moves its target by plan − estimate; the true offset follows.
        let plan = planned(traj, t1)?[0];
        log.plan.push(Point3::from(plan));
        let now = track.offset(t1)[0];
        // A real position controller moves a bounded distance per update: the shift is capped
        // at `max_correction`, so a lost odometry cannot fling the UAV away.
        let shift = plan - odo.state().position;
        let shift = shift * (config.max_correction / shift.norm().max(config.max_correction));
        track = track.retarget(t1, now + shift);
    }
    log.map = odo.map_points().copied().collect();
    Ok(log)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bad_settings_are_typed_errors() {
        let world = World::from_boxes(&[]).unwrap();
        let area = Area {
            min: Point3::origin(),
            max: Point3::new(5.0, 5.0, 3.0),
            start: Point3::new(1.0, 1.0, 1.5),
        };
        for bad in [
            FlightConfig {
                grid: 0.0,
                ..FlightConfig::default()
            },
            FlightConfig {
                clearance: f64::NAN,
                ..FlightConfig::default()
            },
            FlightConfig {
                tracking_lag: -1.0,
                ..FlightConfig::default()
            },
        ] {
            assert!(matches!(
                out_and_back_route(&area, &world, &bad),
                Err(FlightError::InvalidConfig(_))
            ));
        }
        let nan = Area {
            start: Point3::new(f64::NAN, 1.0, 1.5),
            ..area
        };
        assert!(out_and_back_route(&nan, &world, &FlightConfig::default()).is_err());
    }

    #[test]
    fn a_cloud_area_starts_at_its_clearest_point() {
        // The walls, floor and ceiling of a 6 × 4 × 3 m room, sampled every 0.1 m.
        let mut cloud = Vec::new();
        for i in 0..=60 {
            for j in 0..=40 {
                let (x, y) = (f64::from(i) * 0.1, f64::from(j) * 0.1);
                cloud.push(Point3::new(x, y, 0.0));
                cloud.push(Point3::new(x, y, 3.0));
            }
            for k in 0..=30 {
                let (x, z) = (f64::from(i) * 0.1, f64::from(k) * 0.1);
                cloud.push(Point3::new(x, 0.0, z));
                cloud.push(Point3::new(x, 4.0, z));
            }
        }
        for j in 0..=40 {
            for k in 0..=30 {
                let (y, z) = (f64::from(j) * 0.1, f64::from(k) * 0.1);
                cloud.push(Point3::new(0.0, y, z));
                cloud.push(Point3::new(6.0, y, z));
            }
        }
        let world = World::from_points(&cloud, 0.1).unwrap();
        let area = Area::of_cloud(&cloud, &world, 1.5).unwrap();
        assert!(world.distance(&area.start) >= 1.3, "{}", area.start);
        assert!((0..3).all(|k| area.start[k] > area.min[k] && area.start[k] < area.max[k]));
        assert!(Area::of_cloud(&[Point3::new(f64::NAN, 0.0, 0.0)], &world, 1.5).is_none());
    }

    #[test]
    fn the_tracking_offset_moves_from_its_start_to_its_target() {
        let track = Tracking::at_rest(0.0, 0.5)
            .retarget(1.0, Vector3::new(0.1, -0.2, 0.0))
            .retarget(2.0, Vector3::new(-0.1, 0.0, 0.05));
        // Position, velocity and acceleration are continuous across a retarget; the offset
        // settles at the target.
        let before = Tracking::at_rest(0.0, 0.5)
            .retarget(1.0, Vector3::new(0.1, -0.2, 0.0))
            .offset(2.0);
        let after = track.offset(2.0);
        for k in 0..3 {
            assert!(
                (after[k] - before[k]).norm() < 1e-12,
                "{k}: {before:?} {after:?}"
            );
        }
        assert!(
            after[1].norm() > 1e-3,
            "moving at the retarget: {}",
            after[1]
        );
        assert!((track.offset(30.0)[0] - track.target).norm() < 1e-9);
        // Rate and acceleration match central differences.
        let (t, h) = (2.3, 1e-5);
        let [_, v, a] = track.offset(t);
        let dp = (track.offset(t + h)[0] - track.offset(t - h)[0]) / (2.0 * h);
        let dv = (track.offset(t + h)[1] - track.offset(t - h)[1]) / (2.0 * h);
        assert!((dp - v).norm() < 1e-8, "{dp} vs {v}");
        assert!((dv - a).norm() < 1e-6, "{dv} vs {a}");
    }
}
