//! The UAV's attitude from differential flatness, and its IMU.

use nalgebra::{Matrix3, Rotation3, UnitQuaternion, Vector3};

use crate::rng::Rng;

/// Gravity \[m/s²\].
pub const GRAVITY: f64 = 9.81;

/// The attitude of a multicopter flying with acceleration `acc` \[m/s²\] and yaw `yaw` \[rad\]:
/// the body z axis along the thrust, acc + g·e_z, and the body x axis as close to the yaw
/// heading as that allows (differential flatness). A free fall (zero thrust) keeps z up.
///
/// # Example
/// ```
/// use fu_mpc_examples::uav::flat_attitude;
/// use nalgebra::Vector3;
///
/// // Hovering with yaw 0 is level.
/// assert!(flat_attitude(&Vector3::zeros(), 0.0).angle() < 1e-12);
/// // Accelerating forward (+x) tilts the thrust forward.
/// let q = flat_attitude(&Vector3::new(2.0, 0.0, 0.0), 0.0);
/// assert!((q * Vector3::z()).x > 0.1);
/// ```
pub fn flat_attitude(acc: &Vector3<f64>, yaw: f64) -> UnitQuaternion<f64> {
    let thrust = acc + Vector3::z() * GRAVITY;
    let z = if thrust.norm() > 1e-9 {
        thrust.normalize()
    } else {
        Vector3::z()
    };
    let heading = Vector3::new(yaw.cos(), yaw.sin(), 0.0);
    let mut y = z.cross(&heading);
    if y.norm() < 1e-9 {
        // Thrust horizontal along the heading: any perpendicular y will do.
        y = z.cross(&Vector3::y());
    }
    let y = y.normalize();
    let x = y.cross(&z);
    UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(Matrix3::from_columns(
        &[x, y, z],
    )))
}

/// IMU noise: white noise densities and bias random walks (per √Hz), defaults of a typical
/// MEMS IMU (BMI088-class).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ImuNoise {
    /// Accelerometer noise density \[m/s²/√Hz\].
    pub acc_noise: f64,
    /// Gyroscope noise density \[rad/s/√Hz\].
    pub gyro_noise: f64,
    /// Accelerometer bias random walk \[m/s³/√Hz\].
    pub acc_bias_walk: f64,
    /// Gyroscope bias random walk \[rad/s²/√Hz\].
    pub gyro_bias_walk: f64,
}

impl Default for ImuNoise {
    fn default() -> Self {
        Self {
            acc_noise: 2.0e-3,
            gyro_noise: 2.0e-4,
            acc_bias_walk: 3.0e-4,
            gyro_bias_walk: 2.0e-5,
        }
    }
}

/// One IMU sample.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ImuSample {
    /// Time \[s\].
    pub time: f64,
    /// Specific force in the body frame \[m/s²\].
    pub acc: Vector3<f64>,
    /// Angular velocity in the body frame \[rad/s\].
    pub gyro: Vector3<f64>,
}

/// The simulated IMU: true specific force and body rate, plus white noise and random-walk
/// biases, sampled at a fixed rate.
#[derive(Debug, Clone)]
pub struct ImuSim {
    noise: ImuNoise,
    rate: f64,
    rng: Rng,
    acc_bias: Vector3<f64>,
    gyro_bias: Vector3<f64>,
}

impl ImuSim {
    /// An IMU at `rate` \[Hz\] (200 in the simulator) with the given noise and seed.
    pub fn new(noise: ImuNoise, rate: f64, seed: u64) -> Self {
        Self {
            noise,
            rate,
            rng: Rng::new(seed),
            acc_bias: Vector3::zeros(),
            gyro_bias: Vector3::zeros(),
        }
    }

    fn gauss3(&mut self) -> Vector3<f64> {
        Vector3::new(self.rng.normal(), self.rng.normal(), self.rng.normal())
    }

