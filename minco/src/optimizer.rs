//! GCOPTER-style optimisation of a MINCO trajectory under speed and acceleration limits.

use crate::error::{MincoError, Result};
use crate::lbfgs::{self, LbfgsSettings, Status};
use crate::minco::Minco;
use crate::poly::{FALLING, powers};
use crate::trajectory::Trajectory;

/// Settings of the trajectory optimiser.
///
/// The cost is J + ρ ΣT + w Σ_i ∫ [φ(‖v‖² − v_max²) + φ(‖a‖² − a_max²) (+ φ(d² − r²))] dt
/// (+ w_q Σ ‖q_i − path_i‖²), with φ the C² soft hinge of width μ and the integrals taken
/// by the trapezoid rule on K + 1 samples per piece.
///
/// # Example
/// ```
/// use minco::OptimizerConfig;
/// let cfg = OptimizerConfig::default().with_limits(2.0, 4.0);
/// assert!(cfg.validate().is_ok());
/// assert!(OptimizerConfig::default().with_limits(-1.0, 1.0).validate().is_err());
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
#[non_exhaustive]
pub struct OptimizerConfig {
    /// Maximum speed v_max [m/s]. Default 3.0, the FU-MPC experiments' value.
    pub v_max: f64,
    /// Maximum acceleration a_max [m/s²]. Default 3.0.
    pub a_max: f64,
    /// Weight ρ of the total duration [cost units per s]. Default 512.
    pub time_weight: f64,
    /// Weight w of the constraint penalties. Default 1e4.
    pub penalty_weight: f64,
    /// Width μ of the soft hinge, in the squared units of each constraint. Default 1e-2.
    pub hinge_width: f64,
    /// Samples K per piece for the penalty quadrature, 1..=65536. Default 16.
    pub samples_per_piece: usize,
    /// Weight w_q pulling inner waypoints toward the given path points; 0 leaves them free. Default 0.
    pub waypoint_weight: f64,
    /// Radius r \[m\] of a corridor around the path, or `None` for no corridor. Piece i is kept
    /// within r of path segment i (head → first path point → … → tail). Default `None`.
    pub corridor_radius: Option<f64>,
    /// L-BFGS memory, 1..=1024. Default 8. Each stored pair costs 2 × (number of optimised
    /// variables) f64s; pairs are allocated as they are stored, so the history grows to at
    /// most min(memory, iterations) pairs.
    pub memory: usize,
    /// Iteration budget. Default 300.
    pub max_iterations: usize,
    /// Stop when three iterations together lower the cost by less than this fraction. Default 1e-4.
    pub rel_cost_tol: f64,
}

impl Default for OptimizerConfig {
    fn default() -> Self {
        Self {
            v_max: 3.0,
            a_max: 3.0,
            time_weight: 512.0,
            penalty_weight: 1e4,
            hinge_width: 1e-2,
            samples_per_piece: 16,
            waypoint_weight: 0.0,
            corridor_radius: None,
            memory: 8,
            max_iterations: 300,
            rel_cost_tol: 1e-4,
        }
    }
}

impl OptimizerConfig {
    /// Sets v_max [m/s] and a_max [m/s²].
    pub fn with_limits(mut self, v_max: f64, a_max: f64) -> Self {
        self.v_max = v_max;
        self.a_max = a_max;
        self
    }

    /// Sets the corridor radius \[m\].
    pub fn with_corridor(mut self, radius: f64) -> Self {
        self.corridor_radius = Some(radius);
        self
    }

    /// Sets the waypoint weight w_q (0: free waypoints).
    pub fn with_waypoint_weight(mut self, weight: f64) -> Self {
        self.waypoint_weight = weight;
        self
    }

