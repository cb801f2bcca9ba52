//! The complete explorer: every crate of the project in one closed loop, flown in the
//! simulator.
//!
//! Each 0.1 s frame: the motor turns under the scan controller's last command (1 kHz, with the
//! encoder), the IMU samples the true motion (200 Hz), the LiDAR takes a frame with real
//! motion distortion, and the odometry estimates the pose. Mapping inserts the deskewed frame
//! at the *estimated* pose into a [`VoxelMap`] and updates the incremental [`Frontiers`].
//! Global planning (every [`ExplorerConfig::replan_frames`] frames, and whenever the
//! trajectory ends or is blocked) samples viewpoints and dynamic clusters
//! ([`frontier::plan_targets`]), prices them along a topological graph with the costs
//! (7)(8), orders them by an open ATSP tour (9) and flies a MINCO trajectory along the graph path to the
//! first one. When the graph reaches none of the first targets, a grid search runs from the
//! UAV to them, then from each to the nearest graph node the UAV reaches (a bridge); the path
//! found joins the graph. A trajectory that comes closer to an obstacle than the UAV's radius
//! and margin is made again through waypoints at most 1 m apart along the path. A UAV whose
//! positions fit in a box of 4 m diagonal for 30 s gives up the target it keeps choosing. The
//! scan controller then chooses the motor's acceleration along the predicted trajectory
//! (10 Hz), with the Fisher table rebuilt from the odometry's local map every
//! [`ExplorerConfig::fisher_frames`] frames — a fixed cycle, so a run is deterministic.
//!
//! The UAV tracks the plan in the estimated frame exactly as in [`crate::flight`]: the true
//! motion is the plan plus a tracking offset that follows the odometry's error.

use std::fmt;
use std::str::FromStr;
use std::time::Instant;

use frontier::{
    Bounds, FrontierConfig, FrontierError, Frontiers, MapConfig, Omnidirectional, Target,
    ViewpointConfig, VoxelMap, plan_targets_among,
};
use fu_mpc_core::icr::{IcrScan, IcrScanConfig};
use fu_mpc_core::{
    CoreError, FisherConfig, FisherTable, FixedSpeed, FuMpc, MpcConfig, ScanController, ScanInput,
};
use lidar_kinematics::{
    AngleSample, Encoder, Extrinsics, KinematicChain, KinematicsError, LidarSensor, MotorLimits,
    MotorModel, MotorState,
};
use minco::{MincoError, Optimizer, OptimizerConfig, Trajectory};
use nalgebra::{Isometry3, Matrix3, Point3, Translation3, UnitQuaternion, Vector3};
use rustc_hash::FxHashMap;
use topo_tsp::{CostConfig, NodeId, SolverConfig, TopoGraph, TspError, cost_matrix, solve_open};

use crate::flight::{FlightConfig, FlightError, Tracking};
use crate::lidar::LidarSim;
use crate::mission::MissionCache;
use crate::odometry::{NavState, Odometry, OdometryError};
use crate::scene::Explorable;
use crate::uav::{ImuSim, body_rate, flat_attitude};
use crate::world::World;

/// Targets whose viewpoint lies this close to an exhausted one are skipped \[m\].
const EXHAUSTED_RADIUS: f64 = 0.5;

/// Targets per planning cycle the grid search tries when the graph reaches none.
const GRID_SEARCHES: usize = 2;

/// Cell expansions per grid search.
const GRID_EXPANSIONS: usize = 60_000;

/// Targets per planning cycle the last grid search, at the UAV's own clearance, tries.
const SQUEEZE_SEARCHES: usize = 4;

/// Cell expansions per grid search at the UAV's own clearance: a way up a shaft through a
/// narrow opening floods much of the level below first (120,000–240,000 expansions in the
/// sinkhole).
const SQUEEZE_EXPANSIONS: usize = 250_000;

/// Spacing of the lattice of the last search for a way to a target \[m\] (see
/// [`lattice_path`]): five map cells.
const LATTICE_SPACING: f64 = 1.0;

/// A lattice point this close to a target's viewpoint, with a free segment to it, reaches
/// it \[m\]: one and a half lattice spacings, so beside the nearest lattice point (at most
/// 0.87 m away) the next ones count too, in case the nearest is blocked.
const LATTICE_REACH: f64 = 1.5;

/// Lattice points expanded per search (see [`lattice_path`]): up to 100,000 m³ of free
/// space, more than the maze's or the sinkhole's whole bounds (19,040 and 42,525 m³).
const LATTICE_EXPANSIONS: usize = 100_000;

/// Spacing of the points of the UAV's trail \[m\] (see [`trail_path`]).
const TRAIL_SPACING: f64 = 1.0;

/// A UAV that stays in a box of diagonal [`STUCK_SPAN`] this long while it has a target gives
/// that target up \[s\].
const STUCK_TIME: f64 = 30.0;

/// The diagonal of the box the UAV must leave to count as not stuck \[m\]. A box rather than
/// a distance from one point: a UAV swaying about a place would otherwise count as moving
/// whenever it swings from one end of its sway to the other.
const STUCK_SPAN: f64 = 4.0;

/// A UAV whose map has gained fewer than [`IDLE_GAIN`] known cells in this long while its
/// positions fitted in a box of diagonal [`IDLE_SPAN`] is idle \[s\]: it first holds on to its
/// target, and gives it up when idle again (see [`Headway::idle`]).
const IDLE_TIME: f64 = 60.0;

/// The diagonal of the idle box \[m\]: wider than [`STUCK_SPAN`], for a UAV turning back
/// and forth between two targets a few metres apart.
const IDLE_SPAN: f64 = 10.0;

/// A UAV whose map has gained fewer than [`IDLE_GAIN`] known cells in [`IDLE_TIME`] while it
/// flew at least this many times the diagonal of the box its positions spread over is idle
/// as well: it went back and forth, over a box wider than [`IDLE_SPAN`] (see
/// [`Headway::idle`]).
const IDLE_DETOUR: f64 = 3.0;

/// Known cells the map must gain in [`IDLE_TIME`] for the UAV not to be idle: 16 m³ of
/// 0.2 m cells, while exploring the map gains thousands a second.
const IDLE_GAIN: usize = 2_000;

/// Largest spacing of the waypoints of a trajectory made again because the first one came
/// too close to an obstacle \[m\] (see [`densify`]).
const DENSE_SPACING: f64 = 1.0;

/// Graph nodes farther than this from a target are not tried as the ends of a bridge to it
/// \[m\] (see [`Explorer::bridge`]).
const BRIDGE_RADIUS: f64 = 20.0;

/// How long the UAV looks from a reached viewpoint before its frontier counts as out of view
/// from there \[s\].
const DWELL: f64 = 1.0;
/// The current target is kept while a target of the new plan has its viewpoint or its
/// frontier centre this close to it \[m\].
const KEEP_RADIUS: f64 = 1.0;

/// While the idle rule holds on to a target, it is kept as long as a frontier cluster's centre
/// lies this close to its frontier centre \[m\].
const HOLD_RADIUS: f64 = 3.0;

/// Trajectories keep this much more than the UAV's radius from known obstacles \[m\].
const SAFETY_MARGIN: f64 = 0.05;

/// What trajectory checks allow below the margin the path searches keep \[m\]: a search's
/// step between the centres of two cells that keep the margin can pass nearer an occupied
/// cell's corner (0.283 m for 0.3 m with 0.2 m cells).
const STEP_SLACK: f64 = 0.02;

/// A new trajectory may reach at most this multiple of the acceleration limit it was
/// optimised under. The limits are soft: a path that turns back just in front of a UAV in
/// motion made the optimiser pull 18 m/s² (nine times the limit), which no multirotor flies
/// and whose attitude swing, 60° in 20 ms, the 200 Hz IMU could not follow: the odometry
/// was lost and the UAV hit a wall (the sinkhole's `fixed:100` seed 9).
const ACCEL_SLACK: f64 = 3.0;

/// Largest jerk a new trajectory may have \[m/s³\]. The attitude of a multirotor turns at
/// about |jerk|/g: 200 m/s³ is 20 rad/s, beyond what its attitude control reaches. A path
/// whose first point lies 0.18 m behind a UAV flying at 2 m/s gave the optimiser a first
/// piece of 10 ms and 590 m/s³, an attitude swing faster than the 200 Hz IMU follows: the
/// odometry was lost (the sinkhole's `fixed:30` seed 8). The other trajectories of that run
/// stayed below 40 m/s³, those of the maze's FU-MPC seed 2 below 71.
const JERK_MAX: f64 = 200.0;

/// Samples per polynomial piece of the peak acceleration and jerk checks ([`ACCEL_SLACK`],
/// [`JERK_MAX`]).
const ACCEL_SAMPLES: usize = 32;

/// Around the UAV, grid paths may keep as little clearance as the UAV has \[m\].
const ESCAPE_RADIUS: f64 = 1.0;

/// Least length of a leg of [`path_legs`] that does not end the path \[m\].
const LEG_MIN: f64 = 0.5;

/// How far the short moves away from a too-close place go \[m\] (see
/// [`safest`]).
const ESCAPE_STEP: f64 = 1.0;

/// Errors of an exploration run.
#[derive(Debug, thiserror::Error)]
pub enum ExploreError {
    /// A setting out of range.
    #[error("explorer setting {what}: {reason}")]
    InvalidConfig {
        /// The setting.
        what: &'static str,
        /// Why it is rejected.
        reason: &'static str,
    },
    /// An unknown controller name.
    #[error(
        "unknown controller {0:?}: expected fu-mpc, fixed:<deg/s>, uncertainty, frontier, icr or rigid-yaw"
    )]
    UnknownController(String),
    /// The start is outside the bounds or not free.
    #[error("the start {0} is outside the bounds or inside an obstacle")]
    BadStart(Point3<f64>),
    /// A flight error (settings, kinematics, odometry, trajectory).
    #[error(transparent)]
    Flight(#[from] FlightError),
    /// A mapping or frontier error.
    #[error(transparent)]
    Frontier(#[from] FrontierError),
    /// A scan-controller error.
    #[error(transparent)]
    Core(#[from] CoreError),
    /// A global-planning error.
    #[error(transparent)]
    Tsp(#[from] TspError),
}

impl From<KinematicsError> for ExploreError {
    fn from(e: KinematicsError) -> Self {
        Self::Flight(FlightError::Kinematics(e))
    }
}

impl From<OdometryError> for ExploreError {
    fn from(e: OdometryError) -> Self {
        Self::Flight(FlightError::Odometry(e))
    }
}

impl From<MincoError> for ExploreError {
    fn from(e: MincoError) -> Self {
        Self::Flight(FlightError::Minco(e))
    }
}

/// The scan controller of a run.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ControllerKind {
    /// FU-MPC with both terms (the paper's method).
    FuMpc,
    /// A constant motor speed \[deg/s\] (the paper's 30, 100 and 360).
    Fixed(f64),
    /// FU-MPC with α = 0: localisation only, like UA-MPC.
    Uncertainty,
    /// FU-MPC with β = 0: frontiers only.
    Frontier,
    /// The iCR scan controller (information-theoretic, over the local cloud).
    Icr,
    /// The LiDAR does not spin; the UAV yaws toward its targets, as frontier explorers with a
    /// fixed LiDAR do (EPIC, FUEL).
    RigidYaw,
}

impl ControllerKind {
    /// Whether the LiDAR turns on its motor.
    pub fn spins(&self) -> bool {
        !matches!(self, Self::RigidYaw)
    }
}

impl fmt::Display for ControllerKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::FuMpc => f.write_str("fu-mpc"),
            Self::Fixed(d) => write!(f, "fixed:{d}"),
            Self::Uncertainty => f.write_str("uncertainty"),
            Self::Frontier => f.write_str("frontier"),
            Self::Icr => f.write_str("icr"),
            Self::RigidYaw => f.write_str("rigid-yaw"),
        }
    }
}

impl FromStr for ControllerKind {
    type Err = ExploreError;

    /// `fu-mpc`, `fixed:<deg/s>` (finite, not negative), `uncertainty`, `frontier`, `icr` or
    /// `rigid-yaw`.
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let bad = || ExploreError::UnknownController(s.to_string());
        Ok(match s {
            "fu-mpc" => Self::FuMpc,
            "uncertainty" => Self::Uncertainty,
            "frontier" => Self::Frontier,
            "icr" => Self::Icr,
            "rigid-yaw" => Self::RigidYaw,
            _ => {
                let deg: f64 = s
                    .strip_prefix("fixed:")
                    .and_then(|v| v.parse().ok())
                    .ok_or_else(bad)?;
                if !(deg.is_finite() && deg >= 0.0) {
                    return Err(bad());
                }
                Self::Fixed(deg)
            }
        })
    }
}

/// The explorer's platform: the LiDAR at the front of the body on a motor turning about the
/// body's vertical axis, mounted on its side (rotated 90° about x) so the sensor's 360° ring
/// stands vertical and the motor sweeps it around — the paper's front-mounted rotating LiDAR.
/// The scan direction (the motor's x axis) points forward at θ = 0.
pub fn explorer_chain() -> KinematicChain {
    front_mount(Vector3::new(core::f64::consts::FRAC_PI_2, 0.0, 0.0))
}

/// The Mid-360 on the motor at the front of the body, turned by `rotation` (an axis-angle
/// vector \[rad\]) in the motor frame.
fn front_mount(rotation: Vector3<f64>) -> KinematicChain {
    match Extrinsics::try_new(
        Isometry3::new(Vector3::new(0.02, 0.0, 0.05), rotation),
        Isometry3::translation(0.12, 0.0, -0.03),
    ) {
        Ok(e) => KinematicChain::new(e),
        // Finite, unit extrinsics (the callers' rotations are constant): always valid.
        Err(_) => KinematicChain::default(),
    }
}

/// Nose-down pitch of the `rigid-yaw` baseline's LiDAR \[deg\]; see [`rigid_chain`].
pub const RIGID_PITCH_DEG: f64 = 30.0;

/// The `rigid-yaw` baseline's platform: a fixed LiDAR, the Mid-360 upright at the front of
/// the body and pitched [`RIGID_PITCH_DEG`] nose down (no motor turns it: the chain's motor
/// angle stays 0).
///
/// Upright, its ring sees from 7° below the horizon to 52° above, so the floor near the UAV
/// stays unseen; pitched 30° it sees ahead from 37° below the horizon to 22° above, to the
/// sides much as upright, and behind from 23° to 82° above, so yawing toward a target shows
/// the floor before it and the ceiling behind, and the whole ring still returns from every
/// side for the odometry. (The locked motor of [`explorer_chain`], whose ring stands
/// vertical, was the baseline before: its odometry was lost in seven of nine large-scene
/// runs.)
pub fn rigid_chain() -> KinematicChain {
    front_mount(Vector3::new(0.0, RIGID_PITCH_DEG.to_radians(), 0.0))
}

/// Settings of an exploration run. Defaults: the paper's 10 Hz scan cycle and 2 Hz global
/// replanning; the rest explained per field.
#[derive(Debug, Clone, PartialEq)]
pub struct ExplorerConfig {
    /// The scan controller; default FU-MPC.
    pub controller: ControllerKind,
    /// Time budget \[s\]; default 600.
    pub max_time: f64,
    /// Speed and acceleration limits of the trajectories \[m/s\], \[m/s²\]; default 2 and 2 (the
    /// paper flies at up to 3 m/s; 2 keeps the simulated odometry in its comfortable range).
    pub v_max: f64,
    /// See `v_max`.
    pub a_max: f64,
    /// The occupancy map (0.2 m cells, 20 m insertion range) with a weak miss: default
    /// `prob_miss` 0.48 (the map's own default is 0.4), so about nine misses undo a hit
    /// instead of two. A cell a surface runs through is hit by the beams that end on it and
    /// missed by the beams that graze its free part on their way past; with the stronger miss
    /// the grazing beams won, the cell turned free, and its neighbour behind the surface,
    /// which no beam reaches, stayed unknown: a frontier no viewpoint can clear (602 clusters
    /// left at 250 s in the sinkhole's seed 2 with 0.4, 92 with 0.48; see the README).
    pub map: MapConfig,
    /// If positive, the deskewed frame is thinned to one point per voxel of this edge before
    /// it enters the map \[m\]; default 0 (every return). Thinning saves insertion time but
    /// leaves unknown gaps between sparse long rays, which cut the graph's known-free paths:
    /// at 0.1 m the maze run stopped after 20 s with 111 clusters unreachable.
    pub map_voxel: f64,
    /// Whether beams that return nothing within the LiDAR's range clear the map's cells
    /// along them up to its insertion range (as long returns do); default `false`: a beam
    /// without a return says nothing. In a scene open to the sky (the shared `apartment.pcd`
    /// has no ceiling) the space above the walls is seen only through such beams. A real
    /// sensor also returns nothing from dark or mirror-like surfaces, which this would
    /// clear; the simulated world has none. Needs a LiDAR range beyond the map's range.
    pub clear_on_no_return: bool,
    /// Frontier clustering.
    pub frontier: FrontierConfig,
    /// Viewpoint sampling and dynamic clustering.
    pub viewpoints: ViewpointConfig,
    /// Transition costs (7)(8); `v_max` is overwritten by the run's.
    pub cost: CostConfig,
    /// FU-MPC (and its single-term variants); its horizon, Δt and limits also drive iCR.
    /// Default: [`MpcConfig::default`] with the motor kept turning forward at 30–180 deg/s
    /// (30 is the slowest of the paper's fixed speeds, 180 its limit): a scan that stopped
    /// would keep seeing one vertical fan, and frontiers beside a fan that is already looking
    /// at them never shrink, so the controller modulates the speed instead of stopping.
    pub mpc: MpcConfig,
    /// What the motor can do (and the fixed-speed baselines may use); default
    /// [`MotorLimits::default`], ±360 deg/s, so the paper's fastest fixed speed is reachable.
    pub motor: MotorLimits,
    /// The Fisher table.
    pub fisher: FisherConfig,
    /// Frames between Fisher-table rebuilds (and iCR cloud updates); default 10 (1 Hz).
    pub fisher_frames: usize,
    /// Radius of the local cloud the Fisher table is built from \[m\]; default 15.
    pub fisher_radius: f64,
    /// At most this many local-map points (an even subsample) enter the Fisher table;
    /// default 3000.
    pub fisher_points: usize,
    /// At most this many frontier clusters, the nearest to the UAV, enter each global plan
    /// (the next as many when every target those give has been given up); default 50 (the
    /// frontier crate's benchmark size).
    pub max_clusters: usize,
    /// The UAV hovers this long at the start while the motor spins up and the odometry builds
    /// its first map \[s\]; default 2.
    pub warmup: f64,
    /// Frames between global replans; default 5 (2 Hz, as the issue asks).
    pub replan_frames: usize,
    /// Least clearance of the topological graph's edges \[m\]; default 0.5.
    pub clearance: f64,
    /// Radius within which graph nodes are connected \[m\]; default 6.
    pub graph_radius: f64,
    /// New permanent graph nodes are at least this far from existing ones \[m\]; default 1.
    pub node_spacing: f64,
    /// Corridor of the trajectories around the graph path \[m\]; default 0.1, so a trajectory
    /// keeps about `clearance − corridor` from known obstacles.
    pub corridor: f64,
    /// Yaw rate of the rigid-yaw baseline \[rad/s\]; default 45 deg/s: at 90 deg/s the
    /// odometry loses its yaw in the maze and the sinkhole (degrees of error within two
    /// minutes, then metres of drift).
    pub yaw_rate: f64,
    /// How long the plan may have no target, or none reachable, before the run ends (no
    /// reachable frontier left) \[s\]; default 5: time for the sensor to sweep and the map
    /// to open a way.
    pub stall_time: f64,
    /// The harness stops a run whose estimate strays farther than this from the truth \[m\];
    /// default 5.
    pub lost_distance: f64,
    /// Frames between coverage samples; default 10 (1 Hz).
    pub coverage_frames: usize,
    /// Sensors, noise, odometry, UAV radius and tracking (the route settings are unused).
    pub flight: FlightConfig,
}

