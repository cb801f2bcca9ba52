//! The motor that spins the LiDAR: limits, state, and the discrete models (3) and (11)–(12).
//!
//! Two command forms are modelled:
//! - **speed-commanded**, eq. (3): θ_{i+1} = θ_i + ω_i Δt with ω_i the commanded speed,
//!   clipped to [ω_min, ω_max];
//! - **acceleration-commanded**, eqs. (11)–(12), the form FU-MPC optimises:
//!   ω_{i+1} = sat_[ω_min, ω_max](ω_i + u_i Δt), θ_{i+1} = θ_i + ω_{i+1} Δt,
//!   with the command u_i first clipped to |u_i| ≤ u_max (the constraint (21)).
//!
//! Angles are unwrapped radians, speeds rad/s, accelerations rad/s².
//!
//! # Example
//! ```
//! use lidar_kinematics::{MotorLimits, MotorModel, MotorState};
//!
//! # fn main() -> Result<(), lidar_kinematics::KinematicsError> {
//! let motor = MotorModel::new(MotorLimits::try_new(-6.0, 6.0, 20.0)?);
//! let states = motor.rollout(MotorState::new(0.0, 0.0), &[30.0, 30.0, -5.0], 0.1)?;
//! assert_eq!(states.len(), 4);
//! assert!((states[1].omega - 2.0).abs() < 1e-15); // u clipped to u_max = 20
//! # Ok(()) }
//! ```

use crate::error::{KinematicsError, Result, check_finite};

/// Motor limits: speed interval [ω_min, ω_max] (eq. (20)) and acceleration bound u_max (eq. (21)).
///
/// Valid by construction: all finite, ω_min ≤ ω_max, u_max ≥ 0.
///
/// # Example
/// ```
/// use lidar_kinematics::MotorLimits;
/// assert!(MotorLimits::try_new(-1.0, 1.0, 5.0).is_ok());
/// assert!(MotorLimits::try_new(1.0, -1.0, 5.0).is_err());
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MotorLimits {
    omega_min: f64,
    omega_max: f64,
    u_max: f64,
}

impl MotorLimits {
    /// Validates and builds the limits: speeds in rad/s, acceleration in rad/s².
    ///
    /// # Errors
    /// [`KinematicsError::NonFinite`] for NaN or infinite values,
    /// [`KinematicsError::InvertedSpeedLimits`] if `omega_min > omega_max`,
    /// [`KinematicsError::NegativeAccelerationLimit`] if `u_max < 0`.
    pub fn try_new(omega_min: f64, omega_max: f64, u_max: f64) -> Result<Self> {
        check_finite(omega_min, "omega_min")?;
        check_finite(omega_max, "omega_max")?;
        check_finite(u_max, "u_max")?;
        if omega_min > omega_max {
            return Err(KinematicsError::InvertedSpeedLimits {
                omega_min,
                omega_max,
            });
        }
        if u_max < 0.0 {
            return Err(KinematicsError::NegativeAccelerationLimit(u_max));
        }
        Ok(Self {
            omega_min,
            omega_max,
            u_max,
        })
    }

    /// Lower speed limit ω_min [rad/s].
    pub fn omega_min(&self) -> f64 {
        self.omega_min
    }

    /// Upper speed limit ω_max [rad/s].
    pub fn omega_max(&self) -> f64 {
        self.omega_max
    }

    /// Acceleration bound u_max [rad/s²].
    pub fn u_max(&self) -> f64 {
        self.u_max
    }

    /// Clips a speed to [ω_min, ω_max]: the saturation operator of eq. (11).
    #[inline]
    pub fn saturate_speed(&self, omega: f64) -> f64 {
        omega.clamp(self.omega_min, self.omega_max)
    }

    /// Clips an acceleration command to [−u_max, u_max] (eq. (21)).
    #[inline]
    pub fn saturate_acceleration(&self, u: f64) -> f64 {
        u.clamp(-self.u_max, self.u_max)
    }
}

impl Default for MotorLimits {
    /// ±2π rad/s (one revolution per second either way) and 4π rad/s².
    ///
    /// The FU-MPC paper does not state its limits; these suit a small
    /// brushless gimbal motor carrying a 265 g LiDAR.
    fn default() -> Self {
        Self {
            omega_min: -core::f64::consts::TAU,
            omega_max: core::f64::consts::TAU,
            u_max: 2.0 * core::f64::consts::TAU,
        }
    }
}

