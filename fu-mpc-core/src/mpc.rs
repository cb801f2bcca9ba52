//! The FU-MPC solver of equations (19)–(21).

use lidar_kinematics::{KinematicChain, MotorLimits, MotorModel};

use crate::active_set::ActiveSet;
use crate::controller::{ScanCommand, ScanController, ScanInput, ScanStatus};
use crate::error::{invalid, too_large};
use crate::qp::StepQp;
use crate::utility::frontier_surrogates;
use crate::{CoreError, PeriodicPwl, PredictedStep, Result, UtilityConfig, predict_into};

/// Settings of the FU-MPC controller.
///
/// Defaults: the paper's cycle Δt = 0.1 s and speed limit 180 deg/s; the rest chosen here
/// and explained per field.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MpcConfig {
    /// Horizon N (steps); default 20, i.e. 2 s: long enough to plan a dwell and the turn back.
    pub horizon: usize,
    /// Step Δt \[s\]; default 0.1 (the paper's 10 Hz cycle).
    pub dt: f64,
    /// Speed and acceleration limits: default |ω| ≤ π rad/s (the paper's 180 deg/s, in both
    /// directions, so the sensor can turn back to a target instead of going round) and
    /// |u| ≤ 2π rad/s² (full speed in 0.5 s).
    pub limits: MotorLimits,
    /// α of (19), weight of the frontier term (normalised to [0, 1] per step); default 1.
    pub alpha: f64,
    /// β of (19), weight of the localisation cost f ∈ (0, 3/ε]; default 1.
    pub beta: f64,
    /// γ of (19), weight of (u_{k+1} − u_k)²; default 0.01: a change of 3 rad/s² costs about
    /// as much as one step seeing 10 % less of the frontier.
    pub gamma: f64,
    /// Candidate angles N_c of the frontier surrogates; default 72 (5°).
    pub knots: usize,
    /// Gates and decay of the frontier utility.
    pub utility: UtilityConfig,
    /// Sequential-linearisation iterations; default 8.
    pub iterations: usize,
    /// Weight ρ of the proximal term (ρ/2)‖u − ū‖² that keeps each step local; default 0.05.
    /// Each update starts from ρ and moves between ρ·4^j, j = 0..4, like a trust region: a
    /// step the line search cuts to a quarter or less is followed by a QP with four times the
    /// weight, a full step by one with a quarter of it (never below ρ).
    pub proximal: f64,
    /// Which solver takes the QP steps; default [`QpBackend::Dedicated`].
    pub backend: QpBackend,
}

/// The solver of the convex QP in each linearisation step.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum QpBackend {
    /// The dedicated primal active-set solver for this structure: H⁻¹ precomputed once,
    /// warm-started from the current iterate, no allocation. Falls back to Clarabel if it
    /// cannot finish.
    #[default]
    Dedicated,
    /// Clarabel, the general interior-point reference.
    Clarabel,
}

impl Default for MpcConfig {
    fn default() -> Self {
        Self {
            horizon: 20,
            dt: 0.1,
            limits: MotorLimits::try_new(
                -core::f64::consts::PI,
                core::f64::consts::PI,
                core::f64::consts::TAU,
            )
            .unwrap_or_default(),
            alpha: 1.0,
            beta: 1.0,
            gamma: 0.01,
            knots: 72,
            utility: UtilityConfig::default(),
            iterations: 8,
            proximal: 0.05,
            backend: QpBackend::Dedicated,
        }
    }
}

impl MpcConfig {
    /// Checks every setting: the horizon in 1..=[`MAX_HORIZON`](crate::MAX_HORIZON), the knots
    /// in 1..=[`MAX_KNOTS`](crate::MAX_KNOTS), at most
    /// [`MAX_ITERATIONS`](crate::MAX_ITERATIONS) iterations, and the numbers below.
    ///
    /// # Errors
    /// [`CoreError::InvalidConfig`] naming the first setting out of range.
    pub fn validate(&self) -> Result<()> {
        if self.horizon == 0 {
            return invalid("horizon", 0.0, "must be at least 1");
        }
        if self.horizon > crate::MAX_HORIZON {
            return too_large("horizon", self.horizon, "at most MAX_HORIZON steps");
        }
        if self.iterations > crate::MAX_ITERATIONS {
            return too_large("iterations", self.iterations, "at most MAX_ITERATIONS");
        }
        if !(self.dt.is_finite() && self.dt > 0.0) {
            return invalid("dt", self.dt, "must be positive and finite [s]");
        }
        for (what, v) in [
            ("alpha", self.alpha),
            ("beta", self.beta),
            ("gamma", self.gamma),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return invalid(what, v, "must be >= 0 and finite");
            }
        }
        if !(self.proximal.is_finite() && self.proximal > 0.0) {
            return invalid("proximal", self.proximal, "must be positive and finite");
        }
        if self.knots == 0 {
            return invalid("knots", 0.0, "must be at least 1");
        }
        if self.knots > crate::MAX_KNOTS {
            return too_large("knots", self.knots, "at most MAX_KNOTS");
        }
        self.utility.validate()
    }
}

