//! iCR's reward over a control sequence, its gradient (Proposition 1) and Algorithm 1.

use lidar_kinematics::se3;
use nalgebra::{Isometry3, Matrix3, Vector3, Vector6};
use rayon::prelude::*;

use super::fov::{FovSdf, Probit};
use super::map::{InformationMap, Prior};
use crate::Result;
use crate::error::{CoreError, invalid, too_large};

/// Settings of iCR. The defaults are those of the paper's evaluation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IcrConfig {
    /// Horizon K (controls u₀..u_{K−1}, poses T₁..T_K); default 5.
    pub horizon: usize,
    /// Time step τ of the motion model (1) \[s\]; default 0.5.
    pub tau: f64,
    /// Measurement noise σ inside the field of view, eq. (17) \[map units\]; default 1.
    pub sigma: f64,
    /// Smoothing κ of the probit (20) \[m²\]; default 0.5.
    pub kappa: f64,
    /// Gradient-ascent iterations of Algorithm 1; default 10.
    pub iterations: usize,
    /// Step sizes γ⁽ⁱ⁾ of eq. (22) per control component [v; ω]; 0 keeps a component fixed.
    /// Default: only the yaw rate ω_z moves (0.05), as in the planar experiment.
    pub step: [f64; 6],
    /// Bound |u⁽ⁱ⁾| ≤ max_control\[i\] applied after each step (a projection); default ∞.
    pub max_control: [f64; 6],
}

impl Default for IcrConfig {
    fn default() -> Self {
        Self {
            horizon: 5,
            tau: 0.5,
            sigma: 1.0,
            kappa: 0.5,
            iterations: 10,
            step: [0.0, 0.0, 0.0, 0.0, 0.0, 0.05],
            max_control: [f64::INFINITY; 6],
        }
    }
}

impl IcrConfig {
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
        if !(self.tau.is_finite() && self.tau > 0.0) {
            return invalid("tau", self.tau, "must be positive and finite");
        }
        if !(self.sigma.is_finite() && self.sigma > 0.0) {
            return invalid("sigma", self.sigma, "must be positive and finite");
        }
        if !(self.kappa.is_finite() && self.kappa > 0.0) {
            return invalid("kappa", self.kappa, "must be positive and finite");
        }
        if let Some(&g) = self.step.iter().find(|g| !(g.is_finite() && **g >= 0.0)) {
            return invalid("step", g, "must be non-negative and finite");
        }
        if let Some(&b) = self.max_control.iter().find(|b| b.is_nan() || **b < 0.0) {
            return invalid("max_control", b, "must be non-negative");
        }
        Ok(())
    }
}

/// What one run of [`Icr::plan`] did.
#[derive(Debug, Clone, PartialEq)]
pub struct IcrReport {
    /// The reward log det Y_K before each iteration and after the last (iterations + 1 values).
    pub rewards: Vec<f64>,
    /// The iteration whose controls were kept (0: the initial ones).
    pub best_iteration: usize,
}

/// Per cell and pose: the body-frame point q and (∂V⁻¹/∂d)·∇d.
#[derive(Debug, Clone, Copy, Default)]
struct CellSlope {
    q: Vector3<f64>,
    g: Vector3<f64>,
}

/// iCR: gradient ascent on r(U) = log det Y_K over a control sequence U on SE(3).
///
/// Y_K = Y₀ + Σ_{s=1..K} M(T_s), eq. (11), with M(T) = diag((1 − Φ(d(q_j)))/σ²), eqs. (12),
/// (21), q_j = T⁻¹ p_j the cells in the body frame, eq. (14), and T_{k+1} = T_k exp(τ û_k),
/// eq. (1). The gradient of Proposition 1 is evaluated in O(nK) rather than the O(nK²) of
/// the Λ recursion (26): with ξ = 𝒥_L(τu_k) e_i (Lemma 1), eq. (25) reads
/// ∂q/∂u_k⁽ⁱ⁾ = −(ρ + φ × q) for [ρ; φ] = τ Ad(T_s⁻¹T_k) ξ, so
///
/// ∂r/∂u_k = τ 𝒥_L(τu_k)ᵀ Ψ_k,  Ψ_k = Σ_{s>k} Ad(T_s⁻¹T_k)ᵀ Γ_s = Ad(E_k⁻¹)ᵀ (Γ_{k+1} + Ψ_{k+1}),
///
/// where E_k = exp(τû_k) and Γ_s = −Σ_j (Y_K⁻¹)_jj (∂V⁻¹_jj/∂d) [∇d; q_j × ∇d] collects
/// eqs. (23)–(24) for pose s. (The tests check it against the Λ recursion and against finite
/// differences.)
///
/// # Example
/// ```
/// use fu_mpc_core::icr::{Icr, IcrConfig, InformationMap, Triangle};
/// use nalgebra::{Isometry3, Point3, Vector6};
///
/// # fn main() -> Result<(), fu_mpc_core::CoreError> {
/// // A 10 m × 10 m grid of unknown cells (Σ₀ = 100 I) and the paper's triangle.
/// let cells: Vec<Point3<f64>> = (0..2500)
///     .map(|i| Point3::new(f64::from(i % 50) * 0.2 - 5.0, f64::from(i / 50) * 0.2 - 5.0, 0.0))
///     .collect();
/// let map = InformationMap::diagonal(cells, vec![0.01; 2500])?;
/// let fov = Triangle::new(3.0, 30f64.to_radians())?;
/// let mut icr = Icr::new(IcrConfig::default(), fov)?;
/// let mut u = vec![Vector6::new(1.5, 0.0, 0.0, 0.0, 0.0, 0.3); 5];
/// let report = icr.plan(&map, &Isometry3::identity(), &mut u)?;
/// assert!(report.rewards[report.best_iteration] >= report.rewards[0]);
/// # Ok(()) }
/// ```
#[derive(Debug, Clone)]
pub struct Icr<F> {
    config: IcrConfig,
    fov: F,
    probit: Probit,
    slopes: Vec<CellSlope>,
    m: Vec<f64>,
    inv_diag: Vec<f64>,
    poses: Vec<Isometry3<f64>>,
}

