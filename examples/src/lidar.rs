//! The simulated LiDAR: frames from a `lidar-kinematics` beam pattern, each point cast from
//! the sensor pose *at its own time* (real motion distortion), with range noise and no
//! return beyond the range.

use lidar_kinematics::{Beam, KinematicChain, KinematicsError, LidarSensor};
use nalgebra::{Isometry3, Point3, Vector3};

use rayon::prelude::*;

use crate::rng::Rng;
use crate::world::World;

/// Noise of the simulated LiDAR.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LidarNoise {
    /// Standard deviation of the range noise \[m\]; default 0.02 (a Mid-360's 2 cm).
    pub range_std: f64,
}

impl Default for LidarNoise {
    fn default() -> Self {
        Self { range_std: 0.02 }
    }
}

/// One return, as the sensor reports it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LidarPoint {
    /// Time of the return \[s\].
    pub time: f64,
    /// The point in the LiDAR frame at that time \[m\].
    pub point: Point3<f64>,
}

/// The simulated LiDAR on its motor.
#[derive(Debug, Clone)]
pub struct LidarSim {
    sensor: LidarSensor,
    chain: KinematicChain,
    noise: LidarNoise,
    seed: u64,
    beams: Vec<Beam>,
    /// The LiDAR's poses every [`POSE_STEP`] across the current frame.
    poses: Vec<Isometry3<f64>>,
    /// Whether frames also list the beams that returned nothing.
    report_misses: bool,
    /// The last frame's beams without a return (see [`LidarSim::misses`]).
    misses: Vec<LidarPoint>,
}

impl LidarSim {
    /// A LiDAR with its kinematic chain, noise and seed.
    pub fn new(sensor: LidarSensor, chain: KinematicChain, noise: LidarNoise, seed: u64) -> Self {
        Self {
            sensor,
            chain,
            noise,
            seed,
            beams: Vec::new(),
            poses: Vec::new(),
            report_misses: false,
            misses: Vec::new(),
        }
    }

    /// Makes frames also list the beams that return nothing within the range (as sensors
    /// that report empty returns do); off by default. The returns and their noise do not
    /// change.
    #[must_use]
    pub fn with_misses(mut self, report: bool) -> Self {
        self.report_misses = report;
        self
    }

    /// The beams of the last frame that returned nothing within the range, in the order they
    /// were cast, each as its time and the point at the range's end along it, in the LiDAR
    /// frame; empty unless [`LidarSim::with_misses`] turned them on.
    pub fn misses(&self) -> &[LidarPoint] {
        &self.misses
    }

    /// The sensor.
    pub fn sensor(&self) -> &LidarSensor {
        &self.sensor
    }