impl Default for ExplorerConfig {
    fn default() -> Self {
        Self {
            controller: ControllerKind::FuMpc,
            max_time: 600.0,
            v_max: 2.0,
            a_max: 2.0,
            map: MapConfig {
                prob_miss: 0.48,
                ..MapConfig::default()
            },
            map_voxel: 0.0,
            frontier: FrontierConfig::default(),
            viewpoints: ViewpointConfig::default(),
            cost: CostConfig::default(),
            mpc: MpcConfig {
                limits: MotorLimits::try_new(
                    30f64.to_radians(),
                    core::f64::consts::PI,
                    core::f64::consts::TAU,
                )
                .unwrap_or_default(),
                ..MpcConfig::default()
            },
            motor: MotorLimits::default(),
            fisher: FisherConfig::default(),
            clear_on_no_return: false,
            fisher_frames: 10,
            fisher_radius: 15.0,
            fisher_points: 3000,
            replan_frames: 5,
            warmup: 2.0,
            max_clusters: 50,
            clearance: 0.5,
            graph_radius: 6.0,
            node_spacing: 1.0,
            corridor: 0.1,
            yaw_rate: 45f64.to_radians(),
            stall_time: 5.0,
            coverage_frames: 10,
            lost_distance: 5.0,
            flight: FlightConfig::default(),
        }
    }
}

impl ExplorerConfig {
    /// These settings with the optimising controllers' speed band (FU-MPC, its single-term
    /// variants and iCR) set to `min..=max` \[deg/s\] (default 30–180); their acceleration
    /// limit is kept.
    ///
    /// # Errors
    /// [`ExploreError::InvalidConfig`] for a bound that is not finite, `min > max`, or a band
    /// outside the motor's limits ([`ExplorerConfig::motor`]).
    ///
    /// # Example
    /// ```
    /// use fu_mpc_examples::explorer::ExplorerConfig;
    /// let config = ExplorerConfig::default().with_band(90.0, 180.0).unwrap();
    /// assert!((config.mpc.limits.omega_min() - 90f64.to_radians()).abs() < 1e-15);
    /// assert!(ExplorerConfig::default().with_band(180.0, 90.0).is_err());
    /// ```
    pub fn with_band(mut self, min: f64, max: f64) -> Result<Self, ExploreError> {
        let bad = |reason| ExploreError::InvalidConfig {
            what: "band",
            reason,
        };
        if !(min.is_finite() && max.is_finite()) {
            return Err(bad("bounds must be finite [deg/s]"));
        }
        if min > max {
            return Err(bad("the lower bound must not exceed the upper [deg/s]"));
        }
        let limits =
            MotorLimits::try_new(min.to_radians(), max.to_radians(), self.mpc.limits.u_max())?;
        if limits.omega_min() < self.motor.omega_min()
            || limits.omega_max() > self.motor.omega_max()
        {
            return Err(bad("must lie within the motor's speed limits"));
        }
        self.mpc.limits = limits;
        Ok(self)
    }

    /// Checks the explorer's own settings (the crates check theirs when they are built).
    ///
    /// # Errors
    /// [`ExploreError::InvalidConfig`] naming the first setting out of range.
    pub fn validate(&self) -> Result<(), ExploreError> {
        let bad = |what, reason| Err(ExploreError::InvalidConfig { what, reason });
        let pos = |v: f64| v.is_finite() && v > 0.0;
        for (what, v) in [
            ("max_time", self.max_time),
            ("v_max", self.v_max),
            ("a_max", self.a_max),
            ("fisher_radius", self.fisher_radius),
            ("clearance", self.clearance),
            ("graph_radius", self.graph_radius),
            ("node_spacing", self.node_spacing),
            ("corridor", self.corridor),
            ("yaw_rate", self.yaw_rate),
            ("stall_time", self.stall_time),
            ("lost_distance", self.lost_distance),
            ("warmup", self.warmup),
        ] {
            if !pos(v) {
                return bad(what, "must be positive and finite");
            }
        }
        if !(self.map_voxel.is_finite() && self.map_voxel >= 0.0) {
            return bad("map_voxel", "must be finite and >= 0");
        }
        if self.fisher_frames == 0 || self.replan_frames == 0 || self.coverage_frames == 0 {
            return bad(
                "fisher_frames/replan_frames/coverage_frames",
                "must be >= 1",
            );
        }
        if self.max_clusters == 0 {
            return bad("max_clusters", "must be >= 1");
        }
        if let ControllerKind::Fixed(d) = self.controller
            && !(d.is_finite() && d >= 0.0)
        {
            return bad("controller", "a fixed speed must be finite and >= 0");
        }
        self.flight.validate()?;
        Ok(())
    }
}

/// Where to explore: the world, the map bounds, the start, and (for the coverage metric) the
/// ground-truth explorable space.
#[derive(Debug, Clone, Copy)]
pub struct Mission<'a> {
    /// The world the sensors see.
    pub world: &'a World,
    /// Lower corner of the region to explore \[m\].
    pub min: Point3<f64>,
    /// Upper corner \[m\].
    pub max: Point3<f64>,
    /// The start position \[m\].
    pub start: Point3<f64>,
    /// The explorable free cells, if known (generated scenes); coverage is the share of them
    /// the map knows.
    pub explorable: Option<&'a Explorable>,
}

/// Wall-clock milliseconds per call of each module (instrumentation only: nothing in a run
/// depends on them).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ModuleTimes {
    /// LiDAR frame simulation.
    pub lidar: Vec<f64>,
    /// Odometry frame updates.
    pub odometry: Vec<f64>,
    /// Map insertion and the frontier update.
    pub mapping: Vec<f64>,
    /// Global planning (viewpoints, graph, tour, trajectory).
    pub planning: Vec<f64>,
    /// Scan-controller updates.
    pub scan: Vec<f64>,
    /// Fisher-table rebuilds (and iCR cloud updates).
    pub fisher: Vec<f64>,
}

/// Progress reported after every frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Progress {
    /// Simulated time \[s\].
    pub time: f64,
    /// The latest coverage sample (0..1), if coverage is measured.
    pub coverage: Option<f64>,
    /// Targets of the latest global plan.
    pub targets: usize,
}

/// What an exploration run recorded.
#[derive(Debug, Clone, Default)]
pub struct ExploreLog {
    /// The controller's name.
    pub controller: String,
    /// Whether the run ended because no reachable frontier was left (rather than at the time
    /// budget).
    pub finished: bool,
    /// Whether beams that returned nothing cleared the map along them
    /// ([`ExplorerConfig::clear_on_no_return`]).
    pub clear_on_no_return: bool,
    /// Why the harness stopped the run early, if it did: `"odometry lost"` when the
    /// estimate strayed more than [`ExplorerConfig::lost_distance`] from the truth, or
    /// `"left the scene"` when the true position left the bounds by more than a metre. These
    /// checks use the ground truth, which only the harness sees; a run that ends so is
    /// neither finished nor scored as one.
    pub aborted: Option<&'static str>,
    /// Simulated time at the end \[s\].
    pub exploration_time: f64,
    /// Frame end times \[s\].
    pub times: Vec<f64>,
    /// True body poses at the frame ends.
    pub truth: Vec<Isometry3<f64>>,
    /// Odometry poses at the frame ends.
    pub estimate: Vec<Isometry3<f64>>,
    /// Motor speed at the frame ends \[rad/s\].
    pub motor_speed: Vec<f64>,
    /// (time \[s\], coverage 0..1) samples; empty without ground truth.
    pub coverage: Vec<(f64, f64)>,
    /// Least distance from the true position to the world \[m\].
    pub min_clearance: f64,
    /// Times the clearance fell below the UAV's radius.
    pub collisions: usize,
    /// Global replans that produced a new trajectory.
    pub trajectories: usize,
    /// When each new trajectory started \[s\].
    pub trajectory_starts: Vec<f64>,
    /// Frontier clusters left at the end (including unreachable ones).
    pub clusters_left: usize,
    /// Occupied cell centres of the final map (for the top-down picture).
    pub occupied: Vec<Point3<f64>>,
    /// Per-module timings.
    pub timings: ModuleTimes,
}

/// The reference the UAV flies: the current trajectory from its start time, or a hover.
struct Reference {
    traj: Option<Trajectory<3>>,
    t0: f64,
    hover: Vector3<f64>,
    /// Yaw: `yaw0` at `yaw_t0`, turning toward `yaw_goal` at `yaw_rate`.
    yaw0: f64,
    yaw_t0: f64,
    yaw_goal: f64,
    yaw_rate: f64,
}

impl Reference {
    /// Planned position, velocity and acceleration at `t`.
    fn state(&self, t: f64) -> Result<[Vector3<f64>; 3], MincoError> {
        let Some(traj) = &self.traj else {
            return Ok([self.hover, Vector3::zeros(), Vector3::zeros()]);
        };
        let s = (t - self.t0).clamp(0.0, traj.duration());
        Ok([
            Vector3::from(traj.position(s)?),
            Vector3::from(traj.velocity(s)?),
            Vector3::from(traj.acceleration(s)?),
        ])
    }

    /// Whether the trajectory is flown to its end at `t` (a hover always is).
    fn done(&self, t: f64) -> bool {
        self.traj
            .as_ref()
            .is_none_or(|traj| t >= self.t0 + traj.duration() - 1e-9)
    }

    fn yaw(&self, t: f64) -> f64 {
        let e = wrap(self.yaw_goal - self.yaw0);
        let turned = self.yaw_rate * (t - self.yaw_t0).max(0.0);
        self.yaw0 + e.signum() * e.abs().min(turned)
    }
}

/// An angle wrapped into (−π, π].
fn wrap(a: f64) -> f64 {
    let w = a.rem_euclid(core::f64::consts::TAU);
    if w > core::f64::consts::PI {
        w - core::f64::consts::TAU
    } else {
        w
    }
}

/// The scan controller of a run.
enum Scan {
    Mpc(Box<FuMpc>),
    Fixed(FixedSpeed),
    Icr(Box<IcrScan>),
}

impl Scan {
    fn new(kind: ControllerKind, config: &ExplorerConfig) -> Result<Self, ExploreError> {
        let chain = explorer_chain();
        let mpc = config.mpc;
        Ok(match kind {
            ControllerKind::FuMpc => Self::Mpc(Box::new(FuMpc::new(mpc, chain)?)),
            ControllerKind::Uncertainty => {
                Self::Mpc(Box::new(FuMpc::uncertainty_only(mpc, chain)?))
            }
            ControllerKind::Frontier => Self::Mpc(Box::new(FuMpc::frontier_only(mpc, chain)?)),
            ControllerKind::Fixed(deg) => {
                Self::Fixed(FixedSpeed::new(deg.to_radians(), config.motor, mpc.dt)?)
            }
            ControllerKind::RigidYaw => Self::Fixed(FixedSpeed::new(0.0, config.motor, mpc.dt)?),
            ControllerKind::Icr => {
                let cfg = IcrScanConfig {
                    horizon: mpc.horizon,
                    dt: mpc.dt,
                    limits: mpc.limits,
                    ..IcrScanConfig::default()
                };
                Self::Icr(Box::new(IcrScan::new(cfg, chain, LidarSensor::mid360())?))
            }
        })
    }

    fn controller(&mut self) -> &mut dyn ScanController {
        match self {
            Self::Mpc(c) => c.as_mut(),
            Self::Fixed(c) => c,
            Self::Icr(c) => c.as_mut(),
        }
    }
}

/// The targets of the clusters nearest to `here` that are not given up (no viewpoint within
/// [`EXHAUSTED_RADIUS`] of an `exhausted` one). The clusters are taken in batches of `batch`
/// by distance (ties by id), each batch planned in id order: the work stays bounded in a large
/// map and the tour is planned where the UAV can act next. A batch whose targets are all
/// given up passes to the next, so the frontier beyond the nearest clusters is not taken for
/// none. Empty when every batch's targets are given up.
fn open_targets(
    map: &VoxelMap,
    mut clusters: Vec<&frontier::Cluster>,
    here: &Point3<f64>,
    batch: usize,
    viewpoints: &ViewpointConfig,
    exhausted: &[Point3<f64>],
) -> Result<Vec<Target>, ExploreError> {
    if clusters.len() > batch {
        clusters.sort_by(|a, b| {
            let d = |c: &frontier::Cluster| (c.center() - here).norm_squared();
            d(a).total_cmp(&d(b)).then(a.id().cmp(&b.id()))
        });
    }
    for chunk in clusters.chunks(batch.max(1)) {
        let mut chunk = chunk.to_vec();
        chunk.sort_by_key(|c| c.id());
        let plan = plan_targets_among(map, &chunk, here, &Omnidirectional, |_| true, viewpoints)?;
        let open: Vec<Target> = plan
            .targets
            .into_iter()
            .filter(|t| {
                exhausted
                    .iter()
                    .all(|e| (e - t.viewpoint).norm() > EXHAUSTED_RADIUS)
            })
            .collect();
        if !open.is_empty() {
            return Ok(open);
        }
    }
    Ok(Vec::new())
}

/// Whether the segment a → b runs through known-free cells keeping `clearance` from occupied
/// ones; within `relaxed` metres of `a` 70 % of it suffices, or the clearance `a` itself has
/// if that is less (the UAV's own position may sit closer to a wall than the graph's edges
/// do, and it must be able to leave).
fn segment_free(
    map: &VoxelMap,
    a: &Point3<f64>,
    b: &Point3<f64>,
    clearance: f64,
    relaxed: f64,
) -> bool {
    if !map.line_of_sight(a, b) {
        return false;
    }
    let near = if relaxed > 0.0 {
        (0.7 * clearance).min(map.clearance(a, clearance))
    } else {
        clearance
    };
    let d = b - a;
    let len = d.norm();
    let step = 0.5 * map.grid().resolution();
    // Segment lengths are a few metres over centimetres: the count fits u32.
    #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
    let n = (len / step).ceil().max(1.0) as u32;
    (0..=n).all(|i| {
        let s = f64::from(i) / f64::from(n);
        let c = if s * len < relaxed { near } else { clearance };
        map.is_clear(&(a + d * s), c)
    })
}

/// Removes the edges of the graph path `path` that join two permanent nodes (ids below
/// `first_temporary`) and no longer keep `clearance` from the map's obstacles (walls seen
/// after an edge was made can narrow it); returns how many left the graph.
fn remove_narrow_edges(
    graph: &mut TopoGraph,
    map: &VoxelMap,
    path: &[NodeId],
    first_temporary: NodeId,
    clearance: f64,
) -> Result<usize, ExploreError> {
    let mut removed = 0;
    for w in path.windows(2) {
        let (a, b) = (w[0], w[1]);
        if a >= first_temporary || b >= first_temporary {
            continue;
        }
        let (pa, pb) = (
            Point3::from(graph.position(a)?),
            Point3::from(graph.position(b)?),
        );
        if !segment_free(map, &pa, &pb, clearance, 0.0) && graph.remove_edge(a, b)? {
            removed += 1;
        }
    }
    Ok(removed)
}

/// A shortest path on the map's cells from `from` to `to` through known-free cells whose
/// centres keep `clearance` (26-connected, A*), shortened by skipping to the farthest vertex
/// each [`segment_free`] segment reaches; `None` if none is found within `max_expansions`
/// cell expansions. The first cell (the UAV's) needs no clearance, and cells within
/// [`ESCAPE_RADIUS`] of it only the clearance `from` has, if that is less: a UAV pushed
/// close to a wall can always leave.
fn grid_path(
    map: &VoxelMap,
    from: &Point3<f64>,
    to: &Point3<f64>,
    clearance: f64,
    max_expansions: usize,
) -> Option<Vec<Point3<f64>>> {
    let goal = map.grid().cell_of(to)?;
    let centre = map.grid().center(goal);
    let (mut pts, _) = grid_search(
        map,
        from,
        &[centre],
        |c, _| (c == goal).then_some(0),
        clearance,
        max_expansions,
    )?;
    if let Some(last) = pts.last_mut() {
        *last = *to;
    }
    Some(shortcut(map, &pts, clearance))
}

/// The [`grid_path`] to the first of the `tries` goals nearest to `from` in a straight line
/// (ties by index) that one is found to within `max_expansions`: the goal's index and the path.
fn nearest_grid_path(
    map: &VoxelMap,
    from: &Point3<f64>,
    goals: &[Point3<f64>],
    clearance: f64,
    tries: usize,
    max_expansions: usize,
) -> Option<(usize, Vec<Point3<f64>>)> {
    let mut order: Vec<usize> = (0..goals.len()).collect();
    let d2 = |i: usize| (goals[i] - from).norm_squared();
    order.sort_by(|&a, &b| d2(a).total_cmp(&d2(b)).then(a.cmp(&b)));
    order.into_iter().take(tries).find_map(|i| {
        grid_path(map, from, &goals[i], clearance, max_expansions).map(|path| (i, path))
    })
}

