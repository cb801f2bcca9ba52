//! The simulator's LiDAR-inertial odometry: an iterated error-state Kalman filter over attitude,
//! position and velocity. The IMU propagates the state and its covariance; each frame is
//! deskewed with the propagated poses and the encoder's angles, then registered point-to-plane
//! against a local map of earlier registered points, with the prediction as a Gaussian prior
//! (the registration's Gauss–Newton iterations are the filter's iterations, FAST-LIO style);
//! the velocity follows the pose correction through the predicted cross-covariance.
//!
//! Its error comes only from the simulated sensors and the geometry the LiDAR sees: nothing is
//! injected by hand. The IMU biases are not estimated: the filter's process noise is set above
//! the IMU's white noise to cover their slow drift.

use core::f64::consts::{PI, TAU};

use lidar_kinematics::{
    AngleSample, DeskewTarget, Deskewer, KinematicChain, KinematicsError, PoseSample, TimedPoint,
};
use nalgebra::{
    Isometry3, Matrix3, Matrix6, Point3, SMatrix, Translation3, UnitQuaternion, Vector3, Vector6,
};

use rayon::prelude::*;

use crate::lidar::LidarPoint;
use crate::registration::{
    Registration, RegistrationConfig, VoxelCloud, register_with_prior, voxel_key,
};
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
    /// Accelerometer noise density the filter assumes \[m/s²/√Hz\]; default 0.02, ten times
    /// the simulated IMU's, to cover the bias drift the filter does not estimate.
    pub acc_noise: f64,
    /// Gyroscope noise density the filter assumes \[rad/s/√Hz\]; default 0.002, ten times the
    /// simulated IMU's.
    pub gyro_noise: f64,
    /// Standard deviation of one point-to-plane residual \[m\]; default 0.1. Above the
    /// LiDAR's range noise because neighbouring residuals are correlated (plane fits against
    /// a 0.1 m map, deskew): counted as independent, thousands of points would overstate what
    /// a frame tells. At 0.05 the small scene's seeds 1–3 had 11–12 cm largest errors against
    /// 2–6 cm at 0.1; 0.2 gave the same as 0.1.
    pub point_noise: f64,
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
            acc_noise: 0.02,
            gyro_noise: 0.002,
            point_noise: 0.1,
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

/// Covariance of the error state [δθ; δp; δv]: a world-frame attitude error R = exp(δθ) R̂,
/// and position and velocity errors.
type Covariance = SMatrix<f64, 9, 9>;

/// Standard deviation of the initial state's errors (the simulator starts at a known pose, at
/// rest): 1 mm, 1 mrad, 1 mm/s.
const INITIAL_STD: f64 = 1e-3;

/// The LiDAR-inertial odometry.
#[derive(Debug, Clone)]
pub struct Odometry {
    config: OdometryConfig,
    state: NavState,
    covariance: Covariance,
    last_imu: Option<ImuSample>,
    /// Propagated poses since the last frame end (the first one at that frame end).
    poses: Vec<PoseSample>,
    /// One deskewer per chunk of [`DESKEW_CHUNK`] points (at least one), so a frame is
    /// deskewed in parallel.
    deskewers: Vec<Deskewer>,
    /// The local map: registered points, one per voxel; its neighbour search needs no tree.
    map: VoxelCloud,
    frames: usize,
    deskewed: Vec<Point3<f64>>,
    /// The last frame's beams without a return, deskewed like its points.
    deskewed_misses: Vec<Point3<f64>>,
    timed: Vec<TimedPoint>,
}

impl Odometry {
    /// Odometry starting from a known state (the simulator starts at rest at a known pose).
    pub fn new(chain: KinematicChain, config: OdometryConfig, initial: NavState) -> Self {
        Self {
            config,
            state: initial,
            covariance: Covariance::identity() * (INITIAL_STD * INITIAL_STD),
            last_imu: None,
            poses: vec![PoseSample::new(initial.time, initial.pose())],
            deskewers: vec![Deskewer::new(chain)],
            map: VoxelCloud::new(config.map_voxel),
            frames: 0,
            deskewed: Vec::new(),
            deskewed_misses: Vec::new(),
            timed: Vec::new(),
        }
    }