/// The cost of a solution, term by term.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct CostTerms {
    /// α Σ_k J_k(θ_k).
    pub frontier: f64,
    /// β Σ_k f(θ_k).
    pub localisation: f64,
    /// γ Σ_k (u_{k+1} − u_k)².
    pub smoothness: f64,
}

impl CostTerms {
    /// The total cost (19).
    pub fn total(&self) -> f64 {
        self.frontier + self.localisation + self.smoothness
    }
}

/// The full result of the last FU-MPC update.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct MpcSolution {
    /// The control sequence u_0..u_{N−1} \[rad/s²\].
    pub controls: Vec<f64>,
    /// Predicted states x_0..x_N along the reference.
    pub predicted: Vec<PredictedStep>,
    /// The cost of the sequence.
    pub cost: CostTerms,
    /// The cost of the best warm start (shifted previous solution or constant speed).
    pub warm_start_cost: f64,
    /// Sequential-linearisation iterations run.
    pub iterations: usize,
}

/// The FU-MPC scan controller (19)–(21): chooses the motor's angular accelerations so the
/// spinning LiDAR looks at frontiers while keeping localisation well constrained.
///
/// Each update: builds the per-step frontier surrogates J_k, starts from the best of the
/// shifted previous solution, constant-speed candidates and cruise-then-stop candidates
/// (dwells at the reachable angles), then repeats a convex QP in u
/// (the linearised surrogate costs, the smoothness term, a proximal term whose weight adapts
/// like a trust region, see [`MpcConfig::proximal`], |u| ≤ u_max and ω_min ≤ ω_k ≤ ω_max;
/// see [`QpBackend`]) and a backtracking line search on the true surrogate cost. The
/// terms are evaluated at the predicted states θ_1..θ_N, the ones the controls move (θ_0 is
/// fixed). Every sequence it considers satisfies (20)–(21), so the saturation of (11) stays
/// inactive and θ is affine in u (when ω_0 itself is outside the limits, the prediction
/// starts from the nearest limit). Weights so large that every sequence's cost overflows (α
/// or β near `f64::MAX`) make [`ScanController::command`] return [`CoreError::NonFinite`].
///
/// # Example
/// ```
/// use fu_mpc_core::{FrontierTarget, FuMpc, MpcConfig, ScanController, ScanInput};
/// use lidar_kinematics::{KinematicChain, MotorState};
/// use nalgebra::{Isometry3, Point3};
///
/// # fn main() -> Result<(), fu_mpc_core::CoreError> {
/// let config = MpcConfig { beta: 0.0, ..MpcConfig::default() };
/// let mut mpc = FuMpc::new(config, KinematicChain::default())?;
/// let reference = vec![Isometry3::identity(); config.horizon + 1];
/// let targets = [FrontierTarget { center: Point3::new(0.0, 4.0, 0.0), score: 50.0 }];
/// let input = ScanInput { motor: MotorState::new(0.0, 3.0), reference: &reference, targets: &targets, fisher: None };
/// let cmd = mpc.command(&input)?;
/// assert!(cmd.acceleration.abs() <= config.limits.u_max());
/// assert!(mpc.solution().cost.total() <= mpc.solution().warm_start_cost + 1e-12);
/// # Ok(()) }
/// ```
#[derive(Debug, Clone)]
pub struct FuMpc {
    config: MpcConfig,
    chain: KinematicChain,
    motor: MotorModel,
    name: &'static str,
    surrogates: Vec<PeriodicPwl>,
    /// α J_k + β f per step on the shared knots, when the Fisher table has the surrogates'
    /// knot count: one table lookup per step in the solver's many rollouts instead of two.
    combined: Vec<PeriodicPwl>,
    combined_valid: bool,
    previous: Vec<f64>,
    solution: MpcSolution,
    work: Work,
    /// One dedicated solver per proximal level ρ·4^j, j = 0..PROXIMAL_LEVELS.
    active: Vec<ActiveSet>,
}