/// A path from `from` back along `trail` (oldest first, its last point near `from`) to the
/// trail's point nearest to one of `goals`, then a [`grid_path`] from there to the goal, all
/// keeping `clearance` (near `from` as [`grid_path`] allows). The goals are tried in order of
/// their distance to the trail, at most [`SQUEEZE_SEARCHES`] of them; a trail leg no longer
/// free (the map has grown since) is replaced by a grid path, or the goal is passed over.
/// Returns the goal's index and the path, shortened.
fn trail_path(
    map: &VoxelMap,
    trail: &[Point3<f64>],
    from: &Point3<f64>,
    goals: &[Point3<f64>],
    clearance: f64,
) -> Option<(usize, Vec<Point3<f64>>)> {
    // Each goal's nearest trail point, the latest of equals (the shortest way back).
    let nearest = |g: &Point3<f64>| {
        trail
            .iter()
            .enumerate()
            .map(|(j, q)| ((q - g).norm_squared(), j))
            .min_by(|a, b| a.0.total_cmp(&b.0).then(b.1.cmp(&a.1)))
    };
    let mut order: Vec<(f64, usize, usize)> = goals
        .iter()
        .enumerate()
        .filter_map(|(i, g)| nearest(g).map(|(d2, j)| (d2, i, j)))
        .collect();
    order.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    order
        .into_iter()
        .take(SQUEEZE_SEARCHES)
        .find_map(|(_, i, j)| {
            let last = grid_path(map, &trail[j], &goals[i], clearance, GRID_EXPANSIONS)?;
            let mut back: Vec<Point3<f64>> = vec![*from];
            back.extend(trail[j..].iter().rev());
            let mut pts = vec![*from];
            for (k, w) in back.windows(2).enumerate() {
                let relaxed = if k == 0 { ESCAPE_RADIUS } else { 0.0 };
                if segment_free(map, &w[0], &w[1], clearance, relaxed) {
                    pts.push(w[1]);
                } else {
                    let leg = grid_path(map, &w[0], &w[1], clearance, GRID_EXPANSIONS)?;
                    pts.extend(leg.into_iter().skip(1));
                }
            }
            pts.extend(last.into_iter().skip(1));
            Some((i, shortcut(map, &pts, clearance)))
        })
}

/// A path from `from` to one of `goals` over a lattice of points [`LATTICE_SPACING`] apart
/// anchored at `from`: A* over moves to the six nearest lattice points, each move
/// [`segment_free`] at `clearance` (relaxed near `from` as grid paths are), to a lattice
/// point within [`LATTICE_REACH`] of a goal with a free segment to the goal; then shortened.
/// A move spans five map cells, so a budget of expansions covers about a hundred times the
/// volume the cell search covers: ways of 70–110 m that no budgeted cell search finds.
/// Narrow openings between lattice points are missed; the cell searches find those. Returns
/// the goal's index (the nearest goal of the lattice point reached, ties by index) and the path.
fn lattice_path(
    map: &VoxelMap,
    from: &Point3<f64>,
    goals: &[Point3<f64>],
    clearance: f64,
    max_expansions: usize,
) -> Option<(usize, Vec<Point3<f64>>)> {
    type Node = [i32; 3];
    let at = |n: Node| from + Vector3::from(n.map(f64::from)) * LATTICE_SPACING;
    let relaxed = |n: Node| if n == [0; 3] { ESCAPE_RADIUS } else { 0.0 };
    let heuristic = |n: Node| {
        let p = at(n);
        goals
            .iter()
            .map(|g| ((p - g).norm() - LATTICE_REACH).max(0.0))
            .fold(f64::INFINITY, f64::min)
    };
    let goal = |n: Node| {
        let p = at(n);
        goals
            .iter()
            .enumerate()
            .map(|(i, g)| ((p - g).norm(), i))
            .filter(|&(d, i)| {
                d <= LATTICE_REACH && segment_free(map, &p, &goals[i], clearance, relaxed(n))
            })
            .min_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)))
            .map(|(_, i)| i)
    };
    let neighbours = |n: Node, out: &mut Vec<(Node, f64)>| {
        let p = at(n);
        for k in 0..3 {
            for s in [-1, 1] {
                let mut m = n;
                m[k] += s;
                if segment_free(map, &p, &at(m), clearance, relaxed(n)) {
                    out.push((m, LATTICE_SPACING));
                }
            }
        }
    };
    let (nodes, i) = astar([0; 3], heuristic, goal, neighbours, max_expansions)?;
    let mut pts: Vec<Point3<f64>> = nodes.into_iter().map(at).collect();
    pts.push(goals[i]);
    Some((i, shortcut(map, &pts, clearance)))
}

/// A path from the UAV to `to` through the graph: a grid search from `to` to the nearest of
/// the `reached` nodes (graph nodes the UAV reaches, each with its graph path from the UAV),
/// then that node's graph path back to the UAV. A target the UAV's part of the graph never
/// came near (below a floor it flew over, say) is joined to it this way. Only nodes within
/// [`BRIDGE_RADIUS`] of `to` are tried. Returns the positions from the UAV to `to`, and the
/// grid part from `to` to the node.
fn bridge_path(
    map: &VoxelMap,
    reached: &[(Point3<f64>, Vec<[f64; 3]>)],
    to: &Point3<f64>,
    clearance: f64,
) -> Option<Bridge> {
    let near: Vec<&(Point3<f64>, Vec<[f64; 3]>)> = reached
        .iter()
        .filter(|(p, _)| (p - to).norm() <= BRIDGE_RADIUS)
        .collect();
    if near.is_empty() {
        return None;
    }
    let goals: Vec<Point3<f64>> = near.iter().map(|(p, _)| *p).collect();
    let (path, k) = grid_path_to_nearest(map, to, &goals, clearance, GRID_EXPANSIONS)?;
    let mut positions = near[k].1.clone();
    // The grid path runs from `to` to the node, which ends the graph path already.
    positions.extend(path.iter().rev().skip(1).map(arr));
    Some(Bridge {
        positions,
        grid: path,
    })
}

/// A path found by [`bridge_path`].
#[derive(Debug, Clone)]
struct Bridge {
    /// From the UAV along a graph path to a node, then to the target.
    positions: Vec<[f64; 3]>,
    /// The grid part, from the target to the node.
    grid: Vec<Point3<f64>>,
}

/// The points of `path` with points added along every segment longer than `spacing`, evenly,
/// so no two consecutive points are farther apart than `spacing`.
fn densify(path: &[[f64; 3]], spacing: f64) -> Vec<[f64; 3]> {
    let mut out = Vec::with_capacity(path.len());
    for w in path.windows(2) {
        let (a, b) = (Point3::from(w[0]), Point3::from(w[1]));
        let d = b - a;
        // Segment lengths are metres and the spacing is positive: the count is small.
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        let n = (d.norm() / spacing).ceil().max(1.0) as u32;
        for k in 0..n {
            out.push(arr(&(a + d * (f64::from(k) / f64::from(n)))));
        }
    }
    if let Some(last) = path.last() {
        out.push(*last);
    }
    out
}

/// The box of the UAV's positions since a clock started.
#[derive(Debug, Clone, Copy)]
struct Span {
    lo: Point3<f64>,
    hi: Point3<f64>,
    since: f64,
}

impl Span {
    fn start(here: &Point3<f64>, t: f64) -> Self {
        Self {
            lo: *here,
            hi: *here,
            since: t,
        }
    }

    /// Takes `here` in, unless the box would then be wider than `diagonal`: then it stays as
    /// it was and says no.
    fn fits(&mut self, here: &Point3<f64>, diagonal: f64) -> bool {
        let before = *self;
        self.grow(here);
        if self.diagonal() > diagonal {
            *self = before;
            return false;
        }
        true
    }

    /// Takes `here` in however wide the box becomes.
    fn grow(&mut self, here: &Point3<f64>) {
        (self.lo, self.hi) = (self.lo.inf(here), self.hi.sup(here));
    }

    /// The box's diagonal \[m\].
    fn diagonal(&self) -> f64 {
        (self.hi - self.lo).norm()
    }
}

/// Whether the UAV makes headway: it is stuck once its positions since the clock last
/// started have fitted in a box of diagonal [`STUCK_SPAN`] for longer than [`STUCK_TIME`].
/// The clock starts again whenever they no longer fit.
#[derive(Debug, Clone, Copy, Default)]
struct Headway {
    /// The positions since the stuck clock started.
    span: Option<Span>,
    /// The same for [`Headway::idle`], with the map's known cells when its clock started.
    idle: Option<(Span, usize)>,
    /// The detour window of [`Headway::idle`].
    detour: Option<Detour>,
}

/// The positions of one [`IDLE_TIME`] window however far they spread, the way flown through
/// them, and the map's known cells when it started.
#[derive(Debug, Clone, Copy)]
struct Detour {
    span: Span,
    known: usize,
    flown: f64,
    last: Point3<f64>,
}

impl Detour {
    fn start(here: &Point3<f64>, t: f64, known: usize) -> Self {
        Self {
            span: Span::start(here, t),
            known,
            flown: 0.0,
            last: *here,
        }
    }
}

impl Headway {
    /// Records the UAV at `here` at time `t` and says whether it is stuck.
    fn stuck(&mut self, here: &Point3<f64>, t: f64) -> bool {
        if let Some(span) = &mut self.span
            && span.fits(here, STUCK_SPAN)
        {
            return t - span.since > STUCK_TIME;
        }
        self.restart(here, t);
        false
    }

    /// Records the UAV at `here` at time `t` with a map of `known` cells and says whether it
    /// is idle, by either of two clocks. The box clock: its positions since the clock last
    /// started fit in a box of diagonal [`IDLE_SPAN`], the map has gained fewer than
    /// [`IDLE_GAIN`] cells since, and more than [`IDLE_TIME`] has passed; it starts again
    /// when either no longer holds, and when it says idle. The detour clock, for a UAV
    /// turning back and forth over more than that box: the map has gained fewer than
    /// [`IDLE_GAIN`] cells in [`IDLE_TIME`] while the UAV's positions spread over a box
    /// wider than [`IDLE_SPAN`] and it flew at least [`IDLE_DETOUR`] times the box's
    /// diagonal (a flight from one place to another flies about that diagonal); it starts
    /// again when the map gains them and after each [`IDLE_TIME`].
    fn idle(&mut self, here: &Point3<f64>, t: f64, known: usize) -> bool {
        let detour = self.detour_idle(here, t, known);
        let mut idle = false;
        if let Some((span, known0)) = &mut self.idle
            && span.fits(here, IDLE_SPAN)
            && known < known0.saturating_add(IDLE_GAIN)
        {
            idle = t - span.since > IDLE_TIME;
            if !idle {
                return detour;
            }
        }
        self.idle = Some((Span::start(here, t), known));
        idle || detour
    }

    /// The detour clock of [`Headway::idle`].
    fn detour_idle(&mut self, here: &Point3<f64>, t: f64, known: usize) -> bool {
        let Some(d) = &mut self.detour else {
            self.detour = Some(Detour::start(here, t, known));
            return false;
        };
        if known >= d.known.saturating_add(IDLE_GAIN) {
            *d = Detour::start(here, t, known);
            return false;
        }
        d.flown += (here - d.last).norm();
        d.last = *here;
        d.span.grow(here);
        if t - d.span.since <= IDLE_TIME {
            return false;
        }
        // Only boxes the box clock cannot hold: it answers for the others.
        let diagonal = d.span.diagonal();
        let idle = diagonal > IDLE_SPAN && d.flown >= IDLE_DETOUR * diagonal;
        *d = Detour::start(here, t, known);
        idle
    }

    /// Starts the clock again from `here` at `t`.
    fn restart(&mut self, here: &Point3<f64>, t: f64) {
        self.span = Some(Span::start(here, t));
    }
}

/// A grid path as [`grid_path`] from `from` to whichever of `goals` it reaches first along the
/// shortest path: A* with the distance to the nearest goal as its heuristic (admissible, so
/// the goal reached is the nearest by path). A goal is reached in a cell within one cell of
/// it; the path then ends at the goal. Returns the path and the goal's index.
fn grid_path_to_nearest(
    map: &VoxelMap,
    from: &Point3<f64>,
    goals: &[Point3<f64>],
    clearance: f64,
    max_expansions: usize,
) -> Option<(Vec<Point3<f64>>, usize)> {
    let reach = map.grid().resolution();
    let (mut pts, i) = grid_search(
        map,
        from,
        goals,
        |_, d: &[f64]| {
            d.iter()
                .enumerate()
                .filter(|&(_, &d)| d <= reach)
                .min_by(|a, b| a.1.total_cmp(b.1))
                .map(|(i, _)| i)
        },
        clearance,
        max_expansions,
    )?;
    pts.push(goals[i]);
    Some((shortcut(map, &pts, clearance), i))
}

/// The A* search of [`grid_path`] and [`grid_path_to_nearest`]: `reached(cell, distances)`
/// says which goal, if any, a cell reaches, given the distances from its centre to every goal
/// (the heuristic is the least of them). Returns the path's points, `from` first then the
/// centres of the cells after its own, not shortened, and the goal's index.
fn grid_search(
    map: &VoxelMap,
    from: &Point3<f64>,
    goals: &[Point3<f64>],
    reached: impl Fn(frontier::Cell, &[f64]) -> Option<usize>,
    clearance: f64,
    max_expansions: usize,
) -> Option<(Vec<Point3<f64>>, usize)> {
    let grid = map.grid();
    let start = grid.cell_of(from)?;
    let near = map.clearance(from, clearance);
    let res = grid.resolution();
    let nearest = |c: frontier::Cell| {
        let p = grid.center(c);
        goals
            .iter()
            .map(|g| (p - g).norm())
            .fold(f64::INFINITY, f64::min)
    };
    let mut distances = Vec::with_capacity(goals.len());
    let goal = |c: frontier::Cell| {
        let p = grid.center(c);
        distances.clear();
        distances.extend(goals.iter().map(|g| (p - g).norm()));
        reached(c, &distances)
    };
    let mut ok: FxHashMap<frontier::Cell, bool> = FxHashMap::default();
    let neighbours = |c: frontier::Cell, out: &mut Vec<(frontier::Cell, f64)>| {
        for dz in -1..=1 {
            for dy in -1..=1 {
                for dx in -1..=1 {
                    if dx == 0 && dy == 0 && dz == 0 {
                        continue;
                    }
                    let Some(n) = grid.offset(c, [dx, dy, dz]) else {
                        continue;
                    };
                    let pass = *ok.entry(n).or_insert_with(|| {
                        let p = grid.center(n);
                        let need = if (p - from).norm() <= ESCAPE_RADIUS {
                            near
                        } else {
                            clearance
                        };
                        let end = goals.iter().any(|g| grid.cell_of(g) == Some(n));
                        end || (map.cell_state(n) == frontier::CellState::Free
                            && map.is_clear(&p, need))
                    });
                    if pass {
                        out.push((n, res * f64::from(dx * dx + dy * dy + dz * dz).sqrt()));
                    }
                }
            }
        }
    };
    let (cells, i) = astar(start, nearest, goal, neighbours, max_expansions)?;
    let mut pts: Vec<Point3<f64>> = cells.iter().map(|&c| grid.center(c)).collect();
    pts[0] = *from;
    Some((pts, i))
}

/// A* from `start`: `heuristic(n)` must not overestimate the cost from `n` to a goal,
/// `goal(n)` says which goal, if any, `n` reaches, and `neighbours(n, out)` pushes the nodes
/// one move from `n` with the moves' costs (non-negative). Of equal keys the least node is
/// expanded first. Returns the nodes from `start` to the goal's and the goal's index; `None`
/// when no goal is reached within `max_expansions` expansions.
fn astar<N: Copy + Eq + std::hash::Hash + Ord>(
    start: N,
    heuristic: impl Fn(N) -> f64,
    mut goal: impl FnMut(N) -> Option<usize>,
    mut neighbours: impl FnMut(N, &mut Vec<(N, f64)>),
    max_expansions: usize,
) -> Option<(Vec<N>, usize)> {
    use std::cmp::Reverse;
    use std::collections::BinaryHeap;
    // Costs are non-negative: their bit patterns order like the values.
    let key = |f: f64| f.to_bits();
    let mut came: FxHashMap<N, N> = FxHashMap::default();
    let mut cost: FxHashMap<N, f64> = FxHashMap::default();
    let mut open = BinaryHeap::new();
    let mut moves = Vec::new();
    cost.insert(start, 0.0);
    open.push(Reverse((key(heuristic(start)), start)));
    let mut expansions = 0;
    while let Some(Reverse((_, c))) = open.pop() {
        if let Some(i) = goal(c) {
            let mut nodes = vec![c];
            let mut at = c;
            while let Some(&prev) = came.get(&at) {
                nodes.push(prev);
                at = prev;
            }
            nodes.reverse();
            return Some((nodes, i));
        }
        expansions += 1;
        if expansions > max_expansions {
            return None;
        }
        let g = cost.get(&c).copied().unwrap_or(f64::INFINITY);
        moves.clear();
        neighbours(c, &mut moves);
        for &(n, step) in &moves {
            let ng = g + step;
            if cost.get(&n).is_none_or(|&old| ng < old - 1e-12) {
                cost.insert(n, ng);
                came.insert(n, c);
                open.push(Reverse((key(ng + heuristic(n)), n)));
            }
        }
    }
    None
}

/// The path shortened by jumping from each kept vertex to the farthest later one a free
/// segment reaches.
fn shortcut(map: &VoxelMap, pts: &[Point3<f64>], clearance: f64) -> Vec<Point3<f64>> {
    let Some(&first) = pts.first() else {
        return Vec::new();
    };
    let mut out = vec![first];
    let mut i = 0;
    while i + 1 < pts.len() {
        let mut j = pts.len() - 1;
        while j > i + 1 && !segment_free(map, &pts[i], &pts[j], clearance, 0.0) {
            j -= 1;
        }
        out.push(pts[j]);
        i = j;
    }
    out
}

fn arr(p: &Point3<f64>) -> [f64; 3] {
    [p.x, p.y, p.z]
}

