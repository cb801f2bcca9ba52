//! A heuristic ATSP solver: α-nearness candidates, Or-opt, 2-opt and orientation-preserving 3-opt
//! local search with don't-look bits, and iterated double-bridge kicks.
//!
//! This is the first step toward the LKH-style solver: the candidate sets and the lower bound
//! come from the Held–Karp machinery of [`crate::held_karp_bound`]; the local search uses
//! segment insertion (Or-opt, segments of 1–3 nodes), the orientation-preserving segment swap
//! a→b…c→d…e→f ⇒ a→d…e→b…c→f, and 2-opt with reversal, whose asymmetric cost change comes
//! from prefix sums of the forward and backward arc costs. Kicks are double bridges.
//! Everything is seeded: the same instance, settings and seed give the same tour.

use crate::bound::{BoundConfig, alpha_candidates, held_karp_bound};
use crate::error::{Result, TspError};
use crate::exact::Tour;
use crate::matrix::CostMatrix;

/// Settings of [`solve`] and [`solve_open`].
///
/// # Example
/// ```
/// use topo_tsp::SolverConfig;
/// let cfg = SolverConfig::default().with_seed(7).with_max_trials(200);
/// assert_eq!(cfg.seed, 7);
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
#[non_exhaustive]
pub struct SolverConfig {
    /// Candidate successors per city, by α-nearness. Default 10: free arcs into the start of
    /// an open tour and duplicated nodes create many ties, which 5 candidates do not cover.
    pub candidates: usize,
    /// Kick-and-improve trials after the first local optimum. Default 2000.
    pub max_trials: usize,
    /// Stop after this many trials in a row without improvement, plus 5 per city. Default
    /// `usize::MAX` (no such stop). Replanning loops that need a fast answer set it (e.g. 100):
    /// on TSPLIB it trades a few optima for a several-fold speed-up.
    pub stall_trials: usize,
    /// Seed of the kicks. Default 1.
    pub seed: u64,
    /// Settings of the lower bound that also yields the candidates.
    pub bound: BoundConfig,
}

impl Default for SolverConfig {
    fn default() -> Self {
        Self {
            candidates: 10,
            max_trials: 2000,
            stall_trials: usize::MAX,
            seed: 1,
            bound: BoundConfig::default(),
        }
    }
}

impl SolverConfig {
    /// Sets the seed.
    pub fn with_seed(mut self, seed: u64) -> Self {
        self.seed = seed;
        self
    }

    /// Sets the trial budget.
    pub fn with_max_trials(mut self, trials: usize) -> Self {
        self.max_trials = trials;
        self
    }

    /// Sets the stall limit (trials in a row without improvement, plus 5 per city).
    pub fn with_stall_trials(mut self, trials: usize) -> Self {
        self.stall_trials = trials;
        self
    }
}

/// A solved instance: the best tour, the Held–Karp lower bound, and the trials run.
#[derive(Debug, Clone, PartialEq)]
pub struct Solution {
    /// The best tour found (closed length for [`solve`], open length for [`solve_open`]).
    pub tour: Tour,
    /// The Held–Karp lower bound on the closed tour of the solved matrix.
    pub lower_bound: f64,
    /// Trials run (kicks after the first local optimum).
    pub trials: usize,
}

/// SplitMix64: a small, seedable generator for the kicks.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    fn below(&mut self, n: usize) -> usize {
        (self.next() % n as u64) as usize
    }
}

/// The local-search state: order and position of every city.
struct State<'a> {
    m: &'a CostMatrix,
    order: Vec<usize>,
    pos: Vec<usize>,
    /// Prefix sums over the arcs of `order` (arc k runs from position k to k + 1, cyclic):
    /// forward costs, and the costs of the same arcs traversed backwards.
    fwd: Vec<f64>,
    bwd: Vec<f64>,
}