    /// Frame `index` starting at `t0` \[s\] into `out` (cleared): for every beam, the body pose
    /// and motor angle at the beam's own time give the ray; a hit within the range limits
    /// returns the point in the LiDAR frame, with Gaussian range noise.
    ///
    /// The LiDAR's pose is computed exactly every [`POSE_STEP`] across the frame and
    /// interpolated between (translation linearly, rotation by normalised quaternion
    /// interpolation): over 1 ms a motor at 180 deg/s and the UAV's own turn rotate the sensor
    /// by a few milliradians, and the interpolation's error is micrometres at the LiDAR's range.
    ///
    /// Beams are cast in parallel (rayon) in fixed chunks of [`BEAM_CHUNK`]; each chunk's
    /// noise comes from its own generator, seeded by the simulator's seed, the frame index and
    /// the chunk index, so a frame does not depend on the number of threads.
    ///
    /// # Errors
    /// Kinematic errors for a non-finite pose or angle.
    pub fn frame(
        &mut self,
        world: &World,
        index: u64,
        t0: f64,
        body_pose: impl Fn(f64) -> Isometry3<f64> + Sync,
        motor_angle: impl Fn(f64) -> f64 + Sync,
        out: &mut Vec<LidarPoint>,
    ) -> Result<(), KinematicsError> {
        out.clear();
        self.misses.clear();
        // Each beam is a pure function of its index: generated in parallel (the libm sines
        // and cosines would otherwise be a serial share of the frame).
        let pattern = self.sensor.pattern();
        self.beams.resize(
            pattern.points_per_frame(),
            Beam {
                time_offset: 0.0,
                direction: Vector3::x_axis(),
            },
        );
        self.beams
            .par_iter_mut()
            .enumerate()
            .with_min_len(BEAM_CHUNK)
            .for_each(|(k, b)| {
                if let Some(beam) = pattern.beam(index, k) {
                    *b = beam;
                }
            });
        let range = *self.sensor.range();
        // The frame's span of beam times, sampled every `POSE_STEP`.
        let (lo, hi) = self
            .beams
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), b| {
                (lo.min(b.time_offset), hi.max(b.time_offset))
            });
        // No beams, or times that are not finite: nothing to cast.
        if !(lo.is_finite() && hi.is_finite()) || lo > hi {
            return Ok(());
        }
        // At most a million poses, however long a frame.
        let step = POSE_STEP.max((hi - lo) / 1e6);
        // At most a million: the cast is exact.
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        let steps = (((hi - lo) / step).ceil() as usize).max(1);
        self.poses.clear();
        for j in 0..=steps {
            #[allow(clippy::cast_precision_loss)]
            let t = t0 + lo + j as f64 * step;
            self.poses
                .push(self.chain.lidar_pose(&body_pose(t), motor_angle(t))?);
        }
        let (poses, noise, seed) = (&self.poses, self.noise.range_std, self.seed);
        let report = self.report_misses;
        let chunks: Vec<(Vec<LidarPoint>, Vec<LidarPoint>)> = self
            .beams
            .par_chunks(BEAM_CHUNK)
            .enumerate()
            .map(|(c, beams)| {
                let mut rng = Rng::new(chunk_seed(seed, index, c));
                let mut pts = Vec::with_capacity(beams.len());
                let mut misses = Vec::new();
                for beam in beams {
                    let s = (beam.time_offset - lo) / step;
                    // In [0, steps − 1] after the clamp: the cast is exact.
                    #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
                    let i = (s.floor().max(0.0) as usize).min(steps - 1);
                    #[allow(clippy::cast_precision_loss)]
                    let f = s - i as f64;
                    let (a, b) = (&poses[i], &poses[i + 1]);
                    let origin = Point3::from(a.translation.vector.lerp(&b.translation.vector, f));
                    let dir = a.rotation.nlerp(&b.rotation, f) * beam.direction.into_inner();
                    // The noise is drawn for every beam, hit or not, so each beam's noise
                    // depends only on its place in the chunk.
                    let n = if noise > 0.0 {
                        noise * rng.normal()
                    } else {
                        0.0
                    };
                    let time = t0 + beam.time_offset;
                    let noisy = world.cast_ray(&origin, &dir, range.max()).map(|r| r + n);
                    match noisy {
                        Some(r) if range.contains(r) => pts.push(LidarPoint {
                            time,
                            point: Point3::from(beam.direction.into_inner() * r),
                        }),
                        // Nothing within the range; a return too close is not a miss.
                        Some(r) if r < range.min() => {}
                        _ if report => misses.push(LidarPoint {
                            time,
                            point: Point3::from(beam.direction.into_inner() * range.max()),
                        }),
                        _ => {}
                    }
                }
                (pts, misses)
            })
            .collect();
        for (pts, misses) in chunks {
            out.extend(pts);
            self.misses.extend(misses);
        }
        Ok(())
    }
}

/// Beams per parallel task of [`LidarSim::frame`]: fixed, so the noise does not depend on the
/// thread count.
pub const BEAM_CHUNK: usize = 1024;

/// Spacing of the exactly computed LiDAR poses a frame interpolates between \[s\].
pub const POSE_STEP: f64 = 1e-3;