/// Motor state x = [θ; ω] of eq. (10): unwrapped angle \[rad\] and speed [rad/s].
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct MotorState {
    /// Motor angle θ \[rad\], unwrapped.
    pub theta: f64,
    /// Motor speed ω [rad/s].
    pub omega: f64,
}

impl MotorState {
    /// A state from angle \[rad\] and speed [rad/s].
    pub fn new(theta: f64, omega: f64) -> Self {
        Self { theta, omega }
    }

    fn check(&self) -> Result<()> {
        check_finite(self.theta, "motor angle")?;
        check_finite(self.omega, "motor speed")?;
        Ok(())
    }
}

/// The discrete motor model with its limits.
///
/// Two command forms:
/// - **speed-commanded**, eq. (3): θ_{i+1} = θ_i + ω_i Δt with ω_i the commanded speed,
///   clipped to [ω_min, ω_max];
/// - **acceleration-commanded**, eqs. (11)–(12), the form FU-MPC optimises:
///   ω_{i+1} = sat_[ω_min, ω_max](ω_i + u_i Δt), θ_{i+1} = θ_i + ω_{i+1} Δt,
///   with the command u_i first clipped to |u_i| ≤ u_max (the constraint (21)).
///
/// Angles are unwrapped radians, speeds rad/s, accelerations rad/s².
///
/// # Example
/// ```
/// use lidar_kinematics::{MotorLimits, MotorModel, MotorState};
/// # fn main() -> Result<(), lidar_kinematics::KinematicsError> {
/// let motor = MotorModel::new(MotorLimits::default());
/// let next = motor.step(MotorState::new(0.0, 1.0), 2.0, 0.1)?;
/// assert!((next.omega - 1.2).abs() < 1e-15);
/// assert!((next.theta - 0.12).abs() < 1e-15);
/// # Ok(()) }
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct MotorModel {
    limits: MotorLimits,
}

impl MotorModel {
    /// A model with the given limits.
    pub fn new(limits: MotorLimits) -> Self {
        Self { limits }
    }

    /// The model's limits.
    pub fn limits(&self) -> &MotorLimits {
        &self.limits
    }

    /// One step of the speed-commanded model, eq. (3): θ' = θ + sat(ω_cmd) Δt, ω' = sat(ω_cmd).
    ///
    /// # Errors
    /// [`KinematicsError::NonFinite`] for a non-finite state or command, or an angle that
    /// overflows (θ near `f64::MAX`), [`KinematicsError::NonPositiveDt`] unless `dt > 0`.
    pub fn step_speed(&self, state: MotorState, omega_cmd: f64, dt: f64) -> Result<MotorState> {
        state.check()?;
        check_finite(omega_cmd, "speed command")?;
        check_dt(dt)?;
        let omega = self.limits.saturate_speed(omega_cmd);
        // eq. (3)
        finite_angle(MotorState::new(state.theta + omega * dt, omega))
    }

    /// One step of the acceleration-commanded model, eqs. (11)–(12), after clipping `u` to ±u_max.
    ///
    /// # Errors
    /// [`KinematicsError::NonFinite`] for a non-finite state or command, or an angle that
    /// overflows (θ near `f64::MAX`), [`KinematicsError::NonPositiveDt`] unless `dt > 0`.
    pub fn step(&self, state: MotorState, u: f64, dt: f64) -> Result<MotorState> {
        state.check()?;
        check_finite(u, "acceleration command")?;
        check_dt(dt)?;
        finite_angle(self.step_unchecked(state, u, dt))
    }

    #[inline]
    fn step_unchecked(&self, state: MotorState, u: f64, dt: f64) -> MotorState {
        let u = self.limits.saturate_acceleration(u);
        // eq. (11)
        let omega = self.limits.saturate_speed(state.omega + u * dt);
        // eq. (12): the angle advances with the *new* speed.
        MotorState::new(state.theta + omega * dt, omega)
    }

