//! The MINCO problem: set up once, solve for new waypoints and durations, propagate gradients.

use crate::error::{MincoError, Result};
use crate::hermite::{Block, MAX_FREE, TABLES, Table, Tables, spd_inverse};
use crate::poly::{FALLING, MAX_COEFFS, eval, powers};
use crate::trajectory::Trajectory;

/// `ENERGY_WEIGHT[s][k][l]` = k!/(k−s)! · l!/(l−s)! / (k + l − 2s + 1): the coefficient of
/// c_k c_l T^(k+l−2s+1) in ∫₀^T ‖p^(s)‖² dt (zero where k or l < s).
const ENERGY_WEIGHT: [[[f64; MAX_COEFFS]; MAX_COEFFS]; 5] = {
    let mut w = [[[0.0; MAX_COEFFS]; MAX_COEFFS]; 5];
    let mut s = 2;
    while s <= 4 {
        let mut k = s;
        while k < 2 * s {
            let mut l = s;
            while l < 2 * s {
                w[s][k][l] = FALLING[s][k] * FALLING[s][l] / (k + l - 2 * s + 1) as f64;
                l += 1;
            }
            k += 1;
        }
        s += 1;
    }
    w
};

/// Powers T^0, T^−1, …, T^−8 of a duration: every exponent of the scaled tables.
#[inline(always)]
fn inverse_powers(t: f64) -> [f64; MAX_COEFFS + 1] {
    let r = 1.0 / t;
    let mut p = [1.0; MAX_COEFFS + 1];
    for k in 1..=MAX_COEFFS {
        p[k] = p[k - 1] * r;
    }
    p
}

/// A MINCO problem of order `S` (2: minimum acceleration, 3: jerk, 4: snap) in `D` dimensions.
///
/// Piece i is p_i(t) = Σ_{k<2S} c_{i,k} t^k on [0, T_i]. Given the head and tail states
/// (derivatives 0..S−1), the M−1 inner waypoints q_1..q_{M−1} and the durations T_i > 0, the
/// coefficients minimising the control effort J = Σ_i ∫ ‖p_i^(S)‖² dt are those of the banded
/// system A(T) c = b(q, head, tail) of size 2SM (rows: the S head conditions; per junction the
/// continuity of derivatives S..2S−2, the waypoint, the continuity of 0..S−1; the S tail
/// conditions).
///
/// The system is solved in O(M) by eliminating its block structure: each piece is written in
/// Hermite form through the states (derivatives 0..S−1) at its two ends, so only the free
/// derivatives 1..S−1 at each junction remain unknown. Minimising J over them is a symmetric
/// positive-definite block-tridiagonal system with (S−1) × (S−1) blocks — its equations are
/// the continuity of derivatives S..2S−2 — factorised by a block LDLᵀ. The adjoint of any cost
/// reuses that factorisation (see [`Minco::propagate_gradient`]).
///
/// The problem owns all its memory: after [`Minco::new`], [`Minco::solve`] and
/// [`Minco::propagate_gradient`] do not allocate.
///
/// # Example
/// ```
/// use minco::MinimumJerk;
///
/// # fn main() -> Result<(), minco::MincoError> {
/// let mut m = MinimumJerk::<3>::new(2)?;
/// let rest = |p: [f64; 3]| [p, [0.0; 3], [0.0; 3]]; // position, velocity, acceleration
/// m.solve(&rest([0.0; 3]), &rest([2.0, 0.0, 0.0]), &[[1.0, 1.0, 0.0]], &[1.0, 1.0])?;
/// let traj = m.trajectory()?;
/// assert!((traj.position(1.0)?[1] - 1.0).abs() < 1e-12); // passes the waypoint
/// assert!(m.energy() > 0.0);
/// # Ok(()) }
/// ```
#[derive(Debug, Clone)]
pub struct Minco<const S: usize, const D: usize> {
    pieces: usize,
    durations: Vec<f64>,
    /// T_i^0..T_i^−8 per piece.
    inv_powers: Vec<[f64; MAX_COEFFS + 1]>,
    /// States (derivatives 0..S−1) at the M + 1 piece ends: row S·j + m is the m-th derivative
    /// at end j, so piece i's Hermite data is rows S·i..S·(i+2).
    states: Vec<[f64; D]>,
    coeffs: Vec<[f64; D]>,
    /// Inverses of the pivot blocks of the block LDLᵀ, one per junction.
    pivots: Vec<Block>,
    /// The sub-diagonal factor blocks: `lower[k]` couples junction k to k − 1 (k ≥ 1).
    lower: Vec<Block>,
    /// Per junction: the forward-eliminated right-hand side, then the adjoint solution.
    work: Vec<[[f64; D]; MAX_FREE]>,
    /// ∂K/∂z: the cost's partials with respect to the states, same layout as `states`.
    adjoint: Vec<[f64; D]>,
    solved: bool,
}

/// Minimum-acceleration MINCO (S = 2, cubic pieces).
pub type MinimumAcceleration<const D: usize> = Minco<2, D>;
/// Minimum-jerk MINCO (S = 3, quintic pieces).
pub type MinimumJerk<const D: usize> = Minco<3, D>;
/// Minimum-snap MINCO (S = 4, septic pieces).
pub type MinimumSnap<const D: usize> = Minco<4, D>;

fn check_finite_rows<const D: usize>(rows: &[[f64; D]], what: &'static str) -> Result<()> {
    if rows.iter().flatten().all(|v| v.is_finite()) {
        Ok(())
    } else {
        Err(MincoError::NonFinite { what })
    }
}

#[inline(always)]
pub(crate) fn sub<const D: usize>(a: &[f64; D], b: &[f64; D]) -> [f64; D] {
    core::array::from_fn(|d| a[d] - b[d])
}

fn check_len(what: &'static str, expected: usize, found: usize) -> Result<()> {
    if expected == found {
        Ok(())
    } else {
        Err(MincoError::LengthMismatch {
            what,
            expected,
            found,
        })
    }
}

