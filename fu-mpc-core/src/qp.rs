//! The convex QP of one sequential-linearisation step, and its Clarabel back-end.

use clarabel::algebra::CscMatrix;
use clarabel::solver::{
    DefaultSettings, DefaultSettingsBuilder, DefaultSolver, IPSolver, NonnegativeConeT,
    SolverStatus,
};

/// min ½ uᵀ H u + qᵀ u  s.t.  lo ≤ u ≤ hi,  w_lo ≤ ω_0 + Δt·cumsum(u)_k ≤ w_hi (k = 1..N),
/// with H = 2γ DᵀD + ρI (D the first-difference operator), the structure of (19)–(21).
#[derive(Debug, Clone, Default)]
pub(crate) struct StepQp {
    pub(crate) n: usize,
    pub(crate) gamma: f64,
    pub(crate) rho: f64,
    pub(crate) q: Vec<f64>,
    pub(crate) u_max: f64,
    pub(crate) omega0: f64,
    pub(crate) dt: f64,
    pub(crate) w_lo: Vec<f64>,
    pub(crate) w_hi: Vec<f64>,
}

impl StepQp {
    /// The objective at `u`.
    #[cfg(test)]
    pub(crate) fn objective(&self, u: &[f64]) -> f64 {
        let mut v = 0.0;
        for i in 0..self.n {
            v += 0.5 * self.rho * u[i] * u[i] + self.q[i] * u[i];
            if i + 1 < self.n {
                let d = u[i + 1] - u[i];
                v += self.gamma * d * d;
            }
        }
        v
    }

    /// The dense Hessian H (row-major, n × n).
    pub(crate) fn hessian(&self) -> Vec<f64> {
        let n = self.n;
        let mut h = vec![0.0; n * n];
        for i in 0..n {
            h[i * n + i] += self.rho;
            if i + 1 < n {
                let g = 2.0 * self.gamma;
                h[i * n + i] += g;
                h[(i + 1) * n + i + 1] += g;
                h[i * n + i + 1] -= g;
                h[(i + 1) * n + i] -= g;
            }
        }
        h
    }

    /// Solves with Clarabel; `None` if it does not report a solution.
    pub(crate) fn solve_clarabel(&self) -> Option<Vec<f64>> {
        // Clarabel's equilibration can make its iterates cycle at a degenerate vertex (seen
        // with ω0 on a speed limit, the first rows of that limit all active at the optimum);
        // without it, or with shorter steps, those problems solve.
        for (equilibrate, step_fraction) in [(true, 0.99), (false, 0.99), (true, 0.9)] {
            let settings = DefaultSettingsBuilder::default()
                .verbose(false)
                .tol_gap_abs(1e-10)
                .tol_gap_rel(1e-10)
                .tol_feas(1e-10)
                .equilibrate_enable(equilibrate)
                .max_step_fraction(step_fraction)
                .build();
            if let Some(x) = settings.ok().and_then(|s| self.solve_with(s)) {
                return Some(x);
            }
        }
        None
    }

    /// Solves with Clarabel and the given settings.
    fn solve_with(&self, settings: DefaultSettings<f64>) -> Option<Vec<f64>> {
        let n = self.n;
        let h = self.hessian();
        // Upper triangle of H in CSC.
        let (mut colptr, mut rowval, mut nzval) = (vec![0usize], Vec::new(), Vec::new());
        for j in 0..n {
            for i in j.saturating_sub(1)..=j {
                let v = h[i * n + j];
                if v != 0.0 {
                    rowval.push(i);
                    nzval.push(v);
                }
            }
            colptr.push(rowval.len());
        }
        let p = CscMatrix::new(n, n, colptr, rowval, nzval);
        // Rows: u ≤ u_max, −u ≤ u_max, Δt·cumsum ≤ w_hi − ω0, −Δt·cumsum ≤ ω0 − w_lo.
        let m = 4 * n;
        let (mut colptr, mut rowval, mut nzval) = (vec![0usize], Vec::new(), Vec::new());
        for j in 0..n {
            rowval.push(j);
            nzval.push(1.0);
            rowval.push(n + j);
            nzval.push(-1.0);
            // u_j enters ω_k for every k > j, i.e. rows k − 1 ≥ j.
            for k in j..n {
                rowval.push(2 * n + k);
                nzval.push(self.dt);
            }
            for k in j..n {
                rowval.push(3 * n + k);
                nzval.push(-self.dt);
            }
            colptr.push(rowval.len());
        }
        let a = CscMatrix::new(m, n, colptr, rowval, nzval);
        let mut b = vec![self.u_max; 2 * n];
        b.extend(self.w_hi.iter().map(|w| w - self.omega0));
        b.extend(self.w_lo.iter().map(|w| self.omega0 - w));
        let cones = [NonnegativeConeT::<f64>(m)];
        let mut solver = DefaultSolver::new(&p, &self.q, &a, &b, &cones, settings).ok()?;
        solver.solve();
        match solver.solution.status {
            SolverStatus::Solved | SolverStatus::AlmostSolved => Some(solver.solution.x.clone()),
            _ => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]

        /// Clarabel's point is feasible and no feasible perturbation of it is better.
        #[test]
        fn clarabel_solutions_are_optimal(
            q in proptest::collection::vec(-5.0f64..5.0, 8),
            omega0 in -1.0f64..1.0,
            gamma in 0.0f64..1.0,
            dirs in proptest::collection::vec(proptest::collection::vec(-1.0f64..1.0, 8), 20),
        ) {
            let qp = StepQp {
                n: 8,
                gamma,
                rho: 0.1,
                q,
                u_max: 2.0,
                omega0,
                dt: 0.1,
                w_lo: vec![-1.0; 8],
                w_hi: vec![1.0; 8],
            };
            let x = qp.solve_clarabel().unwrap();
            let feasible = |u: &[f64]| {
                let mut w = qp.omega0;
                u.iter().all(|v| {
                    w += v * qp.dt;
                    v.abs() <= qp.u_max + 1e-7 && (-1.0 - 1e-7..=1.0 + 1e-7).contains(&w)
                })
            };
            prop_assert!(feasible(&x));
            let fx = qp.objective(&x);
            for d in &dirs {
                for t in [1e-3, 1e-2, 1e-1] {
                    let y: Vec<f64> = x.iter().zip(d).map(|(a, b)| a + t * b).collect();
                    if feasible(&y) {
                        prop_assert!(qp.objective(&y) >= fx - 1e-7);
                    }
                }
            }
        }
    }

    /// A degenerate vertex (ω0 on the lower limit, the optimum on the first two of its rows)
    /// on which Clarabel's default settings cycle until their iteration limit.
    #[test]
    fn a_degenerate_vertex_is_solved() {
        let band = 2.488_389_921_361_874_5;
        let qp = StepQp {
            n: 3,
            gamma: 0.672_268_099_349_669_8,
            rho: 12.491_435_637_457_42,
            q: vec![
                5.666_323_073_241_197,
                3.766_406_310_270_751_7,
                -14.211_117_186_316_645,
            ],
            u_max: 5.761_649_075_646_14,
            omega0: -band,
            dt: 0.1,
            w_lo: vec![-band; 3],
            w_hi: vec![band; 3],
        };
        let x = qp.solve_clarabel().unwrap();
        // KKT by hand: u0 = u1 = 0 on the speed rows, u2 free inside its box.
        let u2 = -qp.q[2] / (qp.rho + 2.0 * qp.gamma);
        for (got, want) in x.iter().zip([0.0, 0.0, u2]) {
            assert!((got - want).abs() < 1e-7, "{x:?}");
        }
    }
}
