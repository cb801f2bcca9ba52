//! The MINCO problem: set up once, solve for new waypoints and durations, propagate gradients.

use crate::band::BandMatrix;
use crate::error::{MincoError, Result};
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

/// A MINCO problem of order `S` (2: minimum acceleration, 3: jerk, 4: snap) in `D` dimensions.
///
/// Piece i is p_i(t) = Σ_{k<2S} c_{i,k} t^k on [0, T_i]. Given the head and tail states
/// (derivatives 0..S−1), the M−1 inner waypoints q_1..q_{M−1} and the durations T_i > 0, the
/// coefficients minimising the control effort J = Σ_i ∫ ‖p_i^(S)‖² dt solve the banded system
/// A(T) c = b(q, head, tail) of size 2SM with bandwidth 2S. Rows: the S head conditions; per
/// junction the continuity of derivatives S..2S−2, the waypoint, the continuity of 0..S−1;
/// the S tail conditions. It is factorised by a band LU in O(M).
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
    band: BandMatrix,
    coeffs: Vec<[f64; D]>,
    adjoint: Vec<[f64; D]>,
    durations: Vec<f64>,
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
    /// Largest number of pieces: keeps every size computation far from overflow.
    const MAX_PIECES: usize = 1 << 24;

    /// A problem with `pieces` pieces.
    ///
    /// # Errors
    /// [`MincoError::UnsupportedOrder`] unless S ∈ {2, 3, 4}, [`MincoError::ZeroDimension`] for
    /// D = 0, [`MincoError::NoPieces`] for zero pieces.
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
                reason: "at most 2^24 pieces",
            });
        }
        let n = Self::N * pieces;
        let band = BandMatrix::new(n, Self::N);
        let mut problem = Self {
            pieces,
            coeffs: vec![[0.0; D]; band.len()],
            adjoint: vec![[0.0; D]; band.len()],
            band,
            durations: vec![1.0; pieces],
            solved: false,
        };
        // The factors' structure does not depend on the durations: analyse it once.
        problem.fill();
        problem.band.analyze();
        Ok(problem)
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

    /// Row of the waypoint condition of junction `i` (between pieces i and i+1).
    #[inline(always)]
    fn waypoint_row(i: usize) -> usize {
        S + 2 * S * i + S - 1
    }

    /// The derivative order constrained by row `k` of a junction block.
    #[inline(always)]
    fn junction_row_derivative(k: usize) -> usize {
        if k + 1 < S {
            S + k // continuity of S..2S−2
        } else if k + 1 == S {
            0 // waypoint
        } else {
            k - S // continuity of 0..S−1
        }
    }

    /// Writes row `r`: the `d`-th derivative of piece `i` at its end, with powers `tp` of T_i.
    #[inline(always)]
    fn set_end_row(&mut self, r: usize, i: usize, d: usize, tp: &[f64]) {
        for k in d..Self::N {
            self.band.set(r, Self::N * i + k, FALLING[d][k] * tp[k - d]);
        }
    }

    /// Fills A(T).
    fn fill(&mut self) {
        let (n, m) = (Self::N, self.pieces);
        self.band.reset();
        for j in 0..S {
            self.band.set(j, j, FALLING[j][j]);
        }
        for i in 0..m - 1 {
            let tp = powers(self.durations[i]);
            for k in 0..n {
                let r = S + n * i + k;
                let d = Self::junction_row_derivative(k);
                self.set_end_row(r, i, d, &tp);
                if k + 1 != S {
                    // Continuity: minus the next piece's derivative at its start.
                    self.band.set(r, n * (i + 1) + d, -FALLING[d][d]);
                }
            }
        }
        let tp = powers(self.durations[m - 1]);
        for j in 0..S {
            self.set_end_row(n * m - S + j, m - 1, j, &tp);
        }
    }

    /// Solves for the coefficients.
    ///
    /// `head` and `tail` hold derivatives 0..S−1 of the start and end states, `waypoints` the
    /// M−1 inner waypoints, `durations` the M piece durations \[s\].
    ///
    /// # Errors
    /// [`MincoError::LengthMismatch`], [`MincoError::NonFinite`], [`MincoError::BadDuration`]
    /// for bad input; [`MincoError::Singular`] if the system cannot be factorised. On error the
    /// problem is left unsolved.
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
            if !(value > 0.0 && value.is_finite()) {
                return Err(MincoError::BadDuration { index, value });
            }
        }
        self.durations.copy_from_slice(durations);
        self.fill();
        self.band
            .factorize()
            .map_err(|row| MincoError::Singular { row })?;
        let n = Self::N;
        self.coeffs.fill([0.0; D]);
        self.coeffs[..S].copy_from_slice(head);
        for (i, q) in waypoints.iter().enumerate() {
            self.coeffs[Self::waypoint_row(i)] = *q;
        }
        self.coeffs[n * m - S..].copy_from_slice(tail);
        self.band.solve(&mut self.coeffs);
        if check_finite_rows(&self.coeffs, "coefficients").is_err() {
            return Err(MincoError::Singular { row: 0 });
        }
        self.solved = true;
        Ok(())
    }

    /// Coefficient rows of piece `i`.
    #[inline(always)]
    fn piece(&self, i: usize) -> &[[f64; D]] {
        &self.coeffs[Self::N * i..Self::N * (i + 1)]
    }

    /// The control effort J = Σ_i ∫₀^{T_i} ‖p_i^(S)(t)‖² dt, in closed form (0 before a solve).
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
        total
    }

    /// Adds the partial derivatives of J to `grad_c` (∂J/∂c, one row per coefficient row) and
    /// `grad_t` (the explicit ∂J/∂T_i = ‖p_i^(S)(T_i)‖²), and returns J.
    ///
    /// J is quadratic in c, J = ½ ⟨c, ∂J/∂c⟩, so it comes for free with the partials.
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
    /// Solves the adjoint system Aᵀ G = ∂K/∂c once; then ∂K/∂q_i is G's row of the waypoint of
    /// junction i, and dK/dT_i = ∂K/∂T_i − Σ_rows ⟨G_row, p_i^(d_row+1)(T_i)⟩ over the rows of
    /// piece i's junction (or tail) block, d_row being the derivative order of the row.
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
        let (n, m) = (Self::N, self.pieces);
        self.adjoint.copy_from_slice(grad_c);
        self.band.solve_transposed(&mut self.adjoint);
        for (i, g) in grad_q.iter_mut().enumerate() {
            *g = self.adjoint[Self::waypoint_row(i)];
        }
        for i in 0..m {
            let c = &self.coeffs[n * i..n * (i + 1)];
            let t = self.durations[i];
            let mut total = grad_t[i];
            // Row r constrains p_i^(d)(T_i); its T_i-derivative is p_i^(d+1)(T_i).
            let mut subtract = |r: usize, d: usize| {
                let dp = eval(c, d + 1, t);
                let g = &self.adjoint[r];
                for dim in 0..D {
                    total -= g[dim] * dp[dim];
                }
            };
            if i + 1 < m {
                for k in 0..n {
                    subtract(S + n * i + k, Self::junction_row_derivative(k));
                }
            } else {
                for j in 0..S {
                    subtract(n * m - S + j, j);
                }
            }
            grad_t_total[i] = total;
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

    #[cfg(test)]
    pub(crate) fn dense_matrix(&mut self) -> nalgebra::DMatrix<f64> {
        self.fill();
        let n = Self::N * self.pieces;
        nalgebra::DMatrix::from_fn(n, n, |i, j| self.band.get(i, j))
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

    fn check_dense<const S: usize>(p: &Problem<S>) -> std::result::Result<(), TestCaseError> {
        let mut m = solved(p);
        let c = m.coefficients().to_vec();
        let a = m.dense_matrix();
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
                b[(Minco::<S, 3>::waypoint_row(i), d)] = q[d];
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
        let close =
            |a: [f64; 3], b: [f64; 3], what: &str| -> std::result::Result<(), TestCaseError> {
                for d in 0..3 {
                    let tol = 1e-9 * a[d].abs().max(b[d].abs()).max(1.0);
                    prop_assert!((a[d] - b[d]).abs() <= tol, "{what}: {a:?} vs {b:?}");
                }
                Ok(())
            };
        let mm = p.t.len();
        for j in 0..S {
            close(
                eval(traj.piece_coefficients(0).unwrap(), j, 0.0),
                p.head[j],
                "head",
            )?;
            close(
                eval(traj.piece_coefficients(mm - 1).unwrap(), j, p.t[mm - 1]),
                p.tail[j],
                "tail",
            )?;
        }
        for i in 0..mm - 1 {
            let (a, b) = (
                traj.piece_coefficients(i).unwrap(),
                traj.piece_coefficients(i + 1).unwrap(),
            );
            close(eval(a, 0, p.t[i]), p.q[i], "waypoint")?;
            for d in 0..=2 * S - 2 {
                close(eval(a, d, p.t[i]), eval(b, d, 0.0), "continuity")?;
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

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(48))]

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