impl<const S: usize, const D: usize> Minco<S, D> {
    const N: usize = 2 * S;
    /// Free derivatives per junction.
    const F: usize = S - 1;
    /// Largest number of pieces, 2^16: a problem holds about 700 bytes per piece for S = 4
    /// and D = 3 (1.4 kB for D = 8), all allocated by [`Minco::new`], so a count from bad
    /// input cannot ask for gigabytes; trajectories of robots have tens of pieces.
    pub const MAX_PIECES: usize = 1 << 16;
    const TAB: &'static Tables = &TABLES[S];

    /// A problem with `pieces` pieces.
    ///
    /// # Errors
    /// [`MincoError::UnsupportedOrder`] unless S ∈ {2, 3, 4} (code that calls the solver's
    /// methods on an order above 4 does not compile), [`MincoError::ZeroDimension`] for
    /// D = 0, [`MincoError::NoPieces`] for zero pieces, [`MincoError::InvalidConfig`] for more
    /// than [`Minco::MAX_PIECES`].
    pub fn new(pieces: usize) -> Result<Self> {
        if !(2..=4).contains(&S) {
            return Err(MincoError::UnsupportedOrder(S));
        }
        if D == 0 {
            return Err(MincoError::ZeroDimension);
        }
        if pieces == 0 {
            return Err(MincoError::NoPieces);
        }
        if pieces > Self::MAX_PIECES {
            return Err(MincoError::InvalidConfig {
                what: "pieces",
                reason: "at most MAX_PIECES (2^16) pieces",
            });
        }
        let junctions = pieces - 1;
        Ok(Self {
            pieces,
            durations: vec![1.0; pieces],
            inv_powers: vec![[1.0; MAX_COEFFS + 1]; pieces],
            states: vec![[0.0; D]; S * (pieces + 1)],
            coeffs: vec![[0.0; D]; Self::N * pieces],
            pivots: vec![[[0.0; MAX_FREE]; MAX_FREE]; junctions],
            lower: vec![[[0.0; MAX_FREE]; MAX_FREE]; junctions],
            work: vec![[[0.0; D]; MAX_FREE]; junctions],
            adjoint: vec![[0.0; D]; S * (pieces + 1)],
            solved: false,
        })
    }

    /// Number of pieces M.
    pub fn pieces(&self) -> usize {
        self.pieces
    }

    /// The durations of the last solve \[s\] (meaningful only while [`Minco::is_solved`]).
    pub fn durations(&self) -> &[f64] {
        &self.durations
    }

    /// The coefficients of the last solve: row 2S·i + k holds c_{i,k} for all D dimensions
    /// (meaningful only while [`Minco::is_solved`]).
    pub fn coefficients(&self) -> &[[f64; D]] {
        &self.coeffs
    }

    /// W(T)\[a\]\[b\] = W₁\[a\]\[b\] T^{m_a + m_b + 1 − 2S}, from the inverse powers of T.
    #[inline(always)]
    fn w(ip: &[f64; MAX_COEFFS + 1], a: usize, b: usize) -> f64 {
        Self::TAB.w[a][b] * ip[2 * S - 1 - a % S - b % S]
    }

    /// Solves for the coefficients.
    ///
    /// `head` and `tail` hold derivatives 0..S−1 of the start and end states, `waypoints` the
    /// M−1 inner waypoints, `durations` the M piece durations \[s\].
    ///
    /// # Errors
    /// [`MincoError::LengthMismatch`], [`MincoError::NonFinite`], [`MincoError::BadDuration`]
    /// for bad input (a duration not positive and finite, or so large or small that one of
    /// T^±1..T^±2S over- or underflows); [`MincoError::Singular`] if the system cannot be
    /// factorised. On error the problem is left unsolved.
    pub fn solve(
        &mut self,
        head: &[[f64; D]; S],
        tail: &[[f64; D]; S],
        waypoints: &[[f64; D]],
        durations: &[f64],
    ) -> Result<()> {
        let m = self.pieces;
        self.solved = false;
        check_len("waypoints", m - 1, waypoints.len())?;
        check_len("durations", m, durations.len())?;
        check_finite_rows(head, "head state")?;
        check_finite_rows(tail, "tail state")?;
        check_finite_rows(waypoints, "waypoints")?;
        for (index, &value) in durations.iter().enumerate() {
            // T^1..T^(2S−1) and T^−1..T^−2S, the powers the coefficients, the effort and
            // its gradients use, must neither overflow nor underflow (for S = 4 about
            // 1e-38 s < T < 1e38 s): a power of ∞ times one of 0 would make the effort NaN.
            let usable = |v: &f64| v.is_finite() && *v > 0.0;
            if !(value > 0.0
                && value.is_finite()
                && powers(value)[..2 * S].iter().all(usable)
                && inverse_powers(value)[..=2 * S].iter().all(usable))
            {
                return Err(MincoError::BadDuration { index, value });
            }
        }
        self.durations.copy_from_slice(durations);
        for (ip, &t) in self.inv_powers.iter_mut().zip(durations) {
            *ip = inverse_powers(t);
        }
        self.states.fill([0.0; D]);
        self.states[..S].copy_from_slice(head);
        for (i, q) in waypoints.iter().enumerate() {
            self.states[S * (i + 1)] = *q;
        }
        self.states[S * m..].copy_from_slice(tail);
        self.factor_and_solve()?;
        self.fill_coefficients();
        // S = 2 is accurate to ~1e-13 without refinement.
        if S >= 3 {
            self.refine_coefficients(tail);
        }
        if check_finite_rows(&self.coeffs, "coefficients").is_err() {
            return Err(MincoError::Singular { junction: 0 });
        }
        self.solved = true;
        Ok(())
    }

