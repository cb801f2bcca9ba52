//! A dedicated primal active-set solver for the QP of one linearisation step.
//!
//! The QP (see [`StepQp`]) has a constant tridiagonal Hessian H = 2γDᵀD + ρI, so H⁻¹ and its
//! products with the prefix-sum constraint vectors are computed once per controller; each
//! iteration then costs O(n²) plus a Cholesky factorisation of the small matrix of the
//! working set. The solve starts from a feasible point (the current iterate of the
//! linearisation), keeps it feasible, and allocates nothing.

use crate::qp::StepQp;

/// One inequality aᵀu ≤ b of the QP.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Row {
    /// u_j ≤ u_max.
    UHi(usize),
    /// −u_j ≤ u_max.
    ULo(usize),
    /// Δt Σ_{j<k+1} u_j ≤ w_hi_k − ω0 (speed after step k at most its upper limit).
    WHi(usize),
    /// −Δt Σ_{j<k+1} u_j ≤ ω0 − w_lo_k.
    WLo(usize),
}

/// The solver's precomputed data and workspace, for one horizon and one (γ, ρ, Δt).
#[derive(Debug, Clone)]
pub(crate) struct ActiveSet {
    n: usize,
    gamma: f64,
    rho: f64,
    dt: f64,
    /// The Thomas factorisation of the tridiagonal H: superdiagonal ratios c_i and inverse
    /// pivots 1/m_i, so H⁻¹x costs O(n) instead of a dense product.
    thomas_c: Vec<f64>,
    thomas_inv: Vec<f64>,
    /// H's off-diagonal −2γ.
    off: f64,
    /// H⁻¹, row-major.
    minv: Vec<f64>,
    /// P[i][k] = (H⁻¹ ℓ_k)_i with ℓ_k = Δt (1, …, 1, 0, …) (k + 1 ones).
    p: Vec<f64>,
    /// Q[k][l] = ℓ_kᵀ H⁻¹ ℓ_l.
    q: Vec<f64>,
    working: Vec<Row>,
    /// Rows skipped in one ratio test.
    skip: Vec<Row>,
    /// Working-set membership by row slot, and prefix sums of the step and the point.
    mask: Vec<bool>,
    cum_p: Vec<f64>,
    cum_u: Vec<f64>,
    /// Cholesky factor of the working set's A H⁻¹ Aᵀ (lower, row stride `cap`), valid for
    /// its first `factored` rows.
    s: Vec<f64>,
    cap: usize,
    factored: usize,
    lambda: Vec<f64>,
    rhs: Vec<f64>,
    g: Vec<f64>,
    hg: Vec<f64>,
    v: Vec<f64>,
    step: Vec<f64>,
}