/// The head state of a new trajectory and the speed and acceleration limits to optimise it
/// under, from the current plan state `[p, v, a]`; `None` to keep the current plan.
///
/// The head is the state exactly: the UAV flies plan + offset, so a jump in the plan's
/// velocity would be a jump of the true velocity that the IMU never measures (capping the
/// head at the limits did that, and the odometry drifted by metres). The limits are soft, so a
/// plan may exceed them for a while: until it is back within them it is kept, unless it must
/// be `replace`d; then the limits start at the current speed and acceleration, which the
/// optimiser requires of a head.
fn trajectory_head(
    state: &[Vector3<f64>; 3],
    v_max: f64,
    a_max: f64,
    replace: bool,
) -> Option<([[f64; 3]; 3], f64, f64)> {
    let [p, v, a] = state;
    let (speed, accel) = (v.norm(), a.norm());
    if (speed > v_max || accel > a_max) && !replace {
        return None;
    }
    Some((
        [[p.x, p.y, p.z], [v.x, v.y, v.z], [a.x, a.y, a.z]],
        v_max.max(speed),
        a_max.max(accel),
    ))
}

/// The explorer's state between frames.
struct Explorer<'a> {
    config: &'a ExplorerConfig,
    map: VoxelMap,
    frontiers: Frontiers,
    graph: TopoGraph,
    reference: Reference,
    /// The current target's viewpoint and the frontier centre it looks at.
    target: Option<(Point3<f64>, Point3<f64>)>,
    /// The current target's frontier clusters.
    target_members: Vec<frontier::ClusterId>,
    /// Whether the UAV, idle, holds on to its target while any target shares one of its
    /// clusters (the dynamic clusters regroup as the UAV moves, and their viewpoints and
    /// centres with them).
    holding: bool,
    /// Whether the last trajectory flown was a move away from walls (every trajectory
    /// along the path came too close to one).
    escaped: bool,
    /// Since when the plan has had no target, or none reachable.
    stalled_since: Option<f64>,
    /// Viewpoints flown to whose frontier stayed: targets there are not chosen again.
    exhausted: Vec<Point3<f64>>,
    /// When the UAV reached the viewpoint it now hovers at.
    arrival: Option<f64>,
    /// Whether the UAV makes headway toward its targets.
    headway: Headway,
    last_targets: usize,
    /// The mission's region \[m\].
    region: (Point3<f64>, Point3<f64>),
    /// The clusters the mission asks for, as of the last map update: the planner and the
    /// scan targets share one evaluation per frame.
    mission: MissionCache,
    /// The UAV's planned positions at the planning cycles, [`TRAIL_SPACING`] apart: a way
    /// back to where it has been when neither graph nor grid search finds one.
    trail: Vec<Point3<f64>>,
}

impl Explorer<'_> {
    /// Whether a target made of the frontier clusters `members` shares one with the current
    /// target (the idle rule's hold).
    fn shares_target_clusters(&self, members: &[frontier::ClusterId]) -> bool {
        members.iter().any(|m| self.target_members.contains(m))
    }

    /// Adds a permanent graph node at `p` unless one is within the node spacing.
    fn add_node(&mut self, p: &Point3<f64>) -> Result<(), ExploreError> {
        let near = (0..self.graph.len()).any(|n| {
            self.graph
                .position(n)
                .is_ok_and(|q| (Point3::from(q) - p).norm() < self.config.node_spacing)
        });
        if near || !self.map.is_clear(p, self.config.clearance) {
            return Ok(());
        }
        let (map, c) = (&self.map, self.config.clearance);
        let free = |a: &[f64; 3], b: &[f64; 3]| {
            segment_free(map, &Point3::from(*a), &Point3::from(*b), c, 0.0)
        };
        self.graph
            .add_node(arr(p), self.config.graph_radius, &free)?;
        Ok(())
    }

    /// A path from the UAV to `to` when the graph does not reach `to` (see [`bridge_path`]);
    /// the grid part of the path joins the graph.
    fn bridge(
        &mut self,
        reached: &[(Point3<f64>, Vec<[f64; 3]>)],
        to: &Point3<f64>,
    ) -> Result<Option<Vec<[f64; 3]>>, ExploreError> {
        let Some(bridge) = bridge_path(&self.map, reached, to, self.config.clearance) else {
            return Ok(None);
        };
        self.join_path(&bridge.grid)?;
        Ok(Some(bridge.positions))
    }

    /// Adds the vertices of a free path (and points every half graph radius along its
    /// segments) as permanent graph nodes, so the graph reaches where the path goes.
    fn join_path(&mut self, path: &[Point3<f64>]) -> Result<(), ExploreError> {
        let pts: Vec<[f64; 3]> = path.iter().map(arr).collect();
        for p in densify(&pts, 0.5 * self.config.graph_radius) {
            self.add_node(&Point3::from(p))?;
        }
        Ok(())
    }

    /// One global planning cycle at `t`: returns whether a new trajectory was made.
    fn plan(&mut self, t: f64, force: bool) -> Result<bool, ExploreError> {
        let [p, v, a] = self.reference.state(t)?;
        let here = Point3::from(p);
        // A UAV stuck in place gives the target chosen now up like an exhausted one: its
        // trajectory keeps being replaced (blocked, or swinging too close to a wall) before
        // the UAV gets anywhere, and choosing it again would hold the UAV there for the rest
        // of the run.
        let mut stuck = self.headway.stuck(&here, t);
        // Idle once: hold on to the target; idle again while holding: give it up.
        if self.target.is_some() && self.headway.idle(&here, t, self.map.known_cells()) {
            stuck |= self.holding;
            self.holding = !self.holding;
        }
        if self
            .trail
            .last()
            .is_none_or(|q| (q - here).norm() >= TRAIL_SPACING)
        {
            self.trail.push(here);
        }
        let clusters: Vec<&frontier::Cluster> = self
            .mission
            .ids()
            .iter()
            .filter_map(|id| self.frontiers.cluster(*id))
            .collect();
        // While holding, the target stays as long as frontier is left near its centre, in
        // the plan or not: which targets the plan holds changes as the UAV moves.
        let held = self.holding
            && self.target.is_some_and(|(_, c)| {
                clusters
                    .iter()
                    .any(|k| (k.center() - c).norm() < HOLD_RADIUS)
            });
        let targets = open_targets(
            &self.map,
            clusters,
            &here,
            self.config.max_clusters,
            &self.config.viewpoints,
            &self.exhausted,
        )?;
        self.last_targets = targets.len();
        // The current target is kept until it is reached or its frontier is gone: re-choosing
        // the tour's first target every cycle makes the UAV turn back and forth between
        // targets as the map grows, and it reaches none.
        if let Some((vp, center)) = self.target
            && !force
            && !self.reference.done(t)
            && (held
                || targets.iter().any(|t| {
                    (t.viewpoint - vp).norm() < KEEP_RADIUS
                        || (t.center - center).norm() < KEEP_RADIUS
                        || (self.holding && self.shares_target_clusters(&t.members))
                }))
        {
            self.stalled_since = None;
            return Ok(false);
        }
        if targets.is_empty() {
            self.stalled_since.get_or_insert(t);
            return Ok(false);
        }
        // The roadmap grows with the UAV's positions and the viewpoints (free, with clearance).
        self.add_node(&here)?;
        for target in &targets {
            self.add_node(&target.viewpoint)?;
        }
        let (map, c) = (&self.map, self.config.clearance);
        let free_from_uav = |x: &[f64; 3], y: &[f64; 3]| {
            segment_free(map, &Point3::from(*x), &Point3::from(*y), c, 1.0)
        };
        let free = |x: &[f64; 3], y: &[f64; 3]| {
            segment_free(map, &Point3::from(*x), &Point3::from(*y), c, 0.0)
        };
        let r = self.config.graph_radius;
        let odom = self
            .graph
            .add_temporary_node(arr(&here), r, &free_from_uav)?;
        let mut views: Vec<NodeId> = Vec::with_capacity(targets.len());
        for target in &targets {
            views.push(
                self.graph
                    .add_temporary_node(arr(&target.viewpoint), r, &free)?,
            );
        }
        let mut cost = self.config.cost;
        cost.v_max = self.config.v_max;
        let m = cost_matrix(&self.graph, odom, &views, [v.x, v.y, v.z], &cost)?;
        // The real-time preset (LKH's own budget of n trials): the planner re-solves twice a
        // second.
        let tour = solve_open(&m, &SolverConfig::fast(), || false)?.tour;
        // The first target of the tour with a graph path; failing that, the first ones the
        // grid search reaches (their paths then join the graph).
        let mut chosen: Option<(usize, Vec<[f64; 3]>)> = None;
        let mut via: Vec<NodeId> = Vec::new();
        for &i in tour.order.iter().filter(|&&i| i != 0) {
            if let Some(path) = self.graph.shortest_path(odom, views[i - 1])? {
                let pts = path
                    .nodes
                    .iter()
                    .map(|&n| self.graph.position(n))
                    .collect::<Result<Vec<_>, _>>()?;
                via = path.nodes;
                chosen = Some((i - 1, pts));
                break;
            }
        }
        // The permanent nodes the graph reaches from the UAV near the first targets, with
        // their paths, for bridging to targets it does not connect (see `bridge`). Node ids
        // below the UAV's are the permanent ones.
        let mut reached = Vec::new();
        if chosen.is_none() {
            let reach = self.graph.shortest_paths_from(odom)?;
            let first: Vec<Point3<f64>> = tour
                .order
                .iter()
                .filter(|&&i| i != 0)
                .take(GRID_SEARCHES)
                .map(|&i| targets[i - 1].viewpoint)
                .collect();
            for n in 0..odom {
                let p = Point3::from(self.graph.position(n)?);
                if !first.iter().any(|t| (p - t).norm() <= BRIDGE_RADIUS) {
                    continue;
                }
                let Some(via) = reach.path_to(n) else {
                    continue;
                };
                if via.iter().any(|&m| m > odom) {
                    // Through a target's temporary node: not a path of the graph that stays.
                    continue;
                }
                let positions = via
                    .iter()
                    .map(|&m| {
                        if m == odom {
                            Ok(arr(&here))
                        } else {
                            self.graph.position(m)
                        }
                    })
                    .collect::<Result<Vec<_>, _>>()?;
                reached.push((p, positions));
            }
        }
        self.graph.clear_temporary();
        // The first tour target the grid search reaches: its index and path.
        if chosen.is_none()
            && let Some((i, path)) = tour
                .order
                .iter()
                .filter(|&&i| i != 0)
                .take(GRID_SEARCHES)
                .find_map(|&i| {
                    let to = targets[i - 1].viewpoint;
                    grid_path(&self.map, &here, &to, c, GRID_EXPANSIONS).map(|path| (i - 1, path))
                })
        {
            self.join_path(&path)?;
            chosen = Some((i, path.iter().map(arr).collect()));
        }
        if chosen.is_none() {
            for &i in tour.order.iter().filter(|&&i| i != 0).take(GRID_SEARCHES) {
                if let Some(positions) = self.bridge(&reached, &targets[i - 1].viewpoint)? {
                    chosen = Some((i - 1, positions));
                    break;
                }
            }
        }
        // Last, searches at the clearance trajectories must keep, the grid search first:
        // cells seen after the UAV came in (returns off a wall's edge that the weak miss
        // keeps) can narrow a pocket's way out below the planning clearance. Such paths do
        // not join the graph. The nearest targets first, with a larger budget: the tour's
        // order comes from graph costs, which say nothing of targets the graph does not reach.
        if chosen.is_none() {
            let views: Vec<Point3<f64>> = targets.iter().map(|t| t.viewpoint).collect();
            let squeeze = self.config.flight.radius + SAFETY_MARGIN;
            chosen = nearest_grid_path(
                &self.map,
                &here,
                &views,
                squeeze,
                SQUEEZE_SEARCHES,
                SQUEEZE_EXPANSIONS,
            )
            // Then back along the trail to where it came nearest to a target: the UAV flew
            // there, through openings a grid search may need millions of expansions to find.
            .or_else(|| trail_path(&self.map, &self.trail, &here, &views, squeeze))
            // Last, a coarse search whose reach grows with its budget: the target may lie
            // a hundred metres away round the far end of the map, beyond every search above.
            .or_else(|| lattice_path(&self.map, &here, &views, squeeze, LATTICE_EXPANSIONS))
            .map(|(i, path)| (i, path.iter().map(arr).collect()));
        }
        let Some((i, positions)) = chosen else {
            self.stalled_since.get_or_insert(t);
            return Ok(false);
        };
        self.stalled_since = None;
        let target = &targets[i];
        if stuck {
            self.exhausted.push(target.viewpoint);
            self.headway.restart(&here, t);
            if self.escaped {
                // Swaying in front of a way that walls seen since have narrowed: every
                // plan through it would sway again.
                let narrow = self
                    .config
                    .clearance
                    .min(self.config.flight.radius + SAFETY_MARGIN + self.config.corridor);
                remove_narrow_edges(&mut self.graph, &self.map, &via, odom, narrow)?;
            }
        }
        let same = self
            .target
            .is_some_and(|(vp, _)| (vp - target.viewpoint).norm() < 1.0);
        if same && !force && !self.reference.done(t) {
            return Ok(false);
        }
        let Some((head, v_max, a_max)) = trajectory_head(
            &[p, v, a],
            self.config.v_max,
            self.config.a_max,
            force || self.reference.done(t),
        ) else {
            return Ok(false);
        };
        let goal = positions.last().copied().unwrap_or(arr(&here));
        let tail = [goal, [0.0; 3], [0.0; 3]];
        let inner = &positions[1..positions.len().saturating_sub(1).max(1)];
        let mut cfg = OptimizerConfig::default().with_limits(v_max, a_max);
        cfg.corridor_radius = Some(self.config.corridor);
        cfg.waypoint_weight = 1e4;
        let at_rest = v.norm() < 0.05 && a.norm() < 0.05;
        // The path flown leg by leg, straight moves from rest to rest (`None` unless at rest
        // and every leg keeps its clearance).
        let leg_by_leg = || {
            path_legs(
                &self.map,
                self.config.flight.radius,
                &here,
                at_rest,
                &positions,
                head,
                cfg,
            )
        };
        let mut escape = false;
        let mut traj = if at_rest && (Point3::from(goal) - here).norm() < EXHAUSTED_RADIUS {
            // Already there: after a second of looking, a frontier that stays is out of view
            // from here; do not come back for it.
            match self.arrival {
                Some(since) if t - since >= DWELL => {
                    self.exhausted.push(target.viewpoint);
                    self.arrival = None;
                }
                Some(_) => {}
                None => self.arrival = Some(t),
            }
            None
        } else {
            let first = Optimizer::<3, 3>::new(cfg, head, tail, inner)?
                .optimize()?
                .trajectory;
            // A trajectory that cuts closer to a wall or ceiling than the path between two
            // far-apart waypoints is made again through waypoints at most
            // [`DENSE_SPACING`] apart, which hold it to the path.
            if self.too_close(&first, 0.0)? {
                let dense = densify(&positions, DENSE_SPACING);
                let inner = &dense[1..dense.len().saturating_sub(1).max(1)];
                let second = Optimizer::<3, 3>::new(cfg, head, tail, inner)?
                    .optimize()?
                    .trajectory;
                if !self.too_close(&second, 0.0)? {
                    Some(second)
                } else if let Some(legs) = leg_by_leg()? {
                    // From rest, the path flown leg by leg keeps the clearance that both
                    // trajectories lose where they cut its corners.
                    Some(legs)
                } else if force || self.reference.traj.is_none() || self.reference.done(t) {
                    escape = true;
                    // It will be flown whatever it is: fly the one that keeps the most room.
                    Some(safest(
                        &self.map,
                        self.config.flight.radius,
                        &here,
                        head,
                        cfg,
                        first,
                        second,
                    )?)
                } else {
                    Some(first)
                }
            } else {
                Some(first)
            }
        };
        // A new trajectory far beyond the acceleration limit, or jerking the attitude round
        // faster than a multirotor turns, is not flown: the UAV stays on course and plans
        // again; when it must leave its course it comes to rest first, and from rest it flies
        // the path leg by leg (straight moves from rest to rest), or, with no such legs, the
        // trajectory as it is.
        if let Some(new) = &traj
            && too_steep(new, a_max)
        {
            if self.reference.traj.is_some() && !force && !self.reference.done(t) {
                return Ok(false);
            }
            let instead = if at_rest {
                leg_by_leg()?
            } else {
                brake(cfg, head, a_max)
            };
            if instead.is_some() {
                traj = instead;
                escape = false;
            }
        }
        // A new trajectory that swings close to a wall (the UAV's momentum carries it past
        // a sharp turn) does not replace a safe one: the UAV stays on course and plans again.
        if let Some(new) = &traj
            && self.too_close(new, 0.0)?
            && self.reference.traj.is_some()
            && !force
            && !self.reference.done(t)
        {
            return Ok(false);
        }
        if traj.is_some() {
            self.arrival = None;
            self.escaped = escape;
        }
        self.reference.traj = traj;
        self.reference.t0 = t;
        self.reference.hover = p;
        if self.holding && !self.shares_target_clusters(&target.members) {
            self.holding = false;
        }
        self.target = Some((target.viewpoint, target.center));
        self.target_members.clone_from(&target.members);
        Ok(true)
    }

    /// Whether the rest of the trajectory passes closer to a known obstacle than the UAV's
    /// radius and [`SAFETY_MARGIN`], less [`STEP_SLACK`] (see [`Explorer::too_close`]).
    fn blocked(&self, t: f64) -> Result<bool, ExploreError> {
        match &self.reference.traj {
            Some(traj) => self.too_close(traj, t - self.reference.t0),
            None => Ok(false),
        }
    }

    /// Whether `traj` from time `s` on passes closer to a known obstacle than the UAV's radius
    /// and [`SAFETY_MARGIN`], less [`STEP_SLACK`] (what a search's diagonal step between
    /// two cells that keep the margin may lose). Trajectories are kept while their target stays, so obstacles
    /// seen later must be caught with a margin. Within [`ESCAPE_RADIUS`]
    /// of the start the clearance the start has is enough, so a UAV near a wall can keep a
    /// path that leaves it.
    fn too_close(&self, traj: &Trajectory<3>, s: f64) -> Result<bool, ExploreError> {
        let margin = self.config.flight.radius + SAFETY_MARGIN - STEP_SLACK;
        let mut s = s.max(0.0);
        let start = Point3::from(traj.position(s.min(traj.duration()))?);
        let near = self.map.clearance(&start, margin);
        while s < traj.duration() {
            let p = Point3::from(traj.position(s)?);
            let need = if (p - start).norm() <= ESCAPE_RADIUS {
                near.max(self.config.flight.radius)
            } else {
                margin
            };
            if !self.map.is_clear(&p, need) {
                return Ok(true);
            }
            s += 0.05;
        }
        Ok(false)
    }
}