    /// Builds the junction system, factorises it and writes the free derivatives into
    /// `states`. The states' free slots must be zero on entry.
    fn factor_and_solve(&mut self) -> Result<()> {
        let (m, f) = (self.pieces, Self::F);
        if m == 1 {
            return Ok(());
        }
        for k in 0..m - 1 {
            // Junction k joins piece k (its right end) and piece k + 1 (its left end).
            let (ip_left, ip_right) = (self.inv_powers[k], self.inv_powers[k + 1]);
            let (zl, zr) = (S * k, S * (k + 1));
            let mut a: Block = [[0.0; MAX_FREE]; MAX_FREE];
            let mut r = [[0.0; D]; MAX_FREE];
            for x in 0..f {
                let (rx, lx) = (S + 1 + x, 1 + x);
                for y in 0..f {
                    a[x][y] = Self::w(&ip_left, rx, S + 1 + y) + Self::w(&ip_right, lx, 1 + y);
                }
                // Right-hand side: minus the known states' pull on this row (positions, and the
                // whole head or tail state next to the ends).
                let mut acc = [0.0; D];
                let mut pull = |w: f64, z: &[f64; D]| {
                    for d in 0..D {
                        acc[d] += w * z[d];
                    }
                };
                // J is invariant to translation (W[x][0] = −W[x][S]), so positions enter only
                // as differences: no cancellation far from the origin.
                pull(
                    Self::w(&ip_left, rx, S),
                    &sub(&self.states[zr], &self.states[zl]),
                );
                pull(
                    Self::w(&ip_right, lx, S),
                    &sub(&self.states[zr + S], &self.states[zr]),
                );
                if k == 0 {
                    for j in 1..S {
                        pull(Self::w(&ip_left, rx, j), &self.states[j]);
                    }
                }
                if k + 2 == m {
                    for j in 1..S {
                        pull(Self::w(&ip_right, lx, S + j), &self.states[zr + S + j]);
                    }
                }
                for d in 0..D {
                    r[x][d] = -acc[d];
                }
            }
            if k > 0 {
                // Coupling of junctions k − 1 and k through piece k: C[x'][y] = W_k[x'][S + y].
                let mut c: Block = [[0.0; MAX_FREE]; MAX_FREE];
                for x in 0..f {
                    for y in 0..f {
                        c[x][y] = Self::w(&ip_left, 1 + x, S + 1 + y);
                    }
                }
                // L = Cᵀ P⁻¹ with P⁻¹ the previous pivot's inverse; A −= L C; r −= L y.
                let p = &self.pivots[k - 1];
                let y_prev = self.work[k - 1];
                let mut l: Block = [[0.0; MAX_FREE]; MAX_FREE];
                for x in 0..f {
                    for z in 0..f {
                        let mut v = 0.0;
                        for u in 0..f {
                            v += c[u][x] * p[u][z];
                        }
                        l[x][z] = v;
                    }
                }
                for x in 0..f {
                    for y in 0..f {
                        let mut v = 0.0;
                        for z in 0..f {
                            v += l[x][z] * c[z][y];
                        }
                        a[x][y] -= v;
                    }
                    for z in 0..f {
                        for d in 0..D {
                            r[x][d] -= l[x][z] * y_prev[z][d];
                        }
                    }
                }
                self.lower[k] = l;
            }
            self.pivots[k] = spd_inverse(&a, f).ok_or(MincoError::Singular { junction: k })?;
            self.work[k] = r;
        }
        self.backward_in_work();
        for k in 0..m - 1 {
            self.states[S * (k + 1) + 1..S * (k + 1) + S].copy_from_slice(&self.work[k][..f]);
        }
        Ok(())
    }

    /// Replaces the right-hand side in `work` by H⁻¹ times it, with the factors of the solve.
    fn solve_in_work(&mut self) {
        let (m, f) = (self.pieces, Self::F);
        if m == 1 {
            return;
        }
        // Forward: y_k −= L_k y_{k−1}.
        let mut prev = self.work[0];
        for k in 1..m - 1 {
            let l = &self.lower[k];
            let y = &mut self.work[k];
            for x in 0..f {
                for z in 0..f {
                    for d in 0..D {
                        y[x][d] -= l[x][z] * prev[z][d];
                    }
                }
            }
            prev = *y;
        }
        self.backward_in_work();
    }

    /// Block back substitution in `work`: x_k = P_k⁻¹ y_k − L_{k+1}ᵀ x_{k+1}.
    fn backward_in_work(&mut self) {
        let (m, f) = (self.pieces, Self::F);
        let mut next = [[0.0; D]; MAX_FREE];
        for k in (0..m - 1).rev() {
            let p = &self.pivots[k];
            let y = self.work[k];
            let mut x = [[0.0; D]; MAX_FREE];
            for a in 0..f {
                for z in 0..f {
                    for d in 0..D {
                        x[a][d] += p[a][z] * y[z][d];
                    }
                }
            }
            if k + 2 < m {
                let l = &self.lower[k + 1];
                for z in 0..f {
                    for a in 0..f {
                        for d in 0..D {
                            x[a][d] -= l[z][a] * next[z][d];
                        }
                    }
                }
            }
            self.work[k] = x;
            next = x;
        }
    }