impl ActiveSet {
    /// Precomputes H⁻¹ and its products with the speed constraints; `None` if H is not
    /// positive definite (ρ ≤ 0 or a non-finite setting) or the tables overflow.
    pub(crate) fn new(n: usize, gamma: f64, rho: f64, dt: f64) -> Option<Self> {
        if !(rho > 0.0 && gamma >= 0.0 && dt > 0.0 && rho.is_finite() && gamma.is_finite()) {
            return None;
        }
        // H⁻¹ column by column with the Thomas algorithm (H is tridiagonal and diagonally
        // dominant: ρ > 0).
        let diag: Vec<f64> = (0..n)
            .map(|i| {
                let neighbours = usize::from(i > 0) + usize::from(i + 1 < n);
                // Each first difference touching u_i adds 2γ.
                #[allow(clippy::cast_precision_loss)]
                let d = rho + 2.0 * gamma * neighbours as f64;
                d
            })
            .collect();
        let off = -2.0 * gamma;
        let mut minv = vec![0.0; n * n];
        let mut c = vec![0.0; n];
        let mut d = vec![0.0; n];
        for col in 0..n {
            for i in 0..n {
                let rhs = if i == col { 1.0 } else { 0.0 };
                if i == 0 {
                    c[0] = off / diag[0];
                    d[0] = rhs / diag[0];
                } else {
                    let m = diag[i] - off * c[i - 1];
                    c[i] = off / m;
                    d[i] = (rhs - off * d[i - 1]) / m;
                }
            }
            let mut x = d[n - 1];
            minv[(n - 1) * n + col] = x;
            for i in (0..n - 1).rev() {
                x = d[i] - c[i] * x;
                minv[i * n + col] = x;
            }
        }
        let mut thomas_c = vec![0.0; n];
        let mut thomas_inv = vec![0.0; n];
        for i in 0..n {
            let m = if i == 0 {
                diag[0]
            } else {
                diag[i] - off * thomas_c[i - 1]
            };
            thomas_inv[i] = 1.0 / m;
            thomas_c[i] = off / m;
        }
        let mut p = vec![0.0; n * n];
        for i in 0..n {
            let mut acc = 0.0;
            for k in 0..n {
                acc += dt * minv[i * n + k];
                p[i * n + k] = acc;
            }
        }
        let mut q = vec![0.0; n * n];
        for l in 0..n {
            let mut acc = 0.0;
            for k in 0..n {
                acc += dt * p[k * n + l];
                q[k * n + l] = acc;
            }
        }
        // Settings so extreme that the tables overflow (γ near f64::MAX, Δt near 1e155) leave
        // the QP to the general solver.
        if !minv.iter().chain(&p).chain(&q).all(|v| v.is_finite()) {
            return None;
        }
        Some(Self {
            n,
            gamma,
            rho,
            dt,
            thomas_c,
            thomas_inv,
            off,
            minv,
            p,
            q,
            working: Vec::with_capacity(2 * n + 1),
            skip: vec![Row::UHi(0); 4 * n],
            mask: vec![false; 4 * n],
            cum_p: vec![0.0; n],
            cum_u: vec![0.0; n],
            s: vec![0.0; (2 * n + 1) * (2 * n + 1)],
            cap: 2 * n + 1,
            factored: 0,
            lambda: vec![0.0; 2 * n],
            rhs: vec![0.0; 2 * n],
            g: vec![0.0; n],
            hg: vec![0.0; n],
            v: vec![0.0; n],
            step: vec![0.0; n],
        })
    }

    /// Whether the precomputation fits this QP.
    pub(crate) fn fits(&self, qp: &StepQp) -> bool {
        self.n == qp.n && self.gamma == qp.gamma && self.rho == qp.rho && self.dt == qp.dt
    }

    /// aᵀx for a constraint row.
    fn dot(&self, r: Row, x: &[f64]) -> f64 {
        match r {
            Row::UHi(j) => x[j],
            Row::ULo(j) => -x[j],
            Row::WHi(k) => self.dt * x[..=k].iter().sum::<f64>(),
            Row::WLo(k) => -self.dt * x[..=k].iter().sum::<f64>(),
        }
    }

    fn bound(r: Row, qp: &StepQp) -> f64 {
        match r {
            Row::UHi(_) | Row::ULo(_) => qp.u_max,
            Row::WHi(k) => qp.w_hi[k] - qp.omega0,
            Row::WLo(k) => qp.omega0 - qp.w_lo[k],
        }
    }

    /// aᵀ H⁻¹ b for two rows, from the precomputed tables.
    fn inner(&self, a: Row, b: Row) -> f64 {
        let n = self.n;
        let (sa, ia, ka) = split(a);
        let (sb, ib, kb) = split(b);
        let v = match (ka, kb) {
            (false, false) => self.minv[ia * n + ib],
            (false, true) => self.p[ia * n + ib],
            (true, false) => self.p[ib * n + ia],
            (true, true) => self.q[ia * n + ib],
        };
        sa * sb * v
    }

