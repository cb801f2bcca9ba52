//! A heuristic ATSP solver: α-nearness candidates, 2-opt, Or-opt and a variable-depth search
//! over sequential pure 5-opt basic moves with don't-look bits, iterated with double-bridge kicks
//! and restarts.
//!
//! The candidate sets and the lower bound come from the Held–Karp machinery of
//! [`crate::held_karp_bound`] and from the assignment relaxation (its value is a second lower
//! bound; when it is at least as tight as Held–Karp, as on instances whose optimal tour is
//! nearly the optimal set of cycles, its least reduced-cost arcs join the candidates and
//! Karp's patching of its cycles is the first tour). The local search uses segment insertion
//! (Or-opt, segments of 1–3 nodes), 2-opt with reversal, whose asymmetric cost change comes
//! from prefix sums of the forward and backward arc costs, and the moves of LKH on the 2n-node
//! transform written directly on the asymmetric tour: sequential pure k-opt basic moves
//! (k ≤ 5, no segment reversed), chained Lin–Kernighan style (see `State::kopt`), both from
//! a city's outgoing arc through successor candidates and from its incoming arc through
//! predecessor candidates, as LKH starts from either tour neighbour of t₁.
//! A trial kicks the current tour with a double bridge and improves it again; a current tour
//! that 0.3 n kicks in a row have not improved is replaced by a new local optimum (improving
//! basic moves only) from a randomised walk along the candidates. The automatic budget runs at
//! least 2n trials and goes on while the best tour still improves; it stops early when the tour
//! is proven optimal (its length reaches the lower bound, rounded up when every cost is an
//! integer).
//! Everything is seeded: the same instance, settings and seed give the same tour.

use crate::assignment::{assignment, patch};
use crate::bound::{BoundConfig, alpha_candidates, held_karp_bound_until};
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
    /// Kick-and-improve trials after the first local optimum. Default 0: automatic — at least
    /// `trials_per_city` × n (LKH runs n trials) and 30; then, with
    /// `continue_while_improving`, more until `trials_per_city` × max(n, n²/40) trials in a
    /// row have not improved the best tour, at most 50 per city. Instances of up to 12 cities
    /// get 300 cheap random restarts. Any other value is an exact trial budget.
    pub max_trials: usize,
    /// Scale of the automatic budget (used when `max_trials` is 0). Default 2: with 1, the
    /// search misses the optimum of ftv35 or ftv38 (TSPLIB) on some seeds.
    pub trials_per_city: usize,
    /// Whether the automatic budget goes on while the best tour still improves. Default true.
    pub continue_while_improving: bool,
    /// Stop after this many trials in a row without improvement, plus 5 per city, whatever the
    /// trial budget. Default `usize::MAX` (no such stop).
    pub stall_trials: usize,
    /// Seed of the kicks. Default 1.
    pub seed: u64,
    /// Basic moves (sequential pure k-opt, k ≤ 5) chained by the variable-depth search: 1 makes
    /// improving basic moves only, 0 turns the search off, leaving 2-opt and Or-opt. Default 2.
    pub max_depth: usize,
    /// Settings of the lower bound that also yields the candidates.
    pub bound: BoundConfig,
}

impl Default for SolverConfig {
    fn default() -> Self {
        Self {
            candidates: 10,
            max_trials: 0,
            trials_per_city: 2,
            continue_while_improving: true,
            stall_trials: usize::MAX,
            seed: 1,
            max_depth: 2,
            bound: BoundConfig::default(),
        }
    }
}

impl SolverConfig {
    /// The budget of LKH's defaults, for planners that re-solve many times a second: n trials
    /// (and at least 30), no continuation. About a third of the default's time; it finds
    /// the optimum less often on hard instances.
    ///
    /// # Example
    /// ```
    /// use topo_tsp::{CostMatrix, SolverConfig, solve_open};
    /// let m = CostMatrix::from_fn(40, |i, j| ((i * 7 + j * 13) % 23) as f64 + 1.0).unwrap();
    /// let s = solve_open(&m, &SolverConfig::fast(), || false).unwrap();
    /// assert_eq!(s.trials, 40);
    /// ```
    pub fn fast() -> Self {
        Self {
            trials_per_city: 1,
            continue_while_improving: false,
            ..Self::default()
        }
    }

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