    /// The current estimate.
    pub fn state(&self) -> &NavState {
        &self.state
    }

    /// The covariance of the current estimate's errors [δθ; δp; δv] (a world-frame attitude
    /// error \[rad\], then position \[m\] and velocity \[m/s\]).
    pub fn covariance(&self) -> &SMatrix<f64, 9, 9> {
        &self.covariance
    }

    /// The last frame, deskewed into the body frame at its end (before thinning); map it with
    /// [`NavState::pose`] to place it in the world.
    pub fn last_scan(&self) -> &[Point3<f64>] {
        &self.deskewed
    }

    /// The last frame's beams without a return (see [`Odometry::process_frame_with_misses`]),
    /// deskewed into the body frame at its end like [`Odometry::last_scan`]; empty after
    /// [`Odometry::process_frame`].
    pub fn last_misses(&self) -> &[Point3<f64>] {
        &self.deskewed_misses
    }

    /// Points in the local map.
    pub fn map_len(&self) -> usize {
        self.map.len()
    }

    /// The local map's points (in no particular order).
    pub fn map_points(&self) -> impl Iterator<Item = &Point3<f64>> {
        self.map.points()
    }

    /// The local map's points within `radius` \[m\] of `centre`: those of
    /// [`Odometry::map_points`], in the same order, without visiting the map's far blocks.
    pub fn map_points_within<'a>(
        &'a self,
        centre: &'a Point3<f64>,
        radius: f64,
    ) -> impl Iterator<Item = &'a Point3<f64>> + 'a {
        self.map.points_within(centre, radius)
    }

    /// Every ⌈n / `max`⌉-th of the n local-map points within `radius` of `centre` (see
    /// [`VoxelCloud::sample_within`]): an even subsample of at most `max` points.
    pub fn map_sample_within(
        &self,
        centre: &Point3<f64>,
        radius: f64,
        max: usize,
    ) -> Vec<Point3<f64>> {
        self.map.sample_within(centre, radius, max)
    }

    /// Propagates the state and its covariance to `t` with the last IMU sample held constant.
    fn propagate_to(&mut self, t: f64) {
        let dt = t - self.state.time;
        if dt <= 0.0 {
            return;
        }
        let mut acc = Vector3::zeros();
        if let Some(imu) = self.last_imu {
            let s = &mut self.state;
            acc = s.attitude * imu.acc - Vector3::z() * GRAVITY;
            s.position += s.velocity * dt + 0.5 * acc * dt * dt;
            s.velocity += acc * dt;
            s.attitude *= UnitQuaternion::from_scaled_axis(imu.gyro * dt);
        } else {
            // No IMU yet: hold the velocity.
            self.state.position += self.state.velocity * dt;
        }
        // The error state's transition: δp gains δv dt, and δv gains −[a]× δθ dt from the
        // attitude error tilting the specific force (a: the world-frame specific force).
        let specific = acc + Vector3::z() * GRAVITY;
        let tilt = -specific.cross_matrix() * dt;
        let mut f = Covariance::identity();
        f.fixed_view_mut::<3, 3>(3, 0).copy_from(&(0.5 * dt * tilt));
        f.fixed_view_mut::<3, 3>(3, 6)
            .copy_from(&(Matrix3::identity() * dt));
        f.fixed_view_mut::<3, 3>(6, 0).copy_from(&tilt);
        let mut q = Covariance::zeros();
        let (qa, qg) = (
            self.config.acc_noise.powi(2) * dt,
            self.config.gyro_noise.powi(2) * dt,
        );
        q.fixed_view_mut::<3, 3>(0, 0)
            .copy_from(&(Matrix3::identity() * qg));
        q.fixed_view_mut::<3, 3>(6, 6)
            .copy_from(&(Matrix3::identity() * qa));
        let p = f * self.covariance * f.transpose() + q;
        self.covariance = 0.5 * (p + p.transpose());
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
        self.process_frame_with_misses(t_end, points, &[], angles)
    }

    /// [`Odometry::process_frame`], also deskewing `misses`: points along the frame's beams
    /// that returned nothing (e.g. each beam's end at the sensor's range), which
    /// [`Odometry::last_misses`] then holds. They are not registered and do not enter the
    /// local map.
    ///
    /// # Errors
    /// As [`Odometry::process_frame`], for the misses too.
    pub fn process_frame_with_misses(
        &mut self,
        t_end: f64,
        points: &[LidarPoint],
        misses: &[LidarPoint],
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
        self.timed.extend(
            points
                .iter()
                .chain(misses)
                .map(|p| TimedPoint::new(p.time, p.point)),
        );
        self.deskewed.resize(self.timed.len(), Point3::origin());
        if self.poses.len() == 1 {
            // A frame end at the last pose time: deskew needs a span.
            self.poses.push(PoseSample::new(t_end + 1e-9, predicted));
        }
        self.deskew(&angles, t_end)?;
        self.deskewed_misses.clear();
        self.deskewed_misses
            .extend_from_slice(&self.deskewed[points.len()..]);
        self.deskewed.truncate(points.len());
        let scan = thin(&self.deskewed, self.config.scan_voxel);
        let registration = match self.frames {
            0 => None,
            _ => Some(self.update(&scan, &predicted)),
        };
        let pose = self.state.pose();
        self.map.extend_transformed(&pose, &self.deskewed);
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

    /// Deskews `self.timed` into `self.deskewed` to the body frame at `t_end`, in chunks of
    /// [`DESKEW_CHUNK`] points on rayon's pool: each point's deskew depends on that point
    /// alone, so the result does not depend on the chunks, and the error (if any) is the
    /// first chunk's, that of the first bad point as in one pass.
    fn deskew(&mut self, angles: &[AngleSample], t_end: f64) -> Result<(), KinematicsError> {
        let target = DeskewTarget::BodyAt(t_end);
        let chunks = self.timed.len().div_ceil(DESKEW_CHUNK);
        if chunks <= 1 {
            // One chunk, or none: an empty frame still has its samples checked.
            return self.deskewers[0].deskew(
                &self.poses,
                angles,
                &self.timed,
                target,
                &mut self.deskewed,
            );
        }
        while self.deskewers.len() < chunks {
            let more = self.deskewers[0].clone();
            self.deskewers.push(more);
        }
        let poses = &self.poses;
        let results: Vec<Result<(), KinematicsError>> = self.deskewers[..chunks]
            .par_iter_mut()
            .zip(self.timed.par_chunks(DESKEW_CHUNK))
            .zip(self.deskewed.par_chunks_mut(DESKEW_CHUNK))
            .map(|((d, points), out)| d.deskew(poses, angles, points, target, out))
            .collect();
        results.into_iter().collect()
    }

    /// The filter's update: the registration with the prediction as its prior, then the
    /// velocity and the covariance from the joint posterior.
    fn update(&mut self, scan: &[Point3<f64>], predicted: &Isometry3<f64>) -> Registration {
        let noise2 = self.config.point_noise.powi(2);
        // The prior on [δθ; δp]: the inverse of their predicted covariance, in the
        // registration's units (one point's squared residual).
        let pxx: Matrix6<f64> = self.covariance.fixed_view::<6, 6>(0, 0).into_owned();
        let pxx_inv = match pxx.cholesky() {
            Some(c) => c.inverse(),
            None => {
                // A broken covariance: restart it rather than trust it.
                self.covariance = Covariance::identity() * (INITIAL_STD * INITIAL_STD);
                Matrix6::identity() / (INITIAL_STD * INITIAL_STD)
            }
        };
        let mut r = register_with_prior(
            &self.map,
            scan,
            predicted,
            &(pxx_inv * noise2),
            &self.config.registration,
        );
        if r.rejected || r.matched < self.config.min_matches {
            // Too little geometry to trust: keep the prediction and its covariance.
            r.pose = *predicted;
            return r;
        }
        // The pose correction e = [log(R R̂⁻¹); t − t̂]; the velocity follows it through the
        // cross-covariance (the conditional mean of the joint Gaussian).
        let rot = (r.pose.rotation * predicted.rotation.inverse()).scaled_axis();
        let dt = r.pose.translation.vector - predicted.translation.vector;
        let e = Vector6::new(rot.x, rot.y, rot.z, dt.x, dt.y, dt.z);
        let pvx = self.covariance.fixed_view::<3, 6>(6, 0).into_owned();
        let dv = pvx * (pxx_inv * e);
        // The posterior covariance (P⁻¹ + Hᵀ R⁻¹ H)⁻¹, H selecting [δθ; δp].
        let posterior = self.covariance.cholesky().and_then(|c| {
            let mut info = c.inverse();
            let mut block = info.fixed_view_mut::<6, 6>(0, 0);
            block += r.hessian / noise2;
            info.cholesky().map(|c| c.inverse())
        });
        if let Some(p) = posterior
            && p.iter().all(|v| v.is_finite())
        {
            self.covariance = 0.5 * (p + p.transpose());
        }
        if dv.iter().all(|v| v.is_finite()) {
            self.state.velocity += dv;
        }
        self.state.position = r.pose.translation.vector;
        self.state.attitude = r.pose.rotation;
        r
    }
}