/// The seed of chunk `chunk` of frame `frame` (SplitMix64 finaliser of the three).
fn chunk_seed(seed: u64, frame: u64, chunk: usize) -> u64 {
    let mut z = seed
        ^ frame.wrapping_mul(0x9E37_79B9_7F4A_7C15)
        ^ (chunk as u64).wrapping_mul(0xC2B2_AE3D_27D4_EB4F);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::Scene;
    use nalgebra::{Translation3, UnitQuaternion, Vector3};

    #[test]
    fn noiseless_points_lie_on_surfaces_at_their_own_pose() {
        let scene = Scene::small(2);
        let world = scene.world().unwrap();
        let chain = KinematicChain::default();
        let mut lidar = LidarSim::new(
            LidarSensor::mid360(),
            chain,
            LidarNoise { range_std: 0.0 },
            1,
        );
        // Flying at 2 m/s and spinning the motor: every point must map back onto a surface
        // with the pose at its own time, not with the frame's start pose.
        let pose = |t: f64| {
            Isometry3::from_parts(
                Translation3::from(scene.start.coords + Vector3::new(2.0 * t, 0.5 * t, 0.0)),
                UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 0.3 * t),
            )
        };
        let angle = |t: f64| 3.0 * t;
        let mut pts = Vec::new();
        lidar.frame(&world, 0, 0.0, pose, angle, &mut pts).unwrap();
        assert!(pts.len() > 15_000, "{}", pts.len());
        let mut distorted = 0;
        for p in &pts {
            let w = chain.lidar_pose(&pose(p.time), angle(p.time)).unwrap() * p.point;
            assert!(world.distance(&w) < 1e-4, "{w}");
            let w0 = chain.lidar_pose(&pose(0.0), angle(0.0)).unwrap() * p.point;
            if world.distance(&w0) > 0.05 {
                distorted += 1;
            }
        }
        // With the start pose instead, many points are off the surfaces: the motion distorts.
        assert!(distorted > pts.len() / 4, "{distorted}");
    }

    /// Beams run in parallel, each with its own noise: the same frame on 1 and 3 threads.
    #[test]
    fn frames_do_not_depend_on_the_thread_count() {
        let scene = Scene::small(2);
        let world = scene.world().unwrap();
        let run = |threads: usize| {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            pool.install(|| {
                let mut lidar = LidarSim::new(
                    LidarSensor::mid360(),
                    KinematicChain::default(),
                    LidarNoise::default(),
                    4,
                );
                let pose = |t: f64| Isometry3::translation(scene.start.x + t, scene.start.y, 1.5);
                let mut pts = Vec::new();
                lidar
                    .frame(&world, 3, 0.3, pose, |t| 2.0 * t, &mut pts)
                    .unwrap();
                pts
            })
        };
        let one = run(1);
        assert!(one.len() > 15_000);
        assert_eq!(one, run(3));
    }

    #[test]
    fn noise_has_the_configured_spread_and_is_seeded() {
        let mut g = Rng::new(5);
        let xs: Vec<f64> = (0..20_000).map(|_| g.normal()).collect();
        let mean = xs.iter().sum::<f64>() / xs.len() as f64;
        let var = xs.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / xs.len() as f64;
        assert!(
            mean.abs() < 0.03 && (var - 1.0).abs() < 0.05,
            "{mean} {var}"
        );
        let mut h = Rng::new(5);
        assert_eq!(h.normal(), xs[0]);
    }

    /// Under an open sky, the beams without a return are listed when asked for, each ends at
    /// the range along a ray that meets nothing within it, and the returns do not change.
    #[test]
    fn misses_are_the_beams_that_meet_nothing() {
        // A floor and one wall, nothing above.
        let world = World::from_boxes(&[
            (
                Point3::new(-30.0, -30.0, -1.0),
                Point3::new(30.0, 30.0, 0.0),
            ),
            (Point3::new(5.0, -30.0, 0.0), Point3::new(6.0, 30.0, 3.0)),
        ])
        .unwrap();
        let chain = KinematicChain::default();
        let sensor = LidarSensor::mid360();
        let pose = |t: f64| Isometry3::translation(t, 0.5 * t, 1.5);
        let angle = |t: f64| 2.0 * t;
        let mut plain = LidarSim::new(sensor.clone(), chain, LidarNoise::default(), 3);
        let mut with =
            LidarSim::new(sensor.clone(), chain, LidarNoise::default(), 3).with_misses(true);
        let (mut a, mut b) = (Vec::new(), Vec::new());
        plain.frame(&world, 2, 0.2, pose, angle, &mut a).unwrap();
        with.frame(&world, 2, 0.2, pose, angle, &mut b).unwrap();
        assert_eq!(a, b);
        assert!(plain.misses().is_empty());
        let misses = with.misses();
        // Most of the sky is empty: many misses, and with the returns about one per beam
        // (returns nearer than the minimum range are neither).
        assert!(misses.len() > 5_000, "{}", misses.len());
        let mut all = Vec::new();
        sensor.pattern().fill_frame(2, &mut all);
        let beams = all.len();
        assert!(misses.len() + b.len() <= beams);
        assert!(
            misses.len() + b.len() + 50 >= beams,
            "{} + {} of {beams}",
            misses.len(),
            b.len()
        );
        let range = sensor.range().max();
        for m in misses {
            assert!((m.point.coords.norm() - range).abs() < 1e-9);
            let p = chain.lidar_pose(&pose(m.time), angle(m.time)).unwrap();
            let dir = p.rotation * (m.point.coords / range);
            let origin = Point3::from(p.translation.vector);
            // Beyond the range once the noise is added, or nothing at all.
            assert!(
                world
                    .cast_ray(&origin, &dir, range)
                    .is_none_or(|r| r > range - 0.2),
                "{m:?}"
            );
        }
    }
}