    /// The sample at `time` for a body with attitude `attitude`, world acceleration `acc`
    /// \[m/s²\] and body rate `omega_body` \[rad/s\]; advances the biases by one period.
    pub fn sample(
        &mut self,
        time: f64,
        attitude: &UnitQuaternion<f64>,
        acc: &Vector3<f64>,
        omega_body: &Vector3<f64>,
    ) -> ImuSample {
        let dt = 1.0 / self.rate;
        let sqrt_rate = self.rate.sqrt();
        // Discrete white noise has σ = density·√rate; the bias walks by density·√dt.
        let (an, gn) = (self.gauss3(), self.gauss3());
        let (ab, gb) = (self.gauss3(), self.gauss3());
        self.acc_bias += ab * self.noise.acc_bias_walk * dt.sqrt();
        self.gyro_bias += gb * self.noise.gyro_bias_walk * dt.sqrt();
        let specific = attitude.inverse() * (acc + Vector3::z() * GRAVITY);
        ImuSample {
            time,
            acc: specific + self.acc_bias + an * self.noise.acc_noise * sqrt_rate,
            gyro: omega_body + self.gyro_bias + gn * self.noise.gyro_noise * sqrt_rate,
        }
    }
}

/// The body rate that turns attitude `q0` into `q1` over `dt` \[s\], in the body frame.
pub fn body_rate(q0: &UnitQuaternion<f64>, q1: &UnitQuaternion<f64>, dt: f64) -> Vector3<f64> {
    (q0.inverse() * q1).scaled_axis() / dt
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        #[test]
        fn thrust_axis_and_heading(
            ax in -8.0f64..8.0, ay in -8.0f64..8.0, az in -5.0f64..5.0, yaw in -3.1f64..3.1,
        ) {
            let acc = Vector3::new(ax, ay, az);
            let q = flat_attitude(&acc, yaw);
            let thrust = (acc + Vector3::z() * GRAVITY).normalize();
            prop_assert!((q * Vector3::z() - thrust).norm() < 1e-9);
            // The body x axis points along the heading projected off the thrust axis.
            let x = q * Vector3::x();
            let h = Vector3::new(yaw.cos(), yaw.sin(), 0.0);
            let want = (h - thrust * thrust.dot(&h)).normalize();
            prop_assert!((x - want).norm() < 1e-9);
        }
    }

    #[test]
    fn a_noiseless_imu_reads_gravity_and_the_rate() {
        let quiet = ImuNoise {
            acc_noise: 0.0,
            gyro_noise: 0.0,
            acc_bias_walk: 0.0,
            gyro_bias_walk: 0.0,
        };
        let mut imu = ImuSim::new(quiet, 200.0, 1);
        let q0 = flat_attitude(&Vector3::zeros(), 0.0);
        let q1 = flat_attitude(&Vector3::zeros(), 0.01);
        let w = body_rate(&q0, &q1, 0.005);
        let s = imu.sample(0.0, &q0, &Vector3::zeros(), &w);
        assert!((s.acc - Vector3::new(0.0, 0.0, GRAVITY)).norm() < 1e-12);
        assert!((s.gyro - Vector3::new(0.0, 0.0, 2.0)).norm() < 1e-9);
    }

    #[test]
    fn noise_follows_the_densities() {
        let noise = ImuNoise::default();
        let mut imu = ImuSim::new(
            ImuNoise {
                acc_bias_walk: 0.0,
                gyro_bias_walk: 0.0,
                ..noise
            },
            200.0,
            3,
        );
        let q = UnitQuaternion::identity();
        let xs: Vec<f64> = (0..20_000)
            .map(|i| {
                imu.sample(
                    f64::from(i) / 200.0,
                    &q,
                    &Vector3::zeros(),
                    &Vector3::zeros(),
                )
                .gyro
                .x
            })
            .collect();
        let var = xs.iter().map(|x| x * x).sum::<f64>() / xs.len() as f64;
        let want = (noise.gyro_noise * 200f64.sqrt()).powi(2);
        assert!((var / want - 1.0).abs() < 0.05, "{var} vs {want}");
    }
}