    /// One step of iterative refinement of the coefficients on the full system A(T) c = b.
    ///
    /// The Hermite form computes the high coefficients from differences of low-order states,
    /// which costs the continuity of derivatives S..2S−2 some accuracy. Here their jumps are
    /// taken in the monomial form of A, where each row is evaluated to its own scale, and the
    /// correction δc solving A δc = −jumps comes from the junction system: its free
    /// derivatives solve H δx = σ ⊙ jumps (F_m = σ_m · jump of derivative 2S−1−m, with
    /// σ_m = (−1)^(S−1−m), is ½ ∂J/∂x_m), and δc = B δz. The other rows of A (head, tail,
    /// waypoints, derivatives 0..S−1) hold by construction of the Hermite form, except that
    /// the tail state is also re-evaluated in monomial form and its miss corrected. For S = 4,
    /// 30 pieces with durations in [0.3, 3] s, the worst relative jump falls from 2e-8 to
    /// 5e-11 and the worst tail miss from 2e-9 to 2e-11.
    fn refine_coefficients(&mut self, tail: &[[f64; D]; S]) {
        let (m, n, f) = (self.pieces, Self::N, Self::F);
        for k in 0..m - 1 {
            let (left, right) = (n * k, n * (k + 1));
            let tp = powers(self.durations[k]);
            // p_k^(d)(T_k) for d = S..2S−2 from the top coefficients.
            for d in S..=2 * S - 2 {
                let mut v = [0.0; D];
                for j in d..n {
                    let w = FALLING[d][j] * tp[j - d];
                    let c = &self.coeffs[left + j];
                    for e in 0..D {
                        v[e] += w * c[e];
                    }
                }
                let r = &self.coeffs[right + d];
                // Row of x_{2S−1−d}; σ = (−1)^(d − S).
                let sign = if (d - S).is_multiple_of(2) { 1.0 } else { -1.0 };
                self.work[k][2 * S - 2 - d] =
                    core::array::from_fn(|e| sign * (v[e] - FALLING[d][d] * r[e]));
            }
        }
        // The tail rows: the last piece's end state misses the tail by e (evaluated in
        // monomial form); δz takes e at that end, which pulls on the last junction.
        let last = n * (m - 1);
        let t_last = self.durations[m - 1];
        let mut tail_err = [[0.0; D]; MAX_FREE + 1];
        for (j, e) in tail_err.iter_mut().enumerate().take(S) {
            let p = eval(&self.coeffs[last..], j, t_last);
            *e = sub(&p, &tail[j]);
        }
        if m > 1 {
            let ip = &self.inv_powers[m - 1];
            for x in 0..f {
                for (j, e) in tail_err.iter().enumerate().take(S) {
                    let w = Self::w(ip, 1 + x, S + j);
                    for d in 0..D {
                        self.work[m - 2][x][d] -= w * e[d];
                    }
                }
            }
        }
        self.solve_in_work();
        // δx enters piece i at its left end (junction i − 1) and its right end (junction i):
        // c −= B δz, the sign because the solve returned H⁻¹ F with F the current jumps.
        for i in 0..m {
            let (tp, ip) = (powers(self.durations[i]), self.inv_powers[i]);
            let mut z = [[0.0; D]; MAX_COEFFS];
            if i > 0 {
                for x in 0..f {
                    z[1 + x] = self.work[i - 1][x].map(|v| v * tp[1 + x]);
                }
            }
            if i + 1 < m {
                for x in 0..f {
                    z[S + 1 + x] = self.work[i][x].map(|v| v * tp[1 + x]);
                }
            } else {
                for j in 0..S {
                    z[S + j] = tail_err[j].map(|v| v * tp[j]);
                }
            }
            let c = &mut self.coeffs[n * i..n * (i + 1)];
            if i > 0 {
                for x in 0..f {
                    let div = FALLING[1 + x][1 + x];
                    for d in 0..D {
                        c[1 + x][d] -= self.work[i - 1][x][d] / div;
                    }
                }
            }
            for k in S..n {
                let v = Self::table_row(&Self::TAB.b, k, &z);
                for d in 0..D {
                    c[k][d] -= v[d] * ip[k];
                }
            }
        }
        for k in 0..m - 1 {
            for x in 0..f {
                let v = self.work[k][x];
                for d in 0..D {
                    self.states[S * (k + 1) + 1 + x][d] -= v[d];
                }
            }
        }
    }

    /// Scaled states z̃_j = T^{m_j} z_j of piece `i`, its positions relative to the start.
    #[inline(always)]
    fn scaled_states(&self, i: usize, tp: &[f64; MAX_COEFFS]) -> [[f64; D]; MAX_COEFFS] {
        let mut z = [[0.0; D]; MAX_COEFFS];
        for j in 0..Self::N {
            let row = &self.states[S * i + j];
            for d in 0..D {
                z[j][d] = row[d] * tp[j % S];
            }
        }
        // Relative to the start point: the coefficients above c_0 and the effort do not depend
        // on it, and the difference avoids cancellation far from the origin.
        z[S] = sub(&z[S], &z[0]);
        z[0] = [0.0; D];
        z
    }

    /// Row `k` of a 2S × 2S table applied to scaled states: Σ_j table\[k\]\[j\] z̃_j.
    #[inline(always)]
    fn table_row(table: &Table, k: usize, z: &[[f64; D]; MAX_COEFFS]) -> [f64; D] {
        let mut v = [0.0; D];
        for (b, zj) in table[k].iter().zip(z).take(Self::N) {
            for d in 0..D {
                v[d] += b * zj[d];
            }
        }
        v
    }

    /// c_i = B(T_i) z_i: c_k = a_k / k! for k < S, c_k = T^{−k} Σ_j B₁\[k\]\[j\] z̃_j above.
    fn fill_coefficients(&mut self) {
        let n = Self::N;
        for i in 0..self.pieces {
            let (tp, ip) = (powers(self.durations[i]), self.inv_powers[i]);
            let z = self.scaled_states(i, &tp);
            let c = &mut self.coeffs[n * i..n * (i + 1)];
            for k in 0..S {
                let a = &self.states[S * i + k];
                for d in 0..D {
                    c[k][d] = a[d] / FALLING[k][k];
                }
            }
            for k in S..n {
                let v = Self::table_row(&Self::TAB.b, k, &z);
                for d in 0..D {
                    c[k][d] = v[d] * ip[k];
                }
            }
        }
    }

    /// Coefficient rows of piece `i`.
    #[inline(always)]
    fn piece(&self, i: usize) -> &[[f64; D]] {
        &self.coeffs[Self::N * i..Self::N * (i + 1)]
    }
    /// The control effort J = Σ_i ∫₀^{T_i} ‖p_i^(S)(t)‖² dt, in closed form (0 before a solve).
    /// ∞ when it overflows: the squared coefficients of states so large (about 1e150 and
    /// beyond), or of durations so short (for S = 4 below about 1e-23 s with unit states),
    /// that they do.
    pub fn energy(&self) -> f64 {
        if !self.solved {
            return 0.0;
        }
        let n = Self::N;
        let mut total = 0.0;
        for i in 0..self.pieces {
            let c = self.piece(i);
            let tp = powers(self.durations[i]);
            for k in S..n {
                for l in S..n {
                    let e = k + l - 2 * S + 1;
                    let w = ENERGY_WEIGHT[S][k][l] * tp[e];
                    let mut dot = 0.0;
                    for d in 0..D {
                        dot += c[k][d] * c[l][d];
                    }
                    total += w * dot;
                }
            }
        }
        // An overflow inside (∞ − ∞ or ∞ · 0 among the products) reads as NaN: it is ∞.
        if total.is_nan() { f64::INFINITY } else { total }
    }