impl<F: FovSdf> Icr<F> {
    /// A planner with `config` and field of view `fov`.
    ///
    /// # Errors
    /// [`CoreError::InvalidConfig`] for bad settings.
    pub fn new(config: IcrConfig, fov: F) -> Result<Self> {
        config.validate()?;
        Ok(Self {
            config,
            fov,
            probit: Probit::new(config.kappa)?,
            slopes: Vec::new(),
            m: Vec::new(),
            inv_diag: Vec::new(),
            poses: Vec::new(),
        })
    }

    /// The settings.
    pub fn config(&self) -> &IcrConfig {
        &self.config
    }

    /// The field of view.
    pub fn fov(&self) -> &F {
        &self.fov
    }

    /// The information M(T) one pose adds to each cell, V⁻¹_jj of eq. (21), written to `out`.
    ///
    /// # Errors
    /// [`CoreError::NonFinite`] for a bad pose, [`CoreError::LengthMismatch`] for `out`.
    pub fn information_at(
        &self,
        map: &InformationMap,
        pose: &Isometry3<f64>,
        out: &mut [f64],
    ) -> Result<()> {
        check_pose(pose)?;
        if out.len() != map.len() {
            return Err(CoreError::LengthMismatch {
                what: "information buffer",
                expected: map.len(),
                found: out.len(),
            });
        }
        let inv = pose.inverse();
        for (o, p) in out.iter_mut().zip(map.cells()) {
            let (d, _) = self.fov.sdf(&(inv * p).coords);
            *o = self.probit.inverse_noise(d, self.config.sigma).0;
        }
        Ok(())
    }

    fn check(
        &self,
        map: &InformationMap,
        start: &Isometry3<f64>,
        u: &[Vector6<f64>],
    ) -> Result<()> {
        check_pose(start)?;
        if u.len() != self.config.horizon {
            return Err(CoreError::LengthMismatch {
                what: "controls",
                expected: self.config.horizon,
                found: u.len(),
            });
        }
        if !u.iter().all(|v| v.iter().all(|x| x.is_finite())) {
            return Err(CoreError::NonFinite { what: "controls" });
        }
        if map.is_empty() {
            return Err(CoreError::Empty { what: "map cells" });
        }
        Ok(())
    }

    /// The poses T₁..T_K of eq. (1) from `start`.
    fn roll_out(&mut self, start: &Isometry3<f64>, u: &[Vector6<f64>]) {
        self.poses.clear();
        let mut t = *start;
        for uk in u {
            t *= se3::exp(&(uk * self.config.tau));
            self.poses.push(t);
        }
    }

