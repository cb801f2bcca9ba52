//! The Held–Karp lower bound by subgradient optimisation over 1-trees, and α-nearness
//! candidate sets, on the symmetric transform of an asymmetric instance.
//!
//! # The symmetric transform
//!
//! An n-city ATSP becomes a 2n-node symmetric problem (Jonker–Volgenant): city i keeps node i
//! and gains a twin node n + i, joined to it by a fixed edge; the edge between twin n + i and
//! city j ≠ i costs c(i, j); cities are not joined to cities, nor twins to twins. A tour that
//! uses every fixed edge alternates i, n + i, j, n + j, … and costs exactly the ATSP tour
//! i → j → …. Fixed edges are forced into every 1-tree by ordering them before all others.
//!
//! # The bound
//!
//! For node penalties π, the minimum 1-tree T_π (a spanning tree on all nodes but a special
//! one, plus the special node's two cheapest edges) under costs c(u, v) + π_u + π_v gives
//! w(π) = cost(T_π) − 2 Σ π ≤ the optimal tour length. Subgradient ascent on π, stepping along
//! deg(v) − 2, raises w toward the Held–Karp bound. The step schedule is Helsgaun's (LKH, 2000,
//! Section 4.1): the direction mixes the current and the previous subgradient (0.7/0.3); in an
//! initial phase the step doubles while w improves; then the step and the period halve in turn,
//! and a period that still improves at its last iteration is doubled. The ascent stops early
//! when the 1-tree is a tour: the bound is then the optimum.

use crate::error::{Result, TspError};
use crate::matrix::CostMatrix;

/// Settings of the Held–Karp bound computation.
#[derive(Debug, Clone, Copy, PartialEq)]
#[non_exhaustive]
pub struct BoundConfig {
    /// Maximum 1-trees computed (subgradient iterations). Default 0: automatic, 100 + 5n for
    /// n cities. This bounds the ascent's work: with it and the period both huge the ascent
    /// runs about that long ([`crate::solve`] polls its `should_stop` between 1-trees).
    pub max_iterations: usize,
    /// Iterations of the first period; 0 chooses n/2 + 20 for n cities (LKH uses half the
    /// 2n nodes, at least 100; exploration-sized instances converge with fewer). Default 0.
    pub initial_period: usize,
    /// First step, relative to the mean penalised edge cost of the plain 1-tree (the initial
    /// phase doubles it while the bound improves). Default 0.001.
    pub initial_step: f64,
}

impl Default for BoundConfig {
    fn default() -> Self {
        Self {
            max_iterations: 0,
            initial_period: 0,
            initial_step: 0.001,
        }
    }
}

/// The result of [`held_karp_bound`].
#[derive(Debug, Clone, PartialEq)]
pub struct HeldKarpBound {
    /// The best lower bound found on the ATSP tour length.
    pub lower_bound: f64,
    /// The node penalties π (2n entries: cities, then twins) at the best bound.
    pub pi: Vec<f64>,
    /// Subgradient iterations run.
    pub iterations: usize,
    /// Whether the best 1-tree was itself a tour (then the bound is the optimum).
    pub tree_is_tour: bool,
}

/// Cost of the transformed edge (u, v): `None` when absent, `Some(None)` for a fixed edge.
#[inline]
fn edge(m: &CostMatrix, n: usize, u: usize, v: usize) -> Option<Option<f64>> {
    let (city, twin) = match (u < n, v < n) {
        (true, false) => (u, v - n),
        (false, true) => (v, u - n),
        _ => return None,
    };
    if city == twin {
        Some(None)
    } else {
        Some(Some(m.cost(twin, city)))
    }
}

/// A minimum 1-tree: parent of every node in the spanning tree rooted at node n (node 0 is the
/// special node), the special node's two edges, degrees and the penalised cost.
pub(crate) struct OneTree {
    pub(crate) parent: Vec<usize>,
    pub(crate) special: [usize; 2],
    pub(crate) degree: Vec<i64>,
    pub(crate) cost: f64,
}

