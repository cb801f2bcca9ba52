//! The scan-controller interface shared by FU-MPC and its baselines.

use lidar_kinematics::{MotorLimits, MotorState};
use nalgebra::Isometry3;

use crate::error::invalid;
use crate::{CoreError, FisherTable, FrontierTarget, Result};

/// What a scan controller sees at one control cycle.
#[derive(Debug, Clone, Copy)]
pub struct ScanInput<'a> {
    /// The motor's measured state (θ0, ω0).
    pub motor: MotorState,
    /// Body poses along the reference trajectory at t0 + iΔt, i = 0..=N.
    pub reference: &'a [Isometry3<f64>],
    /// Frontier targets (centres and scores).
    pub targets: &'a [FrontierTarget],
    /// The latest localisation-cost table, if one has been built.
    pub fisher: Option<&'a FisherTable>,
}

/// How a controller's command came about.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ScanStatus {
    /// The optimiser converged (no further decrease of the cost).
    Converged,
    /// The optimiser stopped at its iteration limit; the command is the best found.
    IterationLimit,
    /// A QP step failed; the command comes from the best warm start (always feasible).
    Fallback,
    /// A controller without optimisation (a fixed-speed baseline).
    Direct,
}

/// One control command: the motor's angular acceleration for the next cycle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ScanCommand {
    /// Angular acceleration u_0 \[rad/s²\], within ±u_max.
    pub acceleration: f64,
    /// How it was obtained.
    pub status: ScanStatus,
}

/// A scan controller: FU-MPC, its single-term variants, the fixed-speed baselines, or iCR.
pub trait ScanController {
    /// A short name for reports, e.g. `"fu-mpc"` or `"fixed:100"`.
    fn name(&self) -> &str;

    /// The command for this cycle.
    ///
    /// # Errors
    /// Typed errors for malformed input (lengths, NaN); failures inside an optimiser are not
    /// errors but a [`ScanStatus::Fallback`] command.
    fn command(&mut self, input: &ScanInput<'_>) -> Result<ScanCommand>;
}

/// The fixed-speed baseline: accelerate toward a constant speed and hold it (the paper's
/// 30, 100 and 360 deg/s runs).
///
/// # Example
/// ```
/// use fu_mpc_core::{FixedSpeed, ScanController, ScanInput};
/// use lidar_kinematics::{MotorLimits, MotorState};
///
/// let limits = MotorLimits::try_new(0.0, 10.0, 5.0).unwrap();
/// let mut c = FixedSpeed::new(100f64.to_radians(), limits, 0.1).unwrap();
/// let input = ScanInput { motor: MotorState::new(0.0, 0.0), reference: &[], targets: &[], fisher: None };
/// assert_eq!(c.command(&input).unwrap().acceleration, 5.0);
/// ```
#[derive(Debug, Clone)]
pub struct FixedSpeed {
    omega: f64,
    limits: MotorLimits,
    dt: f64,
    name: String,
}

impl FixedSpeed {
    /// A controller holding `omega` \[rad/s\] (clamped into the limits), commanding every `dt` \[s\].
    ///
    /// # Errors
    /// [`CoreError::InvalidConfig`] for a non-finite speed or a Δt that is not positive and
    /// finite.
    pub fn new(omega: f64, limits: MotorLimits, dt: f64) -> Result<Self> {
        if !omega.is_finite() {
            return invalid("omega", omega, "must be finite [rad/s]");
        }
        if !(dt.is_finite() && dt > 0.0) {
            return invalid("dt", dt, "must be positive and finite [s]");
        }
        let omega = omega.clamp(limits.omega_min(), limits.omega_max());
        let name = format!("fixed:{}", omega.to_degrees().round());
        Ok(Self {
            omega,
            limits,
            dt,
            name,
        })
    }
}

impl ScanController for FixedSpeed {
    fn name(&self) -> &str {
        &self.name
    }

    fn command(&mut self, input: &ScanInput<'_>) -> Result<ScanCommand> {
        let w = input.motor.omega;
        if !w.is_finite() {
            return Err(CoreError::NonFinite {
                what: "motor speed",
            });
        }
        let u = self
            .limits
            .saturate_acceleration((self.omega - w) / self.dt);
        Ok(ScanCommand {
            acceleration: u,
            status: ScanStatus::Direct,
        })
    }
}