    /// Rolls out a control sequence u₀..u_{N−1} into `out` = [x₀, x₁, …, x_N] without allocating.
    ///
    /// # Errors
    /// [`KinematicsError::LengthMismatch`] unless `out.len() == controls.len() + 1`;
    /// otherwise as [`MotorModel::step`]. On error `out` is left unchanged.
    pub fn rollout_into(
        &self,
        initial: MotorState,
        controls: &[f64],
        dt: f64,
        out: &mut [MotorState],
    ) -> Result<()> {
        initial.check()?;
        check_dt(dt)?;
        if out.len() != controls.len() + 1 {
            return Err(KinematicsError::LengthMismatch {
                what: "rollout output",
                expected: controls.len() + 1,
                found: out.len(),
            });
        }
        if controls.iter().any(|u| !u.is_finite()) {
            return Err(KinematicsError::NonFinite {
                what: "acceleration command",
            });
        }
        // |θ_N| ≤ |θ₀| + N Δt max|ω|: when that bound overflows, a dry run first finds out
        // whether θ does, so an error leaves `out` unchanged.
        let fastest = self
            .limits
            .omega_min()
            .abs()
            .max(self.limits.omega_max().abs());
        // Control counts are far below 2^53.
        #[allow(clippy::cast_precision_loss)]
        let bound = initial.theta.abs() + controls.len() as f64 * dt * fastest;
        if !bound.is_finite() {
            let mut state = initial;
            for &u in controls {
                state = finite_angle(self.step_unchecked(state, u, dt))?;
            }
        }
        out[0] = initial;
        for (i, &u) in controls.iter().enumerate() {
            out[i + 1] = self.step_unchecked(out[i], u, dt);
        }
        Ok(())
    }

    /// Rolls out a control sequence, returning [x₀, x₁, …, x_N].
    ///
    /// # Errors
    /// As [`MotorModel::rollout_into`].
    pub fn rollout(
        &self,
        initial: MotorState,
        controls: &[f64],
        dt: f64,
    ) -> Result<Vec<MotorState>> {
        let mut out = vec![MotorState::default(); controls.len() + 1];
        self.rollout_into(initial, controls, dt, &mut out)?;
        Ok(out)
    }
}

/// `state`, or [`KinematicsError::NonFinite`] when its angle overflowed.
fn finite_angle(state: MotorState) -> Result<MotorState> {
    if state.theta.is_finite() {
        Ok(state)
    } else {
        Err(KinematicsError::NonFinite {
            what: "motor angle after the step",
        })
    }
}