impl State<'_> {
    fn n(&self) -> usize {
        self.order.len()
    }

    /// `k` reduced modulo n for 0 ≤ k < 2n, without a division (this is the hot path).
    #[inline(always)]
    fn wrap(&self, k: usize) -> usize {
        if k >= self.n() { k - self.n() } else { k }
    }

    fn succ(&self, v: usize) -> usize {
        self.order[self.wrap(self.pos[v] + 1)]
    }

    fn pred(&self, v: usize) -> usize {
        self.order[self.wrap(self.pos[v] + self.n() - 1)]
    }

    /// Position of `v` counted from `a` along the tour.
    fn rel(&self, a: usize, v: usize) -> usize {
        self.wrap(self.pos[v] + self.n() - self.pos[a])
    }

    fn set_order(&mut self, order: Vec<usize>) {
        let n = order.len();
        for (i, &v) in order.iter().enumerate() {
            self.pos[v] = i;
        }
        self.fwd.resize(n + 1, 0.0);
        self.bwd.resize(n + 1, 0.0);
        for k in 0..n {
            let (u, v) = (order[k], order[(k + 1) % n]);
            self.fwd[k + 1] = self.fwd[k] + self.m.cost(u, v);
            self.bwd[k + 1] = self.bwd[k] + self.m.cost(v, u);
        }
        self.order = order;
    }

    /// Sums over the arcs from position p up to (not including) position q, cyclic:
    /// (forward cost, backward cost).
    fn arc_sums(&self, p: usize, q: usize) -> (f64, f64) {
        let n = self.n();
        if p <= q {
            (self.fwd[q] - self.fwd[p], self.bwd[q] - self.bwd[p])
        } else {
            (
                self.fwd[n] - self.fwd[p] + self.fwd[q],
                self.bwd[n] - self.bwd[p] + self.bwd[q],
            )
        }
    }

    /// The tour read from `a`, as a vector of cities.
    fn from(&self, a: usize) -> Vec<usize> {
        let (n, p) = (self.n(), self.pos[a]);
        (0..n).map(|k| self.order[(p + k) % n]).collect()
    }

    fn length(&self) -> f64 {
        self.m.closed_length(&self.order)
    }

    /// Tries improving moves that start at city `a`; applies the first one found.
    /// Returns the cities whose neighbourhoods changed.
    fn improve_at(
        &mut self,
        a: usize,
        cand: &[Vec<usize>],
        pred_cand: &[Vec<usize>],
    ) -> Option<[usize; 6]> {
        let n = self.n();
        let c = |i: usize, j: usize| self.m.cost(i, j);
        let eps = 1e-9;
        // Segment swap: a→b … c→d … e→f  ⇒  a→d … e→b … c→f.
        let b = self.succ(a);
        for &d in &cand[a] {
            let rd = self.rel(a, d);
            if rd < 2 {
                continue;
            }
            let cc = self.pred(d);
            let g1 = c(a, b) + c(cc, d) - c(a, d);
            if g1 <= eps {
                continue;
            }
            for &e in &pred_cand[b] {
                let re = self.rel(a, e);
                if re < rd {
                    continue;
                }
                let f = self.succ(e);
                let gain = g1 + c(e, f) - c(e, b) - c(cc, f);
                if gain > eps {
                    // New order from a: a, [d..e], [b..c], f, …
                    let tour = self.from(a);
                    let mut next = Vec::with_capacity(n);
                    next.push(a);
                    next.extend_from_slice(&tour[rd..=re]);
                    next.extend_from_slice(&tour[1..rd]);
                    next.extend_from_slice(&tour[re + 1..]);
                    self.set_order(next);
                    return Some([a, b, cc, d, e, f]);
                }
            }
        }
        // 2-opt with reversal: a→b … d→e  ⇒  a→d, reversed d…b, b→e. On asymmetric costs the
        // reversed arcs change cost too; prefix sums give their total in O(1).
        for &d in &cand[a] {
            let rd = self.rel(a, d);
            if rd < 2 {
                continue;
            }
            let e = self.succ(d);
            if e == a {
                continue;
            }
            let (fw, bw) = self.arc_sums(self.pos[b], self.pos[d]);
            let gain = c(a, b) + c(d, e) + fw - c(a, d) - c(b, e) - bw;
            if gain > eps {
                let mut tour = self.from(a);
                tour[1..=rd].reverse();
                self.set_order(tour);
                return Some([a, b, d, e, a, b]);
            }
        }
        // Or-opt: move the segment that starts at a (1–3 cities) between two other cities.
        for len in 1..=3usize.min(n.saturating_sub(3)) {
            let first = a;
            let at = |k: usize| self.order[self.wrap(self.pos[first] + k)];
            let (last, next) = (at(len - 1), at(len));
            let prev = self.pred(first);
            let removed = c(prev, first) + c(last, next) - c(prev, next);
            if removed <= eps {
                continue;
            }
            for &bb in &cand[last] {
                let rb = self.rel(first, bb);
                if rb < len + 1 {
                    continue; // inside the segment, or its old successor
                }
                let aa = self.pred(bb);
                let gain = removed + c(aa, bb) - c(aa, first) - c(last, bb);
                if gain > eps {
                    // From first: [seg] next … aa bb … prev  ⇒  next … aa [seg] bb … prev.
                    let tour = self.from(first);
                    let mut order = Vec::with_capacity(n);
                    order.extend_from_slice(&tour[len..rb]);
                    order.extend_from_slice(&tour[..len]);
                    order.extend_from_slice(&tour[rb..]);
                    self.set_order(order);
                    return Some([prev, first, last, next, aa, bb]);
                }
            }
        }
        None
    }

    /// Local search with don't-look bits until no candidate move improves.
    fn local_search(
        &mut self,
        cand: &[Vec<usize>],
        pred_cand: &[Vec<usize>],
        queue: &mut Vec<usize>,
    ) {
        let n = self.n();
        let mut active = vec![false; n];
        for &v in queue.iter() {
            active[v] = true;
        }
        while let Some(a) = queue.pop() {
            active[a] = false;
            if let Some(touched) = self.improve_at(a, cand, pred_cand) {
                for v in touched {
                    if !active[v] {
                        active[v] = true;
                        queue.push(v);
                    }
                }
            }
        }
    }
}