    /// Adds the partial derivatives of J to `grad_c` (∂J/∂c, one row per coefficient row) and
    /// `grad_t` (the explicit ∂J/∂T_i = ‖p_i^(S)(T_i)‖²), and returns J.
    ///
    /// J is quadratic in c, J = ½ ⟨c, ∂J/∂c⟩, so it comes for free with the partials. Where
    /// [`Minco::energy`] overflows, J and the partials are not finite.
    ///
    /// # Errors
    /// [`MincoError::NotSolved`] before a solve, [`MincoError::LengthMismatch`] for wrong lengths.
    pub fn add_energy_partials(&self, grad_c: &mut [[f64; D]], grad_t: &mut [f64]) -> Result<f64> {
        self.check_gradient_buffers(grad_c.len(), grad_t.len())?;
        let n = Self::N;
        let mut energy = 0.0;
        for i in 0..self.pieces {
            let c = self.piece(i);
            let tp = powers(self.durations[i]);
            for k in S..n {
                let mut g = [0.0; D];
                for l in S..n {
                    let e = k + l - 2 * S + 1;
                    let w = 2.0 * ENERGY_WEIGHT[S][k][l] * tp[e];
                    for d in 0..D {
                        g[d] += w * c[l][d];
                    }
                }
                let row = &mut grad_c[n * i + k];
                for d in 0..D {
                    row[d] += g[d];
                    energy += 0.5 * c[k][d] * g[d];
                }
            }
            let js = eval(c, S, self.durations[i]);
            grad_t[i] += js.iter().map(|v| v * v).sum::<f64>();
        }
        Ok(energy)
    }

    fn check_gradient_buffers(&self, len_c: usize, len_t: usize) -> Result<()> {
        if !self.solved {
            return Err(MincoError::NotSolved);
        }
        check_len("coefficient gradient", Self::N * self.pieces, len_c)?;
        check_len("duration gradient", self.pieces, len_t)
    }

    /// Propagates the partials of any cost K(c, T) to the waypoints and durations, in O(M).
    ///
    /// This is the adjoint method of the system A(T) c = b, carried out on its reduced form.
    /// Each piece's coefficients are c_i = B(T_i) z_i for its end states z_i, so ∂K/∂z_i =
    /// B(T_i)ᵀ ∂K/∂c_i. One solve with the (symmetric) junction matrix H then gives the adjoint
    /// λ = H⁻¹ ∂K/∂x of the free derivatives x, and with the junction equations
    /// F(x, q, T) = ½ ∂J/∂x = 0:
    ///
    /// - dK/dq_j = ∂K/∂q_j − λᵀ ∂F/∂q_j,
    /// - dK/dT_i = ∂K/∂T_i + ⟨∂K/∂c_i, B′(T_i) z_i⟩ − λᵀ ∂F/∂T_i.
    ///
    /// `grad_c` (2SM rows) and `grad_t` (M) are the partials; the results go to `grad_q`
    /// (M−1 rows) and `grad_t_total` (M).
    ///
    /// # Errors
    /// [`MincoError::NotSolved`] before a solve, [`MincoError::LengthMismatch`] for wrong lengths.
    pub fn propagate_gradient(
        &mut self,
        grad_c: &[[f64; D]],
        grad_t: &[f64],
        grad_q: &mut [[f64; D]],
        grad_t_total: &mut [f64],
    ) -> Result<()> {
        self.check_gradient_buffers(grad_c.len(), grad_t.len())?;
        check_len("waypoint gradient", self.pieces - 1, grad_q.len())?;
        check_len("total duration gradient", self.pieces, grad_t_total.len())?;
        let (n, m, f) = (Self::N, self.pieces, Self::F);
        let tab = Self::TAB;
        // ∂K/∂z = Bᵀ ∂K/∂c, summed into the shared end states.
        self.adjoint.fill([0.0; D]);
        for i in 0..m {
            let (tp, ip) = (powers(self.durations[i]), self.inv_powers[i]);
            let g = &grad_c[n * i..n * (i + 1)];
            let mut gs = [[0.0; D]; MAX_COEFFS];
            for k in S..n {
                for d in 0..D {
                    gs[k][d] = g[k][d] * ip[k];
                }
            }
            let h = &mut self.adjoint[S * i..S * (i + 2)];
            for j in 0..n {
                let mut v = [0.0; D];
                for k in S..n {
                    let b = tab.b[k][j];
                    for d in 0..D {
                        v[d] += b * gs[k][d];
                    }
                }
                for d in 0..D {
                    h[j][d] += v[d] * tp[j % S];
                }
                if j < S {
                    for d in 0..D {
                        h[j][d] += g[j][d] / FALLING[j][j];
                    }
                }
            }
        }
        // λ = H⁻¹ ∂K/∂x with the factors of the solve.
        for k in 0..m - 1 {
            self.work[k][..f].copy_from_slice(&self.adjoint[S * (k + 1) + 1..S * (k + 1) + S]);
        }
        self.solve_in_work();
        for (j, g) in grad_q.iter_mut().enumerate() {
            *g = self.adjoint[S * (j + 1)];
        }
        for i in 0..m {
            let (tp, ip) = (powers(self.durations[i]), self.inv_powers[i]);
            let z = self.scaled_states(i, &tp);
            // δz: the adjoint in the free slots of piece i's two ends, scaled like z̃.
            let mut dz = [[0.0; D]; MAX_COEFFS];
            if i > 0 {
                for x in 0..f {
                    for d in 0..D {
                        dz[1 + x][d] = self.work[i - 1][x][d] * tp[1 + x];
                    }
                }
            }
            if i + 1 < m {
                for x in 0..f {
                    for d in 0..D {
                        dz[S + 1 + x][d] = self.work[i][x][d] * tp[1 + x];
                    }
                }
            }
            // dK/dq: minus (W δz) at the position slots, where W[0][b] δz_b = W₁ T^{1−2S} δz̃_b.
            for (slot, q) in [(0, i.checked_sub(1)), (S, (i + 1 < m).then_some(i))] {
                let Some(q) = q else { continue };
                let mut v = [0.0; D];
                for b in 0..n {
                    if b % S == 0 {
                        continue;
                    }
                    let w = tab.w[slot][b] * ip[2 * S - 1];
                    for d in 0..D {
                        v[d] += w * dz[b][d];
                    }
                }
                for d in 0..D {
                    grad_q[q][d] -= v[d];
                }
            }
            // dK/dT: ⟨g, B′ z⟩ − δzᵀ W′ z.
            let g = &grad_c[n * i..n * (i + 1)];
            let mut total = grad_t[i];
            for k in S..n {
                let v = Self::table_row(&tab.b_dt, k, &z);
                for d in 0..D {
                    total += g[k][d] * v[d] * ip[k + 1];
                }
            }
            let mut quad = 0.0;
            for a in 0..n {
                if a % S == 0 {
                    continue;
                }
                let mut v = [0.0; D];
                for (b, zb) in z.iter().enumerate().take(n) {
                    let w = tab.w_dt[a][b];
                    for d in 0..D {
                        v[d] += w * zb[d];
                    }
                }
                for d in 0..D {
                    quad += dz[a][d] * v[d];
                }
            }
            grad_t_total[i] = total - quad * ip[2 * S];
        }
        Ok(())
    }