/// The path flown leg by leg, each leg a move from rest to rest, for a UAV at rest whose
/// trajectories through the path's points all cut a corner too close to a wall: a single
/// piece between rest states is a straight line, and the path's search checked its legs at
/// the clearance. Points nearer than [`LEG_MIN`] to a leg's start (grid paths step by a
/// cell) are passed over, except the path's end, unless the leg past one would cut a
/// corner: then the UAV stops at it first. `None` unless the UAV is at rest and every leg,
/// all the way to the path's end, keeps the UAV's `radius` and [`SAFETY_MARGIN`], less
/// [`STEP_SLACK`], from known obstacles from its start on: no allowance near a start close
/// to a wall, as [`Explorer::too_close`] gives, so such moves cannot creep along one, and
/// no move to a point partway along, from which the next plan might fly back.
fn path_legs(
    map: &VoxelMap,
    radius: f64,
    here: &Point3<f64>,
    at_rest: bool,
    positions: &[[f64; 3]],
    head: [[f64; 3]; 3],
    cfg: OptimizerConfig,
) -> Result<Option<Trajectory<3>>, ExploreError> {
    let margin = radius + SAFETY_MARGIN - STEP_SLACK;
    let Some(&goal) = positions.last() else {
        return Ok(None);
    };
    if !at_rest || positions.len() < 2 || !map.is_clear(here, margin) {
        return Ok(None);
    }
    // A move to rest at `to` that keeps the margin. The optimiser's errors only mean no
    // legs: the escape moves follow.
    let clear_move = |from: [[f64; 3]; 3], to: [f64; 3]| -> Result<_, ExploreError> {
        Ok(match move_to_rest(cfg, from, to) {
            Some(leg) if least_clearance(map, &leg, margin)? >= margin => Some(leg),
            _ => None,
        })
    };
    let mut from = head;
    let mut legs: Option<Trajectory<3>> = None;
    // The last point passed over since the last leg's end.
    let mut skipped: Option<[f64; 3]> = None;
    for q in &positions[1..] {
        let d = (Point3::from(*q) - Point3::from(from[0])).norm();
        if (d < LEG_MIN && *q != goal) || d == 0.0 {
            if d > 0.0 {
                skipped = Some(*q);
            }
            continue;
        }
        let leg = match clear_move(from, *q)? {
            Some(leg) => leg,
            None => {
                // A leg past a point passed over leaves the path: stop at the point first.
                let Some(k) = skipped else {
                    return Ok(None);
                };
                let Some(to_k) = clear_move(from, k)? else {
                    return Ok(None);
                };
                let Some(joined) = join_leg(legs, to_k) else {
                    return Ok(None);
                };
                legs = Some(joined);
                from = [k, [0.0; 3], [0.0; 3]];
                let Some(leg) = clear_move(from, *q)? else {
                    return Ok(None);
                };
                leg
            }
        };
        skipped = None;
        let Some(joined) = join_leg(legs, leg) else {
            return Ok(None);
        };
        legs = Some(joined);
        from = [*q, [0.0; 3], [0.0; 3]];
    }
    Ok(legs)
}

/// `legs` with `leg` flown after them; `None` when they do not meet.
fn join_leg(legs: Option<Trajectory<3>>, leg: Trajectory<3>) -> Option<Trajectory<3>> {
    match legs {
        // Legs meet to the optimiser's rounding, far inside `then`'s tolerance.
        Some(before) => before.then(&leg).ok(),
        None => Some(leg),
    }
}

/// Whether `traj` pulls more than [`ACCEL_SLACK`] times `a_max` \[m/s²\] or jerks more than
/// [`JERK_MAX`] anywhere.
fn too_steep(traj: &Trajectory<3>, a_max: f64) -> bool {
    traj.max_acceleration(ACCEL_SAMPLES) > ACCEL_SLACK * a_max
        || traj.max_derivative_norm(3, ACCEL_SAMPLES) > JERK_MAX
}

/// A stop: one polynomial piece from `head` to rest where braking at `a_max` \[m/s²\] along
/// the current velocity ends; `None` when the optimiser fails.
fn brake(cfg: OptimizerConfig, head: [[f64; 3]; 3], a_max: f64) -> Option<Trajectory<3>> {
    let [p, v, _] = head.map(Vector3::from);
    // v²/2a along v: v |v| / 2a.
    let to = p + v * (v.norm() / (2.0 * a_max));
    move_to_rest(cfg, head, [to.x, to.y, to.z])
}

/// One polynomial piece from `head` to rest at `to`, within `cfg`'s limits; `None` when the
/// optimiser fails. From rest it is a straight line.
fn move_to_rest(cfg: OptimizerConfig, head: [[f64; 3]; 3], to: [f64; 3]) -> Option<Trajectory<3>> {
    let tail = [to, [0.0; 3], [0.0; 3]];
    Optimizer::<3, 3>::new(cfg, head, tail, &[])
        .and_then(|mut o| o.optimize())
        .ok()
        .map(|out| out.trajectory)
}

/// Of `first`, `second` and short moves from `here` (state `head`) to rest at the 26 points
/// [`ESCAPE_STEP`] away in line of sight through known-free cells, the trajectory whose
/// least clearance to a known obstacle is largest, then whose end has the most clearance
/// (the first of equals): for a replan
/// that must fly something while every planned trajectory comes too close. A UAV that
/// finds itself too near a floor or wall backs away, and plans again from there.
fn safest(
    map: &VoxelMap,
    radius: f64,
    here: &Point3<f64>,
    head: [[f64; 3]; 3],
    cfg: OptimizerConfig,
    first: Trajectory<3>,
    second: Trajectory<3>,
) -> Result<Trajectory<3>, ExploreError> {
    let mut candidates = vec![second];
    let steps = [-1.0, 0.0, 1.0];
    for dz in steps {
        for dy in steps {
            for dx in steps {
                let d = Vector3::new(dx, dy, dz);
                if d == Vector3::zeros() {
                    continue;
                }
                let q = here + d.normalize() * ESCAPE_STEP;
                if map.state(&q) != frontier::CellState::Free || !map.line_of_sight(here, &q) {
                    continue;
                }
                // The optimiser's errors only mean one move fewer to choose from.
                candidates.extend(move_to_rest(cfg, head, arr(&q)));
            }
        }
    }
    // By least clearance, then by the clearance at the end, where the next plan starts.
    let margin = radius + SAFETY_MARGIN;
    let room = |traj: &Trajectory<3>| -> Result<(f64, f64), ExploreError> {
        let end = Point3::from(traj.position(traj.duration())?);
        Ok((
            least_clearance(map, traj, 2.0 * margin)?,
            map.clearance(&end, 4.0 * margin),
        ))
    };
    let mut best = (room(&first)?, first);
    for traj in candidates {
        let r = room(&traj)?;
        if r > best.0 {
            best = (r, traj);
        }
    }
    Ok(best.1)
}

/// The least clearance to a known obstacle along `traj` (sampled every 0.05 s), up to
/// `cap` \[m\].
fn least_clearance(map: &VoxelMap, traj: &Trajectory<3>, cap: f64) -> Result<f64, ExploreError> {
    let mut least = cap;
    let mut s = 0.0f64;
    loop {
        let p = Point3::from(traj.position(s.min(traj.duration()))?);
        least = least.min(map.clearance(&p, cap));
        if s >= traj.duration() {
            return Ok(least);
        }
        s += 0.05;
    }
}