    /// Sets the scale of the automatic trial budget (used when `max_trials` is 0).
    pub fn with_trials_per_city(mut self, trials: usize) -> Self {
        self.trials_per_city = trials;
        self
    }

    /// Sets the stall limit (trials in a row without improvement, plus 5 per city).
    pub fn with_stall_trials(mut self, trials: usize) -> Self {
        self.stall_trials = trials;
        self
    }
}

/// A solved instance: the best tour, a lower bound, and the trials run.
#[derive(Debug, Clone, PartialEq)]
pub struct Solution {
    /// The best tour found (closed length for [`solve`], open length for [`solve_open`]).
    pub tour: Tour,
    /// A lower bound on the closed tour of the solved matrix: the larger of the Held–Karp
    /// bound and the assignment bound.
    pub lower_bound: f64,
    /// Trials run (kicks or restarts after the first local optimum).
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

/// Candidate arcs of every city: its likely successors and its likely predecessors.
struct Candidates {
    succ: Vec<Vec<usize>>,
    pred: Vec<Vec<usize>>,
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
    /// Whether `fwd` and `bwd` describe `order`.
    sums_ok: bool,
    /// The order before the tentative moves of a k-opt chain, and whether its sums were valid.
    saved: Vec<usize>,
    saved_sums_ok: bool,
    /// A spare order buffer.
    scratch: Vec<usize>,
    /// The order at the last checkpoint of [`State::local_search`].
    checkpoint: Vec<usize>,
}

impl<'a> State<'a> {
    /// A state over `m` with no tour yet (set one with [`State::set_order`]).
    fn new(m: &'a CostMatrix) -> Self {
        Self {
            m,
            order: Vec::new(),
            pos: vec![0; m.len()],
            fwd: Vec::new(),
            bwd: Vec::new(),
            sums_ok: false,
            saved: Vec::new(),
            saved_sums_ok: false,
            scratch: Vec::new(),
            checkpoint: Vec::new(),
        }
    }
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

    /// The successor of `v` on the tour read forwards (`R` false) or backwards (`R` true).
    #[inline(always)]
    fn next<const R: bool>(&self, v: usize) -> usize {
        if R { self.pred(v) } else { self.succ(v) }
    }

    /// The predecessor of `v` on the tour read forwards or backwards.
    #[inline(always)]
    fn prev<const R: bool>(&self, v: usize) -> usize {
        if R { self.succ(v) } else { self.pred(v) }
    }

    /// The cost of the arc i→j of the tour read forwards, or of j→i read backwards.
    #[inline(always)]
    fn cost<const R: bool>(&self, i: usize, j: usize) -> f64 {
        if R {
            self.m.cost(j, i)
        } else {
            self.m.cost(i, j)
        }
    }

    /// The position of `v` on the tour read forwards or backwards.
    #[inline(always)]
    fn place<const R: bool>(&self, v: usize) -> usize {
        if R {
            self.n() - 1 - self.pos[v]
        } else {
            self.pos[v]
        }
    }

    /// Position of `v` counted from `a` along the tour.
    fn rel(&self, a: usize, v: usize) -> usize {
        self.wrap(self.pos[v] + self.n() - self.pos[a])
    }

    fn set_order(&mut self, order: Vec<usize>) {
        self.order = order;
        self.update_positions();
        self.sums_ok = false;
    }

    fn update_positions(&mut self) {
        for (i, &v) in self.order.iter().enumerate() {
            self.pos[v] = i;
        }
    }