/// The cost matrix row by row and column by column, so that both arc directions between two
/// super-nodes are read from contiguous memory in Prim's inner loop.
pub(crate) struct Dense {
    n: usize,
    rows: Vec<f64>,
    cols: Vec<f64>,
}

impl Dense {
    pub(crate) fn new(m: &CostMatrix) -> Self {
        let n = m.len();
        let mut rows = Vec::with_capacity(n * n);
        let mut cols = Vec::with_capacity(n * n);
        for i in 0..n {
            rows.extend((0..n).map(|j| m.cost(i, j)));
            cols.extend((0..n).map(|j| m.cost(j, i)));
        }
        Self { n, rows, cols }
    }
}

/// Prim's algorithm on nodes 1..2n, then the two cheapest edges of node 0.
///
/// Every fixed edge (i, n + i) is in every minimum 1-tree, so the spanning tree is computed on
/// the n "super-nodes" {i, n + i} (i ≥ 1) and {n} (city 0 is the special node), joining two
/// super-nodes by the cheaper of their two real edges: O(n²) instead of O((2n)²). The tree is
/// then written back in terms of the 2n nodes, rooted at node n.
pub(crate) fn one_tree(d: &Dense, pi: &[f64]) -> OneTree {
    let n = d.n;
    let big_n = 2 * n;
    let mut parent = vec![usize::MAX; big_n];
    let mut degree = vec![0i64; big_n];
    let mut cost = 0.0;
    let (pc, pt) = pi.split_at(n);
    // Kept in the order of `rest` (so that the inner loop reads them contiguously): each
    // super-node's cheapest link cost and its penalties; by node: the tree super-node at the
    // other end of that link, and whether it is twin v → city (else twin → city v).
    let mut best_u = vec![0usize; n];
    let mut best_rev = vec![false; n];
    let mut rest: Vec<usize> = (1..n).collect();
    // Super-node 0 holds only twin n (city 0 is the special node): its links are twin 0 → b.
    let mut rc: Vec<f64> = rest.iter().map(|&b| d.rows[b] + pt[0] + pc[b]).collect();
    let mut rpc: Vec<f64> = rest.iter().map(|&b| pc[b]).collect();
    let mut rpt: Vec<f64> = rest.iter().map(|&b| pt[b]).collect();
    // The closest super-node not yet in the tree (ties by index: deterministic).
    let mut next = 0;
    for idx in 1..rest.len() {
        let (bv, bk) = (rc[idx], rc[next]);
        if bv < bk || (bv == bk && rest[idx] < rest[next]) {
            next = idx;
        }
    }
    while next < rest.len() {
        let u = rest.swap_remove(next);
        cost += rc.swap_remove(next);
        rpc.swap_remove(next);
        rpt.swap_remove(next);
        let w = best_u[u];
        // The link joins twin u → city w, or twin w → city u; u's partner hangs below.
        let (inner, outer) = if best_rev[u] { (n + u, w) } else { (u, n + w) };
        parent[inner] = outer;
        parent[if inner < n { inner + n } else { inner - n }] = inner;
        degree[inner] += 1;
        degree[outer] += 1;
        let row = &d.rows[u * n..(u + 1) * n];
        let col = &d.cols[u * n..(u + 1) * n];
        let (pcu, ptu) = (pc[u], pt[u]);
        // Update the links through u, and find the next closest super-node on the way.
        let mut k = usize::MAX;
        let mut kc = f64::INFINITY;
        let mut kv = usize::MAX;
        let items = rest.iter().zip(rc.iter_mut()).zip(rpc.iter().zip(&rpt));
        for (idx, ((&v, c), (&pcv, &ptv))) in items.enumerate() {
            // Twin of u → city v, or twin of v → city u.
            let ab = row[v] + ptu + pcv;
            let ba = col[v] + ptv + pcu;
            let x = ab.min(ba);
            let mut bv = *c;
            if x < bv {
                bv = x;
                *c = x;
                best_u[v] = u;
                best_rev[v] = ba < ab;
            }
            if k == usize::MAX || bv < kc || (bv == kc && v < kv) {
                k = idx;
                kc = bv;
                kv = v;
            }
        }
        next = if rest.is_empty() { usize::MAX } else { k };
    }
    // Fixed edges of the pairs.
    for i in 1..n {
        degree[i] += 1;
        degree[n + i] += 1;
    }
    // Special node 0: its fixed edge to twin n and its cheapest other edge (twin v → city 0).
    let mut second = (usize::MAX, f64::INFINITY);
    for v in 1..n {
        let k = d.cols[v] + pt[v] + pc[0];
        if k < second.1 {
            second = (n + v, k);
        }
    }
    let special = [n, second.0];
    degree[0] += 2;
    degree[n] += 1;
    if second.0 != usize::MAX {
        degree[second.0] += 1;
        cost += second.1;
    }
    // Fixed edges cost 0 but carry their endpoints' penalties.
    for i in 0..n {
        cost += pi[i] + pi[n + i];
    }
    OneTree {
        parent,
        special,
        degree,
        cost,
    }
}

