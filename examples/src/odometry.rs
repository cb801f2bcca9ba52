//! The simulator's LiDAR-inertial odometry: IMU propagation, deskew of each frame with the
//! propagated poses and the encoder's angles, point-to-plane registration against a local map
//! of earlier registered points (optionally with a prior holding the pose at the IMU's
//! prediction), and a simple fusion of the two.
//!
//! Its error comes only from the simulated sensors and the geometry the LiDAR sees: nothing is
//! injected by hand. The IMU biases are not estimated (the registration corrects the drift
//! they cause at every frame).

use core::f64::consts::{PI, TAU};

use lidar_kinematics::{
    AngleSample, DeskewTarget, Deskewer, KinematicChain, KinematicsError, PoseSample, TimedPoint,
};
use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};

use crate::lidar::LidarPoint;
use crate::registration::{Registration, RegistrationConfig, VoxelCloud, register, voxel_key};
use crate::uav::{GRAVITY, ImuSample};

/// Times this close to the odometry's own count as equal \[s\] (rounding of sums of periods).
const TIME_TOLERANCE: f64 = 1e-9;

/// Settings of the odometry.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OdometryConfig {
    /// The scan-to-map registration.
    pub registration: RegistrationConfig,
    /// Edge of the voxels the local map keeps one point per \[m\]; default 0.1.
    pub map_voxel: f64,
    /// Map points farther than this from the current position are dropped \[m\]; default 40.
    pub map_radius: f64,
    /// Edge of the voxels a scan is thinned to before registration \[m\]; default 0.3.
    pub scan_voxel: f64,
    /// Share of the registration's position correction, per frame period, added to the
    /// velocity; default 0.5.
    pub velocity_gain: f64,
    /// Points beyond `map_radius` are dropped every this many frames; default 10.
    pub map_prune_frames: usize,
    /// A registration with fewer matched points, or a rejected step, keeps the IMU's
    /// prediction; default 50.
    pub min_matches: usize,
}

impl Default for OdometryConfig {
    fn default() -> Self {
        Self {
            registration: RegistrationConfig::default(),
            map_voxel: 0.1,
            map_radius: 40.0,
            scan_voxel: 0.3,
            velocity_gain: 0.5,
            map_prune_frames: 10,
            min_matches: 50,
        }
    }
}

/// The estimated navigation state.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NavState {
    /// Time \[s\].
    pub time: f64,
    /// Body position in the world \[m\].
    pub position: Vector3<f64>,
    /// Body velocity in the world \[m/s\].
    pub velocity: Vector3<f64>,
    /// Body attitude.
    pub attitude: UnitQuaternion<f64>,
}

impl NavState {
    /// The body pose.
    pub fn pose(&self) -> Isometry3<f64> {
        Isometry3::from_parts(Translation3::from(self.position), self.attitude)
    }
}

/// What one frame did.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrameReport {
    /// The pose the IMU predicted for the frame end.
    pub predicted: Isometry3<f64>,
    /// The registration (`None` for the first frame, which only starts the map).
    pub registration: Option<Registration>,
    /// Points in the local map after the frame.
    pub map_points: usize,
}

/// Errors of the odometry.
#[derive(Debug, thiserror::Error)]
pub enum OdometryError {
    /// A deskew or kinematics error (bad times, non-finite input).
    #[error(transparent)]
    Kinematics(#[from] KinematicsError),
    /// IMU samples or frames out of order.
    #[error("{what} at {time} s is not after the odometry time {now} s")]
    OutOfOrder {
        /// What came out of order.
        what: &'static str,
        /// Its time \[s\].
        time: f64,
        /// The odometry's time \[s\].
        now: f64,
    },
}

/// The LiDAR-inertial odometry.
#[derive(Debug, Clone)]
pub struct Odometry {
    config: OdometryConfig,
    state: NavState,
    last_imu: Option<ImuSample>,
    /// Propagated poses since the last frame end (the first one at that frame end).
    poses: Vec<PoseSample>,
    deskewer: Deskewer,
    /// The local map: registered points, one per voxel; its neighbour search needs no tree.
    map: VoxelCloud,
    frames: usize,
    deskewed: Vec<Point3<f64>>,
    timed: Vec<TimedPoint>,
}

impl Odometry {
    /// Odometry starting from a known state (the simulator starts at rest at a known pose).
    pub fn new(chain: KinematicChain, config: OdometryConfig, initial: NavState) -> Self {
        Self {
            config,
            state: initial,
            last_imu: None,
            poses: vec![PoseSample::new(initial.time, initial.pose())],
            deskewer: Deskewer::new(chain),
            map: VoxelCloud::new(config.map_voxel),
            frames: 0,
            deskewed: Vec::new(),
            timed: Vec::new(),
        }
    }

    /// The current estimate.
    pub fn state(&self) -> &NavState {
        &self.state
    }

    /// The last frame, deskewed into the body frame at its end (before thinning); map it with
    /// [`NavState::pose`] to place it in the world.
    pub fn last_scan(&self) -> &[Point3<f64>] {
        &self.deskewed
    }

    /// Points in the local map.
    pub fn map_len(&self) -> usize {
        self.map.len()
    }