    /// The energy and its gradients with respect to the inner waypoints and the durations.
    ///
    /// A convenience over [`Minco::add_energy_partials`] + [`Minco::propagate_gradient`] that
    /// allocates its scratch; optimisers should call those two with their own buffers.
    ///
    /// # Errors
    /// As [`Minco::propagate_gradient`].
    pub fn energy_gradient(&mut self) -> Result<(f64, Vec<[f64; D]>, Vec<f64>)> {
        let mut gc = vec![[0.0; D]; Self::N * self.pieces];
        let mut gt = vec![0.0; self.pieces];
        let energy = self.add_energy_partials(&mut gc, &mut gt)?;
        let mut gq = vec![[0.0; D]; self.pieces - 1];
        let mut gtt = vec![0.0; self.pieces];
        self.propagate_gradient(&gc, &gt, &mut gq, &mut gtt)?;
        Ok((energy, gq, gtt))
    }

    /// The trajectory of the last successful solve.
    ///
    /// # Errors
    /// [`MincoError::NotSolved`] before a solve or after a failed one.
    pub fn trajectory(&self) -> Result<Trajectory<D>> {
        if !self.solved {
            return Err(MincoError::NotSolved);
        }
        Ok(Trajectory::from_parts(
            Self::N,
            self.durations.clone(),
            self.coefficients().to_vec(),
        ))
    }