impl FuMpc {
    /// A controller with the given settings and kinematic chain.
    ///
    /// # Errors
    /// An invalid `config`.
    pub fn new(config: MpcConfig, chain: KinematicChain) -> Result<Self> {
        config.validate()?;
        let n = config.horizon;
        let name = match (config.alpha > 0.0, config.beta > 0.0) {
            (true, true) => "fu-mpc",
            (false, true) => "uncertainty",
            (true, false) => "frontier",
            (false, false) => "smooth",
        };
        Ok(Self {
            config,
            chain,
            motor: MotorModel::new(config.limits),
            name,
            surrogates: Vec::new(),
            combined: Vec::new(),
            combined_valid: false,
            previous: vec![0.0; n],
            work: Work {
                best: vec![0.0; n],
                cand: vec![0.0; n],
                trial: vec![0.0; n],
                x: vec![0.0; n],
                slopes: vec![0.0; n],
                qp: StepQp {
                    n,
                    gamma: config.gamma,
                    rho: config.proximal,
                    q: vec![0.0; n],
                    u_max: config.limits.u_max(),
                    omega0: 0.0,
                    dt: config.dt,
                    w_lo: vec![config.limits.omega_min(); n],
                    w_hi: vec![config.limits.omega_max(); n],
                },
            },
            active: (0..PROXIMAL_LEVELS)
                .filter_map(|j| {
                    ActiveSet::new(
                        n,
                        config.gamma,
                        proximal_level(config.proximal, j),
                        config.dt,
                    )
                })
                .collect(),
            solution: MpcSolution {
                controls: vec![0.0; n],
                predicted: vec![PredictedStep::default(); n + 1],
                ..MpcSolution::default()
            },
        })
    }

    /// The uncertainty-only baseline (α = 0, like UA-MPC).
    ///
    /// # Errors
    /// An invalid `config`.
    pub fn uncertainty_only(config: MpcConfig, chain: KinematicChain) -> Result<Self> {
        Self::new(
            MpcConfig {
                alpha: 0.0,
                ..config
            },
            chain,
        )
    }

    /// The frontier-only baseline (β = 0).
    ///
    /// # Errors
    /// An invalid `config`.
    pub fn frontier_only(config: MpcConfig, chain: KinematicChain) -> Result<Self> {
        Self::new(
            MpcConfig {
                beta: 0.0,
                ..config
            },
            chain,
        )
    }

    /// The settings.
    pub fn config(&self) -> &MpcConfig {
        &self.config
    }

    /// The last update's full result.
    pub fn solution(&self) -> &MpcSolution {
        &self.solution
    }

    /// Forgets the previous solution (the next warm start is constant-speed only).
    pub fn reset(&mut self) {
        self.previous.fill(0.0);
    }

    /// The per-step frontier surrogates J_0..J_N of the last update.
    pub fn surrogates(&self) -> &[PeriodicPwl] {
        &self.surrogates
    }

    /// The cost terms of a control sequence for `input`: the surrogates are rebuilt for it and
    /// the sequence is first clipped to the limits (as every sequence the solver considers).
    ///
    /// # Errors
    /// As [`ScanController::command`], and [`CoreError::LengthMismatch`] unless
    /// `controls.len()` is the horizon.
    pub fn evaluate(&mut self, input: &ScanInput<'_>, controls: &[f64]) -> Result<CostTerms> {
        self.check(input)?;
        if controls.len() != self.config.horizon {
            return Err(CoreError::LengthMismatch {
                what: "controls",
                expected: self.config.horizon,
                found: controls.len(),
            });
        }
        self.build_surrogates(input)?;
        let l = self.config.limits;
        let omega0 = input.motor.omega.clamp(l.omega_min(), l.omega_max());
        let mut u = controls.to_vec();
        self.make_feasible(omega0, &mut u);
        Ok(self.cost(
            input.motor.theta,
            omega0,
            &u,
            input.fisher.map(|f| f.cost()),
        ))
    }

    fn check(&self, input: &ScanInput<'_>) -> Result<()> {
        let n = self.config.horizon;
        if input.reference.len() != n + 1 {
            return Err(CoreError::LengthMismatch {
                what: "reference poses (horizon + 1)",
                expected: n + 1,
                found: input.reference.len(),
            });
        }
        if !(input.motor.theta.is_finite() && input.motor.omega.is_finite()) {
            return Err(CoreError::NonFinite {
                what: "motor state",
            });
        }
        Ok(())
    }

    fn build_surrogates(&mut self, input: &ScanInput<'_>) -> Result<()> {
        let mut surrogates = core::mem::take(&mut self.surrogates);
        let built = frontier_surrogates(
            &self.chain,
            input.reference,
            input.targets,
            &self.config.utility,
            self.config.knots,
            &mut surrogates,
        );
        self.surrogates = surrogates;
        built
    }