    /// Checks every setting.
    ///
    /// # Errors
    /// [`MincoError::InvalidConfig`] naming the first bad setting.
    pub fn validate(&self) -> Result<()> {
        let positive = |v: f64, what: &'static str| {
            if v > 0.0 && v.is_finite() {
                Ok(())
            } else {
                Err(MincoError::InvalidConfig {
                    what,
                    reason: "must be positive and finite",
                })
            }
        };
        let non_negative = |v: f64, what: &'static str| {
            if v >= 0.0 && v.is_finite() {
                Ok(())
            } else {
                Err(MincoError::InvalidConfig {
                    what,
                    reason: "must be non-negative and finite",
                })
            }
        };
        positive(self.v_max, "v_max")?;
        positive(self.a_max, "a_max")?;
        non_negative(self.time_weight, "time_weight")?;
        positive(self.penalty_weight, "penalty_weight")?;
        positive(self.hinge_width, "hinge_width")?;
        non_negative(self.waypoint_weight, "waypoint_weight")?;
        non_negative(self.rel_cost_tol, "rel_cost_tol")?;
        if let Some(r) = self.corridor_radius {
            positive(r, "corridor_radius")?;
        }
        if !(1..=1 << 16).contains(&self.samples_per_piece)
            || !(1..=1024).contains(&self.memory)
            || self.max_iterations == 0
        {
            return Err(MincoError::InvalidConfig {
                what: "samples_per_piece, memory, max_iterations",
                reason: "need 1 ≤ samples_per_piece ≤ 65536, 1 ≤ memory ≤ 1024, max_iterations ≥ 1",
            });
        }
        Ok(())
    }
}

/// The result of [`Optimizer::optimize`].
#[derive(Debug, Clone)]
pub struct Solution<const D: usize> {
    /// The optimised trajectory.
    pub trajectory: Trajectory<D>,
    /// Final cost.
    pub cost: f64,
    /// Cost of the initial guess.
    pub initial_cost: f64,
    /// L-BFGS iterations taken.
    pub iterations: usize,
    /// How the minimisation ended.
    pub status: Status,
    /// Largest speed of the trajectory \[m/s\], by dense sampling (64 per piece): compare it
    /// with v_max — the limits are soft penalties, so an unconverged run may exceed them.
    pub max_speed: f64,
    /// Largest acceleration \[m/s²\], by dense sampling (64 per piece).
    pub max_acceleration: f64,
}

/// T(τ) = τ²/2 + τ + 1 for τ > 0, 1/(τ²/2 − τ + 1) otherwise: a smooth bijection ℝ → (0, ∞).
#[inline]
fn tau_to_t(tau: f64) -> (f64, f64) {
    if tau > 0.0 {
        (0.5 * tau * tau + tau + 1.0, tau + 1.0)
    } else {
        let g = 0.5 * tau * tau - tau + 1.0;
        (1.0 / g, (1.0 - tau) / (g * g))
    }
}

/// The inverse of [`tau_to_t`].
#[inline]
fn t_to_tau(t: f64) -> f64 {
    if t > 1.0 {
        (2.0 * t - 1.0).sqrt() - 1.0
    } else {
        1.0 - (2.0 / t - 1.0).sqrt()
    }
}

/// The C² soft hinge φ(x) of width μ and its derivative: 0 for x ≤ 0, x³/μ² − x⁴/(2μ³) on
/// (0, μ), x − μ/2 beyond.
#[inline]
fn hinge(x: f64, mu: f64) -> (f64, f64) {
    if x <= 0.0 {
        (0.0, 0.0)
    } else if x < mu {
        let r = x / mu;
        (x * r * r * (1.0 - 0.5 * r), r * r * (3.0 - 2.0 * r))
    } else {
        (x - 0.5 * mu, 1.0)
    }
}

