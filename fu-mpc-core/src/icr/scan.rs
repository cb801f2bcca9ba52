//! The iCR scan controller: the motor's accelerations by gradient ascent of the log-determinant
//! of the pose information the LiDAR gathers over the horizon.

use core::f64::consts::{PI, TAU};

use lidar_kinematics::{KinematicChain, LidarSensor, MotorLimits, motor_rotation};
use nalgebra::{Isometry3, Matrix3, Point3, Vector3};
use rayon::prelude::*;

use super::fov::Probit;
use crate::Result;
use crate::controller::{ScanCommand, ScanController, ScanInput, ScanStatus};
use crate::error::{CoreError, invalid, too_large};
use crate::fisher::{check_neighbours, normals};
use crate::fov_gap::FovGap;

/// What one horizon step adds: its information and, per point seen, (index, ∂w/∂θ).
type StepTerms = (Matrix3<f64>, Vec<(usize, f64)>);

/// Settings of [`IcrScan`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IcrScanConfig {
    /// Horizon N (steps); default 20, as FU-MPC's.
    pub horizon: usize,
    /// Step Δt \[s\]; default 0.1.
    pub dt: f64,
    /// Motor limits; default |ω| ≤ π rad/s, |u| ≤ 2π rad/s², as FU-MPC's.
    pub limits: MotorLimits,
    /// Smoothing κ of the probit over the field-of-view distance \[m²\]; default 0.05 (the
    /// weight falls from 0.99 to 0.01 over about half a metre across the boundary).
    pub kappa: f64,
    /// Regularisation ε of log det(F + εI), as the Fisher table's; default 1.
    pub epsilon: f64,
    /// Gradient-ascent iterations; default 15.
    pub iterations: usize,
    /// Length of each ascent step in the largest acceleration change \[rad/s²\]; default π/2.
    pub step: f64,
    /// Neighbours K for the PCA normals; default 10.
    pub neighbours: usize,
    /// At most this many cloud points enter the objective (an even subsample); default 1500.
    pub max_points: usize,
}

impl Default for IcrScanConfig {
    fn default() -> Self {
        Self {
            horizon: 20,
            dt: 0.1,
            limits: MotorLimits::try_new(-PI, PI, TAU).unwrap_or_default(),
            kappa: 0.05,
            epsilon: 1.0,
            iterations: 15,
            step: 0.5 * PI,
            neighbours: 10,
            max_points: 1500,
        }
    }
}

impl IcrScanConfig {
    /// Checks every setting (the horizon at most [`MAX_HORIZON`](crate::MAX_HORIZON), the
    /// iterations at most [`MAX_ITERATIONS`](crate::MAX_ITERATIONS)).
    ///
    /// # Errors
    /// [`CoreError::InvalidConfig`] naming the first bad one.
    pub fn validate(&self) -> Result<()> {
        if self.horizon == 0 {
            return invalid("horizon", 0.0, "need at least one step");
        }
        if self.horizon > crate::MAX_HORIZON {
            return too_large("horizon", self.horizon, "at most MAX_HORIZON steps");
        }
        if self.iterations > crate::MAX_ITERATIONS {
            return too_large("iterations", self.iterations, "at most MAX_ITERATIONS");
        }
        if !(self.dt.is_finite() && self.dt > 0.0) {
            return invalid("dt", self.dt, "must be positive and finite");
        }
        if !(self.kappa.is_finite() && self.kappa > 0.0) {
            return invalid("kappa", self.kappa, "must be positive and finite");
        }
        if !(self.epsilon.is_finite() && self.epsilon > 0.0) {
            return invalid("epsilon", self.epsilon, "must be positive and finite");
        }
        if !(self.step.is_finite() && self.step > 0.0) {
            return invalid("step", self.step, "must be positive and finite");
        }
        check_neighbours(self.neighbours)?;
        if self.max_points == 0 {
            return invalid("max_points", 0.0, "need at least one point");
        }
        Ok(())
    }
}