/// The Held–Karp lower bound of the closed ATSP on `m` (see the module docs).
///
/// For n ≤ 2 the only tour's length is returned exactly.
///
/// # Errors
/// [`TspError::InvalidConfig`] for bad settings.
///
/// # Example
/// ```
/// use topo_tsp::{BoundConfig, CostMatrix, held_karp, held_karp_bound};
/// let m = CostMatrix::from_fn(8, |i, j| ((3 * i + 5 * j) % 11) as f64 + 1.0).unwrap();
/// let lb = held_karp_bound(&m, &BoundConfig::default()).unwrap();
/// let opt = held_karp(&m).unwrap().length;
/// assert!(lb.lower_bound <= opt + 1e-9);
/// ```
pub fn held_karp_bound(m: &CostMatrix, cfg: &BoundConfig) -> Result<HeldKarpBound> {
    held_karp_bound_until(m, cfg, &mut || false)
}

/// [`held_karp_bound`], ended early (with the best bound so far) when `should_stop` returns
/// true; it is polled before every 1-tree after the first.
pub(crate) fn held_karp_bound_until(
    m: &CostMatrix,
    cfg: &BoundConfig,
    should_stop: &mut dyn FnMut() -> bool,
) -> Result<HeldKarpBound> {
    if !(cfg.initial_step > 0.0 && cfg.initial_step.is_finite()) {
        return Err(TspError::InvalidConfig {
            what: "bound settings",
            reason: "need a finite initial_step > 0",
        });
    }
    let n = m.len();
    if n <= 2 {
        let order: Vec<usize> = (0..n).collect();
        return Ok(HeldKarpBound {
            lower_bound: m.closed_length(&order),
            pi: vec![0.0; 2 * n],
            iterations: 0,
            tree_is_tour: true,
        });
    }
    Ok(ascent(&Dense::new(m), cfg, should_stop))
}

/// Subgradient ascent with Helsgaun's step schedule (LKH's `Ascent`).
fn ascent(d: &Dense, cfg: &BoundConfig, should_stop: &mut dyn FnMut() -> bool) -> HeldKarpBound {
    let n = d.n;
    let mut pi = vec![0.0; 2 * n];
    let mut tree = one_tree(d, &pi);
    let mut w = tree.cost;
    let norm = |t: &OneTree| -> i64 { t.degree.iter().map(|d| (d - 2) * (d - 2)).sum() };
    let mut best = HeldKarpBound {
        lower_bound: w,
        pi: pi.clone(),
        iterations: 1,
        tree_is_tour: norm(&tree) == 0,
    };
    if best.tree_is_tour {
        return best;
    }
    // Step in cost units: a fraction of the mean arc cost.
    let mean = d.rows.iter().sum::<f64>() / (n * (n - 1)) as f64;
    let mut t = cfg.initial_step * mean.max(f64::MIN_POSITIVE);
    let initial_period = if cfg.initial_period == 0 {
        n / 2 + 20
    } else {
        cfg.initial_period
    };
    let mut period = initial_period;
    let mut last: Vec<i64> = tree.degree.iter().map(|d| d - 2).collect();
    let mut initial_phase = true;
    let max_iterations = if cfg.max_iterations == 0 {
        100 + 5 * n
    } else {
        cfg.max_iterations
    };
    let mut its = 1;
    'outer: while period > 0 {
        let mut p = 1;
        while p <= period {
            if its >= max_iterations || should_stop() {
                break 'outer;
            }
            for ((x, &deg), l) in pi.iter_mut().zip(&tree.degree).zip(last.iter_mut()) {
                let v = deg - 2;
                if v != 0 {
                    *x += t * (0.7 * v as f64 + 0.3 * *l as f64);
                }
                *l = v;
            }
            tree = one_tree(d, &pi);
            its += 1;
            w = tree.cost - 2.0 * pi.iter().sum::<f64>();
            let g2 = norm(&tree);
            if w > best.lower_bound + 1e-12 * w.abs().max(1.0) {
                best.lower_bound = w;
                best.pi.clone_from(&pi);
                best.tree_is_tour = g2 == 0;
                if g2 == 0 {
                    break 'outer;
                }
                if initial_phase {
                    t *= 2.0;
                }
                if p == period {
                    period = (2 * period).min(initial_period);
                }
            } else if initial_phase && p > period / 2 {
                initial_phase = false;
                p = 0;
                t *= 0.75;
            }
            p += 1;
        }
        period /= 2;
        t *= 0.5;
    }
    best.iterations = its;
    best
}