    /// Adds aᵀ-weighted `w` of row `r` into `out` (out += w a).
    fn axpy(&self, r: Row, w: f64, out: &mut [f64]) {
        match r {
            Row::UHi(j) => out[j] += w,
            Row::ULo(j) => out[j] -= w,
            Row::WHi(k) => out[..=k].iter_mut().for_each(|o| *o += w * self.dt),
            Row::WLo(k) => out[..=k].iter_mut().for_each(|o| *o -= w * self.dt),
        }
    }

    /// Extends the Cholesky factor L of S = A H⁻¹ Aᵀ to every row of the working set (rows
    /// already factored are kept: S's entries depend on the rows only). Returns `false`, with
    /// the factor valid up to the last independent row, if a row depends on earlier ones.
    fn extend_factor(&mut self) -> bool {
        let cap = self.cap;
        let m = self.working.len();
        for i in self.factored..m {
            if i >= cap {
                // More rows than the factor holds: some must depend on the others.
                self.factored = i;
                return false;
            }
            let ri = self.working[i];
            for j in 0..=i {
                let mut x = self.inner(ri, self.working[j]);
                for k in 0..j {
                    x -= self.s[i * cap + k] * self.s[j * cap + k];
                }
                if j < i {
                    self.s[i * cap + j] = x / self.s[j * cap + j];
                } else {
                    let diag = self.inner(ri, ri);
                    // Written so a NaN pivot counts as dependent too.
                    if !(x > 1e-10 * diag && x > 0.0) {
                        self.factored = i;
                        return false;
                    }
                    self.s[i * cap + i] = x.sqrt();
                }
            }
        }
        self.factored = m;
        true
    }

    /// Removes working row `a` (the factor is kept up to it).
    fn remove(&mut self, a: usize) {
        self.working.remove(a);
        self.factored = self.factored.min(a);
    }

    /// Multipliers of the working set for the gradient in `g`: solves
    /// (A H⁻¹ Aᵀ) λ = −A H⁻¹ g. Returns `false` if the working set is dependent.
    fn multipliers(&mut self) -> bool {
        if !self.extend_factor() {
            return false;
        }
        let m = self.working.len();
        let cap = self.cap;
        self.hg.copy_from_slice(&self.g);
        thomas(&self.thomas_c, &self.thomas_inv, self.off, &mut self.hg);
        for a in 0..m {
            self.rhs[a] = -self.dot(self.working[a], &self.hg);
        }
        for i in 0..m {
            let mut x = self.rhs[i];
            for k in 0..i {
                x -= self.s[i * cap + k] * self.lambda[k];
            }
            self.lambda[i] = x / self.s[i * cap + i];
        }
        for i in (0..m).rev() {
            let mut x = self.lambda[i];
            for k in i + 1..m {
                x -= self.s[k * cap + i] * self.lambda[k];
            }
            self.lambda[i] = x / self.s[i * cap + i];
        }
        true
    }