    /// Whether the last [`Minco::solve`] succeeded.
    pub fn is_solved(&self) -> bool {
        self.solved
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// A random problem: head, tail, waypoints and durations from a seed.
    #[derive(Debug, Clone)]
    struct Problem<const S: usize> {
        head: [[f64; 3]; S],
        tail: [[f64; 3]; S],
        q: Vec<[f64; 3]>,
        t: Vec<f64>,
    }

    fn problem<const S: usize>(max_pieces: usize) -> impl Strategy<Value = Problem<S>> {
        (1..=max_pieces, any::<u64>()).prop_map(|(m, seed)| {
            let mut next = crate::test_util::uniform(seed);
            let mut row = |scale: f64| [0.0; 3].map(|_: f64| (next() - 0.5) * scale);
            let head: [[f64; 3]; S] = core::array::from_fn(|_| row(2.0));
            let tail: [[f64; 3]; S] = core::array::from_fn(|_| row(2.0));
            let q = (1..m)
                .map(|i| {
                    let r = row(2.0);
                    [r[0] + i as f64, r[1], r[2]]
                })
                .collect();
            let t = (0..m).map(|_| 0.3 + 2.7 * next()).collect();
            Problem { head, tail, q, t }
        })
    }

    fn solved<const S: usize>(p: &Problem<S>) -> Minco<S, 3> {
        let mut m = Minco::<S, 3>::new(p.t.len()).unwrap();
        m.solve(&p.head, &p.tail, &p.q, &p.t).unwrap();
        m
    }

    /// Row of the waypoint condition of junction `i` in the full system A(T) c = b.
    fn waypoint_row<const S: usize>(i: usize) -> usize {
        S + 2 * S * i + S - 1
    }

    /// The full system A(T) of size 2SM, densely: the S head rows, per junction the continuity
    /// of derivatives S..2S−2, the waypoint and the continuity of 0..S−1, the S tail rows.
    fn dense_system<const S: usize>(t: &[f64]) -> nalgebra::DMatrix<f64> {
        let (n, m) = (2 * S, t.len());
        let mut a = nalgebra::DMatrix::zeros(n * m, n * m);
        let end_row = |a: &mut nalgebra::DMatrix<f64>, r: usize, i: usize, d: usize| {
            let tp = powers(t[i]);
            for k in d..n {
                a[(r, n * i + k)] = FALLING[d][k] * tp[k - d];
            }
        };
        for j in 0..S {
            a[(j, j)] = FALLING[j][j];
        }
        for i in 0..m - 1 {
            for k in 0..n {
                let r = S + n * i + k;
                let d = if k + 1 < S {
                    S + k
                } else if k + 1 == S {
                    0
                } else {
                    k - S
                };
                end_row(&mut a, r, i, d);
                if k + 1 != S {
                    a[(r, n * (i + 1) + d)] = -FALLING[d][d];
                }
            }
        }
        for j in 0..S {
            end_row(&mut a, n * m - S + j, m - 1, j);
        }
        a
    }

    fn check_dense<const S: usize>(p: &Problem<S>) -> std::result::Result<(), TestCaseError> {
        let m = solved(p);
        let c = m.coefficients().to_vec();
        let a = dense_system::<S>(&p.t);
        let n = c.len();
        let mut b = nalgebra::DMatrix::zeros(n, 3);
        for j in 0..S {
            for d in 0..3 {
                b[(j, d)] = p.head[j][d];
                b[(n - S + j, d)] = p.tail[j][d];
            }
        }
        for (i, q) in p.q.iter().enumerate() {
            for d in 0..3 {
                b[(waypoint_row::<S>(i), d)] = q[d];
            }
        }
        let x = a.lu().solve(&b).unwrap();
        let scale = x.amax().max(1.0);
        for i in 0..n {
            for d in 0..3 {
                prop_assert!(
                    (c[i][d] - x[(i, d)]).abs() <= 1e-10 * scale,
                    "row {i} dim {d}: {} vs {}",
                    c[i][d],
                    x[(i, d)]
                );
            }
        }
        Ok(())
    }

    fn check_conditions<const S: usize>(p: &Problem<S>) -> std::result::Result<(), TestCaseError> {
        let m = solved(p);
        let traj = m.trajectory().unwrap();
        // Relative to the vectors' size: a small component of a large derivative carries the
        // roundoff of the whole vector.
        let close = |a: [f64; 3],
                     b: [f64; 3],
                     tol: f64,
                     what: &str|
         -> std::result::Result<(), TestCaseError> {
            let norm = |v: [f64; 3]| v.iter().map(|x| x * x).sum::<f64>().sqrt();
            let err = norm([a[0] - b[0], a[1] - b[1], a[2] - b[2]]);
            prop_assert!(
                err <= tol * norm(a).max(norm(b)).max(1.0),
                "{what}: {a:?} vs {b:?}"
            );
            Ok(())
        };
        let tol = |_: usize| 1e-9;
        let mm = p.t.len();
        for j in 0..S {
            close(
                eval(traj.piece_coefficients(0).unwrap(), j, 0.0),
                p.head[j],
                tol(j),
                "head",
            )?;
            close(
                eval(traj.piece_coefficients(mm - 1).unwrap(), j, p.t[mm - 1]),
                p.tail[j],
                tol(j),
                "tail",
            )?;
        }
        for i in 0..mm - 1 {
            let (a, b) = (
                traj.piece_coefficients(i).unwrap(),
                traj.piece_coefficients(i + 1).unwrap(),
            );
            close(eval(a, 0, p.t[i]), p.q[i], tol(0), "waypoint")?;
            for d in 0..=2 * S - 2 {
                close(eval(a, d, p.t[i]), eval(b, d, 0.0), tol(d), "continuity")?;
            }
        }
        Ok(())
    }

    /// Central differences of J over every waypoint coordinate and duration.
    fn check_gradients<const S: usize>(p: &Problem<S>) -> std::result::Result<(), TestCaseError> {
        let mut m = solved(p);
        let (e, gq, gt) = m.energy_gradient().unwrap();
        // J = ½⟨c, ∂J/∂c⟩ agrees with the direct closed form.
        prop_assert!((e - m.energy()).abs() <= 1e-10 * m.energy().abs().max(1.0));
        let energy = |q: &[[f64; 3]], t: &[f64]| {
            let mut m = Minco::<S, 3>::new(t.len()).unwrap();
            m.solve(&p.head, &p.tail, q, t).unwrap();
            m.energy()
        };
        // Central differences with one Richardson step: O(h⁴) truncation, so the comparison
        // is limited by the analytic gradient, not by the finite differences.
        let richardson = |f: &dyn Fn(f64) -> f64, h: f64| {
            let d = |h: f64| (f(h) - f(-h)) / (2.0 * h);
            (4.0 * d(0.5 * h) - d(h)) / 3.0
        };
        let mut num = Vec::new();
        let mut ana = Vec::new();
        for i in 0..p.q.len() {
            for d in 0..3 {
                let f = |h: f64| {
                    let mut q = p.q.clone();
                    q[i][d] += h;
                    energy(&q, &p.t)
                };
                num.push(richardson(&f, 1e-3));
                ana.push(gq[i][d]);
            }
        }
        for i in 0..p.t.len() {
            let f = |h: f64| {
                let mut t = p.t.clone();
                t[i] += h;
                energy(&p.q, &t)
            };
            num.push(richardson(&f, 1e-3 * p.t[i]));
            ana.push(gt[i]);
        }
        crate::test_util::check_gradient_blocks(&num, &ana, 3 * p.q.len())?;
        Ok(())
    }

    /// Moving every position by a large offset moves only c_0: the solve works with position
    /// differences, so no accuracy is lost far from the origin.
    fn check_translation<const S: usize>(p: &Problem<S>) -> std::result::Result<(), TestCaseError> {
        let base = solved(p);
        let off = [1e6, -3e5, 2e4];
        let shift = |v: [f64; 3]| [v[0] + off[0], v[1] + off[1], v[2] + off[2]];
        let mut moved = p.clone();
        moved.head[0] = shift(p.head[0]);
        moved.tail[0] = shift(p.tail[0]);
        moved.q.iter_mut().for_each(|q| *q = shift(*q));
        let far = solved(&moved);
        let n = 2 * S;
        let scale = base
            .coefficients()
            .iter()
            .flatten()
            .fold(1.0_f64, |a, v| a.max(v.abs()));
        for (r, (a, b)) in base
            .coefficients()
            .iter()
            .zip(far.coefficients())
            .enumerate()
        {
            for d in 0..3 {
                let want = if r % n == 0 { a[d] + off[d] } else { a[d] };
                let tol = if r % n == 0 {
                    1e-15 * off[d].abs() + 1e-9 * scale
                } else {
                    1e-9 * scale
                };
                prop_assert!(
                    (b[d] - want).abs() <= tol,
                    "row {r} dim {d}: {} vs {want}",
                    b[d]
                );
            }
        }
        Ok(())
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(48))]