/// An information-theoretic scan controller after iCR: the accelerations a₀..a_{N−1} of the
/// motor maximise log det(εI + Σ_k Σ_j w_j(θ_k) n_j n_jᵀ), the point-to-plane information of
/// the surface normals n_j the LiDAR sees along the reference, where the hard visibility of the
/// Fisher table is replaced by the differentiable weight w = 1 − Φ(d) of eq. (21) over a signed
/// distance d to the sensor's field of view and range (the largest of the distances to its
/// elevation cones, azimuth half-planes and range shells). Each ascent step is projected onto
/// the motor limits (|a| ≤ u_max, then |ω| within bounds along the rollout); a speed ω₀
/// outside the limits is planned from the nearest limit, as FU-MPC's is, so every command
/// satisfies |a| ≤ u_max.
///
/// The cloud is given by [`IcrScan::set_cloud`] (like [`FisherTable::build`](crate::FisherTable::build),
/// once per new local map); without points the controller holds its speed and reports
/// [`ScanStatus::Fallback`].
///
/// # Example
/// ```
/// use fu_mpc_core::icr::{IcrScan, IcrScanConfig};
/// use fu_mpc_core::{ScanController, ScanInput};
/// use lidar_kinematics::{FieldOfView, KinematicChain, LidarSensor, MotorState};
/// use nalgebra::{Isometry3, Point3};
///
/// # fn main() -> Result<(), fu_mpc_core::CoreError> {
/// let sensor = LidarSensor::ring16()
///     .with_field_of_view(FieldOfView::try_new(-0.6, 0.6, -0.26, 0.26)?);
/// let config = IcrScanConfig::default();
/// let mut icr = IcrScan::new(config, KinematicChain::default(), sensor)?;
/// // A wall 4 m ahead and a floor.
/// let mut cloud = Vec::new();
/// for i in 0..30 {
///     for j in 0..30 {
///         let (a, b) = (f64::from(i) * 0.3 - 4.5, f64::from(j) * 0.3 - 4.5);
///         cloud.push(Point3::new(4.0, a, 0.3 * b));
///         cloud.push(Point3::new(a, b, -1.0));
///     }
/// }
/// icr.set_cloud(&cloud);
/// let reference = vec![Isometry3::identity(); config.horizon + 1];
/// let input = ScanInput { motor: MotorState::new(2.0, 0.0), reference: &reference, targets: &[], fisher: None };
/// let cmd = icr.command(&input)?;
/// assert!(cmd.acceleration.abs() <= config.limits.u_max());
/// # Ok(()) }
/// ```
#[derive(Debug, Clone)]
pub struct IcrScan {
    config: IcrScanConfig,
    chain: KinematicChain,
    sensor: LidarSensor,
    gate: FovGap,
    probit: Probit,
    points: Vec<Point3<f64>>,
    normals: Vec<Vector3<f64>>,
    plan: Vec<f64>,
}

impl IcrScan {
    /// A controller for the LiDAR `sensor` on the motor of `chain`.
    ///
    /// # Errors
    /// [`CoreError::InvalidConfig`] for bad settings.
    pub fn new(config: IcrScanConfig, chain: KinematicChain, sensor: LidarSensor) -> Result<Self> {
        config.validate()?;
        Ok(Self {
            config,
            chain,
            gate: FovGap::new(&sensor),
            sensor,
            probit: Probit::new(config.kappa)?,
            points: Vec::new(),
            normals: Vec::new(),
            plan: vec![0.0; config.horizon],
        })
    }

    /// The settings.
    pub fn config(&self) -> &IcrScanConfig {
        &self.config
    }

    /// The LiDAR whose field of view and range weight the points.
    pub fn sensor(&self) -> &LidarSensor {
        &self.sensor
    }

    /// Sets the local cloud (world frame): an even subsample of at most `max_points` finite
    /// points and their PCA normals over the full cloud's K nearest neighbours.
    pub fn set_cloud(&mut self, cloud: &[Point3<f64>]) {
        let finite: Vec<[f64; 3]> = cloud
            .iter()
            .filter(|p| p.iter().all(|v| v.is_finite()))
            .map(|p| [p.x, p.y, p.z])
            .collect();
        let all = normals(&finite, self.config.neighbours);
        let stride = finite.len().div_ceil(self.config.max_points).max(1);
        self.points.clear();
        self.normals.clear();
        for (p, n) in finite.iter().zip(&all).step_by(stride) {
            self.points.push(Point3::new(p[0], p[1], p[2]));
            self.normals.push(*n);
        }
    }

    /// Points in the objective.
    pub fn points(&self) -> usize {
        self.points.len()
    }