/// Points per parallel task of the odometry's deskew.
const DESKEW_CHUNK: usize = 4096;

/// One point per voxel of edge `v` (the first), in input order.
pub(crate) fn thin(points: &[Point3<f64>], v: f64) -> Vec<Point3<f64>> {
    // Sized for every point at once: no rehash as the set grows.
    let mut seen =
        rustc_hash::FxHashSet::with_capacity_and_hasher(points.len(), Default::default());
    points
        .iter()
        .filter(|p| p.iter().all(|c| c.is_finite()) && seen.insert(voxel_key(p, v)))
        .copied()
        .collect()
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::panic)]
    use super::*;

    /// The chunked deskew equals one pass of one deskewer bit for bit, over several chunks,
    /// and reports the first bad point's error as that pass would.
    #[test]
    fn chunked_deskew_equals_one_pass() {
        let chain = KinematicChain::default();
        let initial = NavState {
            time: 0.0,
            position: Vector3::new(1.0, 2.0, 3.0),
            velocity: Vector3::zeros(),
            attitude: UnitQuaternion::identity(),
        };
        let mut odo = Odometry::new(chain, OdometryConfig::default(), initial);
        odo.poses = (0..=20u32)
            .map(|k| {
                let t = f64::from(k) * 0.005;
                PoseSample::new(
                    t,
                    Isometry3::new(
                        Vector3::new(t, 0.5 * t, 0.0),
                        Vector3::new(0.0, 0.1, 0.3 * t),
                    ),
                )
            })
            .collect();
        let angles: Vec<AngleSample> = (0..=100u32)
            .map(|k| {
                let t = f64::from(k) * 0.001;
                AngleSample::new(t, (1.7 * t).rem_euclid(TAU))
            })
            .collect();
        let n = 3 * DESKEW_CHUNK + 17;
        let n_f = f64::from(u32::try_from(n).unwrap());
        odo.timed = (0..n)
            .map(|i| {
                let x = f64::from(u32::try_from(i).unwrap());
                // Times spread over the frame, 0 to 0.1 s.
                TimedPoint::new(
                    0.1 * x / n_f,
                    Point3::new(x.sin() * 5.0, x.cos() * 4.0, 0.3 * (0.1 * x).sin()),
                )
            })
            .collect();
        odo.deskewed.resize(n, Point3::origin());
        odo.deskew(&angles, 0.1).unwrap();
        assert!(odo.deskewers.len() >= 4);
        let whole = Deskewer::new(chain)
            .deskew_to_vec(&odo.poses, &angles, &odo.timed, DeskewTarget::BodyAt(0.1))
            .unwrap();
        assert_eq!(odo.deskewed, whole);
        // Bad times in the third and the second chunk: the second chunk's is the first.
        odo.timed[2 * DESKEW_CHUNK + 5].time = 0.5;
        odo.timed[DESKEW_CHUNK + 3].time = -1.0;
        match odo.deskew(&angles, 0.1) {
            Err(KinematicsError::TimeOutOfRange { time, .. }) => assert_eq!(time, -1.0),
            other => panic!("expected the time error of the first bad point, got {other:?}"),
        }
    }
}