    /// Recomputes the prefix sums (only 2-opt reads them; tentative k-opt moves and their
    /// undoing leave them alone).
    fn update_sums(&mut self) {
        let n = self.n();
        self.fwd.resize(n + 1, 0.0);
        self.bwd.resize(n + 1, 0.0);
        for k in 0..n {
            let (u, v) = (self.order[k], self.order[self.wrap(k + 1)]);
            self.fwd[k + 1] = self.fwd[k] + self.m.cost(u, v);
            self.bwd[k + 1] = self.bwd[k] + self.m.cost(v, u);
        }
        self.sums_ok = true;
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

    /// Tries improving moves that start at city `a`; applies the first one found and pushes
    /// the cities whose arcs changed onto `touched`.
    fn improve_at(
        &mut self,
        a: usize,
        cand: &Candidates,
        max_depth: usize,
        touched: &mut Vec<usize>,
    ) -> bool {
        let n = self.n();
        let c = |i: usize, j: usize| self.m.cost(i, j);
        let eps = 1e-9;
        let b = self.succ(a);
        // 2-opt with reversal: a→b … d→e  ⇒  a→d, reversed d…b, b→e. On asymmetric costs the
        // reversed arcs change cost too; prefix sums give their total in O(1).
        if !self.sums_ok {
            self.update_sums();
        }
        for &d in &cand.succ[a] {
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
                touched.extend([a, b, d, e]);
                return true;
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
            for &bb in &cand.succ[last] {
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
                    touched.extend([prev, first, last, next, aa, bb]);
                    return true;
                }
            }
        }
        // Chains that start by removing a→succ(a) and add successor candidates, then chains that
        // start by removing pred(a)→a and add predecessor candidates: LKH's two directions
        // from t₁ on the 2n-node transform.
        self.kopt::<false>(a, &cand.succ, max_depth, touched)
            || self.kopt::<true>(a, &cand.pred, max_depth, touched)
    }

    /// Variable-depth search over sequential pure k-opt basic moves (no segment is reversed),
    /// k ≤ [`KOPT_MAX`], that starts by removing a→succ(a); the asymmetric counterpart of the
    /// basic moves of Helsgaun's LKH on the 2n-node transform, where only moves that keep
    /// every city next to its twin are valid.
    ///
    /// A basic move removes x₁→y₁, adds x₁→y₂ (y₂ a candidate of x₁), removes x₂→y₂ (x₂ the
    /// predecessor of y₂), …, and closes with x_k→y₁; the partial gain must stay positive, and
    /// only the final arc set has to be a tour (checked in O(k²)). The first improving move is
    /// applied. When none improves, the feasible k = `KOPT_MAX` move of largest partial gain
    /// is made tentatively and the search goes on from its closing arc x_k→y₁, up to
    /// `max_depth` basic moves; a chain that ends without improvement is undone.
    fn kopt<const R: bool>(
        &mut self,
        a: usize,
        cand: &[Vec<usize>],
        max_depth: usize,
        touched: &mut Vec<usize>,
    ) -> bool {
        let mut xs = [0usize; KOPT_MAX];
        let mut ys = [0usize; KOPT_MAX];
        let y1 = self.next::<R>(a);
        let mut x1 = a;
        let mut g = self.cost::<R>(a, y1);
        let mut saved = false;
        // Arcs added by tentative moves (never removed again in this chain), and their cities.
        let mut added: Vec<(usize, usize)> = Vec::new();
        let mut moved: Vec<usize> = Vec::new();
        for step in 0..max_depth {
            xs[0] = x1;
            ys[0] = y1;
            let mut best: Option<BasicMove> = None;
            let want_best = step + 1 < max_depth;
            let k = self.kopt_level::<R>(
                1,
                g,
                &mut xs,
                &mut ys,
                cand,
                &added,
                want_best.then_some(&mut best),
            );
            if k > 0 {
                self.apply_kopt::<R>(&xs[..k], &ys[..k]);
                touched.extend_from_slice(&moved);
                touched.extend_from_slice(&xs[..k]);
                touched.extend_from_slice(&ys[..k]);
                return true;
            }
            let Some(mv) = best else { break };
            if !saved {
                saved = true;
                self.saved.clone_from(&self.order);
                self.saved_sums_ok = self.sums_ok;
            }
            let k = mv.k;
            self.apply_kopt::<R>(&mv.xs[..k], &mv.ys[..k]);
            for i in 0..k - 1 {
                added.push((mv.xs[i], mv.ys[i + 1]));
            }
            moved.extend_from_slice(&mv.xs[..k]);
            moved.extend_from_slice(&mv.ys[..k]);
            x1 = mv.xs[k - 1];
            g = mv.gain;
        }
        if saved {
            // Undo the tentative moves; the prefix sums were not touched by them.
            std::mem::swap(&mut self.order, &mut self.saved);
            self.update_positions();
            self.sums_ok = self.saved_sums_ok;
        }
        false
    }