    /// The local map's points (in no particular order).
    pub fn map_points(&self) -> impl Iterator<Item = &Point3<f64>> {
        self.map.points()
    }

    /// Propagates the state to `t` with the last IMU sample held constant.
    fn propagate_to(&mut self, t: f64) {
        let dt = t - self.state.time;
        if dt <= 0.0 {
            return;
        }
        if let Some(imu) = self.last_imu {
            let s = &mut self.state;
            let acc = s.attitude * imu.acc - Vector3::z() * GRAVITY;
            s.position += s.velocity * dt + 0.5 * acc * dt * dt;
            s.velocity += acc * dt;
            s.attitude *= UnitQuaternion::from_scaled_axis(imu.gyro * dt);
        } else {
            // No IMU yet: hold the velocity.
            self.state.position += self.state.velocity * dt;
        }
        self.state.time = t;
        self.poses.push(PoseSample::new(t, self.state.pose()));
    }

    /// Takes one IMU sample: propagates to its time with the previous sample, then holds it.
    ///
    /// # Errors
    /// [`OdometryError::OutOfOrder`] for a sample before the current time.
    pub fn push_imu(&mut self, imu: &ImuSample) -> Result<(), OdometryError> {
        if imu.time < self.state.time - TIME_TOLERANCE {
            return Err(OdometryError::OutOfOrder {
                what: "IMU sample",
                time: imu.time,
                now: self.state.time,
            });
        }
        self.propagate_to(imu.time);
        self.last_imu = Some(*imu);
        Ok(())
    }

    /// Processes the frame that ends at `t_end` \[s\]: `points` in the LiDAR frame at their own
    /// times (all after the previous frame end), `angles` the encoder's motor angles with
    /// their measurement times (latency removed), sorted. The last angle is extrapolated to
    /// `t_end` at the last measured speed.
    ///
    /// # Errors
    /// [`OdometryError::OutOfOrder`] for a frame end before the current time; deskew errors
    /// for points outside the frame or too few angle samples.
    pub fn process_frame(
        &mut self,
        t_end: f64,
        points: &[LidarPoint],
        angles: &[AngleSample],
    ) -> Result<FrameReport, OdometryError> {
        if t_end < self.state.time - TIME_TOLERANCE {
            return Err(OdometryError::OutOfOrder {
                what: "frame end",
                time: t_end,
                now: self.state.time,
            });
        }
        self.propagate_to(t_end);
        let predicted = self.state.pose();
        let mut angles = angles.to_vec();
        if let [.., a, b] = angles[..]
            && b.time < t_end
            && b.time > a.time
        {
            // Encoders report angles in [0, 2π): the step between two reads is the short way.
            let step = (b.angle - a.angle + PI).rem_euclid(TAU) - PI;
            let rate = step / (b.time - a.time);
            angles.push(AngleSample::new(t_end, b.angle + rate * (t_end - b.time)));
        }
        self.timed.clear();
        self.timed
            .extend(points.iter().map(|p| TimedPoint::new(p.time, p.point)));
        self.deskewed.resize(points.len(), Point3::origin());
        if self.poses.len() == 1 {
            // A frame end at the last pose time: deskew needs a span.
            self.poses.push(PoseSample::new(t_end + 1e-9, predicted));
        }
        self.deskewer.deskew(
            &self.poses,
            &angles,
            &self.timed,
            DeskewTarget::BodyAt(t_end),
            &mut self.deskewed,
        )?;
        let scan = thin(&self.deskewed, self.config.scan_voxel);
        let registration = match self.frames {
            0 => None,
            _ => {
                let mut r = register(&self.map, &scan, &predicted, &self.config.registration);
                if r.rejected || r.matched < self.config.min_matches {
                    // Too little geometry to trust: keep the IMU's prediction.
                    r.pose = predicted;
                }
                // Fusion: the registered pose replaces the prediction; part of the position
                // correction per frame period goes into the velocity.
                let period = (t_end - self.poses[0].time).max(1e-6);
                let correction = r.pose.translation.vector - predicted.translation.vector;
                self.state.velocity += self.config.velocity_gain * correction / period;
                self.state.position = r.pose.translation.vector;
                self.state.attitude = r.pose.rotation;
                Some(r)
            }
        };
        let pose = self.state.pose();
        for p in &self.deskewed {
            self.map.insert(pose * p);
        }
        self.frames += 1;
        if self
            .frames
            .is_multiple_of(self.config.map_prune_frames.max(1))
        {
            self.map
                .retain_within(&Point3::from(self.state.position), self.config.map_radius);
        }
        self.poses.clear();
        self.poses.push(PoseSample::new(t_end, pose));
        Ok(FrameReport {
            predicted,
            registration,
            map_points: self.map.len(),
        })
    }
}

/// One point per voxel of edge `v` (the first), in input order.
pub(crate) fn thin(points: &[Point3<f64>], v: f64) -> Vec<Point3<f64>> {
    let mut seen = rustc_hash::FxHashSet::default();
    points
        .iter()
        .filter(|p| p.iter().all(|c| c.is_finite()) && seen.insert(voxel_key(p, v)))
        .copied()
        .collect()
}