    /// The reward r(U) = log det Y_K, eq. (8), of the controls `u` from pose `start`.
    ///
    /// # Errors
    /// [`CoreError::LengthMismatch`] unless `u` has K entries, [`CoreError::NonFinite`] for
    /// NaN poses or controls, or controls so large that the reward is not finite,
    /// [`CoreError::NotPositiveDefinite`] if a dense Y_K cannot be factorised.
    pub fn reward(
        &mut self,
        map: &InformationMap,
        start: &Isometry3<f64>,
        u: &[Vector6<f64>],
    ) -> Result<f64> {
        self.check(map, start, u)?;
        self.roll_out(start, u);
        self.m.clear();
        self.m.resize(map.len(), 0.0);
        let frames = frames(&self.poses);
        let (fov, probit, sigma) = (&self.fov, &self.probit, self.config.sigma);
        self.m
            .par_chunks_mut(CHUNK)
            .zip(map.cells().par_chunks(CHUNK))
            .for_each(|(m, cells)| {
                for (mj, p) in m.iter_mut().zip(cells) {
                    for (rot, tr) in &frames {
                        let (d, _) = fov.sdf(&(rot * p.coords + tr));
                        *mj += probit.inverse_noise(d, sigma).0;
                    }
                }
            });
        let reward = map.log_det_with(&self.m, None)?;
        // Finite controls so large that the poses overflow give no reward, as in
        // `reward_and_gradient`.
        if !reward.is_finite() {
            return Err(CoreError::NonFinite { what: "reward" });
        }
        Ok(reward)
    }

    /// The reward and its gradient ∂r/∂u_k (Proposition 1), written to `grad`.
    ///
    /// # Errors
    /// As [`Icr::reward`]; [`CoreError::LengthMismatch`] for `grad`.
    pub fn reward_and_gradient(
        &mut self,
        map: &InformationMap,
        start: &Isometry3<f64>,
        u: &[Vector6<f64>],
        grad: &mut [Vector6<f64>],
    ) -> Result<f64> {
        self.check(map, start, u)?;
        if grad.len() != u.len() {
            return Err(CoreError::LengthMismatch {
                what: "gradient",
                expected: u.len(),
                found: grad.len(),
            });
        }
        let (n, k_len) = (map.len(), u.len());
        self.roll_out(start, u);
        let frames = frames(&self.poses);
        let (reward, gamma) = if let Prior::Diagonal(y0) = &map.prior {
            fused_diagonal(
                &frames,
                &self.fov,
                &self.probit,
                self.config.sigma,
                map.cells(),
                y0,
            )
        } else {
            self.two_pass(map, &frames, n, k_len)?
        };
        // Backward: Ψ_k = Ad(E_k⁻¹)ᵀ (Γ_{k+1} + Ψ_{k+1}), the Λ recursion (26) in adjoint form.
        let tau = self.config.tau;
        let mut psi = Vector6::zeros();
        for k in (0..k_len).rev() {
            let xi = u[k] * tau;
            let step_inv = se3::exp(&xi).inverse();
            psi = se3::adjoint(&step_inv).transpose() * (gamma[k] + psi);
            // Lemma 1, eq. (28).
            grad[k] = se3::left_jacobian(&xi).transpose() * psi * tau;
        }
        if !reward.is_finite() || !grad.iter().all(|g| g.iter().all(|v| v.is_finite())) {
            return Err(CoreError::NonFinite { what: "reward" });
        }
        Ok(reward)
    }

    /// Reward and Γ_s for a dense prior: M and the slopes first, then (Y_K⁻¹)_jj from the
    /// factorisation, then Γ.
    fn two_pass(
        &mut self,
        map: &InformationMap,
        frames: &[(Matrix3<f64>, Vector3<f64>)],
        n: usize,
        k_len: usize,
    ) -> Result<(f64, Vec<Vector6<f64>>)> {
        self.m.clear();
        self.m.resize(n, 0.0);
        self.slopes.clear();
        self.slopes.resize(n * k_len, CellSlope::default());
        // Forward: M(T_s) and the slopes of V⁻¹ for every cell and pose (cell-major), in
        // fixed chunks of cells so the result does not depend on the thread count.
        let (fov, probit, sigma) = (&self.fov, &self.probit, self.config.sigma);
        self.m
            .par_chunks_mut(CHUNK)
            .zip(self.slopes.par_chunks_mut(CHUNK * k_len))
            .zip(map.cells().par_chunks(CHUNK))
            .for_each(|((m, slopes), cells)| {
                for ((mj, p), row) in m.iter_mut().zip(cells).zip(slopes.chunks_mut(k_len)) {
                    *mj = cell_terms(frames, fov, probit, sigma, p, row);
                }
            });
        self.inv_diag.clear();
        self.inv_diag.resize(n, 0.0);
        let reward = map.log_det_with(&self.m, Some(&mut self.inv_diag))?;
        // Γ_s, eqs. (23)–(24): tr(Y⁻¹ ∂M) = Σ_j (Y⁻¹)_jj ∂M_jj; chunk sums added in order.
        let partial: Vec<Vec<Vector6<f64>>> = self
            .slopes
            .par_chunks(CHUNK * k_len)
            .zip(self.inv_diag.par_chunks(CHUNK))
            .map(|(slopes, weights)| {
                let mut acc = vec![Vector6::zeros(); k_len];
                for (row, w) in slopes.chunks(k_len).zip(weights) {
                    add_gamma(&mut acc, row, *w);
                }
                acc
            })
            .collect();
        let mut gamma = vec![Vector6::zeros(); k_len];
        for acc in &partial {
            for (g, a) in gamma.iter_mut().zip(acc) {
                *g += a;
            }
        }
        Ok((reward, gamma))
    }