    /// Clips `u` in place so that |u_k| ≤ u_max and every ω_k stays in the limits.
    fn make_feasible(&self, omega0: f64, u: &mut [f64]) {
        let mut w = omega0;
        for x in u.iter_mut() {
            *x = self.clip(&mut w, *x);
        }
    }

    /// One step of [`FuMpc::make_feasible`]: `x` clipped so that |x| ≤ u_max and the speed
    /// `w` after it stays in the limits (0 for a non-finite `x`); `w` moves on by the step.
    #[inline]
    fn clip(&self, w: &mut f64, x: f64) -> f64 {
        let l = &self.config.limits;
        let dt = self.config.dt;
        let inv_dt = 1.0 / dt;
        let lo = ((l.omega_min() - *w) * inv_dt).max(-l.u_max());
        let hi = ((l.omega_max() - *w) * inv_dt).min(l.u_max());
        let x = if x.is_finite() {
            x.clamp(lo, hi)
        } else {
            0.0f64.clamp(lo, hi)
        };
        *w = (*w + x * dt).clamp(l.omega_min(), l.omega_max());
        x
    }

    /// The cost terms of a feasible sequence, with θ from the affine model.
    fn cost(&self, theta0: f64, omega0: f64, u: &[f64], fisher: Option<&PeriodicPwl>) -> CostTerms {
        self.rollout(theta0, omega0, u, fisher, None)
    }

    /// Rolls a feasible sequence out through the affine model, eqs. (11)–(12), and returns its
    /// cost terms; with `slopes`, also writes s_k = α J_k'(θ_k) + β f'(θ_k), k = 1..N.
    fn rollout(
        &self,
        theta0: f64,
        omega0: f64,
        u: &[f64],
        fisher: Option<&PeriodicPwl>,
        mut slopes: Option<&mut [f64]>,
    ) -> CostTerms {
        let c = &self.config;
        let (mut th, mut w) = (theta0, omega0);
        let mut t = CostTerms::default();
        for (k, x) in u.iter().enumerate() {
            w += x * c.dt; // eq. (11), inside the limits
            th += w * c.dt; // eq. (12)
            let mut slope = 0.0;
            if c.alpha > 0.0 {
                let (v, d) = self.surrogates[k + 1].eval(th);
                t.frontier += c.alpha * v;
                slope += c.alpha * d;
            }
            if let (Some(f), true) = (fisher, c.beta > 0.0) {
                let (v, d) = f.eval(th);
                t.localisation += c.beta * v;
                slope += c.beta * d;
            }
            if let Some(s) = slopes.as_deref_mut() {
                s[k] = slope;
            }
            if k + 1 < u.len() {
                let d = u[k + 1] - x;
                t.smoothness += c.gamma * d * d;
            }
        }
        t
    }

    /// Fills the combined tables α J_k + β f for steps 1..N when f shares the surrogates'
    /// knots (or is absent); otherwise marks them invalid and the solver evaluates the terms
    /// apart.
    fn build_combined(&mut self, fisher: Option<&PeriodicPwl>) -> Result<()> {
        let c = &self.config;
        let knots = c.knots;
        self.combined_valid = fisher.is_none_or(|f| f.len() == knots);
        if !self.combined_valid {
            return Ok(());
        }
        let n = c.horizon;
        if self.combined.len() != n || self.combined.iter().any(|f| f.len() != knots) {
            self.combined.clear();
            for _ in 0..n {
                self.combined.push(PeriodicPwl::new(vec![0.0; knots])?);
            }
        }
        let (alpha, beta) = (c.alpha, c.beta);
        for (table, j) in self.combined.iter_mut().zip(&self.surrogates[1..]) {
            for (i, (x, jv)) in table.values_mut().iter_mut().zip(j.values()).enumerate() {
                let mut v = 0.0;
                if alpha > 0.0 {
                    v += alpha * jv;
                }
                if let (Some(f), true) = (fisher, beta > 0.0) {
                    v += beta * f.values()[i];
                }
                *x = v;
            }
        }
        Ok(())
    }