/// Nearest point to `p` on the segment from `a` to `b`. The squared distance to a segment
/// (a convex set) is C¹ in `p`, with gradient 2 (p − nearest).
fn nearest_on_segment<const D: usize>(a: &[f64; D], b: &[f64; D], p: &[f64; D]) -> [f64; D] {
    let mut ab2 = 0.0;
    let mut ap_ab = 0.0;
    for d in 0..D {
        ab2 += (b[d] - a[d]) * (b[d] - a[d]);
        ap_ab += (p[d] - a[d]) * (b[d] - a[d]);
    }
    let s = if ab2 > 0.0 {
        (ap_ab / ab2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    let mut c = [0.0; D];
    for d in 0..D {
        c[d] = a[d] + s * (b[d] - a[d]);
    }
    c
}

fn norm2<const D: usize>(v: &[f64; D]) -> f64 {
    v.iter().map(|x| x * x).sum()
}

fn dot<const D: usize>(a: &[f64; D], b: &[f64; D]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// One quadrature sample of a piece: its weight, its place and the powers of its time.
struct Sample {
    omega: f64,
    frac: f64,
    t_i: f64,
    tp: [f64; crate::poly::MAX_COEFFS],
}

impl Sample {
    /// Adds w ω φ(g)'s partials for a constraint g = ‖u‖² − bound with u the `deriv`-th
    /// derivative (or, for the corridor, the offset from the path), and returns its value.
    /// `dg_dt` is dg/dt at the sample; `dir` is u, so that ∂g/∂u = 2u.
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn add<const D: usize>(
        &self,
        cfg: &OptimizerConfig,
        gc: &mut [[f64; D]],
        gt: &mut f64,
        g: f64,
        dg_dt: f64,
        dir: &[f64; D],
        deriv: usize,
    ) -> f64 {
        if g <= 0.0 {
            return 0.0;
        }
        let (phi, dphi) = hinge(g, cfg.hinge_width);
        let w = cfg.penalty_weight;
        let scale = 2.0 * w * self.omega * dphi;
        for (k, row) in gc.iter_mut().enumerate().skip(deriv) {
            let basis = FALLING[deriv][k] * self.tp[k - deriv];
            for d in 0..D {
                row[d] += scale * dir[d] * basis;
            }
        }
        // T_i enters through ω = β T_i/K and through the sample time t = (j/K) T_i.
        *gt += w * (self.omega / self.t_i * phi + self.omega * dphi * dg_dt * self.frac);
        w * self.omega * phi
    }
}

/// Optimises the inner waypoints and durations of a MINCO trajectory from a head state to a
/// tail state along a path, as GCOPTER does: decision variables are the waypoints and
/// τ with T = T(τ) > 0, minimised by L-BFGS with a Lewis–Overton line search.
///
/// # Example
/// ```
/// use minco::{Optimizer, OptimizerConfig};
/// # fn main() -> Result<(), minco::MincoError> {
/// let rest = |p: [f64; 3]| [p, [0.0; 3], [0.0; 3]];
/// let path = [[2.0, 0.0, 1.0], [2.0, 2.0, 1.0], [4.0, 2.0, 1.5]];
/// let mut opt = Optimizer::<3, 3>::new(
///     OptimizerConfig::default().with_limits(2.0, 3.0),
///     rest([0.0, 0.0, 1.0]),
///     rest([4.0, 4.0, 1.5]),
///     &path,
/// )?;
/// let sol = opt.optimize()?;
/// assert!(sol.cost < sol.initial_cost);
/// assert!(sol.trajectory.max_speed(64) <= 2.0 * 1.02);
/// # Ok(()) }
/// ```
#[derive(Debug, Clone)]
pub struct Optimizer<const S: usize, const D: usize> {
    config: OptimizerConfig,
    minco: Minco<S, D>,
    head: [[f64; D]; S],
    tail: [[f64; D]; S],
    /// Inner path points (initial waypoints).
    path: Vec<[f64; D]>,
    /// The full polyline head → path → tail, for the corridor.
    polyline: Vec<[f64; D]>,
    q: Vec<[f64; D]>,
    t: Vec<f64>,
    dt_dtau: Vec<f64>,
    gc: Vec<[f64; D]>,
    gt: Vec<f64>,
    gq: Vec<[f64; D]>,
    gtt: Vec<f64>,
}

impl<const S: usize, const D: usize> Optimizer<S, D> {
    /// Sets up the problem: start state `head`, goal state `tail` (derivatives 0..S−1) and the
    /// inner path points (e.g. the topological path's interior nodes). The trajectory has
    /// `path.len() + 1` pieces.
    ///
    /// # Errors
    /// [`MincoError::InvalidConfig`] for bad settings, a path of `usize::MAX` points or
    /// segments so long for `v_max` that their first durations' parameters τ overflow (a
    /// duration that is finite but outside [`Minco::solve`]'s range fails there, as
    /// [`MincoError::BadDuration`]),
    /// [`MincoError::NonFinite`] for non-finite
    /// input, [`MincoError::Infeasible`] if the head or tail speed or acceleration exceeds the
    /// limits, and the errors of [`Minco::new`].
    pub fn new(
        config: OptimizerConfig,
        head: [[f64; D]; S],
        tail: [[f64; D]; S],
        path: &[[f64; D]],
    ) -> Result<Self> {
        config.validate()?;
        // Checks the order and size before anything indexes the boundary states.
        let Some(m) = path.len().checked_add(1) else {
            return Err(MincoError::InvalidConfig {
                what: "path",
                reason: "too many waypoints",
            });
        };
        let minco = Minco::new(m)?;
        let finite = |rows: &[[f64; D]]| rows.iter().flatten().all(|v| v.is_finite());
        if !finite(&head) || !finite(&tail) || !finite(path) {
            return Err(MincoError::NonFinite {
                what: "head, tail or path",
            });
        }
        for state in [&head, &tail] {
            if norm2(&state[1]).sqrt() > config.v_max {
                return Err(MincoError::Infeasible("boundary speed exceeds v_max"));
            }
            if S > 2 && norm2(&state[2]).sqrt() > config.a_max {
                return Err(MincoError::Infeasible(
                    "boundary acceleration exceeds a_max",
                ));
            }
        }
        let mut polyline = Vec::with_capacity(m + 1);
        polyline.push(head[0]);
        polyline.extend_from_slice(path);
        polyline.push(tail[0]);
        // Segments so long for v_max (1e300 m, or a v_max of 1e-308 m/s) that their first
        // durations overflow: named here rather than as a bad decision vector later.
        for w in polyline.windows(2) {
            let t = norm2(&crate::minco::sub(&w[1], &w[0])).sqrt() / (0.5 * config.v_max);
            if !t_to_tau(t.max(0.1)).is_finite() {
                return Err(MincoError::InvalidConfig {
                    what: "path",
                    reason: "a segment's duration at v_max overflows",
                });
            }
        }
        let n = 2 * S * m;
        Ok(Self {
            config,
            minco,
            head,
            tail,
            path: path.to_vec(),
            polyline,
            q: path.to_vec(),
            t: vec![1.0; m],
            dt_dtau: vec![0.0; m],
            gc: vec![[0.0; D]; n],
            gt: vec![0.0; m],
            gq: vec![[0.0; D]; m - 1],
            gtt: vec![0.0; m],
        })
    }

    /// Number of decision variables: D (M − 1) waypoint coordinates, then M duration parameters τ.
    pub fn dimension(&self) -> usize {
        D * self.path.len() + self.t.len()
    }

    /// The initial guess: the path points, and durations for a trapezoid-like speed profile
    /// (each segment's length over half of v_max, at least 0.1 s).
    pub fn initial_guess(&self) -> Vec<f64> {
        let mut x = Vec::with_capacity(self.dimension());
        x.extend(self.path.iter().flatten());
        for w in self.polyline.windows(2) {
            let mut len2 = 0.0;
            for d in 0..D {
                len2 += (w[1][d] - w[0][d]).powi(2);
            }
            let t = (len2.sqrt() / (0.5 * self.config.v_max)).max(0.1);
            x.push(t_to_tau(t));
        }
        x
    }

    /// The cost at decision vector `x`, writing its gradient to `grad`.
    ///
    /// # Errors
    /// [`MincoError::LengthMismatch`] for wrong lengths, [`MincoError::NonFinite`] for a
    /// non-finite `x`, and the solve errors of [`Minco::solve`].
    pub fn cost_and_gradient(&mut self, x: &[f64], grad: &mut [f64]) -> Result<f64> {
        let dim = self.dimension();
        for (what, len) in [("decision vector", x.len()), ("gradient", grad.len())] {
            if len != dim {
                return Err(MincoError::LengthMismatch {
                    what,
                    expected: dim,
                    found: len,
                });
            }
        }
        if x.iter().any(|v| !v.is_finite()) {
            return Err(MincoError::NonFinite {
                what: "decision vector",
            });
        }
        let m = self.t.len();
        let nq = D * (m - 1);
        for (i, q) in self.q.iter_mut().enumerate() {
            q.copy_from_slice(&x[D * i..D * (i + 1)]);
        }
        for i in 0..m {
            (self.t[i], self.dt_dtau[i]) = tau_to_t(x[nq + i]);
        }
        self.minco.solve(&self.head, &self.tail, &self.q, &self.t)?;
        self.gc.fill([0.0; D]);
        self.gt.fill(0.0);
        let mut cost = self.minco.add_energy_partials(&mut self.gc, &mut self.gt)?;
        cost += self.add_penalties();
        self.minco
            .propagate_gradient(&self.gc, &self.gt, &mut self.gq, &mut self.gtt)?;
        let wq = self.config.waypoint_weight;
        for i in 0..m - 1 {
            for d in 0..D {
                let diff = self.q[i][d] - self.path[i][d];
                cost += wq * diff * diff;
                grad[D * i + d] = self.gq[i][d] + 2.0 * wq * diff;
            }
        }
        let rho = self.config.time_weight;
        for i in 0..m {
            cost += rho * self.t[i];
            grad[nq + i] = (self.gtt[i] + rho) * self.dt_dtau[i];
        }
        Ok(cost)
    }

    /// Adds the penalty integrals' partials to `gc`, `gt` and returns their value.
    fn add_penalties(&mut self) -> f64 {
        let cfg = self.config;
        let (v2, a2) = (cfg.v_max * cfg.v_max, cfg.a_max * cfg.a_max);
        let k_samples = cfg.samples_per_piece;
        let n = 2 * S;
        let mut total = 0.0;
        let coeffs = self.minco.coefficients();
        for i in 0..self.t.len() {
            let t_i = self.t[i];
            let c = &coeffs[n * i..n * (i + 1)];
            let gc = &mut self.gc[n * i..n * (i + 1)];
            let step = t_i / k_samples as f64;
            for j in 0..=k_samples {
                let frac = j as f64 / k_samples as f64;
                let t = frac * t_i;
                let sample = Sample {
                    // Trapezoid weight ω = β T_i / K.
                    omega: if j == 0 || j == k_samples {
                        0.5 * step
                    } else {
                        step
                    },
                    frac,
                    t_i,
                    tp: powers(t),
                };
                let derivative = |r: usize| {
                    let mut out = [0.0; D];
                    for k in r..n {
                        let basis = FALLING[r][k] * sample.tp[k - r];
                        for d in 0..D {
                            out[d] += basis * c[k][d];
                        }
                    }
                    out
                };
                let (vel, acc, jerk) = (derivative(1), derivative(2), derivative(3));
                total += sample.add(
                    &cfg,
                    gc,
                    &mut self.gt[i],
                    norm2(&vel) - v2,
                    2.0 * dot(&vel, &acc),
                    &vel,
                    1,
                );
                total += sample.add(
                    &cfg,
                    gc,
                    &mut self.gt[i],
                    norm2(&acc) - a2,
                    2.0 * dot(&acc, &jerk),
                    &acc,
                    2,
                );
                if let Some(r) = cfg.corridor_radius {
                    let pos = derivative(0);
                    // Piece i keeps to segment i of the path: the distance to one segment is
                    // smooth, the distance to the whole polyline is not.
                    let near = nearest_on_segment(&self.polyline[i], &self.polyline[i + 1], &pos);
                    let mut off = [0.0; D];
                    for d in 0..D {
                        off[d] = pos[d] - near[d];
                    }
                    total += sample.add(
                        &cfg,
                        gc,
                        &mut self.gt[i],
                        norm2(&off) - r * r,
                        2.0 * dot(&off, &vel),
                        &off,
                        0,
                    );
                }
            }
        }
        total
    }

    /// Runs the optimisation from [`Optimizer::initial_guess`].
    ///
    /// # Errors
    /// The errors of [`Optimizer::cost_and_gradient`] at the initial guess, and
    /// [`MincoError::Infeasible`] if no finite trajectory results.
    pub fn optimize(&mut self) -> Result<Solution<D>> {
        let mut x = self.initial_guess();
        let mut grad = vec![0.0; x.len()];
        let initial_cost = self.cost_and_gradient(&x, &mut grad)?;
        let cfg = self.config;
        let settings = LbfgsSettings {
            memory: cfg.memory,
            max_iterations: cfg.max_iterations,
            rel_cost_tol: cfg.rel_cost_tol,
            past: 3,
            grad_tol: 1e-10,
            c1: 1e-4,
            c2: 0.9,
            max_line_search: 64,
        };
        let result = lbfgs::minimize(&mut x, &settings, |x, g| {
            self.cost_and_gradient(x, g).unwrap_or(f64::INFINITY)
        });
        // Re-solve at the final point so the trajectory matches x.
        let cost = self.cost_and_gradient(&x, &mut grad)?;
        if !cost.is_finite() {
            return Err(MincoError::Infeasible(
                "the optimisation produced no finite trajectory",
            ));
        }
        let trajectory = self.minco.trajectory()?;
        Ok(Solution {
            max_speed: trajectory.max_speed(64),
            max_acceleration: trajectory.max_acceleration(64),
            trajectory,
            cost,
            initial_cost,
            iterations: result.iterations,
            status: result.status,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn tau_map_is_a_smooth_bijection() {
        for &tau in &[-5.0, -1.0, -1e-9, 0.0, 1e-9, 0.5, 3.0] {
            let (t, dt) = tau_to_t(tau);
            assert!(t > 0.0);
            assert!((t_to_tau(t) - tau).abs() < 1e-9, "tau {tau}");
            let h = 1e-6;
            let fd = (tau_to_t(tau + h).0 - tau_to_t(tau - h).0) / (2.0 * h);
            assert!((fd - dt).abs() < 1e-6);
        }
    }

    #[test]
    fn hinge_is_c2() {
        let mu = 0.3;
        for &x in &[-1.0, 0.0, 0.1, 0.29, 0.3, 1.0] {
            let (_, d) = hinge(x, mu);
            let h = 1e-7;
            let fd = (hinge(x + h, mu).0 - hinge(x - h, mu).0) / (2.0 * h);
            assert!((fd - d).abs() < 1e-6, "x {x}");
        }
        // Continuity of value, slope and curvature at the joints 0 and μ.
        let e = 1e-9;
        assert!((hinge(mu - e, mu).0 - hinge(mu + e, mu).0).abs() < 1e-8);
        assert!((hinge(mu - e, mu).1 - hinge(mu + e, mu).1).abs() < 1e-8);
        assert!(hinge(e, mu).1 < 1e-8);
        let curvature = |x: f64| {
            let h = 1e-6;
            (hinge(x + h, mu).1 - hinge(x - h, mu).1) / (2.0 * h)
        };
        for joint in [0.0, mu] {
            let (left, right) = (curvature(joint - 1e-4), curvature(joint + 1e-4));
            assert!(
                (left - right).abs() < 1e-2,
                "curvature jumps at {joint}: {left} vs {right}"
            );
        }
        // Away from the joints the curvature is what the formula says: 6x/μ² − 6x²/μ³.
        let x = 0.5 * mu;
        assert!((curvature(x) - (6.0 * x / (mu * mu) - 6.0 * x * x / mu.powi(3))).abs() < 1e-5);
    }

    fn random_path(seed: u64, n: usize) -> Vec<[f64; 3]> {
        let mut next = crate::test_util::uniform(seed);
        let mut p = [0.0, 0.0, 1.0];
        (0..n)
            .map(|_| {
                p = [
                    p[0] + 0.5 + 2.0 * next(),
                    p[1] + 3.0 * (next() - 0.5),
                    p[2] + (next() - 0.5),
                ];
                p
            })
            .collect()
    }

    fn check_gradient<const S: usize>(
        seed: u64,
        inner: usize,
        corridor: bool,
    ) -> std::result::Result<(), TestCaseError> {
        let path = random_path(seed, inner + 1);
        let mut head = [[0.0; 3]; S];
        head[0] = [0.0, 0.0, 1.0];
        let mut tail = [[0.0; 3]; S];
        tail[0] = path[inner];
        // Tight limits so that the speed, acceleration and corridor penalties are active.
        let mut cfg = OptimizerConfig::default()
            .with_limits(0.8, 0.5)
            .with_waypoint_weight(3.0);
        cfg.hinge_width = 0.5;
        if corridor {
            cfg = cfg.with_corridor(0.05);
        }
        let mut opt = Optimizer::<S, 3>::new(cfg, head, tail, &path[..inner]).unwrap();
        let mut x = opt.initial_guess();
        // Perturb the waypoints off the path so the corridor penalty is active.
        for (k, v) in x.iter_mut().enumerate() {
            *v += 0.3 * ((k as f64) * 1.7).sin();
        }
        let mut g = vec![0.0; x.len()];
        let f0 = opt.cost_and_gradient(&x, &mut g).unwrap();
        prop_assert!(f0.is_finite());
        let mut num = Vec::new();
        let mut noise = Vec::new();
        let mut scratch = vec![0.0; x.len()];
        for k in 0..x.len() {
            // Richardson's extrapolation of central differences with steps h and h/2 cancels
            // their h² error: one step cannot serve every case, as at 1e-6 the cost's
            // rounding (it sums many terms) reached 1e-6 of the gradient in some and at 1e-5
            // the truncation did in others.
            let h = 1e-5 * x[k].abs().max(1.0);
            let mut central = |h: f64| {
                let (mut xp, mut xm) = (x.clone(), x.clone());
                xp[k] += h;
                xm[k] -= h;
                let fp = opt.cost_and_gradient(&xp, &mut scratch).unwrap();
                let fm = opt.cost_and_gradient(&xm, &mut scratch).unwrap();
                ((fp - fm) / (2.0 * h), fp.abs().max(fm.abs()))
            };
            let (coarse, f1) = central(h);
            let (fine, f2) = central(0.5 * h);
            num.push((4.0 * fine - coarse) / 3.0);
            // The differences' rounding, a few ulps of the cost over each step, as weighted.
            let ulps = 8.0 * f64::EPSILON;
            noise.push((4.0 * ulps * f2 / h + ulps * f1 / (2.0 * h)) / 3.0);
        }
        crate::test_util::check_gradient_blocks_with_noise(&num, &g, 3 * inner, &noise)?;
        Ok(())
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(16))]
        /// Gradient of the full cost (energy, time, speed, acceleration, corridor and
        /// waypoint terms) against central differences.
        #[test] fn cost_gradient_s2(seed in any::<u64>(), inner in 0usize..5, corridor in any::<bool>()) { check_gradient::<2>(seed, inner, corridor)?; }
        #[test] fn cost_gradient_s3(seed in any::<u64>(), inner in 0usize..5, corridor in any::<bool>()) { check_gradient::<3>(seed, inner, corridor)?; }
        #[test] fn cost_gradient_s4(seed in any::<u64>(), inner in 0usize..5, corridor in any::<bool>()) { check_gradient::<4>(seed, inner, corridor)?; }
    }
}