    /// Algorithm 1: `iterations` steps U ← U + Γ ∂r/∂U, eq. (22), each followed by the
    /// projection onto |u⁽ⁱ⁾| ≤ max_control. `u` holds the initial controls and receives those
    /// with the highest reward seen (the step is fixed, so an iterate can overshoot).
    ///
    /// # Errors
    /// As [`Icr::reward_and_gradient`]; `u` is unchanged on error.
    pub fn plan(
        &mut self,
        map: &InformationMap,
        start: &Isometry3<f64>,
        u: &mut [Vector6<f64>],
    ) -> Result<IcrReport> {
        let mut cur = u.to_vec();
        let mut grad = vec![Vector6::zeros(); u.len()];
        let mut rewards = Vec::with_capacity(self.config.iterations + 1);
        let mut best = (f64::NEG_INFINITY, 0, cur.clone());
        for it in 0..=self.config.iterations {
            let r = if it < self.config.iterations {
                self.reward_and_gradient(map, start, &cur, &mut grad)?
            } else {
                self.reward(map, start, &cur)?
            };
            rewards.push(r);
            if r > best.0 {
                best = (r, it, cur.clone());
            }
            if it < self.config.iterations {
                for (uk, gk) in cur.iter_mut().zip(&grad) {
                    for i in 0..6 {
                        let b = self.config.max_control[i];
                        uk[i] = (uk[i] + self.config.step[i] * gk[i]).clamp(-b, b);
                    }
                }
            }
        }
        u.copy_from_slice(&best.2);
        Ok(IcrReport {
            rewards,
            best_iteration: best.1,
        })
    }
}

/// Cells per parallel chunk: fixed, so sums do not depend on the number of threads.
const CHUNK: usize = 1024;

/// Reward and Γ_s for a diagonal prior in one pass: (Y_K⁻¹)_jj = 1/(y₀ⱼ + mⱼ) is known as
/// soon as a cell's K poses are done, so its slopes never leave the cache.
fn fused_diagonal<F: FovSdf>(
    frames: &[(Matrix3<f64>, Vector3<f64>)],
    fov: &F,
    probit: &Probit,
    sigma: f64,
    cells: &[nalgebra::Point3<f64>],
    y0: &[f64],
) -> (f64, Vec<Vector6<f64>>) {
    let k_len = frames.len();
    let partial: Vec<(f64, Vec<Vector6<f64>>)> = cells
        .par_chunks(CHUNK)
        .zip(y0.par_chunks(CHUNK))
        .map(|(cells, y0)| {
            let mut acc = vec![Vector6::zeros(); k_len];
            let mut row = vec![CellSlope::default(); k_len];
            let mut log_det = 0.0;
            for (p, y) in cells.iter().zip(y0) {
                let yk = y + cell_terms(frames, fov, probit, sigma, p, &mut row);
                log_det += yk.ln();
                add_gamma(&mut acc, &row, 1.0 / yk);
            }
            (log_det, acc)
        })
        .collect();
    let mut gamma = vec![Vector6::zeros(); k_len];
    let mut reward = 0.0;
    for (l, acc) in &partial {
        reward += l;
        for (g, a) in gamma.iter_mut().zip(acc) {
            *g += a;
        }
    }
    (reward, gamma)
}

/// One cell over all poses: writes q and (∂V⁻¹/∂d)·∇d per pose to `row` and returns the
/// information Σ_s M_jj(T_s) the cell receives, eqs. (14), (21).
#[inline]
fn cell_terms<F: FovSdf>(
    frames: &[(Matrix3<f64>, Vector3<f64>)],
    fov: &F,
    probit: &Probit,
    sigma: f64,
    p: &nalgebra::Point3<f64>,
    row: &mut [CellSlope],
) -> f64 {
    let mut m = 0.0;
    for ((rot, tr), out) in frames.iter().zip(row) {
        let q = rot * p.coords + tr;
        let (d, gd) = fov.sdf(&q);
        let (w, dw) = probit.inverse_noise(d, sigma);
        m += w;
        *out = CellSlope { q, g: gd * dw };
    }
    m
}