    /// The total cost (19) of a feasible sequence and, with `slopes`, its θ-slopes per step,
    /// from the combined tables when they are valid.
    fn total(
        &self,
        theta0: f64,
        omega0: f64,
        u: &[f64],
        fisher: Option<&PeriodicPwl>,
        slopes: Option<&mut [f64]>,
    ) -> f64 {
        if !self.combined_valid {
            return self.rollout(theta0, omega0, u, fisher, slopes).total();
        }
        let c = &self.config;
        let (mut th, mut w) = (theta0, omega0);
        let mut cost = 0.0;
        let mut smooth = 0.0;
        let mut prev = u.first().copied().unwrap_or(0.0);
        let mut slopes = slopes;
        for (k, (x, table)) in u.iter().zip(&self.combined).enumerate() {
            w += x * c.dt; // eq. (11), inside the limits
            th += w * c.dt; // eq. (12)
            let (v, d) = table.eval(th);
            cost += v;
            if let Some(s) = slopes.as_deref_mut() {
                s[k] = d;
            }
            let du = x - prev;
            smooth += du * du;
            prev = *x;
        }
        cost + c.gamma * smooth
    }

    /// [`FuMpc::make_feasible`] then [`FuMpc::total`] of `u`, in one pass over the
    /// sequence when the combined tables are valid (the same operations in the same order,
    /// so the same sequence and cost to the bit).
    fn feasible_total(
        &self,
        theta0: f64,
        omega0: f64,
        u: &mut [f64],
        fisher: Option<&PeriodicPwl>,
    ) -> f64 {
        if !self.combined_valid {
            self.make_feasible(omega0, u);
            return self.total(theta0, omega0, u, fisher, None);
        }
        let c = &self.config;
        let dt = c.dt;
        // The clipped speed of `make_feasible` and the unclipped one of `total`.
        let mut wf = omega0;
        let (mut th, mut w) = (theta0, omega0);
        let (mut cost, mut smooth) = (0.0, 0.0);
        let mut prev = 0.0;
        for (k, (x, table)) in u.iter_mut().zip(&self.combined).enumerate() {
            *x = self.clip(&mut wf, *x);
            w += *x * dt; // eq. (11), inside the limits
            th += w * dt; // eq. (12)
            let (v, _) = table.eval(th);
            cost += v;
            if k == 0 {
                prev = *x;
            }
            let du = *x - prev;
            smooth += du * du;
            prev = *x;
        }
        cost + c.gamma * smooth
    }