pub(crate) fn check_dt(dt: f64) -> Result<f64> {
    check_finite(dt, "time step")?;
    if dt > 0.0 {
        Ok(dt)
    } else {
        Err(KinematicsError::NonPositiveDt(dt))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn limits() -> impl Strategy<Value = MotorLimits> {
        (-10.0f64..10.0, 0.0f64..10.0, 0.0f64..50.0)
            .prop_map(|(lo, width, u_max)| MotorLimits::try_new(lo, lo + width, u_max).unwrap())
    }

    proptest! {
        #[test]
        fn rollout_stays_within_limits(
            limits in limits(),
            theta0 in -100.0f64..100.0,
            omega0 in -20.0f64..20.0,
            controls in proptest::collection::vec(-100.0f64..100.0, 0..40),
            dt in 1e-3f64..0.5,
        ) {
            let motor = MotorModel::new(limits);
            let states = motor.rollout(MotorState::new(theta0, omega0), &controls, dt).unwrap();
            prop_assert_eq!(states.len(), controls.len() + 1);
            for (k, s) in states.iter().enumerate().skip(1) {
                prop_assert!(s.omega >= limits.omega_min() && s.omega <= limits.omega_max());
                // The realised acceleration respects u_max unless the previous speed was
                // outside the limits (only possible for the initial state).
                if k >= 2 {
                    let accel = (s.omega - states[k - 1].omega) / dt;
                    prop_assert!(accel.abs() <= limits.u_max() * (1.0 + 1e-12) + 1e-9);
                }
            }
        }

        /// For admissible commands the rollout is exactly eqs. (11)–(12).
        #[test]
        fn rollout_matches_equations(
            limits in limits(),
            theta0 in -100.0f64..100.0,
            omega0 in -20.0f64..20.0,
            fractions in proptest::collection::vec(-1.0f64..1.0, 1..40),
            dt in 1e-3f64..0.5,
        ) {
            let motor = MotorModel::new(limits);
            let controls: Vec<f64> = fractions.iter().map(|f| f * limits.u_max()).collect();
            let states = motor.rollout(MotorState::new(theta0, omega0), &controls, dt).unwrap();
            let (mut theta, mut omega) = (theta0, omega0);
            for (k, u) in controls.iter().enumerate() {
                omega = (omega + u * dt).clamp(limits.omega_min(), limits.omega_max());
                theta += omega * dt;
                prop_assert_eq!(states[k + 1], MotorState::new(theta, omega));
            }
        }

        /// Eq. (3) with the command clipped to the speed limits (commands reach beyond them).
        #[test]
        fn speed_model_is_eq3(theta in -10.0f64..10.0, cmd in -10.0f64..10.0, dt in 1e-3f64..1.0) {
            let motor = MotorModel::new(MotorLimits::try_new(-6.0, 4.0, 1.0).unwrap());
            let s = motor.step_speed(MotorState::new(theta, 0.0), cmd, dt).unwrap();
            let w = cmd.clamp(-6.0, 4.0);
            prop_assert_eq!(s, MotorState::new(theta + w * dt, w));
        }

        /// Commands beyond ±u_max act as ±u_max (the constraint (21)), then eqs. (11)–(12).
        #[test]
        fn acceleration_commands_are_clipped(
            omega0 in -5.0f64..5.0,
            controls in proptest::collection::vec(-100.0f64..100.0, 1..30),
            dt in 1e-3f64..0.3,
        ) {
            let limits = MotorLimits::try_new(-6.0, 6.0, 8.0).unwrap();
            let motor = MotorModel::new(limits);
            let states = motor.rollout(MotorState::new(0.0, omega0), &controls, dt).unwrap();
            let (mut theta, mut omega) = (0.0, omega0);
            for (k, u) in controls.iter().enumerate() {
                omega = (omega + u.clamp(-8.0, 8.0) * dt).clamp(-6.0, 6.0);
                theta += omega * dt;
                prop_assert_eq!(states[k + 1], MotorState::new(theta, omega));
            }
        }
    }

    #[test]
    fn bad_input_is_a_typed_error() {
        use KinematicsError as E;
        assert!(matches!(
            MotorLimits::try_new(2.0, 1.0, 1.0),
            Err(E::InvertedSpeedLimits { .. })
        ));
        assert!(matches!(
            MotorLimits::try_new(f64::NAN, 1.0, 1.0),
            Err(E::NonFinite { .. })
        ));
        assert!(matches!(
            MotorLimits::try_new(0.0, f64::INFINITY, 1.0),
            Err(E::NonFinite { .. })
        ));
        assert!(matches!(
            MotorLimits::try_new(0.0, 1.0, -1.0),
            Err(E::NegativeAccelerationLimit(_))
        ));
        let m = MotorModel::default();
        let s = MotorState::default();
        assert!(matches!(m.step(s, 1.0, 0.0), Err(E::NonPositiveDt(_))));
        assert!(matches!(m.step(s, 1.0, -0.1), Err(E::NonPositiveDt(_))));
        assert!(matches!(m.step(s, 1.0, f64::NAN), Err(E::NonFinite { .. })));
        assert!(matches!(m.step(s, f64::NAN, 0.1), Err(E::NonFinite { .. })));
        assert!(matches!(
            m.step(MotorState::new(f64::INFINITY, 0.0), 0.0, 0.1),
            Err(E::NonFinite { .. })
        ));
        assert!(matches!(
            m.step_speed(s, f64::NAN, 0.1),
            Err(E::NonFinite { .. })
        ));
        assert!(matches!(
            m.rollout(s, &[0.0, f64::NEG_INFINITY], 0.1),
            Err(E::NonFinite { .. })
        ));
        let mut out = [MotorState::default(); 2];
        assert!(matches!(
            m.rollout_into(s, &[0.0, 1.0], 0.1, &mut out),
            Err(E::LengthMismatch {
                expected: 3,
                found: 2,
                ..
            })
        ));
    }
}