/// Solves the closed ATSP on `m` heuristically; `should_stop` is polled between trials (pass
/// `|| false` for a pure trial budget, or a deadline check for a time budget — the library
/// reads no clock itself).
///
/// # Errors
/// [`TspError::InvalidConfig`] for bad settings.
///
/// # Example
/// ```
/// use topo_tsp::{CostMatrix, SolverConfig, held_karp, solve};
/// let m = CostMatrix::from_fn(9, |i, j| ((7 * i + 3 * j) % 13) as f64 + 1.0).unwrap();
/// let s = solve(&m, &SolverConfig::default(), || false).unwrap();
/// assert_eq!(s.tour.length, held_karp(&m).unwrap().length);
/// assert!(s.lower_bound <= s.tour.length);
/// ```
pub fn solve(
    m: &CostMatrix,
    cfg: &SolverConfig,
    mut should_stop: impl FnMut() -> bool,
) -> Result<Solution> {
    if cfg.candidates == 0 {
        return Err(TspError::InvalidConfig {
            what: "candidates",
            reason: "must be at least 1",
        });
    }
    let n = m.len();
    let bound = held_karp_bound(m, &cfg.bound)?;
    if n <= 3 {
        // Every order of ≤ 3 cities from city 0 is checked directly.
        let t = crate::exact::brute_force(m)?;
        return Ok(Solution {
            tour: t,
            lower_bound: bound.lower_bound,
            trials: 0,
        });
    }
    // Successor candidates of city i: the cities among the α-candidates of its twin n + i.
    let sym = alpha_candidates(m, &bound.pi, cfg.candidates)?;
    let cand: Vec<Vec<usize>> = (0..n)
        .map(|i| {
            sym[n + i]
                .iter()
                .copied()
                .filter(|&j| j < n && j != i)
                .collect()
        })
        .collect();
    let mut pred_cand = vec![Vec::new(); n];
    for (i, list) in cand.iter().enumerate() {
        for &j in list {
            pred_cand[j].push(i);
        }
    }
    // Nearest-neighbour start through the candidates (any city when they are used up).
    let mut seen = vec![false; n];
    let mut order = vec![0];
    seen[0] = true;
    while order.len() < n {
        let cur = order[order.len() - 1];
        let next = cand[cur].iter().copied().find(|&j| !seen[j]).or_else(|| {
            (0..n)
                .filter(|&j| !seen[j])
                .min_by(|&a, &b| m.cost(cur, a).total_cmp(&m.cost(cur, b)))
        });
        let Some(next) = next else { break };
        seen[next] = true;
        order.push(next);
    }
    let mut st = State {
        m,
        order: Vec::new(),
        pos: vec![0; n],
        fwd: Vec::new(),
        bwd: Vec::new(),
    };
    st.set_order(order);
    let mut queue: Vec<usize> = (0..n).rev().collect();
    st.local_search(&cand, &pred_cand, &mut queue);
    let mut best = st.order.clone();
    let mut best_len = st.length();
    let mut rng = Rng(cfg.seed);
    let mut trials = 0;
    let optimal = |len: f64| len <= bound.lower_bound + 1e-9 * len.abs().max(1.0);
    let stall_limit = cfg.stall_trials.saturating_add(5 * n);
    let mut stall = 0;
    while trials < cfg.max_trials && stall < stall_limit && !optimal(best_len) && !should_stop() {
        trials += 1;
        stall += 1;
        // Double bridge on the best tour: A B C D ⇒ A C B D.
        let mut cuts = [
            1 + rng.below(n - 1),
            1 + rng.below(n - 1),
            1 + rng.below(n - 1),
        ];
        cuts.sort_unstable();
        if cuts[0] == cuts[1] || cuts[1] == cuts[2] {
            continue;
        }
        let (p, q, r) = (cuts[0], cuts[1], cuts[2]);
        let mut kicked = Vec::with_capacity(n);
        kicked.extend_from_slice(&best[..p]);
        kicked.extend_from_slice(&best[q..r]);
        kicked.extend_from_slice(&best[p..q]);
        kicked.extend_from_slice(&best[r..]);
        st.set_order(kicked);
        let mut queue = vec![
            best[p - 1],
            best[p],
            best[q - 1],
            best[q],
            best[r - 1],
            best[r % n],
        ];
        st.local_search(&cand, &pred_cand, &mut queue);
        let len = st.length();
        if len < best_len - 1e-9 * best_len.abs().max(1.0) {
            stall = 0;
        }
        if len <= best_len {
            best_len = len;
            best.clone_from(&st.order);
        }
    }
    // Report the tour from city 0.
    let p0 = best.iter().position(|&v| v == 0).unwrap_or(0);
    best.rotate_left(p0);
    Ok(Solution {
        tour: Tour {
            length: m.closed_length(&best),
            order: best,
        },
        lower_bound: bound.lower_bound,
        trials,
    })
}