    fn solve(&mut self, input: &ScanInput<'_>) -> Result<ScanStatus> {
        let c = self.config;
        let n = c.horizon;
        let l = c.limits;
        // The cost tables are 2π-periodic: the reduced angle keeps their lookups on the
        // one-turn fast path.
        let theta0 = input.motor.theta.rem_euclid(core::f64::consts::TAU);
        let omega0 = input.motor.omega.clamp(l.omega_min(), l.omega_max());
        let fisher = input.fisher.map(|f| f.cost());
        self.build_surrogates(input)?;
        self.build_combined(fisher)?;
        let mut w = core::mem::take(&mut self.work);
        // Warm starts: the shifted previous solution, constant-speed and cruise-then-stop
        // sequences.
        w.best.copy_from_slice(&self.previous);
        w.best.rotate_left(1);
        w.best[n - 1] = self.previous[n - 1];
        self.make_feasible(omega0, &mut w.best);
        let mut best_cost = self.total(theta0, omega0, &w.best, fisher, None);
        let consider = |this: &Self, w: &mut Work, best_cost: &mut f64| {
            let cc = this.total(theta0, omega0, &w.cand, fisher, None);
            if cc < *best_cost {
                *best_cost = cc;
                w.best.copy_from_slice(&w.cand);
            }
        };
        // Each candidate is built feasible (the clipping of `make_feasible` applied as it goes).
        let fill = |cand: &mut [f64], cruise: f64, m: usize, stop: f64| {
            let mut speed = omega0;
            for (k, x) in cand.iter_mut().enumerate() {
                let target = if k < m { cruise } else { stop };
                *x = toward(&l, c.dt, &mut speed, target);
            }
        };
        for target in [
            l.omega_min(),
            l.omega_max(),
            0.5 * (l.omega_min() + l.omega_max()),
            omega0,
        ] {
            fill(&mut w.cand, target, n, target);
            consider(self, &mut w, &mut best_cost);
        }
        // Cruise at ω0, ω_max or ω_min, then slow to the speed nearest zero from step m, so
        // a dwell at any reachable angle is among the starts (the surrogates have many local
        // minima; the linearised steps only refine).
        let stop = 0.0f64.clamp(l.omega_min(), l.omega_max());
        for cruise in [omega0, l.omega_max(), l.omega_min()] {
            if self.combined_valid {
                // The candidates of one cruise speed share their cruise phase: it is rolled
                // out once, and each candidate continues from its state (the same operations
                // in the same order as `fill` and `total`, so the same costs to the bit).
                let mut head = Cruise::new(theta0, omega0);
                for m in 0..n {
                    if m % 2 == 0 {
                        let mut tail = head;
                        for k in m..n {
                            tail.step(self, stop, k);
                        }
                        let cc = tail.cost + c.gamma * tail.smooth;
                        if cc < best_cost {
                            best_cost = cc;
                            fill(&mut w.best, cruise, m, stop);
                        }
                    }
                    head.step(self, cruise, m);
                }
            } else {
                for m in (0..n).step_by(2) {
                    fill(&mut w.cand, cruise, m, stop);
                    consider(self, &mut w, &mut best_cost);
                }
            }
        }
        self.solution.warm_start_cost = best_cost;
        if !best_cost.is_finite() {
            // Weights so large that every sequence's cost overflows (α or β near f64::MAX):
            // no sequence is better than another.
            self.work = w;
            return Err(CoreError::NonFinite {
                what: "weighted cost (alpha, beta or gamma too large)",
            });
        }
        // Sequential linearisation.
        let mut cost = best_cost;
        let mut status = ScanStatus::IterationLimit;
        let mut iterations = 0;
        let dt2 = c.dt * c.dt;
        w.qp.omega0 = omega0;
        let mut level = 0;
        for _ in 0..c.iterations {
            iterations += 1;
            self.total(theta0, omega0, &w.best, fisher, Some(&mut w.slopes));
            // q_j = Σ_{k>j} s_k Δt² (k − j) − ρ ū_j: θ_k moves by Δt²(k − j) per unit of u_j.
            let (mut acc, mut weighted) = (0.0, 0.0);
            for j in (0..n).rev() {
                acc += w.slopes[j];
                weighted += acc;
                w.qp.q[j] = dt2 * weighted - proximal_level(c.proximal, level) * w.best[j];
            }
            // The QP step from the feasible current iterate.
            w.x.copy_from_slice(&w.best);
            w.qp.rho = proximal_level(c.proximal, level);
            let solved = match (c.backend, self.active.get_mut(level)) {
                (QpBackend::Dedicated, Some(active)) if active.fits(&w.qp) => {
                    active.solve(&w.qp, &mut w.x)
                }
                _ => false,
            } || match w.qp.solve_clarabel() {
                Some(x) => {
                    w.x.copy_from_slice(&x);
                    true
                }
                None => false,
            };
            if !solved {
                status = ScanStatus::Fallback;
                break;
            }
            // Backtracking on the true surrogate cost.
            let mut t = 1.0;
            let mut accepted = false;
            for halvings in 0..10usize {
                for j in 0..n {
                    w.trial[j] = w.best[j] + t * (w.x[j] - w.best[j]);
                }
                let tc = self.feasible_total(theta0, omega0, &mut w.trial, fisher);
                if tc < cost - 1e-12 * (1.0 + cost.abs()) {
                    w.best.copy_from_slice(&w.trial);
                    cost = tc;
                    accepted = true;
                    // Trust-region rule: a full step widens the next one, a short one
                    // narrows it.
                    level = if halvings == 0 {
                        level.saturating_sub(1)
                    } else {
                        (level + usize::from(halvings >= 2)).min(PROXIMAL_LEVELS - 1)
                    };
                    break;
                }
                t *= 0.5;
            }
            if !accepted {
                status = ScanStatus::Converged;
                break;
            }
        }
        self.solution.cost = self.cost(theta0, omega0, &w.best, fisher);
        self.solution.iterations = iterations;
        self.solution.controls.copy_from_slice(&w.best);
        self.previous.copy_from_slice(&w.best);
        self.work = w;
        // The reported prediction comes from the motor model itself, eqs. (11)–(14).
        predict_into(
            &self.chain,
            &self.motor,
            input.motor,
            &self.solution.controls,
            c.dt,
            input.reference,
            &mut self.solution.predicted,
        )?;
        Ok(status)
    }
}

/// The control that moves `speed` toward `target` in one step as far as the limits allow,
/// and the speed after it (clipped as [`FuMpc::make_feasible`] clips).
#[inline]
fn toward(l: &MotorLimits, dt: f64, speed: &mut f64, target: f64) -> f64 {
    let inv_dt = 1.0 / dt;
    let lo = ((l.omega_min() - *speed) * inv_dt).max(-l.u_max());
    let hi = ((l.omega_max() - *speed) * inv_dt).min(l.u_max());
    let x = ((target - *speed) * inv_dt).clamp(lo, hi);
    *speed = (*speed + x * dt).clamp(l.omega_min(), l.omega_max());
    x
}