        #[test] fn translation_s3(p in problem::<3>(30)) { check_translation(&p)?; }
        #[test] fn translation_s4(p in problem::<4>(30)) { check_translation(&p)?; }
        #[test] fn dense_s2(p in problem::<2>(30)) { check_dense(&p)?; }
        #[test] fn dense_s3(p in problem::<3>(30)) { check_dense(&p)?; }
        #[test] fn dense_s4(p in problem::<4>(30)) { check_dense(&p)?; }
        #[test] fn conditions_s2(p in problem::<2>(30)) { check_conditions(&p)?; }
        #[test] fn conditions_s3(p in problem::<3>(30)) { check_conditions(&p)?; }
        #[test] fn conditions_s4(p in problem::<4>(30)) { check_conditions(&p)?; }
        #[test] fn gradient_s2(p in problem::<2>(8)) { check_gradients(&p)?; }
        #[test] fn gradient_s3(p in problem::<3>(8)) { check_gradients(&p)?; }
        #[test] fn gradient_s4(p in problem::<4>(8)) { check_gradients(&p)?; }
    }

    /// One piece at rest at both ends is the classic closed-form polynomial in τ = t/T.
    #[test]
    fn single_piece_closed_forms() {
        fn check<const S: usize>(shape: fn(f64) -> f64) {
            let (a, b, t) = (-1.0, 2.5, 1.7);
            let mut head = [[0.0; 1]; S];
            let mut tail = [[0.0; 1]; S];
            head[0] = [a];
            tail[0] = [b];
            let mut m = Minco::<S, 1>::new(1).unwrap();
            m.solve(&head, &tail, &[], &[t]).unwrap();
            let traj = m.trajectory().unwrap();
            for k in 0..=20 {
                let x = t * f64::from(k) / 20.0;
                let expected = a + (b - a) * shape(x / t);
                assert!(
                    (traj.position(x).unwrap()[0] - expected).abs() < 1e-12,
                    "S={S}"
                );
            }
        }
        check::<2>(|s| 3.0 * s * s - 2.0 * s.powi(3));
        check::<3>(|s| 10.0 * s.powi(3) - 15.0 * s.powi(4) + 6.0 * s.powi(5));
        check::<4>(|s| 35.0 * s.powi(4) - 84.0 * s.powi(5) + 70.0 * s.powi(6) - 20.0 * s.powi(7));
    }

    #[test]
    fn bad_input_is_a_typed_error() {
        assert!(matches!(Minco::<3, 3>::new(0), Err(MincoError::NoPieces)));
        assert!(Minco::<4, 8>::new(Minco::<4, 8>::MAX_PIECES).is_ok());
        assert!(matches!(
            Minco::<4, 8>::new(Minco::<4, 8>::MAX_PIECES + 1),
            Err(MincoError::InvalidConfig { what: "pieces", .. })
        ));
        assert!(matches!(
            Minco::<5, 3>::new(2),
            Err(MincoError::UnsupportedOrder(5))
        ));
        assert!(matches!(
            Minco::<3, 0>::new(2),
            Err(MincoError::ZeroDimension)
        ));
        let mut m = Minco::<3, 3>::new(2).unwrap();
        let z = [[0.0; 3]; 3];
        assert!(matches!(m.energy_gradient(), Err(MincoError::NotSolved)));
        assert!(matches!(
            m.solve(&z, &z, &[], &[1.0, 1.0]),
            Err(MincoError::LengthMismatch { .. })
        ));
        assert!(matches!(
            m.solve(&z, &z, &[[0.0; 3]], &[1.0]),
            Err(MincoError::LengthMismatch { .. })
        ));
        assert!(matches!(
            m.solve(&z, &z, &[[0.0; 3]], &[1.0, 0.0]),
            Err(MincoError::BadDuration { index: 1, .. })
        ));
        assert!(matches!(
            m.solve(&z, &z, &[[0.0; 3]], &[-1.0, 1.0]),
            Err(MincoError::BadDuration { index: 0, .. })
        ));
        assert!(matches!(
            m.solve(&z, &z, &[[0.0; 3]], &[f64::NAN, 1.0]),
            Err(MincoError::BadDuration { .. })
        ));
        assert!(matches!(
            m.solve(&z, &z, &[[f64::NAN, 0.0, 0.0]], &[1.0, 1.0]),
            Err(MincoError::NonFinite { .. })
        ));
        let mut bad = z;
        bad[1][2] = f64::INFINITY;
        assert!(matches!(
            m.solve(&bad, &z, &[[0.0; 3]], &[1.0, 1.0]),
            Err(MincoError::NonFinite { .. })
        ));
        // Durations so extreme the system under/overflows: an error, never NaN coefficients.
        let r = m.solve(
            &z,
            &[[1.0; 3], [0.0; 3], [0.0; 3]],
            &[[0.5; 3]],
            &[1e-300, 1e300],
        );
        assert!(r.is_err());
        assert!(!m.is_solved());
        assert!(matches!(m.trajectory(), Err(MincoError::NotSolved)));
        assert!(matches!(
            Minco::<3, 3>::new(1 << 60),
            Err(MincoError::InvalidConfig { .. })
        ));
        // Mismatched gradient buffers.
        m.solve(&z, &z, &[[1.0; 3]], &[1.0, 1.0]).unwrap();
        let mut gq = vec![[0.0; 3]; 2];
        let mut gt = vec![0.0; 2];
        let gc = vec![[0.0; 3]; 12];
        assert!(matches!(
            m.propagate_gradient(&gc, &[0.0; 2], &mut gq, &mut gt),
            Err(MincoError::LengthMismatch { .. })
        ));
        assert!(matches!(
            m.add_energy_partials(&mut [[0.0; 3]; 3], &mut gt),
            Err(MincoError::LengthMismatch { .. })
        ));
    }
}