    /// The signed distance \[m\] of a LiDAR-frame point to the field of view and range, and its
    /// gradient: the largest of the distances to the elevation cones, r sin(β_min − β) and
    /// r sin(β − β_max), to the azimuth half-planes, ρ sin(|α − α_c| − w/2), and to the range
    /// shells, r − r_max and r_min − r (negative inside). No trigonometry per point: the sines
    /// expand into the coordinates with the bounds' sines and cosines.
    fn sdf(&self, p: &Vector3<f64>) -> (f64, Vector3<f64>) {
        let g = &self.gate;
        let r = p.norm();
        if r <= 0.0 {
            return (g.r_min, Vector3::zeros());
        }
        let u = p / r;
        let mut best = (g.r_min - r, -u);
        let mut take = |d: f64, grad: Vector3<f64>| {
            if d > best.0 {
                best = (d, grad);
            }
        };
        take(r - g.r_max, u);
        let rho = (p.x * p.x + p.y * p.y).sqrt();
        if rho > 0.0 {
            let drho = Vector3::new(p.x / rho, p.y / rho, 0.0);
            // r sin(β_min − β) = ρ sin β_min − z cos β_min, and the same for β_max.
            take(
                rho * g.sin_el_min - p.z * g.cos_el_min,
                drho * g.sin_el_min - Vector3::z() * g.cos_el_min,
            );
            take(
                p.z * g.cos_el_max - rho * g.sin_el_max,
                Vector3::z() * g.cos_el_max - drho * g.sin_el_max,
            );
            if let Some((c, s, cos_h, sin_h)) = g.azimuth {
                // In the wedge's frame: x′ along its centre; ρ sin(|δ| − h) = |y′| cos h − x′ sin h.
                let x1 = p.x * c + p.y * s;
                let y1 = -p.x * s + p.y * c;
                let sign = if y1 >= 0.0 { 1.0 } else { -1.0 };
                take(
                    y1.abs() * cos_h - x1 * sin_h,
                    Vector3::new(
                        -s * sign * cos_h - c * sin_h,
                        c * sign * cos_h - s * sin_h,
                        0.0,
                    ),
                );
            }
        }
        best
    }

    /// log det(εI + F(θ)) for the motor angles `theta[1..=N]` along `reference`, and its
    /// gradient in each θ_k, written to `grad`.
    fn objective(
        &self,
        reference: &[Isometry3<f64>],
        theta: &[f64],
        grad: &mut [f64],
    ) -> Result<f64> {
        let e = self.chain.extrinsics();
        let (base, mount) = (e.motor_base_in_body(), e.lidar_in_motor());
        let mount_inv = mount.inverse();
        let m_rot = mount_inv.rotation.to_rotation_matrix().into_inner();
        let m_tr = mount_inv.translation.vector;
        // Per step (in parallel, combined in step order): the information the step adds and,
        // per point, ∂w_j/∂θ_k.
        let per_step: Vec<StepTerms> = (1..theta.len())
            .into_par_iter()
            .map(|k| {
                // World → motor base → rotated by −θ_k about the motor axis.
                let rotated_from_world = Isometry3::from_parts(
                    nalgebra::Translation3::identity(),
                    motor_rotation(theta[k]).inverse(),
                ) * (reference[k] * base).inverse();
                let r_rot = rotated_from_world
                    .rotation
                    .to_rotation_matrix()
                    .into_inner();
                let r_tr = rotated_from_world.translation.vector;
                let mut info = Matrix3::zeros();
                let mut slopes = Vec::new();
                for (j, (p, n)) in self.points.iter().zip(&self.normals).enumerate() {
                    let pr = r_rot * p.coords + r_tr;
                    let pl = m_rot * pr + m_tr;
                    if !pl.iter().all(|v| v.is_finite()) {
                        // A finite point so far out that its transform overflows.
                        continue;
                    }
                    let (d, g) = self.sdf(&pl);
                    let (w, dw) = self.probit.inverse_noise(d, 1.0);
                    if w <= 1e-12 && dw.abs() <= 1e-12 {
                        continue;
                    }
                    info += n * n.transpose() * w;
                    // ∂p_L/∂θ = R_mount⁻¹ (−ẑ × p_rot): the rotation by −θ about the motor axis.
                    let dpl = m_rot * Vector3::new(pr.y, -pr.x, 0.0);
                    slopes.push((j, dw * g.dot(&dpl)));
                }
                (info, slopes)
            })
            .collect();
        let mut info = Matrix3::identity() * self.config.epsilon;
        for (f, _) in &per_step {
            info += f;
        }
        let chol = info.cholesky().ok_or(CoreError::NotPositiveDefinite {
            what: "pose information",
        })?;
        let logdet = 2.0 * chol.l().diagonal().iter().map(|v| v.ln()).sum::<f64>();
        let inv = chol.inverse();
        grad.fill(0.0);
        // ∂/∂θ_k log det(εI + F) = Σ_j (∂w_j/∂θ_k) n_jᵀ (εI + F)⁻¹ n_j.
        for (g, (_, slopes)) in grad[1..].iter_mut().zip(&per_step) {
            *g = slopes
                .iter()
                .map(|&(j, dw)| dw * self.normals[j].dot(&(inv * self.normals[j])))
                .sum();
        }
        Ok(logdet)
    }