/// The state of a warm-start candidate's rollout after some steps: the clipped speed of the
/// candidate's construction and the running terms of [`FuMpc::total`] on the combined tables.
#[derive(Debug, Clone, Copy)]
struct Cruise {
    speed: f64,
    theta: f64,
    omega: f64,
    cost: f64,
    smooth: f64,
    prev: f64,
}

impl Cruise {
    fn new(theta0: f64, omega0: f64) -> Self {
        Self {
            speed: omega0,
            theta: theta0,
            omega: omega0,
            cost: 0.0,
            smooth: 0.0,
            prev: 0.0,
        }
    }

    /// Step `k` toward speed `target`: the control of `fill`, then the terms of `total`.
    fn step(&mut self, mpc: &FuMpc, target: f64, k: usize) {
        let c = &mpc.config;
        let x = toward(&c.limits, c.dt, &mut self.speed, target);
        self.omega += x * c.dt; // eq. (11), inside the limits
        self.theta += self.omega * c.dt; // eq. (12)
        let (v, _) = mpc.combined[k].eval(self.theta);
        self.cost += v;
        if k == 0 {
            // `total` starts from the sequence's first control: no change at step 0.
            self.prev = x;
        }
        let du = x - self.prev;
        self.smooth += du * du;
        self.prev = x;
    }
}

/// Number of proximal levels ρ·4^j the solver moves between.
const PROXIMAL_LEVELS: usize = 5;

/// The proximal weight of level `j`: ρ·4^j.
fn proximal_level(rho: f64, j: usize) -> f64 {
    let mut r = rho;
    for _ in 0..j {
        r *= 4.0;
    }
    r
}

/// Buffers of one update, kept between updates so a solve allocates nothing.
#[derive(Debug, Clone, Default)]
struct Work {
    best: Vec<f64>,
    cand: Vec<f64>,
    trial: Vec<f64>,
    x: Vec<f64>,
    slopes: Vec<f64>,
    qp: StepQp,
}

impl ScanController for FuMpc {
    fn name(&self) -> &str {
        self.name
    }

    fn command(&mut self, input: &ScanInput<'_>) -> Result<ScanCommand> {
        self.check(input)?;
        let status = self.solve(input)?;
        Ok(ScanCommand {
            acceleration: self.solution.controls[0],
            status,
        })
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;
    use crate::FrontierTarget;
    use lidar_kinematics::MotorState;
    use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};

    /// A default controller with its surrogates built along a reference flying at 1 m/s in x
    /// and `vy` in y at height `z` while yawing at `yaw_rate`, and its combined tables built
    /// with `fisher`.
    fn prepared(
        vy: f64,
        z: f64,
        yaw_rate: f64,
        targets: &[FrontierTarget],
        fisher: &PeriodicPwl,
    ) -> FuMpc {
        let cfg = MpcConfig::default();
        let mut mpc = FuMpc::new(cfg, KinematicChain::default()).unwrap();
        let refs: Vec<_> = (0..=cfg.horizon)
            .map(|i| {
                let t = 0.1 * f64::from(u32::try_from(i).unwrap());
                Isometry3::from_parts(
                    Translation3::new(t, vy * t, z),
                    UnitQuaternion::from_axis_angle(&Vector3::z_axis(), yaw_rate * t),
                )
            })
            .collect();
        let input = ScanInput {
            motor: MotorState::new(0.0, 0.0),
            reference: &refs,
            targets,
            fisher: None,
        };
        mpc.build_surrogates(&input).unwrap();
        mpc.build_combined(Some(fisher)).unwrap();
        mpc
    }

    /// A cruise-then-stop candidate rolled out from the shared cruise phase costs, to the
    /// bit, what the whole sequence costs.
    #[test]
    fn shared_cruise_phases_cost_what_whole_sequences_cost() {
        let cfg = MpcConfig::default();
        let n = cfg.horizon;
        let targets = [
            FrontierTarget {
                center: Point3::new(2.0, 3.0, 0.5),
                score: 10.0,
            },
            FrontierTarget {
                center: Point3::new(-4.0, -1.0, 0.0),
                score: 30.0,
            },
        ];
        let fisher =
            PeriodicPwl::new((0..72).map(|c| 1.0 + (0.2 * f64::from(c)).cos()).collect()).unwrap();
        let mpc = prepared(-0.4, 0.2, -0.5, &targets, &fisher);
        let l = cfg.limits;
        let mut u = vec![0.0; n];
        for (theta0, omega0) in [(0.3, 1.0), (5.9, -3.1), (2.0, 0.0), (1.0, 3.0)] {
            for cruise in [omega0, l.omega_max(), l.omega_min(), 0.5] {
                let mut head = Cruise::new(theta0, omega0);
                for m in 0..n {
                    let mut tail = head;
                    for k in m..n {
                        tail.step(&mpc, 0.0, k);
                    }
                    let mut speed = omega0;
                    for (k, x) in u.iter_mut().enumerate() {
                        *x = toward(&l, cfg.dt, &mut speed, if k < m { cruise } else { 0.0 });
                    }
                    let whole = mpc.total(theta0, omega0, &u, Some(&fisher), None);
                    let shared = tail.cost + cfg.gamma * tail.smooth;
                    assert_eq!(shared.to_bits(), whole.to_bits(), "{m} {shared} {whole}");
                    head.step(&mpc, cruise, m);
                }
            }
        }
    }