    /// Solves the QP from the feasible point `u` (overwritten with the solution). Returns
    /// `false` (leaving a feasible `u`) if it cannot finish within its iteration limit.
    pub(crate) fn solve(&mut self, qp: &StepQp, u: &mut [f64]) -> bool {
        let n = self.n;
        self.working.clear();
        self.factored = 0;
        // Warm start: the constraints active at u, while they stay independent.
        // Prefix sums make each speed row's aᵀu O(1).
        let mut cu = 0.0;
        for j in 0..n {
            cu += u[j];
            self.cum_u[j] = self.dt * cu;
        }
        let rows = (0..n).flat_map(|j| [Row::UHi(j), Row::ULo(j), Row::WHi(j), Row::WLo(j)]);
        for r in rows {
            let au = match r {
                Row::UHi(j) => u[j],
                Row::ULo(j) => -u[j],
                Row::WHi(k) => self.cum_u[k],
                Row::WLo(k) => -self.cum_u[k],
            };
            let slack = Self::bound(r, qp) - au;
            if slack.abs() <= 1e-12 * (1.0 + Self::bound(r, qp).abs()) {
                self.working.push(r);
                if !self.extend_factor() {
                    self.working.pop();
                }
            }
        }
        for _ in 0..8 * n + 16 {
            // g = H u + q.
            for i in 0..n {
                let mut x = (self.rho
                    + 2.0 * self.gamma * (usize::from(i > 0) + usize::from(i + 1 < n)) as f64)
                    * u[i]
                    + qp.q[i];
                if i > 0 {
                    x -= 2.0 * self.gamma * u[i - 1];
                }
                if i + 1 < n {
                    x -= 2.0 * self.gamma * u[i + 1];
                }
                self.g[i] = x;
            }
            if !self.multipliers() {
                return false;
            }
            // Step p = −H⁻¹ (g + Aᵀλ).
            let m = self.working.len();
            let mut t = core::mem::take(&mut self.step);
            t.copy_from_slice(&self.g);
            for a in 0..m {
                self.axpy(self.working[a], self.lambda[a], &mut t);
            }
            for i in 0..n {
                self.v[i] = -t[i];
            }
            self.step = t;
            thomas(&self.thomas_c, &self.thomas_inv, self.off, &mut self.v);
            let norm = self.v.iter().map(|x| x.abs()).fold(0.0, f64::max);
            // Stationary up to the rounding of the working set's solve (its matrix can be
            // ill-conditioned: prefix sums of neighbouring steps are nearly parallel).
            let scale = 1.0
                + u.iter().map(|x| x.abs()).fold(0.0, f64::max)
                + self.hg.iter().map(|x| x.abs()).fold(0.0, f64::max);
            if norm <= 1e-10 * scale || m >= n {
                // Stationary on the working set: optimal if every multiplier is ≥ 0.
                let (mut worst, mut at) = (-1e-12, usize::MAX);
                for a in 0..m {
                    if self.lambda[a] < worst {
                        worst = self.lambda[a];
                        at = a;
                    }
                }
                if at == usize::MAX {
                    u.iter_mut().for_each(|x| *x = x.clamp(-qp.u_max, qp.u_max));
                    return true;
                }
                self.remove(at);
                continue;
            }
            // Longest feasible step along p, up to 1. A row that rounding makes look blocking
            // although it depends on the working set is skipped: adding it would make the
            // set dependent, and p does not move along it.
            let mut skipped = 0usize;
            // Prefix sums make every row's aᵀp and aᵀu O(1); a mask marks working rows.
            self.mask.fill(false);
            for r in &self.working {
                self.mask[index(*r)] = true;
            }
            let (mut cp, mut cu) = (0.0, 0.0);
            for j in 0..n {
                cp += self.v[j];
                cu += u[j];
                self.cum_p[j] = self.dt * cp;
                self.cum_u[j] = self.dt * cu;
            }
            let alpha = loop {
                let mut alpha = 1.0;
                let mut blocking = None;
                for j in 0..n {
                    let rows = [
                        (Row::UHi(j), self.v[j], u[j]),
                        (Row::ULo(j), -self.v[j], -u[j]),
                        (Row::WHi(j), self.cum_p[j], self.cum_u[j]),
                        (Row::WLo(j), -self.cum_p[j], -self.cum_u[j]),
                    ];
                    for (r, ap, au) in rows {
                        if self.mask[index(r)] || self.skip[..skipped].contains(&r) {
                            continue;
                        }
                        if ap > 1e-12 * norm {
                            let room = (Self::bound(r, qp) - au).max(0.0);
                            let a = room / ap;
                            if a < alpha {
                                alpha = a;
                                blocking = Some(r);
                            }
                        }
                    }
                }
                let Some(r) = blocking else {
                    break alpha;
                };
                self.working.push(r);
                if self.extend_factor() {
                    // The blocking row joins the working set with its row of the factor,
                    // the one the next multipliers would compute.
                    break alpha;
                }
                self.working.pop();
                self.factored = self.factored.min(self.working.len());
                if skipped == self.skip.len() {
                    break alpha;
                }
                self.skip[skipped] = r;
                skipped += 1;
            };
            for i in 0..n {
                u[i] += alpha * self.v[i];
            }
            // Keep active bounds on u exact, so rounding never leaves the box.
            for r in &self.working {
                match *r {
                    Row::UHi(j) => u[j] = qp.u_max,
                    Row::ULo(j) => u[j] = -qp.u_max,
                    _ => {}
                }
            }
        }
        false
    }
}