    /// Depth-first search of [`State::kopt`] with `i` arcs removed so far and partial gain `g`:
    /// returns the k of an improving feasible move left in `xs`, `ys`, or 0. When `best` is
    /// given, it keeps the feasible non-improving move of k = [`KOPT_MAX`] with the largest
    /// partial gain.
    #[allow(clippy::too_many_arguments)]
    fn kopt_level<const R: bool>(
        &self,
        i: usize,
        g: f64,
        xs: &mut [usize; KOPT_MAX],
        ys: &mut [usize; KOPT_MAX],
        cand: &[Vec<usize>],
        added: &[(usize, usize)],
        mut best: Option<&mut Option<BasicMove>>,
    ) -> usize {
        let eps = 1e-9;
        let x = xs[i - 1];
        let sx = self.next::<R>(x);
        for &y in cand[x].iter().take(KOPT_BREADTH) {
            if y == sx || ys[..i].contains(&y) {
                continue;
            }
            let g1 = g - self.cost::<R>(x, y);
            if g1 <= eps {
                continue;
            }
            let xn = self.prev::<R>(y);
            if added.contains(&(xn, y)) {
                continue;
            }
            xs[i] = xn;
            ys[i] = y;
            let g2 = g1 + self.cost::<R>(xn, y);
            let closes = g2 - self.cost::<R>(xn, ys[0]) > eps;
            let leaf = i + 1 == KOPT_MAX;
            let track = leaf
                && best
                    .as_ref()
                    .is_some_and(|b| b.as_ref().is_none_or(|b| g2 > b.gain));
            // One feasibility test serves both the closing move and the best tentative move.
            if (closes || track) && self.kopt_feasible::<R>(&xs[..=i]) {
                if closes {
                    return i + 1;
                }
                if let Some(b) = best.as_deref_mut() {
                    *b = Some(BasicMove {
                        gain: g2,
                        k: i + 1,
                        xs: *xs,
                        ys: *ys,
                    });
                }
            }
            if !leaf {
                let k = self.kopt_level::<R>(i + 1, g2, xs, ys, cand, added, best.as_deref_mut());
                if k > 0 {
                    return k;
                }
            }
        }
        0
    }

    /// Whether replacing the arcs x_i→succ(x_i) by x_i→y_{i+1} (cyclic) leaves one tour.
    fn kopt_feasible<const R: bool>(&self, xs: &[usize]) -> bool {
        let k = xs.len();
        if k < 3 {
            // Exchanging two arcs without reversing a segment always splits the tour.
            return false;
        }
        // rank[i]: place of arc i in tour order. The segment after arc i ends at the tail of the
        // arc ranked next; from there the added arc leads to the segment after arc i + 1.
        let mut rank = [0usize; KOPT_MAX];
        let mut by_rank = [0usize; KOPT_MAX];
        let mut p = [0usize; KOPT_MAX];
        for (pi, &x) in p.iter_mut().zip(xs) {
            *pi = self.place::<R>(x);
        }
        for i in 0..k {
            rank[i] = p[..k].iter().filter(|&&q| q < p[i]).count();
            by_rank[rank[i]] = i;
        }
        let mut arc = 0;
        for step in 1..=k {
            let end = by_rank[(rank[arc] + 1) % k];
            arc = (end + 1) % k;
            if arc == 0 {
                return step == k;
            }
        }
        false
    }

    /// Rebuilds the tour after the k-opt move of `xs`, `ys`.
    fn apply_kopt<const R: bool>(&mut self, xs: &[usize], ys: &[usize]) {
        let n = self.n();
        let k = xs.len();
        let mut order = std::mem::take(&mut self.scratch);
        order.clear();
        let mut v = ys[0];
        while order.len() < n {
            order.push(v);
            v = match xs.iter().position(|&x| x == v) {
                Some(i) => ys[(i + 1) % k],
                None => self.next::<R>(v),
            };
        }
        if R {
            order.reverse();
        }
        self.scratch = std::mem::replace(&mut self.order, order);
        self.update_positions();
        self.sums_ok = false;
    }