    /// The line search's one-pass clip and cost give what clipping and then costing give, to
    /// the bit, for sequences inside, outside and far outside the limits, with NaN too.
    #[test]
    fn one_pass_clip_and_cost_match_the_two_passes() {
        let n = MpcConfig::default().horizon;
        let targets = [FrontierTarget {
            center: Point3::new(3.0, -2.0, 0.5),
            score: 12.0,
        }];
        let fisher =
            PeriodicPwl::new((0..72).map(|c| 1.5 + (0.4 * f64::from(c)).sin()).collect()).unwrap();
        let mpc = prepared(0.3, 0.1, 0.4, &targets, &fisher);
        assert!(mpc.combined_valid);
        for seed in 0..200u32 {
            let scale = [0.5, 6.0, 40.0][(seed % 3) as usize];
            let mut u: Vec<f64> = (0..n)
                .map(|k| {
                    let k = f64::from(u32::try_from(k).unwrap());
                    (f64::from(seed) * 0.37 + 1.3 * k).sin() * scale
                })
                .collect();
            if seed % 7 == 0 {
                u[(seed as usize) % n] = f64::NAN;
            }
            let (theta0, omega0) = (0.1 * f64::from(seed), -3.0 + 0.03 * f64::from(seed));
            let mut a = u.clone();
            mpc.make_feasible(omega0, &mut a);
            let want = mpc.total(theta0, omega0, &a, Some(&fisher), None);
            let mut b = u;
            let got = mpc.feasible_total(theta0, omega0, &mut b, Some(&fisher));
            assert_eq!(got.to_bits(), want.to_bits(), "seed {seed}");
            for (x, y) in a.iter().zip(&b) {
                assert_eq!(x.to_bits(), y.to_bits(), "seed {seed}");
            }
        }
    }

    /// The combined tables give the same total as the terms evaluated apart.
    #[test]
    fn combined_tables_match_the_separate_terms() {
        let cfg = MpcConfig::default();
        let fisher =
            PeriodicPwl::new((0..72).map(|c| 2.0 + (0.3 * f64::from(c)).sin()).collect()).unwrap();
        let targets = [
            FrontierTarget {
                center: Point3::new(3.0, 1.0, 0.0),
                score: 20.0,
            },
            FrontierTarget {
                center: Point3::new(-2.0, 4.0, 1.0),
                score: 5.0,
            },
        ];
        let mut mpc = prepared(0.5, 0.0, 0.3, &targets, &fisher);
        assert!(mpc.combined_valid);
        let mut s1 = vec![0.0; cfg.horizon];
        let mut s2 = vec![0.0; cfg.horizon];
        for seed in 0..20u32 {
            let mut u: Vec<f64> = (0..cfg.horizon)
                .map(|k| {
                    (f64::from(seed) * 1.7 + 0.9 * f64::from(u32::try_from(k).unwrap())).sin() * 6.0
                })
                .collect();
            mpc.make_feasible(1.0, &mut u);
            let a = mpc.total(0.4, 1.0, &u, Some(&fisher), Some(&mut s1));
            let b = mpc
                .rollout(0.4, 1.0, &u, Some(&fisher), Some(&mut s2))
                .total();
            assert!((a - b).abs() <= 1e-12 * (1.0 + b.abs()), "{a} vs {b}");
            for (x, y) in s1.iter().zip(&s2) {
                assert!((x - y).abs() <= 1e-9 * (1.0 + y.abs()), "{x} vs {y}");
            }
        }
        // A table on another grid is evaluated apart.
        let coarse = PeriodicPwl::new(vec![1.0; 36]).unwrap();
        mpc.build_combined(Some(&coarse)).unwrap();
        assert!(!mpc.combined_valid);
    }
}