/// Solves the open tour (9) from node 0: [`solve`] on the matrix with free arcs into node 0,
/// cut before the return; the reported length is the open length.
///
/// # Errors
/// As [`solve`].
pub fn solve_open(
    m: &CostMatrix,
    cfg: &SolverConfig,
    should_stop: impl FnMut() -> bool,
) -> Result<Solution> {
    let s = solve(&m.with_free_return_to_start(), cfg, should_stop)?;
    Ok(Solution {
        tour: Tour {
            length: m.open_length(&s.tour.order),
            order: s.tour.order,
        },
        ..s
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::exact::{held_karp, held_karp_open};
    use crate::matrix::is_permutation_from_zero;
    use proptest::prelude::*;

    /// Random costs with some penalty arcs (unreachable pairs) and duplicated nodes.
    fn matrix(n: usize, seed: u64) -> CostMatrix {
        let mut s = seed;
        let mut next = move || {
            s = s
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            s >> 33
        };
        let dup = (next() % n as u64) as usize;
        let raw: Vec<Vec<f64>> = (0..n)
            .map(|_| {
                (0..n)
                    .map(|_| {
                        if next() % 7 == 0 {
                            10_000.0
                        } else {
                            (next() % 100) as f64
                        }
                    })
                    .collect()
            })
            .collect();
        CostMatrix::from_fn(n, |i, j| {
            // Node `dup` duplicates node 0: zero arcs between them, the same costs otherwise.
            let (i2, j2) = (if i == dup { 0 } else { i }, if j == dup { 0 } else { j });
            if i2 == j2 { 0.0 } else { raw[i2][j2] }
        })
        .unwrap()
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(300))]

        #[test]
        fn closed_tours_are_optimal(n in 1usize..=12, seed in any::<u64>()) {
            let m = matrix(n, seed);
            let s = solve(&m, &SolverConfig::default(), || false).unwrap();
            let opt = held_karp(&m).unwrap();
            prop_assert!(is_permutation_from_zero(&s.tour.order, n));
            prop_assert_eq!(s.tour.length, m.closed_length(&s.tour.order));
            prop_assert!((s.tour.length - opt.length).abs() < 1e-9, "{} vs optimum {}", s.tour.length, opt.length);
            prop_assert!(s.lower_bound <= opt.length + 1e-6);
        }

        #[test]
        fn open_tours_are_optimal(n in 1usize..=12, seed in any::<u64>()) {
            let m = matrix(n, seed);
            let s = solve_open(&m, &SolverConfig::default(), || false).unwrap();
            let opt = held_karp_open(&m).unwrap();
            prop_assert!(is_permutation_from_zero(&s.tour.order, n));
            prop_assert_eq!(s.tour.length, m.open_length(&s.tour.order));
            prop_assert!((s.tour.length - opt.length).abs() < 1e-9, "{} vs optimum {}", s.tour.length, opt.length);
        }
    }

    #[test]
    fn deterministic_and_stoppable() {
        let m = matrix(40, 9);
        let a = solve(&m, &SolverConfig::default(), || false).unwrap();
        let b = solve(&m, &SolverConfig::default(), || false).unwrap();
        assert_eq!(a, b);
        let stopped = solve(&m, &SolverConfig::default(), || true).unwrap();
        assert_eq!(stopped.trials, 0);
        assert!(is_permutation_from_zero(&stopped.tour.order, 40));
        let bad = SolverConfig {
            candidates: 0,
            ..SolverConfig::default()
        };
        assert!(solve(&m, &bad, || false).is_err());
    }
}