/// Overwrites `x` with H⁻¹x for the tridiagonal H of Thomas factors `c`, `inv` and
/// off-diagonal `off`.
fn thomas(c: &[f64], inv: &[f64], off: f64, x: &mut [f64]) {
    let n = x.len();
    if n == 0 {
        return;
    }
    x[0] *= inv[0];
    for i in 1..n {
        x[i] = (x[i] - off * x[i - 1]) * inv[i];
    }
    for i in (0..n - 1).rev() {
        x[i] -= c[i] * x[i + 1];
    }
}

/// A row's slot in the mask.
fn index(r: Row) -> usize {
    match r {
        Row::UHi(j) => 4 * j,
        Row::ULo(j) => 4 * j + 1,
        Row::WHi(j) => 4 * j + 2,
        Row::WLo(j) => 4 * j + 3,
    }
}

/// (sign, index, is a speed row) of a constraint.
fn split(r: Row) -> (f64, usize, bool) {
    match r {
        Row::UHi(j) => (1.0, j, false),
        Row::ULo(j) => (-1.0, j, false),
        Row::WHi(k) => (1.0, k, true),
        Row::WLo(k) => (-1.0, k, true),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn cases() -> u32 {
        std::env::var("PROPTEST_CASES")
            .ok()
            .and_then(|s| s.parse().ok())
            .unwrap_or(500)
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(cases()))]

        /// The active-set solution matches Clarabel's objective and is feasible.
        #[test]
        fn matches_clarabel(
            n in 1usize..24,
            q in proptest::collection::vec(-20.0f64..20.0, 24),
            omega0 in -3.0f64..3.0,
            gamma in 0.0f64..1.0,
            rho in 0.01f64..20.0,
            u_max in 0.5f64..8.0,
            band in 0.5f64..3.2,
            start in proptest::collection::vec(-1.0f64..1.0, 24),
        ) {
            let qp = StepQp {
                n,
                gamma,
                rho,
                q: q[..n].to_vec(),
                u_max,
                omega0: omega0.clamp(-band, band),
                dt: 0.1,
                w_lo: vec![-band; n],
                w_hi: vec![band; n],
            };
            // A feasible start: the given directions, clipped along the prefix sums.
            let mut u: Vec<f64> = start[..n].iter().map(|s| s * u_max).collect();
            let mut w = qp.omega0;
            for x in u.iter_mut() {
                let lo = ((-band - w) / qp.dt).max(-u_max);
                let hi = ((band - w) / qp.dt).min(u_max);
                *x = x.clamp(lo, hi);
                w += *x * qp.dt;
            }
            let mut solver = ActiveSet::new(n, gamma, rho, qp.dt).unwrap();
            prop_assert!(solver.fits(&qp));
            prop_assert!(solver.solve(&qp, &mut u));
            let reference = qp.solve_clarabel().unwrap();
            let (a, b) = (qp.objective(&u), qp.objective(&reference));
            prop_assert!((a - b).abs() <= 1e-6 * (1.0 + b.abs()), "{} vs {}", a, b);
            let mut w = qp.omega0;
            for x in &u {
                prop_assert!(x.abs() <= u_max * (1.0 + 1e-12));
                w += x * qp.dt;
                prop_assert!(w >= -band - 1e-9 && w <= band + 1e-9);
            }
        }
    }
}