    /// Local search with don't-look bits until no candidate move improves; returns true when
    /// `should_stop`, polled every n moves, ended it early.
    ///
    /// A move is made when its computed gain exceeds a small constant, but rounding (2-opt's
    /// prefix sums, huge or nearly equal costs) can make a zero gain look positive, and such
    /// moves can cycle. So every n moves the recomputed length must have dropped strictly
    /// since the last checkpoint, or the checkpoint tour is restored and the search ends: the
    /// checkpoint lengths strictly decrease, so the search terminates. Ordinary moves gain far
    /// more than the rounding of the length, so they pass the check.
    fn local_search(
        &mut self,
        cand: &Candidates,
        queue: &mut Vec<usize>,
        max_depth: usize,
        should_stop: &mut dyn FnMut() -> bool,
    ) -> bool {
        let n = self.n();
        let mut active = vec![false; n];
        for &v in queue.iter() {
            active[v] = true;
        }
        let mut touched = Vec::new();
        let mut moves = 0usize;
        let mut checkpoint_len = self.length();
        self.checkpoint.clone_from(&self.order);
        while let Some(a) = queue.pop() {
            active[a] = false;
            touched.clear();
            if self.improve_at(a, cand, max_depth, &mut touched) {
                moves += 1;
                if moves.is_multiple_of(n) {
                    let len = self.length();
                    // Lengths are sums of finite non-negative costs: never NaN, maybe +∞.
                    if len >= checkpoint_len {
                        let order = std::mem::take(&mut self.checkpoint);
                        self.set_order(order);
                        return false;
                    }
                    checkpoint_len = len;
                    self.checkpoint.clone_from(&self.order);
                    if should_stop() {
                        return true;
                    }
                }
                for &v in &touched {
                    if !active[v] {
                        active[v] = true;
                        queue.push(v);
                    }
                }
            }
        }
        false
    }
}

/// Up to this many cities, trials restart from random tours instead of kicking the best.
const RESTART_MAX: usize = 12;

/// The automatic trial budget of instances of up to `RESTART_MAX` cities (cheap restarts).
const TINY_TRIALS: usize = 300;

/// The smallest automatic trial budget (tiny instances need more trials than cities).
const MIN_AUTO_TRIALS: usize = 30;

/// The automatic budget never runs more than this many trials per city.
const MAX_TRIALS_PER_CITY: usize = 50;

/// The search restarts from a new tour (a randomised walk along the candidates) after this
/// many tenths of n kicks in a row that do not improve the current tour: short runs from many
/// starts escape the deep, wrong funnels of some instances better than long runs.
const RUN_STALL_TENTHS: usize = 3;

/// Most arcs exchanged by one basic move of [`State::kopt`].
const KOPT_MAX: usize = 5;

/// Candidates tried for each added arc of a basic move.
const KOPT_BREADTH: usize = 5;

/// Arcs of least reduced cost added to each candidate list when the assignment bound guides
/// the search.
const AP_CANDIDATES: usize = 5;

/// A feasible basic move of [`State::kopt`]: arcs x_i→y_i (i < k) replaced by x_i→y_{i+1}
/// and x_k→y₁, with its partial gain before the closing arc.
#[derive(Clone, Copy)]
struct BasicMove {
    gain: f64,
    k: usize,
    xs: [usize; KOPT_MAX],
    ys: [usize; KOPT_MAX],
}

/// The double bridge A B C D ⇒ A C B D of `tour` at three random cuts, with the six cities at
/// the ends of the changed arcs; `None` when two cuts coincide.
fn double_bridge(tour: &[usize], rng: &mut Rng) -> Option<(Vec<usize>, [usize; 6])> {
    let n = tour.len();
    let mut cuts = [
        1 + rng.below(n - 1),
        1 + rng.below(n - 1),
        1 + rng.below(n - 1),
    ];
    cuts.sort_unstable();
    if cuts[0] == cuts[1] || cuts[1] == cuts[2] {
        return None;
    }
    let (p, q, r) = (cuts[0], cuts[1], cuts[2]);
    let mut kicked = Vec::with_capacity(n);
    kicked.extend_from_slice(&tour[..p]);
    kicked.extend_from_slice(&tour[q..r]);
    kicked.extend_from_slice(&tour[p..q]);
    kicked.extend_from_slice(&tour[r..]);
    let ends = [
        tour[p - 1],
        tour[p],
        tour[q - 1],
        tour[q],
        tour[r - 1],
        tour[r % n],
    ];
    Some((kicked, ends))
}

/// Trials without improvement, per unit of `trials_per_city`, after which the automatic budget
/// stops (once its minimum is spent): n, growing to n²/40 above 40 cities, where a kick is less likely to reach the part
/// of the tour that still needs work and a trial is a smaller part of the time than the lower
/// bound.
fn improvement_window(n: usize) -> usize {
    n.max(n * n / 40)
}

/// A test of "this closed length is optimal": it reaches the lower bound, or, when every cost
/// is an integer, the bound rounded up.
fn proven_optimal(m: &CostMatrix, lower_bound: f64) -> impl Fn(f64) -> bool {
    let n = m.len();
    let integral = (0..n).all(|i| (0..n).all(|j| m.cost(i, j).fract() == 0.0));
    let target = if integral {
        (lower_bound - 1e-6).ceil()
    } else {
        lower_bound
    };
    move |len: f64| len <= target + 1e-9 * len.abs().max(1.0)
}

/// Solves the closed ATSP on `m` heuristically; `should_stop` is polled between the lower
/// bound's 1-trees, between trials and every n improving moves of a local search (pass
/// `|| false` for a pure trial budget, or a deadline check for a time budget — the library
/// reads no clock itself). Stopped early, it still returns the best tour found, at least the
/// first trial's.
///
/// Every local search terminates, even when rounding makes moves look improving that are not
/// (huge or nearly equal costs): it ends when n moves in a row do not shorten the recomputed
/// tour.
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
    let bound = held_karp_bound_until(m, &cfg.bound, &mut should_stop)?;
    if n <= 3 {
        // Every order of ≤ 3 cities from city 0 is checked directly.
        let t = crate::exact::brute_force(m)?;
        return Ok(Solution {
            tour: t,
            lower_bound: bound.lower_bound,
            trials: 0,
        });
    }
    // Successor candidates of city i: the cities among the α-candidates of its twin n + i;
    // predecessor candidates: the twins among the α-candidates of city i.
    let sym = alpha_candidates(m, &bound.pi, cfg.candidates)?;
    let mut cand = Candidates {
        succ: (0..n)
            .map(|i| {
                sym[n + i]
                    .iter()
                    .copied()
                    .filter(|&j| j < n && j != i)
                    .collect()
            })
            .collect(),
        pred: (0..n)
            .map(|i| {
                sym[i]
                    .iter()
                    .filter(|&&j| j >= n && j - n != i)
                    .map(|&j| j - n)
                    .collect()
            })
            .collect(),
    };
    // The assignment relaxation: a second lower bound, its cheapest reduced-cost arcs as extra
    // candidates, and Karp's patching of its cycles as the first tour.
    let tol = |x: f64| 1e-9 * x.abs().max(1.0);
    let ap = assignment(m);
    let mut lower_bound = bound.lower_bound;
    let mut order = Vec::with_capacity(n);
    // When the assignment bound is at least as tight as Held–Karp (the cycles of the assignment
    // are then nearly a tour), its reduced costs and its patched cycles guide the search.
    if let Some(ap) = ap
        .as_ref()
        .filter(|ap| ap.cost >= bound.lower_bound - tol(bound.lower_bound))
    {
        let extend = |list: &mut Vec<usize>, reduced: &dyn Fn(usize) -> f64, i: usize| {
            let mut extra: Vec<(f64, usize)> = (0..n)
                .filter(|&j| j != i)
                .map(|j| (reduced(j), j))
                .collect();
            extra.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
            for &(_, j) in extra.iter().take(AP_CANDIDATES) {
                if !list.contains(&j) {
                    list.push(j);
                }
            }
        };
        for i in 0..n {
            extend(&mut cand.succ[i], &|j| ap.reduced(m, i, j), i);
            extend(&mut cand.pred[i], &|j| ap.reduced(m, j, i), i);
        }
        let succ = patch(m, &ap.succ);
        let mut x = 0;
        for _ in 0..n {
            order.push(x);
            x = succ[x];
        }
    }
    if let Some(ap) = &ap {
        lower_bound = lower_bound.max(ap.cost);
    }
    if order.len() != n {
        order = nearest_neighbour(m, &cand.succ);
    }
    let mut st = State::new(m);
    st.set_order(order);
    let mut queue: Vec<usize> = (0..n).rev().collect();
    let mut stopped = st.local_search(&cand, &mut queue, cfg.max_depth, &mut should_stop);
    let mut best = st.order.clone();
    let mut best_len = st.length();
    let mut rng = Rng(cfg.seed);
    let mut trials = 0;
    let optimal = proven_optimal(m, lower_bound);
    let stall_limit = cfg.stall_trials.saturating_add(5 * n);
    // Trials since the best tour last improved, and since the current tour last improved.
    let mut stall = 0;
    let mut run_stall = 0;
    let (min_trials, max_trials, window) = if cfg.max_trials == 0 {
        let floor = if n <= RESTART_MAX {
            TINY_TRIALS
        } else {
            MIN_AUTO_TRIALS
        };
        let base = cfg.trials_per_city.saturating_mul(n).max(floor);
        let cap = if cfg.continue_while_improving {
            base.max(MAX_TRIALS_PER_CITY.saturating_mul(n))
        } else {
            base
        };
        let window = cfg.trials_per_city.saturating_mul(improvement_window(n));
        (base, cap, window)
    } else {
        (cfg.max_trials, cfg.max_trials, 0)
    };
    let mut cur = best.clone();
    let mut cur_len = best_len;
    while trials < max_trials
        && (trials < min_trials || stall < window)
        && stall < stall_limit
        && !optimal(best_len)
        && !stopped
        && !should_stop()
    {
        trials += 1;
        stall += 1;
        run_stall += 1;
        if n <= RESTART_MAX {
            // Tiny instances: a random restart explores more than a kick among so few arcs.
            let mut order = best.clone();
            for i in (2..n).rev() {
                order.swap(i, 1 + rng.below(i));
            }
            st.set_order(order);
            let mut queue: Vec<usize> = (0..n).collect();
            // Every other restart without k-opt moves: among so few tours the two local
            // searches have different basins, and the optimum is sometimes in only one.
            let depth = if trials % 2 == 0 { 0 } else { cfg.max_depth };
            stopped = st.local_search(&cand, &mut queue, depth, &mut should_stop);
            let len = st.length();
            if len < best_len - tol(best_len) {
                stall = 0;
            }
            if len <= best_len {
                best_len = len;
                best.clone_from(&st.order);
            }
            continue;
        }
        if run_stall > RUN_STALL_TENTHS * n / 10 {
            // The current tour is stuck: restart from a new local optimum. Improving basic moves
            // suffice there (the restart is for diversity), and keep restarts cheap.
            run_stall = 0;
            let order = candidate_walk(&cand.succ, &mut rng);
            st.set_order(order);
            let mut queue: Vec<usize> = (0..n).collect();
            stopped = st.local_search(&cand, &mut queue, cfg.max_depth.min(1), &mut should_stop);
            cur.clone_from(&st.order);
            cur_len = st.length();
        } else {
            let Some((kicked, ends)) = double_bridge(&cur, &mut rng) else {
                continue;
            };
            st.set_order(kicked);
            let mut queue = ends.to_vec();
            stopped = st.local_search(&cand, &mut queue, cfg.max_depth, &mut should_stop);
            let len = st.length();
            if len < cur_len - tol(cur_len) {
                run_stall = 0;
            }
            if len <= cur_len {
                cur_len = len;
                cur.clone_from(&st.order);
            }
        }
        if cur_len < best_len - tol(best_len) {
            stall = 0;
        }
        if cur_len <= best_len {
            best_len = cur_len;
            best.clone_from(&cur);
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
        lower_bound,
        trials,
    })
}