/// Explores `mission` with the sensors, the odometry and the whole planning stack; `progress`
/// is called after every frame (for a progress bar). Runs until no reachable frontier is
/// left or the time budget runs out.
///
/// Deterministic: the same mission, settings and seed give the same log (timings aside).
///
/// # Errors
/// Invalid settings, a start outside the bounds or in an obstacle, and the errors of the
/// crates (kinematics, odometry, trajectory optimisation, planning).
pub fn explore(
    mission: &Mission<'_>,
    config: &ExplorerConfig,
    seed: u64,
    mut progress: impl FnMut(&Progress),
) -> Result<ExploreLog, ExploreError> {
    config.validate()?;
    let world = mission.world;
    let fc = &config.flight;
    // The map pads the region by two cells so walls on its border are inside.
    let pad = Vector3::repeat(2.0 * config.map.resolution);
    let bounds = Bounds::new(mission.min - pad, mission.max + pad)?;
    if !bounds.contains(&mission.start) || world.distance(&mission.start) < fc.radius {
        return Err(ExploreError::BadStart(mission.start));
    }
    let chain = if config.controller.spins() {
        explorer_chain()
    } else {
        rigid_chain()
    };
    let sensor = LidarSensor::mid360();
    if config.clear_on_no_return && sensor.range().max() <= config.map.max_range {
        // A miss's end would lie within the map's range and count as a hit.
        return Err(ExploreError::InvalidConfig {
            what: "clear_on_no_return",
            reason: "needs a LiDAR range beyond the map's insertion range",
        });
    }
    let mut lidar = LidarSim::new(sensor.clone(), chain, fc.lidar_noise, seed)
        .with_misses(config.clear_on_no_return);
    let mut imu = ImuSim::new(fc.imu_noise, 200.0, seed.wrapping_add(1));
    let motor = MotorModel::new(config.motor);
    let mut encoder = Encoder::new(fc.encoder);
    let mut scan = Scan::new(config.controller, config)?;
    let map = VoxelMap::new(bounds, config.map)?;
    let mission_cache = MissionCache::new(&map);
    let mut ex = Explorer {
        config,
        map,
        frontiers: Frontiers::new(config.frontier)?,
        graph: TopoGraph::new(),
        reference: Reference {
            traj: None,
            t0: 0.0,
            hover: mission.start.coords,
            yaw0: 0.0,
            yaw_t0: 0.0,
            yaw_goal: 0.0,
            yaw_rate: config.yaw_rate,
        },
        target: None,
        stalled_since: None,
        trail: Vec::new(),
        exhausted: Vec::new(),
        arrival: None,
        headway: Headway::default(),
        target_members: Vec::new(),
        holding: false,
        escaped: false,
        last_targets: 0,
        region: (mission.min, mission.max),
        mission: mission_cache,
    };
    let mut track = Tracking::at_rest(0.0, fc.tracking_lag);
    let actual =
        |r: &Reference, track: &Tracking, t: f64| -> Result<[Vector3<f64>; 3], ExploreError> {
            let plan = r.state(t)?;
            let off = track.offset(t);
            Ok([plan[0] + off[0], plan[1] + off[1], plan[2] + off[2]])
        };
    let attitude =
        |r: &Reference, track: &Tracking, t: f64| -> Result<UnitQuaternion<f64>, ExploreError> {
            Ok(flat_attitude(&actual(r, track, t)?[2], r.yaw(t)))
        };
    let pose = |r: &Reference, track: &Tracking, t: f64| -> Result<Isometry3<f64>, ExploreError> {
        Ok(Isometry3::from_parts(
            Translation3::from(actual(r, track, t)?[0]),
            attitude(r, track, t)?,
        ))
    };
    let mut odo = Odometry::new(
        chain,
        fc.odometry,
        NavState {
            time: 0.0,
            position: mission.start.coords,
            velocity: Vector3::zeros(),
            attitude: attitude(&ex.reference, &track, 0.0)?,
        },
    );
    let mut log = ExploreLog {
        controller: config.controller.to_string(),
        clear_on_no_return: config.clear_on_no_return,
        min_clearance: f64::INFINITY,
        ..ExploreLog::default()
    };
    let mut motor_state = MotorState::new(0.0, 0.0);
    let mut command = 0.0;
    encoder.record(0.0, 0.0)?;
    let mut motor_samples: Vec<(f64, f64)> = vec![(0.0, 0.0)];
    let mut points = Vec::new();
    let mut world_points = Vec::new();
    let mut angles: Vec<AngleSample> = Vec::with_capacity(101);
    let mut body_samples: Vec<Isometry3<f64>> = Vec::with_capacity(101);
    let mut reference_poses: Vec<Isometry3<f64>> = Vec::with_capacity(config.mpc.horizon + 1);
    let mut fisher: Option<FisherTable> = None;
    let latency = fc.encoder.latency();
    angles.push(AngleSample::new(0.0, encoder.read(latency)?.angle));
    let mut inside = false;
    let mut coverage = None;
    // Coverage counted incrementally: the map never forgets a cell, and each frame's newly
    // known map cells are the only ones whose explorable cells can change.
    let mut counter: Option<crate::scene::CoverageCounter<'_>> = mission.explorable.map(|e| {
        let mut c = e.coverage_counter();
        c.update(|p| ex.map.state(p) != frontier::CellState::Unknown);
        c
    });
    // Frame counts are small; times are exact ratios so ticks and frame ends meet.
    #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
    let frames = (config.max_time * 10.0).ceil() as u64;
    #[allow(clippy::cast_precision_loss)]
    for k in 0..frames {
        let t0 = k as f64 / 10.0;
        let t1 = (k + 1) as f64 / 10.0;
        // Motor (under the last command) and encoder at 1 kHz.
        motor_samples.drain(..motor_samples.len() - 1);
        angles.drain(..angles.len().saturating_sub(1));
        for j in 1..=100u64 {
            let t = (100 * k + j) as f64 / 1000.0;
            motor_state = motor.step(motor_state, command, 1e-3)?;
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
        // IMU at 200 Hz, and the true clearance.
        let r = &ex.reference;
        for i in 0..20u64 {
            let t = (20 * k + i) as f64 / 200.0;
            let h = 1e-4;
            let rate = body_rate(
                &attitude(r, &track, (t - h).max(track.t0))?,
                &attitude(r, &track, t + h)?,
                t + h - (t - h).max(track.t0),
            );
            let [p, _, a] = actual(r, &track, t)?;
            let s = imu.sample(t, &attitude(r, &track, t)?, &a, &rate);
            odo.push_imu(&s)?;
            let c = world.distance(&Point3::from(p));
            log.min_clearance = log.min_clearance.min(c);
            let now_inside = c < fc.radius;
            if now_inside && !inside {
                log.collisions += 1;
            }
            inside = now_inside;
        }
        body_samples.clear();
        for j in 0..=100u64 {
            body_samples.push(pose(r, &track, (100 * k + j) as f64 / 1000.0)?);
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
        log.timings.lidar.push(ms(clock));
        let clock = Instant::now();
        odo.process_frame_with_misses(t1, &points, lidar.misses(), &angles)?;
        log.timings.odometry.push(ms(clock));
        let truth = pose(r, &track, t1)?;
        let estimate = odo.state().pose();
        log.times.push(t1);
        log.truth.push(truth);
        log.estimate.push(estimate);
        log.motor_speed.push(motor_state.omega);

        // Mapping at the estimated pose, from the sensor's estimated position.
        let clock = Instant::now();
        world_points.clear();
        // Optionally one return per `map_voxel` voxel: rays into one map cell from one
        // origin are nearly the same ray.
        let thinned;
        let frame = if config.map_voxel > 0.0 {
            thinned = crate::odometry::thin(odo.last_scan(), config.map_voxel);
            &thinned[..]
        } else {
            odo.last_scan()
        };
        world_points.extend(frame.iter().map(|p| estimate * p));
        let returns = world_points.len();
        // Each miss ends at the LiDAR's range, beyond the map's: the map clears up to its
        // range and marks no hit.
        world_points.extend(odo.last_misses().iter().map(|p| estimate * p));
        let origin =
            estimate * Point3::from(chain.lidar_in_body(motor_state.theta)?.translation.vector);
        if ex.map.bounds().contains(&origin) {
            let update = ex.map.insert_frame(&origin, &world_points)?;
            let delta = ex.frontiers.update(&ex.map, &update);
            if let Some(counter) = counter.as_mut() {
                let h = Vector3::repeat(0.5 * ex.map.grid().resolution());
                let known = |p: &Point3<f64>| ex.map.state(p) != frontier::CellState::Unknown;
                for ch in &update.changed {
                    if ch.before == frontier::CellState::Unknown {
                        let c = ex.map.grid().center(ch.cell);
                        counter.reveal(&(c - h), &(c + h), known);
                    }
                }
            }
            // The cells returns end in (the map counts no hit beyond its range).
            let range2 = config.map.max_range * config.map.max_range;
            let grid = *ex.map.grid();
            let hits = world_points[..returns]
                .iter()
                .filter(|p| (*p - origin).norm_squared() <= range2)
                .filter_map(|p| grid.cell_of(p));
            ex.mission.refresh(
                &ex.frontiers,
                &ex.map,
                Some((&update, &delta)),
                hits,
                ex.region,
            );
        } else {
            ex.mission
                .refresh(&ex.frontiers, &ex.map, None, core::iter::empty(), ex.region);
        }
        log.timings.mapping.push(ms(clock));

        // The tracking controller moves its target by plan − estimate (as in `flight`).
        let plan_now = ex.reference.state(t1)?[0];
        let now = track.offset(t1)[0];
        let shift = plan_now - estimate.translation.vector;
        let shift = shift * (fc.max_correction / shift.norm().max(fc.max_correction));
        track = track.retarget(t1, now + shift);

        // Global planning at its rate, when the trajectory ends, or when it is blocked.
        let clock = Instant::now();
        let due = (k + 1).is_multiple_of(config.replan_frames as u64);
        let blocked = due && ex.blocked(t1)?;
        if t1 >= config.warmup && (due || ex.reference.done(t1)) {
            if ex.reference.done(t1) || blocked {
                ex.target = None;
            }
            if ex.plan(t1, blocked)? {
                log.trajectories += 1;
                log.trajectory_starts.push(t1);
            }
            log.timings.planning.push(ms(clock));
        }
        // Yaw: the rigid-yaw baseline turns toward the target's frontier.
        let yaw_now = ex.reference.yaw(t1);
        ex.reference.yaw0 = yaw_now;
        ex.reference.yaw_t0 = t1;
        if !config.controller.spins()
            && let Some((_, center)) = ex.target
        {
            let d = center.coords - plan_now;
            if d.xy().norm() > 0.3 {
                ex.reference.yaw_goal = yaw_now + wrap(d.y.atan2(d.x) - yaw_now);
            }
        } else {
            ex.reference.yaw_goal = yaw_now;
        }

        // The Fisher table (and iCR's cloud) on its fixed cycle.
        if config.controller.spins() && k.is_multiple_of(config.fisher_frames as u64) {
            let clock = Instant::now();
            let here = Point3::from(estimate.translation.vector);
            // An even subsample keeps the table's cost bounded in large open scenes.
            let cloud = odo.map_sample_within(&here, config.fisher_radius, config.fisher_points);
            match &mut scan {
                Scan::Icr(c) => c.set_cloud(&cloud),
                Scan::Mpc(_) => {
                    fisher = Some(FisherTable::build(
                        &cloud,
                        &estimate,
                        &chain,
                        &sensor,
                        &config.fisher,
                    )?);
                }
                Scan::Fixed(_) => {}
            }
            log.timings.fisher.push(ms(clock));
        }
        // The scan controller on the predicted trajectory.
        let clock = Instant::now();
        reference_poses.clear();
        for i in 0..=config.mpc.horizon {
            #[allow(clippy::cast_precision_loss)]
            let t = t1 + i as f64 * config.mpc.dt;
            let [p, _, a] = ex.reference.state(t)?;
            reference_poses.push(Isometry3::from_parts(
                Translation3::from(p),
                flat_attitude(&a, ex.reference.yaw(t)),
            ));
        }
        let measured = measured_motor(&angles, latency);
        let input = ScanInput {
            motor: measured.unwrap_or(motor_state),
            reference: &reference_poses,
            targets: ex.mission.targets(),
            fisher: fisher.as_ref(),
        };
        let band = match &scan {
            Scan::Fixed(_) => None,
            Scan::Mpc(_) | Scan::Icr(_) => Some(config.mpc.limits),
        };
        command = match band {
            // Spin-up: the optimisers plan from a speed inside their band (they clamp the
            // measured one into it), so the motor is first brought into the band.
            Some(l) if !(l.omega_min()..=l.omega_max()).contains(&input.motor.omega) => {
                let goal = input.motor.omega.clamp(l.omega_min(), l.omega_max());
                l.saturate_acceleration((goal - input.motor.omega) / config.mpc.dt)
            }
            _ => scan.controller().command(&input)?.acceleration,
        };
        log.timings.scan.push(ms(clock));

        if (k + 1).is_multiple_of(config.coverage_frames as u64)
            && let Some(counter) = &counter
        {
            let c = counter.share();
            log.coverage.push((t1, c));
            coverage = Some(c);
        }
        progress(&Progress {
            time: t1,
            coverage,
            targets: ex.last_targets,
        });
        log.exploration_time = t1;
        let p = truth.translation.vector;
        let outside = (0..3).any(|i| p[i] < mission.min[i] - 1.0 || p[i] > mission.max[i] + 1.0);
        if (p - estimate.translation.vector).norm() > config.lost_distance {
            log.aborted = Some("odometry lost");
            break;
        }
        if outside {
            log.aborted = Some("left the scene");
            break;
        }
        let nothing_left = ex
            .stalled_since
            .is_some_and(|s| t1 - s >= config.stall_time);
        if k > 0 && nothing_left && ex.reference.done(t1) {
            log.finished = true;
            break;
        }
    }
    if let Some(e) = mission.explorable
        && log
            .coverage
            .last()
            .is_none_or(|&(t, _)| t < log.exploration_time)
    {
        let c = e.coverage(|p| ex.map.state(p) != frontier::CellState::Unknown);
        log.coverage.push((log.exploration_time, c));
    }
    log.clusters_left = ex.frontiers.clusters().count();
    let grid = *ex.map.grid();
    ex.map.for_each_known(|c, s| {
        if s == frontier::CellState::Occupied {
            log.occupied.push(grid.center(c));
        }
    });
    Ok(log)
}

/// The motor's state now from the encoder's reads over the last frame: a least-squares
/// parabola θ(s) through the reads (unwrapped), its angle and slope at the last read carried
/// on over the read latency. A 12-bit encoder read at 1 kHz moves one count (1.5 mrad) per
/// millisecond at 88 deg/s, so the step between the last two reads gives the speed only in
/// steps of 88 deg/s; a frame's hundred reads give it to within a degree per second. The
/// motor runs each frame under one acceleration command, so a parabola fits it.
fn measured_motor(angles: &[AngleSample], latency: f64) -> Option<MotorState> {
    let last = angles.last()?;
    if angles.len() < 3 {
        return None;
    }
    // Normal equations of θ = c₀ + c₁ x + c₂ x², x = s − s_last, over the unwrapped reads.
    let mut ata = Matrix3::<f64>::zeros();
    let mut atb = Vector3::<f64>::zeros();
    let mut unwrapped = 0.0;
    let mut next = last;
    for a in angles.iter().rev() {
        // Encoders report angles in [0, 2π): the step between two reads is the short way
        // (none for the last read itself; a NaN read makes every later term NaN).
        unwrapped -= wrap(next.angle - a.angle);
        next = a;
        let x = a.time - last.time;
        let row = Vector3::new(1.0, x, x * x);
        ata += row * row.transpose();
        atb += row * unwrapped;
    }
    let c = ata.lu().solve(&atb)?;
    if !c.iter().all(|v| v.is_finite()) {
        return None;
    }
    let omega = c[1] + 2.0 * c[2] * latency;
    let theta = last.angle + c[0] + c[1] * latency + c[2] * latency * latency;
    Some(MotorState::new(theta, omega))
}

fn ms(clock: Instant) -> f64 {
    clock.elapsed().as_secs_f64() * 1e3
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A new trajectory starts at the plan's state exactly; a plan above the limits is kept
    /// unless it must be replaced, and then the optimiser accepts its state as the head.
    #[test]
    fn trajectory_heads_continue_the_plan_exactly() {
        let p = Vector3::new(1.0, 2.0, 3.0);
        let slow = [p, Vector3::new(1.5, 0.0, 0.0), Vector3::new(0.0, 1.0, 0.0)];
        let (head, v, a) = trajectory_head(&slow, 2.0, 2.0, false).unwrap();
        assert_eq!(head, [[1.0, 2.0, 3.0], [1.5, 0.0, 0.0], [0.0, 1.0, 0.0]]);
        assert_eq!((v, a), (2.0, 2.0));
        let fast = [p, Vector3::new(3.0, 0.0, 0.0), Vector3::new(0.0, 2.5, 0.0)];
        assert!(trajectory_head(&fast, 2.0, 2.0, false).is_none());
        let (head, v, a) = trajectory_head(&fast, 2.0, 2.0, true).unwrap();
        assert_eq!(head[1], [3.0, 0.0, 0.0]);
        assert_eq!(head[2], [0.0, 2.5, 0.0]);
        assert_eq!((v, a), (3.0, 2.5));
        let cfg = OptimizerConfig::default().with_limits(v, a);
        let tail = [[8.0, 2.0, 3.0], [0.0; 3], [0.0; 3]];
        let traj = Optimizer::<3, 3>::new(cfg, head, tail, &[[5.0, 2.0, 3.0]])
            .unwrap()
            .optimize()
            .unwrap()
            .trajectory;
        let v0 = traj.velocity(0.0).unwrap();
        assert!((Vector3::from(v0) - fast[1]).norm() < 1e-9, "{v0:?}");
        let a0 = traj.acceleration(0.0).unwrap();
        assert!((Vector3::from(a0) - fast[2]).norm() < 1e-9, "{a0:?}");
    }

    /// The explorer's first trajectory for a UAV in `state` and a path through `inner` to
    /// rest at `goal` (2 m/s and 2 m/s², the 0.1 m corridor), with its head, settings and
    /// acceleration limit.
    fn planned_from(
        state: &[Vector3<f64>; 3],
        inner: &[[f64; 3]],
        goal: [f64; 3],
    ) -> (Trajectory<3>, [[f64; 3]; 3], OptimizerConfig, f64) {
        let (head, v_max, a_max) = trajectory_head(state, 2.0, 2.0, false).unwrap();
        let mut cfg = OptimizerConfig::default().with_limits(v_max, a_max);
        cfg.corridor_radius = Some(0.1);
        cfg.waypoint_weight = 1e4;
        let tail = [goal, [0.0; 3], [0.0; 3]];
        let traj = Optimizer::<3, 3>::new(cfg, head, tail, inner)
            .unwrap()
            .optimize()
            .unwrap()
            .trajectory;
        (traj, head, cfg, a_max)
    }

    /// The plan of the sinkhole's `fixed:100` seed 9 at 302.0 s (its state and path to the
    /// digit): moving at 1 m/s, the UAV's path turned back to a point 0.25 m behind it, the
    /// UAV's own position first. Held to that path, the optimiser pulls 18 m/s²;
    /// `too_steep` refuses it, and the brake stops the UAV within the limits from the same
    /// state, where braking along its velocity ends.
    #[test]
    fn a_path_turning_back_in_front_of_a_moving_uav_is_refused_and_the_brake_is_not() {
        let state = [
            Vector3::new(18.347162250692374, 34.73884320516566, 8.115041844140608),
            Vector3::new(
                0.6103776905725178,
                0.8235842389576553,
                0.0011891469889704076,
            ),
            Vector3::new(
                -0.4022549936747961,
                -1.9572536972645624,
                -0.07927089482665184,
            ),
        ];
        let inner = [
            [18.347162250692374, 34.73884320516566, 8.115041844140608],
            [18.3, 34.5, 8.1],
            [17.700000000000003, 32.900000000000006, 8.1],
            [22.20974252416577, 27.562365473033964, 8.68286254287518],
            [51.300000000000004, 21.300000000000004, 1.1],
            [52.300000000000004, 21.300000000000004, 1.1],
        ];
        let goal = [52.493750000000006, 21.2042362605664, 1.111771432346219];
        let (turn, head, cfg, a_max) = planned_from(&state, &inner, goal);
        assert!(too_steep(&turn, a_max), "{}", turn.max_acceleration(64));
        let stop = brake(cfg, head, a_max).unwrap();
        assert!(!too_steep(&stop, a_max), "{}", stop.max_acceleration(64));
        let at = |t: f64| Vector3::from(stop.position(t).unwrap());
        assert!((at(0.0) - state[0]).norm() < 1e-9);
        assert!((Vector3::from(stop.velocity(0.0).unwrap()) - state[1]).norm() < 1e-9);
        let end = state[0] + state[1] * (state[1].norm() / (2.0 * a_max));
        assert!(
            (at(stop.duration()) - end).norm() < 1e-6,
            "{:?}",
            at(stop.duration())
        );
        assert!(Vector3::from(stop.velocity(stop.duration()).unwrap()).norm() < 1e-9);
        // A gentle plan is not refused.
        let ahead = state[0] + state[1] * 3.0;
        let calm = move_to_rest(cfg, head, [ahead.x, ahead.y, ahead.z]).unwrap();
        assert!(!too_steep(&calm, a_max), "{}", calm.max_acceleration(64));
    }

    /// The plan of the sinkhole's `fixed:30` seed 8 at 185.0 s (its state and path to the
    /// digit): flying at 2 m/s, its path's first point 0.18 m behind the UAV. The optimiser
    /// makes a first piece of about 10 ms with hundreds of m/s³ of jerk while the acceleration
    /// stays near the limit: `too_steep` refuses it for the jerk, and the brake is gentle.
    #[test]
    fn a_first_point_just_behind_a_fast_uav_is_refused_for_its_jerk() {
        let state = [
            Vector3::new(34.65500372291096, 11.429368436906929, 1.0421293478227307),
            Vector3::new(
                -1.9700132473032355,
                0.03747892677817044,
                0.03529762542974024,
            ),
            Vector3::new(
                -0.5837785916770922,
                0.03567755285015384,
                0.013089484604161261,
            ),
        ];
        let inner = [[34.77176882206745, 11.565792634436875, 1.111771432346219]];
        let goal = [34.10719098880726, 11.516620057604724, 1.111771432346219];
        let (turn, head, cfg, a_max) = planned_from(&state, &inner, goal);
        assert!(turn.max_acceleration(64) < ACCEL_SLACK * a_max);
        assert!(
            too_steep(&turn, a_max),
            "{}",
            turn.max_derivative_norm(3, 64)
        );
        let stop = brake(cfg, head, a_max).unwrap();
        assert!(
            !too_steep(&stop, a_max),
            "{}",
            stop.max_derivative_norm(3, 64)
        );
    }

    use crate::scene::Scene;

    #[test]
    fn controller_names_round_trip_and_bad_ones_are_errors() {
        for name in [
            "fu-mpc",
            "fixed:30",
            "fixed:100",
            "fixed:360",
            "uncertainty",
            "frontier",
            "icr",
            "rigid-yaw",
        ] {
            let kind: ControllerKind = name.parse().unwrap();
            assert_eq!(kind.to_string(), name);
        }
        assert!(!ControllerKind::RigidYaw.spins());
        assert!(ControllerKind::Fixed(0.0).spins());
        for bad in [
            "",
            "fixed",
            "fixed:",
            "fixed:-5",
            "fixed:nan",
            "fixed:inf",
            "mpc",
        ] {
            assert!(
                matches!(
                    bad.parse::<ControllerKind>(),
                    Err(ExploreError::UnknownController(_))
                ),
                "{bad}"
            );
        }
    }

    #[test]
    fn the_band_sets_the_optimisers_speed_limits_and_rejects_bad_bounds() {
        let base = ExplorerConfig::default();
        let deg = |r: f64| r.to_degrees();
        assert!((deg(base.mpc.limits.omega_min()) - 30.0).abs() < 1e-12);
        assert!((deg(base.mpc.limits.omega_max()) - 180.0).abs() < 1e-12);
        let c = base.clone().with_band(90.0, 270.0).unwrap();
        assert!((deg(c.mpc.limits.omega_min()) - 90.0).abs() < 1e-12);
        assert!((deg(c.mpc.limits.omega_max()) - 270.0).abs() < 1e-12);
        assert_eq!(c.mpc.limits.u_max(), base.mpc.limits.u_max());
        // Everything else is untouched.
        assert_eq!(ExplorerConfig { mpc: base.mpc, ..c }, base);
        // Both directions, the motor's whole range and a single speed are bands too.
        assert!(base.clone().with_band(-180.0, 180.0).is_ok());
        assert!(base.clone().with_band(-360.0, 360.0).is_ok());
        assert!(base.clone().with_band(120.0, 120.0).is_ok());
        for (lo, hi) in [
            (f64::NAN, 180.0),
            (30.0, f64::INFINITY),
            (180.0, 90.0),
            (30.0, 400.0),
            (-400.0, 0.0),
        ] {
            assert!(
                matches!(
                    base.clone().with_band(lo, hi),
                    Err(ExploreError::InvalidConfig { what: "band", .. })
                ),
                "{lo} {hi}"
            );
        }
    }

    #[test]
    fn bad_settings_and_starts_are_typed_errors() {
        let scene = Scene::small(1);
        let world = scene.world().unwrap();
        let mission = Mission {
            world: &world,
            min: scene.min,
            max: scene.max,
            start: scene.start,
            explorable: None,
        };
        for bad in [
            ExplorerConfig {
                max_time: f64::NAN,
                ..ExplorerConfig::default()
            },
            ExplorerConfig {
                v_max: 0.0,
                ..ExplorerConfig::default()
            },
            ExplorerConfig {
                replan_frames: 0,
                ..ExplorerConfig::default()
            },
            ExplorerConfig {
                max_clusters: 0,
                ..ExplorerConfig::default()
            },
            ExplorerConfig {
                controller: ControllerKind::Fixed(-1.0),
                ..ExplorerConfig::default()
            },
            ExplorerConfig {
                map_voxel: -0.1,
                ..ExplorerConfig::default()
            },
            ExplorerConfig {
                map_voxel: f64::NAN,
                ..ExplorerConfig::default()
            },
            // The Mid-360's 40 m do not reach beyond a 50 m map range: a miss would be a hit.
            ExplorerConfig {
                clear_on_no_return: true,
                map: MapConfig {
                    max_range: 50.0,
                    ..MapConfig::default()
                },
                ..ExplorerConfig::default()
            },
        ] {
            assert!(matches!(
                explore(&mission, &bad, 1, |_| {}),
                Err(ExploreError::InvalidConfig { .. })
            ));
        }
        let config = ExplorerConfig::default();
        for start in [
            Point3::new(-5.0, 1.0, 1.0),
            Point3::new(6.0, 0.5, 1.0), // inside the dividing wall
        ] {
            let m = Mission { start, ..mission };
            assert!(matches!(
                explore(&m, &config, 1, |_| {}),
                Err(ExploreError::BadStart(_))
            ));
        }
        // A bad map resolution is the frontier crate's typed error.
        let mut bad_map = ExplorerConfig::default();
        bad_map.map.resolution = -0.2;
        assert!(matches!(
            explore(&mission, &bad_map, 1, |_| {}),
            Err(ExploreError::Frontier(_))
        ));
    }

    #[test]
    fn a_short_run_stops_at_its_budget_with_a_consistent_log() {
        let scene = Scene::small(2);
        let world = scene.world().unwrap();
        let explorable = scene.explorable(0.2);
        let mission = Mission {
            world: &world,
            min: scene.min,
            max: scene.max,
            start: scene.start,
            explorable: Some(&explorable),
        };
        let config = ExplorerConfig {
            controller: ControllerKind::RigidYaw,
            max_time: 4.0,
            ..ExplorerConfig::default()
        };
        let mut calls = 0;
        let log = explore(&mission, &config, 3, |_| calls += 1).unwrap();
        assert!(!log.finished);
        assert_eq!(log.aborted, None);
        assert_eq!(log.times.len(), 40);
        assert_eq!(calls, 40);
        assert_eq!(log.truth.len(), log.estimate.len());
        assert_eq!(log.motor_speed.len(), 40);
        // The rigid LiDAR does not turn.
        assert!(log.motor_speed.iter().all(|w| w.abs() < 1e-9));
        // Coverage once a second, plus none extra at the end (4 s is a whole second).
        assert_eq!(log.coverage.len(), 4);
        assert!(log.coverage.iter().all(|&(_, c)| (0.0..=1.0).contains(&c)));
        assert!(!log.occupied.is_empty());
        // The UAV hovered through the warm-up: no trajectory before 2 s.
        assert!(log.trajectory_starts.iter().all(|&t| t >= config.warmup));
    }

    /// A wall whose surface runs through a column of cells (x = 5.05, inside the cells
    /// [5.0, 5.2]), seen once head-on and then by beams grazing its free part: with the
    /// explorer's map the surface cells stay occupied; with the map's own default the grazing
    /// beams clear them, and the cells in front of the unseen inside of the wall become
    /// frontier that no viewpoint can clear.
    #[test]
    fn grazing_beams_leave_a_surface_seen_head_on_occupied() {
        let frontier_on_the_wall = |config: MapConfig| {
            let bounds =
                Bounds::new(Point3::new(0.0, 0.0, 0.0), Point3::new(10.0, 10.0, 3.0)).unwrap();
            let mut map = VoxelMap::new(bounds, config).unwrap();
            let (ys, zs) = ((20..80).map(|i| 0.1 * f64::from(i)), [1.3, 1.5, 1.7]);
            let head_on: Vec<Point3<f64>> = ys
                .clone()
                .flat_map(|y| zs.map(|z| Point3::new(5.05, y, z)))
                .collect();
            map.insert_frame(&Point3::new(2.0, 5.0, 1.5), &head_on)
                .unwrap();
            // Beams along the wall, 2 cm in front of it, out of the bounds (no hit).
            for _ in 0..3 {
                for z in zs {
                    let origin = Point3::new(5.03, 0.5, z);
                    map.insert_frame(&origin, &[Point3::new(5.03, 12.0, z)])
                        .unwrap();
                }
            }
            let surface: Vec<frontier::Cell> = ys
                .flat_map(|y| zs.map(move |z| Point3::new(5.1, y, z)))
                .map(|p| map.grid().cell_of(&p).unwrap())
                .collect();
            let occupied = surface
                .iter()
                .filter(|c| map.cell_state(**c) == frontier::CellState::Occupied)
                .count();
            let frontier = surface
                .iter()
                .filter(|c| Frontiers::is_frontier_in(&map, **c))
                .count();
            (surface.len(), occupied, frontier)
        };
        let (n, occupied, frontier) = frontier_on_the_wall(ExplorerConfig::default().map);
        assert_eq!((occupied, frontier), (n, 0));
        let (n, occupied, frontier) = frontier_on_the_wall(MapConfig::default());
        assert_eq!((occupied, frontier), (0, n));
    }

    /// Where beams from `o` end: `azimuths × elevations` directions (elevations from index
    /// `first` on, −90° up), each marched in 5 cm steps to its last point inside `bounds`, to
    /// the first point `stop` accepts, or to `max_length`.
    fn beam_ends(
        o: &Point3<f64>,
        bounds: &Bounds,
        [azimuths, elevations]: [u32; 2],
        first: u32,
        max_length: f64,
        stop: impl Fn(&Point3<f64>) -> bool,
    ) -> Vec<Point3<f64>> {
        let mut ends = Vec::new();
        for i in 0..azimuths {
            for j in first..elevations {
                let az = f64::from(i) / f64::from(azimuths) * core::f64::consts::TAU;
                let el = (f64::from(j) / f64::from(elevations) - 0.5) * core::f64::consts::PI;
                let d = Vector3::new(el.cos() * az.cos(), el.cos() * az.sin(), el.sin());
                let mut t = 0.0;
                let mut end = *o;
                while t < max_length {
                    let p = o + d * t;
                    if !bounds.contains(&p) {
                        break;
                    }
                    end = p;
                    if stop(&p) {
                        break;
                    }
                    t += 0.05;
                }
                ends.push(end);
            }
        }
        ends
    }

    /// A fully known 10 × 6 × 3 m box with a wall across x = 5 leaving a gap at y > 4.
    fn walled_map() -> VoxelMap {
        let bounds = Bounds::new(Point3::new(0.0, 0.0, 0.0), Point3::new(10.0, 6.0, 3.0)).unwrap();
        let mut map = VoxelMap::new(bounds, MapConfig::default()).unwrap();
        let wall = |p: &Point3<f64>| (p.x - 5.0).abs() < 0.15 && p.y < 4.0;
        for o in [Point3::new(2.0, 3.0, 1.5), Point3::new(8.0, 3.0, 1.5)] {
            let hits = beam_ends(&o, &bounds, [200, 100], 0, 12.0, wall);
            map.insert_frame(&o, &hits).unwrap();
        }
        map
    }

    /// Targets past the nearest batch: in a 24 m hall seen only within 2.5 m of two points
    /// 17 m apart, with the targets of the clusters near the UAV given up, the planner takes
    /// the far ones instead of none; with every target given up it has none.
    #[test]
    fn given_up_near_targets_pass_planning_to_the_farther_clusters() {
        let bounds = Bounds::new(Point3::new(0.0, 0.0, 0.0), Point3::new(24.0, 6.0, 3.0)).unwrap();
        let config = MapConfig {
            max_range: 2.5,
            ..ExplorerConfig::default().map
        };
        let mut map = VoxelMap::new(bounds, config).unwrap();
        let mut frontiers = Frontiers::new(FrontierConfig::default()).unwrap();
        let (near, far) = (Point3::new(3.0, 3.0, 1.5), Point3::new(20.0, 3.0, 1.5));
        for o in [near, far] {
            // Beams to the hall's faces; the map keeps the first 2.5 m of each.
            let hits = beam_ends(&o, &bounds, [120, 60], 1, f64::INFINITY, |_| false);
            let update = map.insert_frame(&o, &hits).unwrap();
            frontiers.update(&map, &update);
        }
        let clusters: Vec<&frontier::Cluster> = frontiers.clusters().collect();
        let viewpoints = ExplorerConfig::default().viewpoints;
        let by_centre = |c: &frontier::Cluster, p: &Point3<f64>| (c.center() - p).norm() < 5.0;
        assert!(clusters.iter().any(|c| by_centre(c, &near)));
        assert!(clusters.iter().any(|c| by_centre(c, &far)));
        // Every target any single cluster gives, near ones and all.
        let mut near_views = Vec::new();
        let mut all_views = Vec::new();
        for c in &clusters {
            let one = open_targets(&map, vec![*c], &near, 1, &viewpoints, &[]).unwrap();
            all_views.extend(one.iter().map(|t| t.viewpoint));
            if by_centre(c, &near) {
                near_views.extend(one.iter().map(|t| t.viewpoint));
            }
        }
        assert!(!near_views.is_empty());
        // One cluster per batch: the nearest ones' targets are all given up, so the first
        // batch that has any lies at the far point.
        let targets =
            open_targets(&map, clusters.clone(), &near, 1, &viewpoints, &near_views).unwrap();
        assert!(!targets.is_empty());
        assert!(targets.iter().all(|t| (t.center - far).norm() < 5.0));
        // The nearest cluster alone (the old cut) had nothing left to plan.
        let nearest = clusters
            .iter()
            .copied()
            .min_by(|a, b| {
                let d = |c: &frontier::Cluster| (c.center() - near).norm_squared();
                d(a).total_cmp(&d(b)).then(a.id().cmp(&b.id()))
            })
            .unwrap();
        let cut = open_targets(&map, vec![nearest], &near, 1, &viewpoints, &near_views).unwrap();
        assert!(cut.is_empty());
        // Every cluster's targets given up: nothing.
        let none = open_targets(&map, clusters, &near, 1, &viewpoints, &all_views).unwrap();
        assert!(none.is_empty());
    }

    /// Graph edges narrowed below a clearance leave the graph, wider ones and edges of
    /// temporary nodes stay.
    #[test]
    fn narrowed_edges_leave_the_graph() {
        let map = walled_map();
        let free = |_: &[f64; 3], _: &[f64; 3]| true;
        let mut graph = TopoGraph::new();
        // Through the gap beside the wall's end (y = 4): 0.3 m from it at y = 4.3, 1.2 m
        // at y = 5.2 (0.8 m from the box's face at y = 6).
        let nodes: Vec<NodeId> = [
            [4.0, 4.3, 1.5],
            [6.0, 4.3, 1.5],
            [4.0, 5.2, 1.5],
            [6.0, 5.2, 1.5],
        ]
        .into_iter()
        .map(|p| graph.add_node(p, 10.0, &free).unwrap())
        .collect();
        let uav = graph
            .add_temporary_node([5.0, 4.3, 1.5], 10.0, &free)
            .unwrap();
        let joined = |g: &TopoGraph, a: NodeId, b: NodeId| {
            g.neighbors(a).unwrap().iter().any(|&(n, _)| n == b)
        };
        let near = [uav, nodes[0], nodes[1]];
        assert_eq!(
            remove_narrow_edges(&mut graph, &map, &near, uav, 0.4).unwrap(),
            1
        );
        assert!(!joined(&graph, nodes[0], nodes[1]) && !joined(&graph, nodes[1], nodes[0]));
        // The temporary node's edge is not judged, though it is as narrow.
        assert!(joined(&graph, uav, nodes[0]));
        let wide = [nodes[2], nodes[3]];
        assert_eq!(
            remove_narrow_edges(&mut graph, &map, &wide, uav, 0.4).unwrap(),
            0
        );
        assert!(joined(&graph, nodes[2], nodes[3]));
        // A tighter clearance keeps what it passes; an edge already gone is not counted.
        assert_eq!(
            remove_narrow_edges(&mut graph, &map, &near, uav, 0.2).unwrap(),
            0
        );
        assert_eq!(
            remove_narrow_edges(&mut graph, &map, &near, uav, 0.4).unwrap(),
            0
        );
    }

    #[test]
    fn grid_paths_go_round_walls_and_keep_their_clearance() {
        let map = walled_map();
        let (a, b) = (Point3::new(2.0, 2.0, 1.5), Point3::new(8.0, 2.0, 1.5));
        assert!(!segment_free(&map, &a, &b, 0.5, 0.0));
        let path = grid_path(&map, &a, &b, 0.5, 200_000).unwrap();
        assert_eq!(path.first(), Some(&a));
        assert_eq!(path.last(), Some(&b));
        // The path goes through the gap, and every leg is free with the clearance.
        assert!(path.iter().any(|p| p.y > 4.0));
        for w in path.windows(2) {
            assert!(segment_free(&map, &w[0], &w[1], 0.5, 0.0), "{w:?}");
        }
        // No path when the gap is too narrow for the clearance.
        assert!(grid_path(&map, &a, &b, 1.2, 200_000).is_none());
        // Of two goals, the nearer by path is reached, not the nearer in a straight line
        // (behind the wall).
        let from = Point3::new(3.0, 1.5, 1.5);
        let behind = Point3::new(5.9, 1.5, 1.5);
        let open = Point3::new(0.9, 3.6, 1.5);
        assert!((behind - from).norm() < (open - from).norm());
        let (path, k) = grid_path_to_nearest(&map, &from, &[behind, open], 0.5, 200_000).unwrap();
        assert_eq!(k, 1);
        assert_eq!(path.first(), Some(&from));
        assert_eq!(path.last(), Some(&open));
        let (path, k) = grid_path_to_nearest(&map, &from, &[behind], 0.5, 200_000).unwrap();
        assert_eq!((k, path.last()), (0, Some(&behind)));
        assert!(path.iter().any(|p| p.y > 4.0));
        for w in path.windows(2) {
            assert!(segment_free(&map, &w[0], &w[1], 0.5, 0.0), "{w:?}");
        }
        assert!(grid_path_to_nearest(&map, &from, &[behind], 1.2, 200_000).is_none());
        // A UAV pushed to 0.2 m from the wall (no neighbouring cell has 0.5 m) still leaves:
        // near it the path keeps the clearance it has, farther on the full clearance.
        let c = Point3::new(4.61, 2.0, 1.5);
        let near = map.clearance(&c, 0.5);
        assert!(near < 0.25, "{near}");
        let path = grid_path(&map, &c, &b, 0.5, 200_000).unwrap();
        assert_eq!(path.last(), Some(&b));
        for p in &path[1..] {
            let need = if (p - c).norm() <= ESCAPE_RADIUS {
                near
            } else {
                0.5
            };
            assert!(map.clearance(p, 0.5) >= need - 1e-9, "{p:?}");
        }
        for w in path.windows(2) {
            assert!(map.line_of_sight(&w[0], &w[1]), "{w:?}");
        }
    }

    #[test]
    fn the_squeeze_search_tries_the_nearest_goals_first() {
        let map = walled_map();
        let from = Point3::new(2.0, 2.0, 1.5);
        // Behind the wall (a long way round), then two in the open, the second nearer.
        let behind = Point3::new(8.0, 2.0, 1.5);
        let open = Point3::new(1.0, 3.5, 1.5);
        let nearer = Point3::new(2.5, 3.0, 1.5);
        let goals = [behind, open, nearer];
        let (k, path) = nearest_grid_path(&map, &from, &goals, 0.5, 1, 200_000).unwrap();
        assert_eq!(k, 2);
        assert_eq!(path.last(), Some(&nearer));
        // The goal behind the wall alone: found with a budget that covers the way round, not
        // with one that does not, and not when it is beyond the number of tries.
        let (k, _) = nearest_grid_path(&map, &from, &[behind], 0.5, 1, 200_000).unwrap();
        assert_eq!(k, 0);
        assert!(nearest_grid_path(&map, &from, &[behind], 0.5, 1, 50).is_none());
        assert!(nearest_grid_path(&map, &from, &[open, behind], 0.5, 0, 200_000).is_none());
        assert!(nearest_grid_path(&map, &from, &[], 0.5, 4, 200_000).is_none());
    }

    #[test]
    fn trail_paths_go_back_the_way_the_uav_came() {
        let map = walled_map();
        let from = Point3::new(2.0, 2.0, 1.5);
        let goal = Point3::new(8.5, 1.5, 1.5);
        let check = |path: &[Point3<f64>]| {
            assert_eq!(path.first(), Some(&from));
            assert_eq!(path.last(), Some(&goal));
            assert!(path.iter().any(|p| p.y > 4.0), "{path:?}");
            for w in path.windows(2) {
                assert!(segment_free(&map, &w[0], &w[1], 0.5, 0.0), "{w:?}");
            }
        };
        // Came from behind the wall through the gap; a second goal farther from the trail.
        let trail = [
            Point3::new(8.0, 2.0, 1.5),
            Point3::new(7.0, 5.0, 1.5),
            Point3::new(5.0, 5.0, 1.5),
            Point3::new(3.0, 5.0, 1.5),
            Point3::new(2.0, 2.5, 1.5),
        ];
        let far = Point3::new(9.0, 0.8, 1.5);
        let (k, path) = trail_path(&map, &trail, &from, &[far, goal], 0.5).unwrap();
        assert_eq!(k, 1);
        check(&path);
        // A trail leg through the wall (the map grew since) is replaced by a grid path.
        let (k, path) = trail_path(&map, &trail[..1], &from, &[goal], 0.5).unwrap();
        assert_eq!(k, 0);
        check(&path);
        assert!(trail_path(&map, &[], &from, &[goal], 0.5).is_none());
        assert!(trail_path(&map, &trail, &from, &[], 0.5).is_none());
    }

    #[test]
    fn lattice_paths_go_round_walls_and_reach_farther_per_expansion() {
        let map = walled_map();
        let (a, b) = (Point3::new(2.0, 2.0, 1.5), Point3::new(8.0, 2.0, 1.5));
        let check = |path: &[Point3<f64>], from: &Point3<f64>, to: &Point3<f64>, near: f64| {
            assert_eq!(path.first(), Some(from));
            assert_eq!(path.last(), Some(to));
            assert!(path.iter().any(|p| p.y > 4.0), "{path:?}");
            for (k, w) in path.windows(2).enumerate() {
                let relaxed = if k == 0 { near } else { 0.0 };
                assert!(segment_free(&map, &w[0], &w[1], 0.5, relaxed), "{w:?}");
            }
        };
        let (k, path) = lattice_path(&map, &a, &[b], 0.5, 100_000).unwrap();
        assert_eq!(k, 0);
        check(&path, &a, &b, 0.0);
        // A budget the lattice needs is far too small for the cell search.
        let budget = 60;
        assert!(lattice_path(&map, &a, &[b], 0.5, budget).is_some());
        assert!(grid_path(&map, &a, &b, 0.5, budget).is_none());
        assert!(grid_path(&map, &a, &b, 0.5, 100 * budget).is_some());
        // Of two goals, the nearer by path (not in a straight line) is reached.
        let from = Point3::new(3.0, 1.5, 1.5);
        let behind = Point3::new(5.9, 1.5, 1.5);
        let open = Point3::new(0.9, 3.6, 1.5);
        let (k, _) = lattice_path(&map, &from, &[behind, open], 0.5, 100_000).unwrap();
        assert_eq!(k, 1);
        // A UAV pushed to 0.2 m from the wall leaves by a first move that keeps less.
        let c = Point3::new(4.61, 2.0, 1.5);
        assert!(map.clearance(&c, 0.5) < 0.25);
        let (_, path) = lattice_path(&map, &c, &[b], 0.5, 100_000).unwrap();
        check(&path, &c, &b, ESCAPE_RADIUS);
        // No way through a gap too narrow, to no goal, from or to a point that is not finite.
        assert!(lattice_path(&map, &a, &[b], 1.2, 100_000).is_none());
        assert!(lattice_path(&map, &a, &[], 0.5, 100_000).is_none());
        let nan = Point3::new(f64::NAN, 2.0, 1.5);
        assert!(lattice_path(&map, &nan, &[b], 0.5, 100_000).is_none());
        assert!(lattice_path(&map, &a, &[nan], 0.5, 100_000).is_none());
    }

    #[test]
    fn bridges_join_a_target_behind_a_wall_through_the_nearest_reached_node() {
        let map = walled_map();
        let uav = [1.0, 1.0, 1.5];
        let node = Point3::new(3.0, 3.0, 1.5);
        let corner = Point3::new(0.8, 0.8, 1.5);
        let reached = vec![
            (corner, vec![uav, arr(&corner)]),
            (node, vec![uav, arr(&node)]),
        ];
        let to = Point3::new(8.0, 2.0, 1.5);
        let Bridge {
            positions,
            grid: path,
        } = bridge_path(&map, &reached, &to, 0.5).unwrap();
        // From the UAV along the node's graph path, then through the gap to the target.
        assert_eq!(positions.first(), Some(&uav));
        assert_eq!(positions[1], arr(&node));
        assert_eq!(positions.last(), Some(&arr(&to)));
        assert_eq!((path.first(), path.last()), (Some(&to), Some(&node)));
        assert!(path.iter().any(|p| p.y > 4.0));
        for w in positions.windows(2) {
            let (a, b) = (Point3::from(w[0]), Point3::from(w[1]));
            assert!(segment_free(&map, &a, &b, 0.5, 0.0), "{w:?}");
        }
        // Without nodes, or with a clearance the gap cannot give, there is no bridge.
        assert!(bridge_path(&map, &[], &to, 0.5).is_none());
        assert!(bridge_path(&map, &reached, &to, 1.2).is_none());
    }

    /// Reads of the default encoder (12 bits, 1 ms late) over one frame of a motor under one
    /// acceleration command, the way the explorer takes them: the fitted speed is within a
    /// degree per second, where the last two reads alone are off by tens.
    #[test]
    fn motor_speed_comes_from_the_whole_frame_of_reads() {
        let config = crate::flight::FlightConfig::default().encoder;
        let latency = config.latency();
        let motor = MotorModel::new(MotorLimits::default());
        let deg = std::f64::consts::PI / 180.0;
        for (w0, u, theta0) in [
            (100.0, 0.0, 1.0),
            (47.0, 300.0, 6.2),
            (170.0, -250.0, 0.3),
            (-60.0, 100.0, 0.05),
        ] {
            let mut encoder = Encoder::new(config);
            let mut state = MotorState::new(theta0, w0 * deg);
            let mut angles = Vec::new();
            for j in 1..=100u32 {
                let t = f64::from(j) / 1000.0;
                state = motor.step(state, u * deg, 1e-3).unwrap();
                encoder.record(t, state.theta).unwrap();
                if t - latency > 0.0 {
                    let r = encoder.read(t).unwrap();
                    angles.push(AngleSample::new(t - latency, r.angle));
                }
            }
            let m = measured_motor(&angles, latency).unwrap();
            let err = (m.omega - state.omega) / deg;
            assert!(err.abs() < 1.0, "{w0} {u}: {err} deg/s");
            let dtheta = wrap(m.theta - state.theta);
            assert!(dtheta.abs() < 2e-3, "{w0} {u}: {dtheta} rad");
            // The step between the last two reads, as the speed was measured before.
            let [.., a, b] = &angles[..] else { panic!() };
            let two = wrap(b.angle - a.angle) / (b.time - a.time);
            if (47.0..=170.0).contains(&w0) {
                assert!(((two - state.omega) / deg).abs() > 10.0, "{w0}: {two}");
            }
        }
        assert!(measured_motor(&[], latency).is_none());
        let two = [AngleSample::new(0.0, 0.0), AngleSample::new(0.001, 0.01)];
        assert!(measured_motor(&two, latency).is_none());
        let same_time = [AngleSample::new(0.0, 0.0); 5];
        assert!(measured_motor(&same_time, latency).is_none());
        let mut nan = [0.0, 0.001, 0.002, 0.003].map(|t| AngleSample::new(t, 10.0 * t));
        nan[2].angle = f64::NAN;
        assert!(measured_motor(&nan, latency).is_none());
        nan[2] = AngleSample::new(f64::INFINITY, 0.02);
        assert!(measured_motor(&nan, latency).is_none());
    }

    #[test]
    fn a_forced_replan_flies_the_move_that_keeps_the_most_room() {
        let map = walled_map();
        let radius = 0.25;
        // 0.12 m above the floor cells' tops: closer than the UAV's radius.
        let here = Point3::new(2.0, 3.0, 0.32);
        let start = map.clearance(&here, 1.0);
        assert!(start < radius, "{start}");
        let cfg = OptimizerConfig::default().with_limits(2.0, 2.0);
        let rest = [arr(&here), [0.0; 3], [0.0; 3]];
        let to = |p: Point3<f64>| {
            Optimizer::<3, 3>::new(cfg, rest, [arr(&p), [0.0; 3], [0.0; 3]], &[])
                .unwrap()
                .optimize()
                .unwrap()
                .trajectory
        };
        let end = |t: &Trajectory<3>| Point3::from(t.position(t.duration()).unwrap());
        let cap = 2.0 * (radius + SAFETY_MARGIN);
        // Planned trajectories that sink toward the floor: the move straight up wins.
        let low = to(Point3::new(4.0, 3.0, 0.25));
        assert!(least_clearance(&map, &low, cap).unwrap() < start - 0.05);
        let chosen = safest(&map, radius, &here, rest, cfg, low.clone(), low.clone()).unwrap();
        assert!((end(&chosen) - Point3::new(2.0, 3.0, 1.32)).norm() < 1e-6);
        let least = least_clearance(&map, &chosen, cap).unwrap();
        assert!((least - start).abs() < 1e-9, "{least} {start}");
        // A planned trajectory that never comes closer than the start is kept (the first of
        // equals).
        let up = to(Point3::new(3.0, 3.0, 1.5));
        let chosen = safest(&map, radius, &here, rest, cfg, up, low).unwrap();
        assert!((end(&chosen) - Point3::new(3.0, 3.0, 1.5)).norm() < 1e-6);
    }

    /// A UAV at rest flies the path leg by leg, straight and stopping at its points, with
    /// the full clearance; not when moving, starting too close to a wall, or when any leg,
    /// however far along, passes one.
    #[test]
    fn a_path_is_flown_leg_by_leg_from_rest_with_the_full_clearance() {
        let map = walled_map();
        let radius = 0.25;
        let cfg = OptimizerConfig::default().with_limits(2.0, 2.0);
        let here = Point3::new(2.0, 3.0, 1.5);
        let rest = [arr(&here), [0.0; 3], [0.0; 3]];
        // Round the end of the wall at x = 5 (y < 4); the point 0.2 m on is passed over.
        let corner = Point3::new(5.0, 4.6, 1.5);
        let goal = Point3::new(8.0, 3.0, 1.5);
        let path = [arr(&here), [2.2, 3.0, 1.5], arr(&corner), arr(&goal)];
        let legs = path_legs(&map, radius, &here, true, &path, rest, cfg)
            .unwrap()
            .unwrap();
        assert_eq!(legs.piece_count(), 2);
        let stop = legs.durations()[0];
        let at = |t: f64| Point3::from(legs.position(t).unwrap());
        assert!((at(stop) - corner).norm() < 1e-6, "{}", at(stop));
        assert!((at(legs.duration()) - goal).norm() < 1e-6);
        assert!(Vector3::from(legs.velocity(stop).unwrap()).norm() < 1e-9);
        // Each leg on its straight line, with the clearance all along.
        let mut s = 0.0;
        while s <= legs.duration() {
            let p = at(s);
            let (a, b) = if s < stop {
                (here, corner)
            } else {
                (corner, goal)
            };
            let dir = (b - a).normalize();
            let off = (p - a) - dir * (p - a).dot(&dir);
            assert!(off.norm() < 1e-6, "{s}: {}", off.norm());
            assert!(map.is_clear(&p, radius + SAFETY_MARGIN), "{s}: {p}");
            s += 0.01;
        }
        let none = |from: &Point3<f64>, moving: bool, path: &[[f64; 3]]| {
            let v = if moving { [0.0, 1.0, 0.0] } else { [0.0; 3] };
            let head = [arr(from), v, [0.0; 3]];
            path_legs(&map, radius, from, !moving, path, head, cfg)
                .unwrap()
                .is_none()
        };
        assert!(!none(&here, false, &path));
        // Moving: a piece from there is no straight line.
        assert!(none(&here, true, &path));
        // The last leg goes through the wall: not even the first is flown.
        assert!(none(
            &here,
            false,
            &[arr(&here), arr(&corner), [5.0, 2.0, 1.5]]
        ));
        // From 0.12 m above the floor's cells.
        let low = Point3::new(2.0, 3.0, 0.32);
        assert!(none(&low, false, &[arr(&low), [2.0, 3.0, 1.5]]));
        // A short path is flown to its end.
        let short = [arr(&here), [2.3, 3.0, 1.5]];
        let legs = path_legs(&map, radius, &here, true, &short, rest, cfg)
            .unwrap()
            .unwrap();
        assert!(
            (Point3::from(legs.position(legs.duration()).unwrap()) - Point3::new(2.3, 3.0, 1.5))
                .norm()
                < 1e-6
        );
    }

    /// A point passed over (nearer than `LEG_MIN`) is stopped at when the leg past it would
    /// cut a corner the path itself goes round.
    #[test]
    fn a_leg_that_would_cut_a_corner_stops_at_the_point_passed_over() {
        let map = walled_map();
        let radius = 0.25;
        let margin = radius + SAFETY_MARGIN - STEP_SLACK;
        let cfg = OptimizerConfig::default().with_limits(2.0, 2.0);
        // Below the end of the wall at x = 5 (y < 4), then up 0.4 m, then along past it.
        let here = Point3::new(4.3, 4.2, 1.5);
        let up = Point3::new(4.3, 4.6, 1.5);
        let goal = Point3::new(8.0, 4.6, 1.5);
        assert!((up - here).norm() < LEG_MIN);
        let rest = |p: &Point3<f64>| [arr(p), [0.0; 3], [0.0; 3]];
        let leg = |a: &Point3<f64>, b: &Point3<f64>| {
            let l = move_to_rest(cfg, rest(a), arr(b)).unwrap();
            least_clearance(&map, &l, margin).unwrap()
        };
        // The straight leg cuts the wall's end; the path's own two keep the margin.
        assert!(leg(&here, &goal) < margin, "{}", leg(&here, &goal));
        assert!(leg(&here, &up) >= margin && leg(&up, &goal) >= margin);
        let path = [arr(&here), arr(&up), arr(&goal)];
        let legs = path_legs(&map, radius, &here, true, &path, rest(&here), cfg)
            .unwrap()
            .unwrap();
        assert_eq!(legs.piece_count(), 2);
        let at = |t: f64| Point3::from(legs.position(t).unwrap());
        assert!((at(legs.durations()[0]) - up).norm() < 1e-6);
        assert!((at(legs.duration()) - goal).norm() < 1e-6);
        assert!(least_clearance(&map, &legs, margin).unwrap() >= margin);
        // With no point to stop at, no legs.
        let straight = [arr(&here), arr(&goal)];
        assert!(
            path_legs(&map, radius, &here, true, &straight, rest(&here), cfg)
                .unwrap()
                .is_none()
        );
    }

    #[test]
    fn densified_paths_keep_their_points_and_the_spacing() {
        let path = [
            [0.0, 0.0, 1.0],
            [3.5, 0.0, 1.0],
            [3.5, 0.2, 1.0],
            [3.5, 2.2, 3.0],
        ];
        let dense = densify(&path, 1.0);
        // 4 pieces, 1 piece and 3 pieces, then the end.
        assert_eq!(dense.len(), 9);
        for p in &path {
            assert!(dense.contains(p), "{p:?}");
        }
        assert_eq!((dense.first(), dense.last()), (path.first(), path.last()));
        for w in dense.windows(2) {
            let d = (Point3::from(w[1]) - Point3::from(w[0])).norm();
            assert!(d > 0.0 && d <= 1.0 + 1e-12, "{w:?}");
        }
        assert_eq!(densify(&path[..1], 1.0), path[..1].to_vec());
        assert!(densify(&[], 1.0).is_empty());
    }

    #[test]
    fn a_uav_that_stays_in_place_is_stuck_and_one_that_moves_is_not() {
        let mut h = Headway::default();
        for i in 0..200 {
            let t = f64::from(i) * 0.5;
            assert!(!h.stuck(&Point3::new(t, 0.0, 1.0), t), "{t}");
        }
        // Swaying 1.5 m either way about one place, and 0.6 m up and down: stuck once more
        // than STUCK_TIME has passed (from one end of the sway, the other is 3.1 m away).
        let mut h = Headway::default();
        let at = Point3::new(5.0, 5.0, 1.0);
        for i in 0..=80 {
            let t = f64::from(i) * 0.5;
            let p = at + Vector3::new(1.5 * t.sin(), 0.0, 0.3 * (0.7 * t).cos());
            assert_eq!(h.stuck(&p, t), t > STUCK_TIME, "{t}");
        }
        // A restart starts the clock again.
        h.restart(&at, 40.0);
        assert!(!h.stuck(&at, 40.0 + STUCK_TIME));
        assert!(h.stuck(&at, 40.5 + STUCK_TIME));
        // So does a position that no longer fits the box.
        let near = at + Vector3::new(0.9 * STUCK_SPAN, 0.0, 0.0);
        assert!(h.stuck(&near, 80.0));
        let away = at + Vector3::new(STUCK_SPAN + 0.1, 0.0, 0.0);
        assert!(!h.stuck(&away, 81.0));
        assert!(!h.stuck(&away, 81.0 + STUCK_TIME));
        assert!(h.stuck(&away, 81.5 + STUCK_TIME));
    }

    #[test]
    fn a_uav_that_turns_back_and_forth_and_sees_nothing_new_is_idle() {
        // Back and forth between two places 5.2 m apart (wider than the stuck box), the map
        // gaining twenty cells a second: idle once more than IDLE_TIME has passed, and again
        // IDLE_TIME after that.
        let (a, b) = (Point3::new(46.5, 5.5, 2.6), Point3::new(51.0, 3.0, 2.9));
        let sway = |t: f64| a + (b - a) * (0.5 - 0.5 * (t * 0.15).cos());
        let mut h = Headway::default();
        let mut fired = Vec::new();
        for i in 0..=300 {
            let t = f64::from(i) * 0.5;
            // Too wide a sway for the stuck rule.
            assert!(!h.stuck(&sway(t), t), "{t}");
            if h.idle(&sway(t), t, 1_000_000 + 10 * i as usize) {
                fired.push(t);
            }
        }
        assert_eq!(fired, [IDLE_TIME + 0.5, 2.0 * IDLE_TIME + 1.0]);
        // The same sway while the map grows by IDLE_GAIN every 30 s: never idle.
        let mut h = Headway::default();
        for i in 0..=300 {
            let t = f64::from(i) * 0.5;
            let known = 1_000_000 + IDLE_GAIN * (i / 60) as usize;
            assert!(!h.idle(&sway(t), t, known), "{t}");
        }
        // Flying on at 0.5 m/s with nothing new in view: never idle.
        let mut h = Headway::default();
        for i in 0..=300 {
            let t = f64::from(i) * 0.5;
            let p = Point3::new(0.5 * t, 0.0, 1.0);
            assert!(!h.idle(&p, t, 1_000_000), "{t}");
        }
    }

    /// The maze's `frontier` seed 2 turned back and forth between (28.4, 7.1, 2.3) and
    /// (31.4, 17.1, 3.1) for 450 s: a box 10.5 m across, wider than the idle box.
    #[test]
    fn a_uav_that_turns_back_and_forth_over_more_than_the_idle_box_is_idle() {
        let (a, b) = (Point3::new(28.4, 7.1, 2.3), Point3::new(31.4, 17.1, 3.1));
        assert!((b - a).norm() > IDLE_SPAN);
        // One way in 7 s (about 1.5 m/s), as in that run.
        let sway = |t: f64| a + (b - a) * (0.5 - 0.5 * (t * core::f64::consts::PI / 7.0).cos());
        let mut h = Headway::default();
        let mut fired = Vec::new();
        for i in 0..=400 {
            let t = f64::from(i) * 0.5;
            if h.idle(&sway(t), t, 1_000_000 + 10 * i as usize) {
                fired.push(t);
            }
        }
        // At the end of each window: the detour clock's alone.
        assert_eq!(
            fired,
            [
                IDLE_TIME + 0.5,
                2.0 * IDLE_TIME + 1.0,
                3.0 * IDLE_TIME + 1.5
            ]
        );
        // The same sway while the map grows by IDLE_GAIN every 30 s: never idle.
        let mut h = Headway::default();
        for i in 0..=400 {
            let t = f64::from(i) * 0.5;
            let known = 1_000_000 + IDLE_GAIN * (i / 60) as usize;
            assert!(!h.idle(&sway(t), t, known), "{t}");
        }
        // A flight through a maze with nothing new in view: 1.5 m/s on a zigzag across a
        // corridor 20 m wide while it moves 0.6 m/s along it, turning every 15 s. It flies
        // about twice its box's diagonal in a window: never idle.
        let zigzag = |t: f64| {
            let leg = (t / 15.0).floor();
            let s = t - 15.0 * leg;
            let y = if leg % 2.0 == 0.0 { s } else { 15.0 - s };
            Point3::new(0.6 * t, 1.3 * y, 1.5)
        };
        let mut h = Headway::default();
        for i in 0..=400 {
            let t = f64::from(i) * 0.5;
            assert!(!h.idle(&zigzag(t), t, 1_000_000), "{t}");
        }
    }

    #[test]
    fn the_rigid_lidar_sees_the_floor_ahead_and_the_ceiling_behind() {
        let (chain, mid) = (rigid_chain(), LidarSensor::mid360());
        let body = Isometry3::translation(0.0, 0.0, 1.5);
        let sees = |x: f64, y: f64, z: f64| {
            mid.can_see(&chain, &body, 0.0, &Point3::new(x, y, z))
                .unwrap()
        };
        // Ahead: the floor 3 m away (27° down) and a wall at the horizon; not 60° up.
        assert!(sees(3.0, 0.0, 0.0) && sees(6.0, 0.0, 1.5));
        assert!(!sees(3.0, 0.0, 1.5 + 3.0 * 60f64.to_radians().tan()));
        // Behind: the ceiling 3 m up and 2 m back (56° up), not the floor.
        assert!(sees(-2.0, 0.0, 4.5) && !sees(-3.0, 0.0, 0.0));
        // Upright (no pitch) the floor 3 m ahead is out of view.
        let upright = front_mount(Vector3::zeros());
        assert!(
            !mid.can_see(&upright, &body, 0.0, &Point3::new(3.0, 0.0, 0.0))
                .unwrap()
        );
    }

    #[test]
    fn yaw_turns_toward_its_goal_at_its_rate_the_short_way() {
        let r = Reference {
            traj: None,
            t0: 0.0,
            hover: Vector3::zeros(),
            yaw0: 3.0,
            yaw_t0: 1.0,
            yaw_goal: 3.0 + wrap(-3.0 - 3.0),
            yaw_rate: 1.0,
        };
        // From 3 rad to −3 rad the short way is +0.28 rad, through π.
        assert!((r.yaw(1.1) - 3.1).abs() < 1e-12);
        assert!((r.yaw(5.0) - (3.0 + wrap(-6.0))).abs() < 1e-12);
        assert!((wrap(-3.0 - 3.0) - (core::f64::consts::TAU - 6.0)).abs() < 1e-12);
        assert!(r.done(0.0));
    }
}