/// α-nearness candidate lists on the symmetric transform: for every node of the 2n-node
/// problem, its `k` non-fixed neighbours with the smallest α (the increase of the minimum
/// 1-tree forced to contain the edge), ties broken by penalised cost then index.
///
/// α(u, v) = c_π(u, v) − β(u, v), with β the largest penalised edge on the tree path from u to
/// v (α = 0 for tree edges). The special node's edges use the larger of its two tree edges
/// as β. Fixed edges are always in the tour and are not listed.
///
/// # Errors
/// [`TspError::InvalidConfig`] for `k = 0` or a `pi` of the wrong length.
pub fn alpha_candidates(m: &CostMatrix, pi: &[f64], k: usize) -> Result<Vec<Vec<usize>>> {
    let n = m.len();
    if k == 0 || pi.len() != 2 * n {
        return Err(TspError::InvalidConfig {
            what: "alpha candidates",
            reason: "need k ≥ 1 and 2n penalties",
        });
    }
    let big_n = 2 * n;
    let tree = one_tree(&Dense::new(m), pi);
    let cost = |u: usize, v: usize| match edge(m, n, u, v) {
        Some(Some(c)) => Some(c + pi[u] + pi[v]),
        _ => None,
    };
    // Order the spanning tree (rooted at node n) so that parents come before children.
    let mut children = vec![Vec::new(); big_n];
    for v in 1..big_n {
        if tree.parent[v] != usize::MAX {
            children[tree.parent[v]].push(v);
        }
    }
    let mut order = vec![n];
    let mut i = 0;
    while i < order.len() {
        let u = order[i];
        order.extend(children[u].iter().copied());
        i += 1;
    }
    let edge_w = |v: usize| -> f64 {
        let p = tree.parent[v];
        cost(v, p).unwrap_or(f64::NEG_INFINITY)
    };
    let special_beta = tree
        .special
        .iter()
        .filter(|&&v| v != usize::MAX)
        .filter_map(|&v| cost(0, v))
        .fold(f64::NEG_INFINITY, f64::max);
    let mut out = vec![Vec::new(); big_n];
    let mut beta = vec![f64::NEG_INFINITY; big_n];
    for u in 1..big_n {
        // β(u, ·) by walking the tree from u: first up the path to the root, then down.
        beta.fill(f64::NEG_INFINITY);
        // Max edge from u up to each ancestor.
        let mut mark = vec![false; big_n];
        let (mut v, mut cur) = (u, f64::NEG_INFINITY);
        mark[u] = true;
        while tree.parent[v] != usize::MAX {
            cur = cur.max(edge_w(v));
            v = tree.parent[v];
            beta[v] = cur;
            mark[v] = true;
        }
        beta[u] = f64::NEG_INFINITY;
        // Every other node: max over its path to its first marked ancestor.
        for &w in &order {
            if !mark[w] {
                let p = tree.parent[w];
                beta[w] = beta[p].max(edge_w(w));
            }
        }
        let cands: Vec<(f64, f64, usize)> = (0..big_n)
            .filter(|&v| v != u)
            .filter_map(|v| {
                let c = cost(u, v)?;
                let b = if v == 0 { special_beta } else { beta[v] };
                Some(((c - b).max(0.0), c, v))
            })
            .collect();
        out[u] = smallest(cands, k);
    }
    // The special node: α = c − (larger special edge).
    let cands: Vec<(f64, f64, usize)> = (n + 1..big_n)
        .filter_map(|v| cost(0, v).map(|c| ((c - special_beta).max(0.0), c, v)))
        .collect();
    out[0] = smallest(cands, k);
    Ok(out)
}

