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
//! deg(v) − 2, raises w toward the Held–Karp bound. The step follows Polyak's rule toward an
//! upper bound from a nearest-neighbour tour, halving its factor when the bound stalls.

use crate::error::{Result, TspError};
use crate::matrix::CostMatrix;

/// Settings of the Held–Karp bound computation.
#[derive(Debug, Clone, Copy, PartialEq)]
#[non_exhaustive]
pub struct BoundConfig {
    /// Maximum subgradient iterations. Default 300.
    pub max_iterations: usize,
    /// Initial Polyak step factor λ (0, 2]. Default 2.
    pub initial_step: f64,
    /// Iterations without improvement before λ halves. Default 20.
    pub patience: usize,
    /// Stop when λ falls below this. Default 1e-6.
    pub min_step: f64,
}

impl Default for BoundConfig {
    fn default() -> Self {
        Self {
            max_iterations: 300,
            initial_step: 2.0,
            patience: 20,
            min_step: 1e-6,
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

/// A minimum 1-tree: parent of every node in the spanning tree rooted at node 1 (node 0 is the
/// special node), the special node's two edges, degrees and the penalised cost.
struct OneTree {
    parent: Vec<usize>,
    special: [usize; 2],
    degree: Vec<i64>,
    cost: f64,
}

/// Sort key of an edge for the tree algorithms: fixed edges before all others.
#[inline]
fn key(e: Option<f64>, pu: f64, pv: f64) -> (bool, f64) {
    match e {
        None => (false, 0.0),
        Some(c) => (true, c + pu + pv),
    }
}

fn less(a: (bool, f64), b: (bool, f64)) -> bool {
    (a.0, a.1) < (b.0, b.1)
}

/// Prim's algorithm on nodes 1..2n, then the two cheapest edges of node 0.
///
/// Every fixed edge (i, n + i) is in every minimum 1-tree, so the spanning tree is computed on
/// the n "super-nodes" {i, n + i} (i ≥ 1) and {n} (city 0 is the special node), joining two
/// super-nodes by the cheaper of their two real edges: O(n²) instead of O((2n)²). The tree is
/// then written back in terms of the 2n nodes, rooted at node n.
fn one_tree(m: &CostMatrix, pi: &[f64]) -> OneTree {
    let n = m.len();
    let big_n = 2 * n;
    let mut parent = vec![usize::MAX; big_n];
    let mut degree = vec![0i64; big_n];
    let mut cost = 0.0;
    // The cheapest real edge between super-nodes a and b, as (cost, node in a, node in b).
    let link = |a: usize, b: usize| -> (f64, usize, usize) {
        // Twin of a → city b, when a has a twin in the tree part (always) and b is a city pair.
        let ab = m.cost(a, b) + pi[n + a] + pi[b];
        if a == 0 {
            return (ab, n, b);
        }
        let ba = m.cost(b, a) + pi[n + b] + pi[a];
        if ba < ab {
            (ba, a, n + b)
        } else {
            (ab, n + a, b)
        }
    };
    let mut in_tree = vec![false; n];
    let mut best = vec![(f64::INFINITY, usize::MAX, usize::MAX); n];
    in_tree[0] = true;
    for b in 1..n {
        best[b] = link(0, b);
    }
    for _ in 1..n {
        // The closest super-node not yet in the tree (ties by index: deterministic).
        let mut u = usize::MAX;
        for v in 1..n {
            if !in_tree[v] && (u == usize::MAX || best[v].0 < best[u].0) {
                u = v;
            }
        }
        if u == usize::MAX {
            break;
        }
        in_tree[u] = true;
        let (c, from, to) = best[u];
        cost += c;
        parent[to] = from;
        // The partner of `to` hangs below it on the fixed edge.
        let partner = if to < n { to + n } else { to - n };
        parent[partner] = to;
        degree[from] += 1;
        degree[to] += 1;
        for v in 1..n {
            if !in_tree[v] {
                let cand = link(u, v);
                if cand.0 < best[v].0 {
                    best[v] = cand;
                }
            }
        }
    }
    // Fixed edges of the pairs.
    for i in 1..n {
        degree[i] += 1;
        degree[n + i] += 1;
    }
    // Special node 0: its fixed edge to twin n and its cheapest other edge.
    let mut second = (usize::MAX, (true, f64::INFINITY));
    for v in n + 1..big_n {
        if let Some(e) = edge(m, n, 0, v) {
            let k = key(e, pi[0], pi[v]);
            if less(k, second.1) {
                second = (v, k);
            }
        }
    }
    let special = [n, second.0];
    degree[0] += 2;
    degree[n] += 1;
    if second.0 != usize::MAX {
        degree[second.0] += 1;
        cost += second.1.1;
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

/// A nearest-neighbour closed tour from city 0 (an upper bound for the step rule).
fn nearest_neighbour_length(m: &CostMatrix) -> f64 {
    let n = m.len();
    let mut seen = vec![false; n];
    let (mut cur, mut total) = (0, 0.0);
    seen[0] = true;
    for _ in 1..n {
        let mut next = usize::MAX;
        for j in 0..n {
            if !seen[j] && (next == usize::MAX || m.cost(cur, j) < m.cost(cur, next)) {
                next = j;
            }
        }
        seen[next] = true;
        total += m.cost(cur, next);
        cur = next;
    }
    total + m.cost(cur, 0)
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
    if cfg.max_iterations == 0
        || !(cfg.initial_step > 0.0 && cfg.initial_step <= 2.0)
        || cfg.min_step.is_nan()
        || cfg.min_step <= 0.0
    {
        return Err(TspError::InvalidConfig {
            what: "bound settings",
            reason: "need max_iterations ≥ 1, 0 < initial_step ≤ 2, min_step > 0",
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
    let upper = nearest_neighbour_length(m);
    let mut pi = vec![0.0; 2 * n];
    let mut best = HeldKarpBound {
        lower_bound: f64::NEG_INFINITY,
        pi: pi.clone(),
        iterations: 0,
        tree_is_tour: false,
    };
    let (mut lambda, mut stall) = (cfg.initial_step, 0);
    for it in 0..cfg.max_iterations {
        let tree = one_tree(m, &pi);
        let w = tree.cost - 2.0 * pi.iter().sum::<f64>();
        let g2: i64 = tree.degree.iter().map(|d| (d - 2) * (d - 2)).sum();
        best.iterations = it + 1;
        if w > best.lower_bound + 1e-12 * w.abs().max(1.0) {
            best.lower_bound = w;
            best.pi.clone_from(&pi);
            best.tree_is_tour = g2 == 0;
            stall = 0;
        } else {
            stall += 1;
            if stall >= cfg.patience {
                lambda *= 0.5;
                stall = 0;
            }
        }
        if g2 == 0 || lambda < cfg.min_step {
            break;
        }
        // Polyak step toward the upper bound.
        let t = lambda * (upper - w).max(1e-9 * upper.abs().max(1.0)) / g2 as f64;
        for (p, d) in pi.iter_mut().zip(&tree.degree) {
            *p += t * (*d - 2) as f64;
        }
    }
    Ok(best)
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
    let tree = one_tree(m, pi);
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
        let mut cands: Vec<(f64, f64, usize)> = (0..big_n)
            .filter(|&v| v != u)
            .filter_map(|v| {
                let c = cost(u, v)?;
                let b = if v == 0 { special_beta } else { beta[v] };
                Some(((c - b).max(0.0), c, v))
            })
            .collect();
        cands.sort_by(|a, b| {
            a.0.total_cmp(&b.0)
                .then(a.1.total_cmp(&b.1))
                .then(a.2.cmp(&b.2))
        });
        out[u] = cands.into_iter().take(k).map(|c| c.2).collect();
    }
    // The special node: α = c − (larger special edge).
    let mut cands: Vec<(f64, f64, usize)> = (n + 1..big_n)
        .filter_map(|v| cost(0, v).map(|c| ((c - special_beta).max(0.0), c, v)))
        .collect();
    cands.sort_by(|a, b| {
        a.0.total_cmp(&b.0)
            .then(a.1.total_cmp(&b.1))
            .then(a.2.cmp(&b.2))
    });
    out[0] = cands.into_iter().take(k).map(|c| c.2).collect();
    Ok(out)
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
            let plain = one_tree(&m, &vec![0.0; 2 * n]).cost;
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
            initial_step: 3.0,
            ..BoundConfig::default()
        };
        assert!(held_karp_bound(&m, &bad).is_err());
        assert!(alpha_candidates(&m, &[0.0; 3], 5).is_err());
        assert!(alpha_candidates(&m, &[0.0; 4], 0).is_err());
    }
}