    /// Rolls the accelerations out, projecting them onto the limits: |a| ≤ u_max, then the
    /// speed clamped along the way (and a adjusted to match, within ±u_max again: the
    /// division can round past it). Writes θ₀..θ_N. `omega0` must be within the limits.
    fn project_and_roll(&self, omega0: f64, theta0: f64, a: &mut [f64], theta: &mut [f64]) {
        let (dt, lim) = (self.config.dt, &self.config.limits);
        theta[0] = theta0;
        let mut w = omega0;
        for (k, ak) in a.iter_mut().enumerate() {
            let u = lim.saturate_acceleration(*ak);
            let w_next = lim.saturate_speed(w + u * dt);
            *ak = lim.saturate_acceleration((w_next - w) / dt);
            // eq. (12): the angle advances with the new speed.
            theta[k + 1] = theta[k] + w_next * dt;
            w = w_next;
        }
    }
}

impl ScanController for IcrScan {
    fn name(&self) -> &str {
        "icr"
    }

    fn command(&mut self, input: &ScanInput<'_>) -> Result<ScanCommand> {
        let n = self.config.horizon;
        let (theta0, omega0) = (input.motor.theta, input.motor.omega);
        if !(theta0.is_finite() && omega0.is_finite()) {
            return Err(CoreError::NonFinite {
                what: "motor state",
            });
        }
        if input.reference.len() != n + 1 {
            return Err(CoreError::LengthMismatch {
                what: "reference",
                expected: n + 1,
                found: input.reference.len(),
            });
        }
        for pose in input.reference {
            let ok = pose.translation.vector.iter().all(|v| v.is_finite())
                && pose.rotation.coords.iter().all(|v| v.is_finite());
            if !ok {
                return Err(CoreError::NonFinite {
                    what: "reference pose",
                });
            }
        }
        let dt = self.config.dt;
        if self.points.is_empty() {
            // Nothing to look at: hold the speed (within limits).
            let w = self.config.limits.saturate_speed(omega0);
            return Ok(ScanCommand {
                acceleration: self.config.limits.saturate_acceleration((w - omega0) / dt),
                status: ScanStatus::Fallback,
            });
        }
        // A speed outside the limits (a motor still spinning up, or measured): the plan
        // starts from the nearest limit, as FU-MPC's does, so every command stays within
        // ±u_max.
        let omega0 = self.config.limits.saturate_speed(omega0);
        // Warm start: the previous plan shifted by one step.
        let mut a = vec![0.0; n];
        a[..n - 1].copy_from_slice(&self.plan[1..]);
        a[n - 1] = self.plan[n - 1];
        let mut theta = vec![0.0; n + 1];
        let mut grad = vec![0.0; n + 1];
        let mut ga = vec![0.0; n];
        self.project_and_roll(omega0, theta0, &mut a, &mut theta);
        let value = self.objective(input.reference, &theta, &mut grad)?;
        let mut best = (value, a.clone());
        let mut status = ScanStatus::IterationLimit;
        for _ in 0..self.config.iterations {
            // ∂θ_k/∂a_l = (k − l) Δt² for l < k (within the limits).
            for (l, g) in ga.iter_mut().enumerate() {
                // Small step counts.
                #[allow(clippy::cast_precision_loss)]
                let s: f64 = (l + 1..=n).map(|k| (k - l) as f64 * grad[k]).sum();
                *g = s * dt * dt;
            }
            let scale = ga.iter().fold(0.0f64, |m, g| m.max(g.abs()));
            if scale.is_nan() || scale <= 1e-12 {
                status = ScanStatus::Converged;
                break;
            }
            let mut trial = a.clone();
            for (t, g) in trial.iter_mut().zip(&ga) {
                *t += self.config.step * g / scale;
            }
            self.project_and_roll(omega0, theta0, &mut trial, &mut theta);
            let v = self.objective(input.reference, &theta, &mut grad)?;
            if v > best.0 {
                best = (v, trial.clone());
            }
            a = trial;
        }
        self.plan.copy_from_slice(&best.1);
        Ok(ScanCommand {
            acceleration: self.plan[0],
            status,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use lidar_kinematics::{FieldOfView, MotorState};
    use proptest::prelude::*;

    fn scene() -> Vec<Point3<f64>> {
        let mut cloud = Vec::new();
        for i in 0..15 {
            for j in 0..15 {
                let (a, b) = (f64::from(i) * 0.6 - 4.5, f64::from(j) * 0.6 - 4.5);
                cloud.push(Point3::new(4.0, a, 0.3 * b));
                cloud.push(Point3::new(a, 5.0, 0.2 * b));
                cloud.push(Point3::new(a, b, -1.0));
            }
        }
        cloud
    }

    fn controller() -> IcrScan {
        controller_with(400, 8)
    }

    /// Fewer points and iterations than the defaults keep the unoptimised test build quick.
    fn controller_with(max_points: usize, iterations: usize) -> IcrScan {
        let sensor = LidarSensor::ring16()
            .with_field_of_view(FieldOfView::try_new(-0.6, 0.6, -0.26, 0.26).unwrap());
        let cfg = IcrScanConfig {
            max_points,
            iterations,
            ..IcrScanConfig::default()
        };
        let mut c = IcrScan::new(cfg, KinematicChain::default(), sensor).unwrap();
        c.set_cloud(&scene());
        c
    }

    /// The angle gradient of the objective equals central differences.
    #[test]
    fn objective_gradient_matches_differences() {
        let c = controller();
        let n = c.config.horizon;
        let reference: Vec<Isometry3<f64>> = (0..=n)
            .map(|k| {
                Isometry3::new(
                    Vector3::new(0.05 * k as f64, 0.0, 0.0),
                    Vector3::new(0.0, 0.0, 0.02 * k as f64),
                )
            })
            .collect();
        let theta: Vec<f64> = (0..=n).map(|k| 0.3 + 0.25 * k as f64).collect();
        let mut grad = vec![0.0; n + 1];
        c.objective(&reference, &theta, &mut grad).unwrap();
        let mut tmp = vec![0.0; n + 1];
        let h = 1e-6;
        let mut checked = 0;
        for k in 1..=n {
            let (mut up, mut dn) = (theta.clone(), theta.clone());
            up[k] += h;
            dn[k] -= h;
            let fd = (c.objective(&reference, &up, &mut tmp).unwrap()
                - c.objective(&reference, &dn, &mut tmp).unwrap())
                / (2.0 * h);
            assert!(
                (fd - grad[k]).abs() < 1e-5 * fd.abs().max(1e-3),
                "k={k}: {fd} vs {}",
                grad[k]
            );
            if fd.abs() > 1e-3 {
                checked += 1;
            }
        }
        assert!(checked > 3, "the objective should depend on the angles");
    }

    /// The margin-based distance agrees with the sensor's hard visibility test.
    #[test]
    fn sdf_sign_matches_visibility() {
        let c = controller();
        for i in 0..2000 {
            let t = f64::from(i);
            let p = Vector3::new(
                8.0 * (t * 0.37).sin(),
                8.0 * (t * 0.73).cos(),
                3.0 * (t * 1.1).sin(),
            );
            let (d, _) = c.sdf(&p);
            let inside = c.sensor.sees_in_lidar_frame(&Point3::from(p));
            if d.abs() > 1e-9 {
                assert_eq!(d < 0.0, inside, "{p:?}: {d}");
            }
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(8))]

        /// Commands and the whole plan stay within the motor limits, exactly, whatever the
        /// step and also from a speed outside the limits (planned from the nearest limit).
        #[test]
        fn respects_motor_limits(
            theta in -10.0..10.0f64,
            omega in -10.0..10.0f64,
            yaw in -3.0..3.0f64,
            dt in prop::sample::select(vec![0.1, 0.013, 1e-3]),
        ) {
            let mut c = controller_with(120, 5);
            c.config.dt = dt;
            let n = c.config.horizon;
            let reference: Vec<Isometry3<f64>> = (0..=n)
                .map(|k| Isometry3::new(Vector3::new(0.1 * k as f64, 0.0, 0.0), Vector3::new(0.0, 0.0, yaw)))
                .collect();
            let input = ScanInput { motor: MotorState::new(theta, omega), reference: &reference, targets: &[], fisher: None };
            for _ in 0..2 {
                let cmd = c.command(&input).unwrap();
                let lim = c.config.limits;
                prop_assert!(cmd.acceleration.abs() <= lim.u_max());
                let mut w = lim.saturate_speed(omega);
                for a in &c.plan {
                    prop_assert!(a.abs() <= lim.u_max());
                    w += a * c.config.dt;
                    prop_assert!(w >= lim.omega_min() - 1e-9 && w <= lim.omega_max() + 1e-9);
                }
            }
        }
    }

    /// A finite point so far out that its transform overflows is left out of the objective
    /// instead of making every later update fail.
    #[test]
    fn a_point_whose_transform_overflows_is_left_out() {
        let mut c = controller();
        let n = c.config.horizon;
        let reference = vec![Isometry3::identity(); n + 1];
        let input = ScanInput {
            motor: MotorState::new(0.3, 1.0),
            reference: &reference,
            targets: &[],
            fisher: None,
        };
        let want = c.command(&input).unwrap();
        // First, so the even subsample keeps it.
        let mut cloud = vec![Point3::new(f64::MAX, f64::MAX, 0.0)];
        cloud.extend(scene());
        let mut d = controller();
        d.set_cloud(&cloud);
        let got = d.command(&input).unwrap();
        assert!(got.acceleration.is_finite());
        assert!((got.acceleration - want.acceleration).abs() < 1e-6);
    }

    #[test]
    fn ascent_improves_the_objective_and_bad_input_is_an_error() {
        let mut c = controller();
        let n = c.config.horizon;
        let reference = vec![Isometry3::identity(); n + 1];
        // Looking away from the wall at rest: the plan should turn toward information.
        let input = ScanInput {
            motor: MotorState::new(PI, 0.0),
            reference: &reference,
            targets: &[],
            fisher: None,
        };
        let mut theta = vec![0.0; n + 1];
        let mut g = vec![0.0; n + 1];
        let mut zero = vec![0.0; n];
        c.project_and_roll(0.0, PI, &mut zero, &mut theta);
        let before = c.objective(&reference, &theta, &mut g).unwrap();
        c.command(&input).unwrap();
        let mut plan = c.plan.clone();
        c.project_and_roll(0.0, PI, &mut plan, &mut theta);
        let after = c.objective(&reference, &theta, &mut g).unwrap();
        assert!(after > before, "{after} vs {before}");

        let bad = ScanInput {
            motor: MotorState::new(f64::NAN, 0.0),
            reference: &reference,
            targets: &[],
            fisher: None,
        };
        assert!(matches!(c.command(&bad), Err(CoreError::NonFinite { .. })));
        let short = ScanInput {
            motor: MotorState::new(0.0, 0.0),
            reference: &reference[..3],
            targets: &[],
            fisher: None,
        };
        assert!(matches!(
            c.command(&short),
            Err(CoreError::LengthMismatch { .. })
        ));
        let mut nan_ref = reference.clone();
        nan_ref[4].translation.vector.x = f64::NAN;
        let nan_in = ScanInput {
            motor: MotorState::new(0.0, 0.0),
            reference: &nan_ref,
            targets: &[],
            fisher: None,
        };
        assert!(c.command(&nan_in).is_err());
        // No points: hold the speed, reported as a fallback.
        let mut empty = controller();
        empty.set_cloud(&[Point3::new(f64::NAN, 0.0, 0.0)]);
        let cmd = empty.command(&input).unwrap();
        assert_eq!(cmd.status, ScanStatus::Fallback);
        assert_eq!(cmd.acceleration, 0.0);
        let cfg = IcrScanConfig {
            kappa: 0.0,
            ..IcrScanConfig::default()
        };
        assert!(IcrScan::new(cfg, KinematicChain::default(), LidarSensor::mid360()).is_err());
        for cfg in [
            IcrScanConfig {
                horizon: 0,
                ..IcrScanConfig::default()
            },
            IcrScanConfig {
                horizon: usize::MAX,
                ..IcrScanConfig::default()
            },
            IcrScanConfig {
                iterations: crate::MAX_ITERATIONS + 1,
                ..IcrScanConfig::default()
            },
        ] {
            assert!(IcrScan::new(cfg, KinematicChain::default(), LidarSensor::mid360()).is_err());
        }
    }
}