/// Adds one cell's share of each Γ_s, eqs. (23)–(24), with weight (Y_K⁻¹)_jj.
#[inline]
fn add_gamma(acc: &mut [Vector6<f64>], row: &[CellSlope], weight: f64) {
    for (a, c) in acc.iter_mut().zip(row) {
        let g = c.g * weight;
        let qg = c.q.cross(&g);
        *a -= Vector6::new(g.x, g.y, g.z, qg.x, qg.y, qg.z);
    }
}

/// World-to-body rotation matrices and translations of the poses.
fn frames(poses: &[Isometry3<f64>]) -> Vec<(Matrix3<f64>, Vector3<f64>)> {
    poses
        .iter()
        .map(|pose| {
            let inv = pose.inverse();
            (
                inv.rotation.to_rotation_matrix().into_inner(),
                inv.translation.vector,
            )
        })
        .collect()
}

fn check_pose(pose: &Isometry3<f64>) -> Result<()> {
    let ok = pose.translation.vector.iter().all(|v| v.is_finite())
        && pose.rotation.coords.iter().all(|v| v.is_finite());
    if ok {
        Ok(())
    } else {
        Err(CoreError::NonFinite { what: "pose" })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::icr::{Cone, Triangle};
    use nalgebra::{Matrix4, Point3, Vector4};
    use proptest::prelude::*;

    /// A seeded uniform sequence on [0, 1).
    fn uniform(seed: u64) -> impl FnMut() -> f64 {
        let mut s = seed;
        move || {
            s = s
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            (s >> 11) as f64 / (1u64 << 53) as f64
        }
    }

    fn grid_map(seed: u64, n_side: usize, dense: bool) -> InformationMap {
        let mut next = uniform(seed);
        let cells: Vec<Point3<f64>> = (0..n_side * n_side)
            .map(|i| {
                let (x, y) = ((i % n_side) as f64, (i / n_side) as f64);
                Point3::new(x * 0.4 - 2.0, y * 0.4 - 2.0, 0.0)
            })
            .collect();
        if dense {
            InformationMap::squared_exponential(cells, 50.0, 0.3, 1.0).unwrap()
        } else {
            let info = (0..cells.len()).map(|_| 0.01 + next() * 2.0).collect();
            InformationMap::diagonal(cells, info).unwrap()
        }
    }

    fn cloud_map(seed: u64, n: usize) -> InformationMap {
        let mut next = uniform(seed);
        let cells: Vec<Point3<f64>> = (0..n)
            .map(|_| Point3::new(6.0 * next() - 1.0, 6.0 * next() - 3.0, 4.0 * next() - 2.0))
            .collect();
        let info = (0..n).map(|_| 0.01 + next()).collect();
        InformationMap::diagonal(cells, info).unwrap()
    }

    /// Central differences of r over every control component that moves, with steps of 1e-5
    /// and, if those miss, 1e-6: the SDFs have ridges (a cone's axis, where the nearest edge
    /// changes), and a map cell within a step of one bends the difference quotient while
    /// the gradient at the point itself is right (the random case
    /// `seed = 11472059390893309169` missed by 5.9e-5 relative at 1e-5 and matched to about
    /// 1e-7 at 1e-6). A wrong gradient misses at both steps.
    fn check_fd<F: FovSdf>(
        icr: &mut Icr<F>,
        map: &InformationMap,
        start: &Isometry3<f64>,
        u: &[Vector6<f64>],
        components: &[usize],
    ) -> std::result::Result<(), TestCaseError> {
        let mut grad = vec![Vector6::zeros(); u.len()];
        icr.reward_and_gradient(map, start, u, &mut grad).unwrap();
        let mut misses = Vec::new();
        for h in [1e-5, 1e-6] {
            let (mut num, mut ana) = (Vec::new(), Vec::new());
            for k in 0..u.len() {
                for &i in components {
                    let mut up = u.to_vec();
                    let mut dn = u.to_vec();
                    up[k][i] += h;
                    dn[k][i] -= h;
                    let fd = (icr.reward(map, start, &up).unwrap()
                        - icr.reward(map, start, &dn).unwrap())
                        / (2.0 * h);
                    num.push(fd);
                    ana.push(grad[k][i]);
                }
            }
            let err: f64 = num
                .iter()
                .zip(&ana)
                .map(|(a, b)| (a - b).powi(2))
                .sum::<f64>()
                .sqrt();
            let norm: f64 = num.iter().map(|a| a * a).sum::<f64>().sqrt();
            if err <= 1e-5 * norm.max(1e-8) {
                return Ok(());
            }
            misses.push(format!(
                "h {h:e}: error {err} vs norm {norm}\n{num:?}\n{ana:?}"
            ));
        }
        prop_assert!(false, "{}", misses.join("\n"));
        Ok(())
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(16))]

        /// SE(2): planar poses and controls [v_x, v_y, ω_z] over a 2-D map.
        #[test]
        fn gradient_se2(seed in any::<u64>(), x in -1.0..1.0f64, y in -1.0..1.0f64, yaw in -3.0..3.0f64,
                        v in proptest::collection::vec((0.2..2.0f64, -0.5..0.5f64, -1.0..1.0f64), 4)) {
            let map = grid_map(seed, 12, false);
            let cfg = IcrConfig { horizon: 4, tau: 0.4, ..IcrConfig::default() };
            let mut icr = Icr::new(cfg, Triangle::new(3.0, 30f64.to_radians()).unwrap()).unwrap();
            let start = Isometry3::new(Vector3::new(x, y, 0.0), Vector3::new(0.0, 0.0, yaw));
            let u: Vec<Vector6<f64>> = v.iter().map(|&(a, b, w)| Vector6::new(a, b, 0.0, 0.0, 0.0, w)).collect();
            check_fd(&mut icr, &map, &start, &u, &[0, 1, 5])?;
        }

        /// SE(3): full 6-D controls, a 3-D cone and scattered cells.
        #[test]
        fn gradient_se3(seed in any::<u64>(), r in proptest::collection::vec(-0.6..0.6f64, 3),
                        v in proptest::collection::vec(proptest::collection::vec(-1.0..1.0f64, 6), 3)) {
            let map = cloud_map(seed, 150);
            let cfg = IcrConfig { horizon: 3, tau: 0.3, kappa: 0.3, ..IcrConfig::default() };
            let mut icr = Icr::new(cfg, Cone::new(4.0, 0.6).unwrap()).unwrap();
            let start = Isometry3::new(Vector3::new(0.2, -0.1, 0.3), Vector3::new(r[0], r[1], r[2]));
            let u: Vec<Vector6<f64>> = v.iter().map(|c| Vector6::from_column_slice(c)).collect();
            check_fd(&mut icr, &map, &start, &u, &[0, 1, 2, 3, 4, 5])?;
        }

        /// The dense path: a squared-exponential prior.
        #[test]
        fn gradient_dense_prior(seed in any::<u64>(), w in proptest::collection::vec(-1.0..1.0f64, 3)) {
            let map = grid_map(seed, 8, true);
            let cfg = IcrConfig { horizon: 3, tau: 0.4, ..IcrConfig::default() };
            let mut icr = Icr::new(cfg, Triangle::new(3.0, 30f64.to_radians()).unwrap()).unwrap();
            let start = Isometry3::new(Vector3::new(-1.5, 0.0, 0.0), Vector3::zeros());
            let u: Vec<Vector6<f64>> = w.iter().map(|&w| Vector6::new(1.0, 0.0, 0.0, 0.0, 0.0, w)).collect();
            check_fd(&mut icr, &map, &start, &u, &[0, 5])?;
        }
    }

    /// The gradient equals the literal Λ recursion (26) with eq. (25) in 4 × 4 matrices.
    #[test]
    fn gradient_equals_the_lambda_recursion() {
        let map = cloud_map(3, 200);
        let cfg = IcrConfig {
            horizon: 4,
            tau: 0.3,
            ..IcrConfig::default()
        };
        let mut icr = Icr::new(cfg, Cone::new(4.0, 0.6).unwrap()).unwrap();
        let start = Isometry3::new(Vector3::new(0.1, 0.2, -0.1), Vector3::new(0.1, -0.2, 0.3));
        let u: Vec<Vector6<f64>> = (0..4)
            .map(|k| Vector6::from_fn(|i, _| ((k * 6 + i) as f64 * 0.77).sin()))
            .collect();
        let mut grad = vec![Vector6::zeros(); 4];
        icr.reward_and_gradient(&map, &start, &u, &mut grad)
            .unwrap();
        let tau = cfg.tau;
        // (Y_K⁻¹)_jj of the diagonal prior from the information of each pose.
        let (mut m, mut tmp) = (vec![0.0; map.len()], vec![0.0; map.len()]);
        let mut pose = start;
        for uk in &u {
            pose *= se3::exp(&(uk * tau));
            icr.information_at(&map, &pose, &mut tmp).unwrap();
            m.iter_mut().zip(&tmp).for_each(|(a, b)| *a += b);
        }
        let w: Vec<f64> = map
            .prior_diagonal()
            .iter()
            .zip(&m)
            .map(|(y, m)| 1.0 / (y + m))
            .collect();
        let exps: Vec<Matrix4<f64>> = u.iter().map(|uk| se3::exp_matrix(&(uk * tau))).collect();
        let mut poses = vec![start.to_homogeneous()];
        for e in &exps {
            let last = poses[poses.len() - 1];
            poses.push(last * e);
        }
        let probit = Probit::new(cfg.kappa).unwrap();
        for k in 0..4 {
            for i in 0..6 {
                // Λ_{k+1} = T_k ∂exp/∂u (Lemma 1), then Λ_s = Λ_{s−1} exp(τ û_{s−1}).
                let xi = se3::left_jacobian(&(u[k] * tau)) * Vector6::ith(i, 1.0) * tau;
                let mut lambda = poses[k] * se3::hat(&xi) * exps[k];
                let mut total = 0.0;
                for s in k + 1..=4 {
                    if s > k + 1 {
                        lambda *= exps[s - 1];
                    }
                    let t_inv = poses[s].try_inverse().unwrap();
                    for (j, p) in map.cells().iter().enumerate() {
                        let ph = Vector4::new(p.x, p.y, p.z, 1.0);
                        let q = (t_inv * ph).xyz();
                        let dq = -(t_inv * lambda * t_inv * ph).xyz(); // eq. (25)
                        let (d, gd) = icr.fov.sdf(&q);
                        let (_, dw) = probit.inverse_noise(d, cfg.sigma);
                        total += w[j] * dw * gd.dot(&dq); // eqs. (23)–(24)
                    }
                }
                assert!(
                    (total - grad[k][i]).abs() < 1e-9 * total.abs().max(1.0),
                    "k={k} i={i}: {total} vs {}",
                    grad[k][i]
                );
            }
        }
    }

    /// The chunked parallel passes give bit-identical results on 1 and 3 threads, for both
    /// prior kinds.
    #[test]
    fn results_do_not_depend_on_the_thread_count() {
        let run = |threads: usize, dense: bool| {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            pool.install(|| {
                // More cells than one chunk, so several chunks are combined.
                let map = grid_map(9, if dense { 34 } else { 60 }, dense);
                let mut icr =
                    Icr::new(IcrConfig::default(), Triangle::new(3.0, 0.5).unwrap()).unwrap();
                let start =
                    Isometry3::new(Vector3::new(-1.0, 0.5, 0.0), Vector3::new(0.0, 0.0, 0.3));
                let u = vec![Vector6::new(1.2, 0.1, 0.0, 0.0, 0.0, 0.4); 5];
                let mut g = vec![Vector6::zeros(); 5];
                let r = icr.reward_and_gradient(&map, &start, &u, &mut g).unwrap();
                (
                    r.to_bits(),
                    g.iter()
                        .flat_map(|v| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>())
                        .collect::<Vec<_>>(),
                )
            })
        };
        for dense in [false, true] {
            assert_eq!(run(1, dense), run(3, dense));
        }
    }

    #[test]
    fn a_small_step_increases_the_reward() {
        let map = grid_map(5, 15, false);
        let cfg = IcrConfig {
            horizon: 5,
            ..IcrConfig::default()
        };
        let mut icr = Icr::new(cfg, Triangle::new(3.0, 30f64.to_radians()).unwrap()).unwrap();
        let start = Isometry3::new(Vector3::new(-2.5, -2.5, 0.0), Vector3::zeros());
        let u = vec![Vector6::new(1.5, 0.0, 0.0, 0.0, 0.0, 0.1); 5];
        let mut g = vec![Vector6::zeros(); 5];
        let r0 = icr.reward_and_gradient(&map, &start, &u, &mut g).unwrap();
        let stepped: Vec<Vector6<f64>> = u.iter().zip(&g).map(|(a, b)| a + b * 1e-4).collect();
        assert!(g.iter().any(|v| v.norm() > 1e-6));
        assert!(icr.reward(&map, &start, &stepped).unwrap() > r0);
        let mut planned = u.clone();
        let rep = icr.plan(&map, &start, &mut planned).unwrap();
        assert_eq!(rep.rewards.len(), cfg.iterations + 1);
        assert!(rep.rewards[rep.best_iteration] >= rep.rewards[0]);
        assert!(
            (icr.reward(&map, &start, &planned).unwrap() - rep.rewards[rep.best_iteration]).abs()
                < 1e-9
        );
    }

    #[test]
    fn diagonal_and_dense_priors_give_the_same_plan() {
        let side = 10u32;
        let cells: Vec<Point3<f64>> = (0..side * side)
            .map(|i| {
                Point3::new(
                    f64::from(i % side) * 0.5 - 2.0,
                    f64::from(i / side) * 0.5 - 2.0,
                    0.0,
                )
            })
            .collect();
        let n = cells.len();
        let diag = InformationMap::diagonal(cells.clone(), vec![0.01; n]).unwrap();
        let mut cov = vec![0.0; n * n];
        for i in 0..n {
            cov[i * n + i] = 100.0;
        }
        let dense = InformationMap::dense_covariance(cells, &cov).unwrap();
        let cfg = IcrConfig::default();
        let fov = Triangle::new(3.0, 30f64.to_radians()).unwrap();
        let mut icr = Icr::new(cfg, fov).unwrap();
        let start = Isometry3::new(Vector3::new(-2.0, 0.0, 0.0), Vector3::zeros());
        let mut ua = vec![Vector6::new(1.5, 0.0, 0.0, 0.0, 0.0, 0.2); 5];
        let mut ub = ua.clone();
        let ra = icr.plan(&diag, &start, &mut ua).unwrap();
        let rb = icr.plan(&dense, &start, &mut ub).unwrap();
        for (a, b) in ra.rewards.iter().zip(&rb.rewards) {
            assert!((a - b).abs() < 1e-9 * a.abs().max(1.0), "{a} vs {b}");
        }
        for (a, b) in ua.iter().zip(&ub) {
            assert!((a - b).norm() < 1e-9);
        }
    }

    #[test]
    fn projection_respects_bounds() {
        let map = grid_map(2, 10, false);
        let mut cfg = IcrConfig {
            step: [0.0, 0.0, 0.0, 0.0, 0.0, 100.0],
            ..IcrConfig::default()
        };
        cfg.max_control[5] = 0.4;
        let mut icr = Icr::new(cfg, Triangle::new(3.0, 0.5).unwrap()).unwrap();
        let mut u = vec![Vector6::new(1.5, 0.0, 0.0, 0.0, 0.0, 0.0); 5];
        icr.plan(&map, &Isometry3::identity(), &mut u).unwrap();
        assert!(u.iter().all(|v| v[5].abs() <= 0.4 && v[0] == 1.5));
    }

    #[test]
    fn bad_input_is_a_typed_error() {
        let fov = Triangle::new(3.0, 0.5).unwrap();
        let mut step = [0.0; 6];
        step[2] = -1.0;
        let d = IcrConfig::default;
        for cfg in [
            IcrConfig { horizon: 0, ..d() },
            IcrConfig { kappa: 0.0, ..d() },
            IcrConfig { kappa: -1.0, ..d() },
            IcrConfig {
                tau: f64::NAN,
                ..d()
            },
            IcrConfig { step, ..d() },
            IcrConfig {
                horizon: usize::MAX,
                ..d()
            },
            IcrConfig {
                iterations: usize::MAX,
                ..d()
            },
        ] {
            assert!(Icr::new(cfg, fov).is_err(), "{cfg:?}");
        }
        let map = grid_map(1, 4, false);
        let mut icr = Icr::new(IcrConfig::default(), fov).unwrap();
        let u = vec![Vector6::zeros(); 5];
        let bad = Isometry3::new(Vector3::new(f64::NAN, 0.0, 0.0), Vector3::zeros());
        assert!(matches!(
            icr.reward(&map, &bad, &u),
            Err(CoreError::NonFinite { .. })
        ));
        assert!(matches!(
            icr.reward(&map, &Isometry3::identity(), &u[..3]),
            Err(CoreError::LengthMismatch { .. })
        ));
        let mut nan_u = u.clone();
        nan_u[2][5] = f64::NAN;
        assert!(matches!(
            icr.reward(&map, &Isometry3::identity(), &nan_u),
            Err(CoreError::NonFinite { .. })
        ));
        // Huge but finite controls, starts and cells: a finite reward or an error, never
        // Ok(NaN).
        for c in [1e20, 1e155, 1e300, f64::MAX] {
            let far = Isometry3::new(Vector3::new(c, -c, c), Vector3::zeros());
            let cells = vec![Point3::new(c, c, 0.0), Point3::new(-c, 0.0, c)];
            for (map, start, u) in [
                (
                    grid_map(1, 4, false),
                    Isometry3::identity(),
                    vec![Vector6::repeat(c); 5],
                ),
                (grid_map(1, 4, true), far, u.clone()),
                (
                    InformationMap::diagonal(cells, vec![1.0, c]).unwrap(),
                    Isometry3::identity(),
                    vec![Vector6::repeat(0.1); 5],
                ),
            ] {
                let mut g = vec![Vector6::zeros(); 5];
                for r in [
                    icr.reward(&map, &start, &u),
                    icr.reward_and_gradient(&map, &start, &u, &mut g),
                ] {
                    assert!(r.as_ref().map_or(true, |r| r.is_finite()), "{c}: {r:?}");
                }
            }
        }
        let mut g = vec![Vector6::zeros(); 4];
        assert!(
            icr.reward_and_gradient(&map, &Isometry3::identity(), &u, &mut g)
                .is_err()
        );
        let mut out = vec![0.0; 3];
        assert!(
            icr.information_at(&map, &Isometry3::identity(), &mut out)
                .is_err()
        );
    }
}