/// The nodes of the `k` smallest (α, cost, node) triples, in increasing order (the order is
/// total, so selecting before sorting gives the same lists as a full sort).
fn smallest(mut cands: Vec<(f64, f64, usize)>, k: usize) -> Vec<usize> {
    let cmp = |a: &(f64, f64, usize), b: &(f64, f64, usize)| {
        a.0.total_cmp(&b.0)
            .then(a.1.total_cmp(&b.1))
            .then(a.2.cmp(&b.2))
    };
    if k < cands.len() {
        cands.select_nth_unstable_by(k, cmp);
        cands.truncate(k);
    }
    cands.sort_by(cmp);
    cands.into_iter().map(|c| c.2).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::exact::held_karp;
    use proptest::prelude::*;

    fn matrix(n: usize, seed: u64) -> CostMatrix {
        crate::test_util::random_matrix(n, seed, 1000)
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]

        /// The bound never exceeds the optimum, and is exact when the 1-tree is a tour.
        #[test]
        fn bound_is_below_the_optimum(n in 3usize..=10, seed in any::<u64>()) {
            let m = matrix(n, seed);
            let lb = held_karp_bound(&m, &BoundConfig::default()).unwrap();
            let opt = held_karp(&m).unwrap().length;
            prop_assert!(lb.lower_bound <= opt + 1e-6 * opt.max(1.0), "bound {} > optimum {opt}", lb.lower_bound);
            if lb.tree_is_tour {
                prop_assert!((lb.lower_bound - opt).abs() <= 1e-6 * opt.max(1.0));
            }
            // The subgradient ascent lifts the bound well above the plain 1-tree.
            let plain = one_tree(&Dense::new(&m), &vec![0.0; 2 * n]).cost;
            prop_assert!(lb.lower_bound >= plain - 1e-9);
        }

        /// An optimal tour's arcs are among the α candidates (k = 8) in nearly every case.
        #[test]
        fn optimal_arcs_are_candidates(n in 5usize..=10, seed in any::<u64>()) {
            let m = matrix(n, seed);
            let lb = held_karp_bound(&m, &BoundConfig::default()).unwrap();
            let cands = alpha_candidates(&m, &lb.pi, 8).unwrap();
            let opt = held_karp(&m).unwrap();
            let mut missing = 0;
            for w in 0..n {
                let (i, j) = (opt.order[w], opt.order[(w + 1) % n]);
                // Arc i → j is the edge between twin n + i and city j.
                if !cands[n + i].contains(&j) && !cands[j].contains(&(n + i)) {
                    missing += 1;
                }
            }
            prop_assert!(missing <= 1, "{missing} optimal arcs missing from the candidates");
        }
    }

    #[test]
    fn small_and_bad_input() {
        let m = matrix(2, 1);
        let lb = held_karp_bound(&m, &BoundConfig::default()).unwrap();
        assert_eq!(lb.lower_bound, m.closed_length(&[0, 1]));
        let bad = BoundConfig {
            initial_step: f64::NAN,
            ..BoundConfig::default()
        };
        assert!(held_karp_bound(&m, &bad).is_err());
        assert!(alpha_candidates(&m, &[0.0; 3], 5).is_err());
        assert!(alpha_candidates(&m, &[0.0; 4], 0).is_err());
    }
}
