//! Predictive scanning, equations (10)–(14).

use lidar_kinematics::{KinematicChain, KinematicsError, MotorModel, MotorState};
use nalgebra::{Isometry3, Point3, Unit, Vector3};

use crate::{CoreError, Result};

/// One predicted scanning state (p_i, θ_i, ω_i, d_i^W).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PredictedStep {
    /// Sensor (body) position p_i = p_ref(t0 + iΔt), eq. (13) \[m\].
    pub position: Point3<f64>,
    /// Motor angle θ_i \[rad\], unwrapped.
    pub theta: f64,
    /// Motor speed ω_i \[rad/s\].
    pub omega: f64,
    /// Scan direction d_i^W in the world frame, eq. (14).
    pub direction: Unit<Vector3<f64>>,
}

impl Default for PredictedStep {
    fn default() -> Self {
        Self {
            position: Point3::origin(),
            theta: 0.0,
            omega: 0.0,
            direction: Vector3::x_axis(),
        }
    }
}

/// Predicts the scanning process over a horizon: the motor states of (11)–(12) under a control
/// sequence, and the sensor position and scan direction along the reference trajectory.
///
/// The reference is given as body poses sampled at t0 + iΔt, i = 0..N (a slice, so any
/// trajectory type can feed it without implementing a trait of this crate).
///
/// # Example
/// ```
/// use fu_mpc_core::{PredictedStep, predict_into};
/// use lidar_kinematics::{KinematicChain, MotorLimits, MotorModel, MotorState};
/// use nalgebra::Isometry3;
///
/// # fn main() -> Result<(), fu_mpc_core::CoreError> {
/// let motor = MotorModel::new(MotorLimits::try_new(-3.0, 3.0, 10.0)?);
/// let poses = vec![Isometry3::identity(); 4];
/// let mut out = [PredictedStep::default(); 4];
/// predict_into(&KinematicChain::default(), &motor, MotorState::new(0.0, 1.0), &[0.0; 3], 0.1, &poses, &mut out)?;
/// assert!((out[3].theta - 0.3).abs() < 1e-12);
/// # Ok(()) }
/// ```
///
/// # Errors
/// [`CoreError::LengthMismatch`] unless `reference.len() == out.len() == controls.len() + 1`;
/// [`CoreError::NonFinite`] for a non-finite initial state or pose translation, and kinematic
/// errors for a Δt that is not positive and finite (also with no controls), a non-finite
/// command or a bad attitude.
pub fn predict_into(
    chain: &KinematicChain,
    motor: &MotorModel,
    initial: MotorState,
    controls: &[f64],
    dt: f64,
    reference: &[Isometry3<f64>],
    out: &mut [PredictedStep],
) -> Result<()> {
    let n = controls.len() + 1;
    for (what, len) in [
        ("reference poses", reference.len()),
        ("prediction output", out.len()),
    ] {
        if len != n {
            return Err(CoreError::LengthMismatch {
                what,
                expected: n,
                found: len,
            });
        }
    }
    if !(initial.theta.is_finite() && initial.omega.is_finite()) {
        return Err(CoreError::NonFinite {
            what: "motor state",
        });
    }
    // The errors the motor model gives for a bad step, also with no step to take.
    if !dt.is_finite() {
        return Err(KinematicsError::NonFinite { what: "time step" }.into());
    }
    if dt <= 0.0 {
        return Err(KinematicsError::NonPositiveDt(dt).into());
    }
    let mut state = initial;
    for i in 0..n {
        if i > 0 {
            state = motor.step(state, controls[i - 1], dt)?; // eqs. (11)–(12)
        }
        let pose = &reference[i];
        if !pose.translation.vector.iter().all(|v| v.is_finite()) {
            return Err(CoreError::NonFinite {
                what: "reference pose",
            });
        }
        let direction = chain.scan_direction(&pose.rotation, state.theta)?; // eq. (14)
        out[i] = PredictedStep {
            position: Point3::from(pose.translation.vector), // eq. (13)
            theta: state.theta,
            omega: state.omega,
            direction,
        };
    }
    Ok(())
}