/// A random tour along the candidates: from a random city, the first unvisited candidate
/// (the second one with probability 1/3), or a random unvisited city when none is left.
fn candidate_walk(cand: &[Vec<usize>], rng: &mut Rng) -> Vec<usize> {
    let n = cand.len();
    let mut seen = vec![false; n];
    let mut rest: Vec<usize> = (0..n).collect();
    let mut order = Vec::with_capacity(n);
    let mut cur = rng.below(n);
    loop {
        seen[cur] = true;
        order.push(cur);
        if order.len() == n {
            return order;
        }
        let mut free = cand[cur].iter().copied().filter(|&j| !seen[j]);
        cur = match (free.next(), free.next()) {
            (Some(_), Some(second)) if rng.below(3) == 0 => second,
            (Some(first), _) => first,
            _ => {
                rest.retain(|&j| !seen[j]);
                rest[rng.below(rest.len())]
            }
        };
    }
}

/// Nearest-neighbour tour from city 0 through the candidates (any city when they are used up).
fn nearest_neighbour(m: &CostMatrix, cand: &[Vec<usize>]) -> Vec<usize> {
    let n = m.len();
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
    order
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

    /// Checks a solution of `m` by [`solve`] (closed) or [`solve_open`] (open).
    fn assert_valid(m: &CostMatrix, s: &Solution, open: bool) {
        let n = m.len();
        assert!(is_permutation_from_zero(&s.tour.order, n), "{:?}", s.tour);
        let len = if open {
            m.open_length(&s.tour.order)
        } else {
            m.closed_length(&s.tour.order)
        };
        assert_eq!(s.tour.length, len);
    }

    #[test]
    fn rounding_cannot_make_local_search_cycle() {
        // Equal costs: every move gains nothing, but 2-opt's prefix sums round some gains above
        // the threshold; without the checkpoints of `local_search` these moves cycle.
        let equal = CostMatrix::from_fn(20, |_, _| 1_234_567.891).unwrap();
        // Huge costs: the sums' rounding errors dwarf the threshold.
        let flat_huge = CostMatrix::from_fn(20, |_, _| 1e300).unwrap();
        let huge = CostMatrix::from_fn(25, |i, j| {
            1e300 * (1.0 + ((i * 7 + j * 3) % 11) as f64 / 1e14)
        })
        .unwrap();
        for m in [&equal, &huge, &flat_huge] {
            let closed = solve(m, &SolverConfig::default(), || false).unwrap();
            assert_valid(m, &closed, false);
            let open = solve_open(m, &SolverConfig::default(), || false).unwrap();
            assert_valid(m, &open, true);
        }
    }

    #[test]
    fn long_local_search_polls_the_stop() {
        // Points on a circle visited in a scrambled order: far more than n improving moves.
        let n = 100;
        let angle = |i: usize| (i * 37 % n) as f64 * std::f64::consts::TAU / n as f64;
        let m = CostMatrix::from_fn(n, |i, j| {
            let (a, b) = (angle(i), angle(j));
            (a.cos() - b.cos()).hypot(a.sin() - b.sin())
        })
        .unwrap();
        let nearest = |i: usize| {
            let mut others: Vec<usize> = (0..n).filter(|&j| j != i).collect();
            others.sort_by(|&a, &b| m.cost(i, a).total_cmp(&m.cost(i, b)));
            others.truncate(8);
            others
        };
        let cand = Candidates {
            succ: (0..n).map(nearest).collect(),
            pred: (0..n).map(nearest).collect(),
        };
        let mut st = State::new(&m);
        let start: Vec<usize> = (0..n).collect();
        let start_len = m.closed_length(&start);
        st.set_order(start.clone());
        let mut polls = 0;
        let stopped = st.local_search(&cand, &mut (0..n).collect(), 2, &mut || {
            polls += 1;
            true
        });
        assert!(stopped);
        assert_eq!(polls, 1);
        assert!(is_permutation_from_zero(&st.from(0), n));
        assert!(st.length() < start_len);
        // Without the stop, the search runs to a local optimum.
        st.set_order(start);
        assert!(!st.local_search(&cand, &mut (0..n).collect(), 2, &mut || false));
        assert!(st.length() < 7.0);
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

    /// A bound with no iteration limit and an endless first period would not end by
    /// itself: `should_stop` ends it, and the tour comes back all the same.
    #[test]
    fn an_endless_bound_is_stoppable() {
        let m = matrix(5, 3);
        let mut cfg = SolverConfig::default();
        cfg.bound.max_iterations = usize::MAX;
        cfg.bound.initial_period = usize::MAX;
        let mut polls = 0;
        let s = solve(&m, &cfg, || {
            polls += 1;
            polls > 1000
        })
        .unwrap();
        assert!(is_permutation_from_zero(&s.tour.order, 5));
        assert!(s.lower_bound <= s.tour.length + 1e-9);
        assert!(polls > 1000);
    }
}
