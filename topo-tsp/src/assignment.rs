//! The assignment-problem relaxation of the ATSP: a minimum-cost set of disjoint cycles covering
//! every city (no self-loops), solved by shortest augmenting paths with potentials (the
//! Hungarian method, O(n³)), and Karp's patching of its cycles into a tour.
//!
//! Its value is a lower bound on the tour length, tight on many asymmetric instances whose
//! Held–Karp ascent converges slowly; its reduced costs rank the arcs the way α-nearness ranks
//! them on the symmetric transform.

use crate::matrix::CostMatrix;

/// An optimal assignment: the successor of every city, the total cost and the dual potentials
/// (row `u`, column `v`), so that c(i, j) − u\[i\] − v\[j\] ≥ 0 with equality on assigned arcs.
pub(crate) struct Assignment {
    pub(crate) succ: Vec<usize>,
    pub(crate) cost: f64,
    pub(crate) u: Vec<f64>,
    pub(crate) v: Vec<f64>,
}

impl Assignment {
    /// The reduced cost of arc (i, j).
    pub(crate) fn reduced(&self, m: &CostMatrix, i: usize, j: usize) -> f64 {
        m.cost(i, j) - self.u[i] - self.v[j]
    }
}

/// Solves the assignment problem on `m` without self-loops; `None` for n < 2.
pub(crate) fn assignment(m: &CostMatrix) -> Option<Assignment> {
    let n = m.len();
    if n < 2 {
        return None;
    }
    let c = |i: usize, j: usize| if i == j { f64::INFINITY } else { m.cost(i, j) };
    // 1-based rows and columns; row 0 / column 0 are the virtual start of each augmentation.
    let mut u = vec![0.0; n + 1];
    let mut v = vec![0.0; n + 1];
    let mut p = vec![0usize; n + 1]; // p[j]: row assigned to column j
    let mut way = vec![0usize; n + 1];
    let mut minv = vec![f64::INFINITY; n + 1];
    let mut used = vec![false; n + 1];
    for i in 1..=n {
        p[0] = i;
        let mut j0 = 0;
        minv.fill(f64::INFINITY);
        used.fill(false);
        loop {
            used[j0] = true;
            let i0 = p[j0];
            let mut delta = f64::INFINITY;
            let mut j1 = 0;
            for j in 1..=n {
                if !used[j] {
                    let cur = c(i0 - 1, j - 1) - u[i0] - v[j];
                    if cur < minv[j] {
                        minv[j] = cur;
                        way[j] = j0;
                    }
                    if minv[j] < delta {
                        delta = minv[j];
                        j1 = j;
                    }
                }
            }
            if j1 == 0 {
                // No finite augmenting path (cannot happen for n ≥ 2); give up cleanly.
                return None;
            }
            for j in 0..=n {
                if used[j] {
                    u[p[j]] += delta;
                    v[j] -= delta;
                } else {
                    minv[j] -= delta;
                }
            }
            j0 = j1;
            if p[j0] == 0 {
                break;
            }
        }
        loop {
            let j1 = way[j0];
            p[j0] = p[j1];
            j0 = j1;
            if j0 == 0 {
                break;
            }
        }
    }
    let mut succ = vec![0; n];
    for j in 1..=n {
        succ[p[j] - 1] = j - 1;
    }
    let cost = (0..n).map(|i| m.cost(i, succ[i])).sum();
    Some(Assignment {
        succ,
        cost,
        u: u[1..].to_vec(),
        v: v[1..].to_vec(),
    })
}

/// Karp's patching: merges the cycles of `succ` into one tour, each time joining the smallest
/// cycle to another by the exchange of two arcs (a→a', b→b' ⇒ a→b', b→a') of least cost
/// increase. Returns the tour as a successor array.
pub(crate) fn patch(m: &CostMatrix, succ: &[usize]) -> Vec<usize> {
    let n = succ.len();
    let mut succ = succ.to_vec();
    let mut cycle = vec![usize::MAX; n];
    loop {
        // Label the cycles.
        cycle.fill(usize::MAX);
        let mut sizes = Vec::new();
        for s in 0..n {
            if cycle[s] != usize::MAX {
                continue;
            }
            let id = sizes.len();
            let (mut x, mut len) = (s, 0);
            while cycle[x] == usize::MAX {
                cycle[x] = id;
                len += 1;
                x = succ[x];
            }
            sizes.push(len);
        }
        if sizes.len() <= 1 {
            return succ;
        }
        let small = (0..sizes.len()).min_by_key(|&k| sizes[k]).unwrap_or(0);
        let mut best: Option<(f64, usize, usize)> = None;
        for a in (0..n).filter(|&a| cycle[a] == small) {
            let a2 = succ[a];
            for b in (0..n).filter(|&b| cycle[b] != small) {
                let b2 = succ[b];
                let d = m.cost(a, b2) + m.cost(b, a2) - m.cost(a, a2) - m.cost(b, b2);
                if best.is_none_or(|x| d < x.0) {
                    best = Some((d, a, b));
                }
            }
        }
        let Some((_, a, b)) = best else { return succ };
        let (a2, b2) = (succ[a], succ[b]);
        succ[a] = b2;
        succ[b] = a2;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::exact::held_karp;

    #[test]
    fn assignment_is_a_lower_bound_and_patching_gives_a_tour() {
        for seed in 0..40 {
            let n = 3 + (seed as usize % 9);
            let m = crate::test_util::random_matrix(n, seed, 1000);
            let a = assignment(&m).unwrap();
            let opt = held_karp(&m).unwrap().length;
            assert!(a.cost <= opt + 1e-9, "{} > {opt}", a.cost);
            // Dual feasibility and complementary slackness.
            for i in 0..n {
                assert!(a.reduced(&m, i, a.succ[i]).abs() < 1e-6);
                for j in (0..n).filter(|&j| j != i) {
                    assert!(a.reduced(&m, i, j) > -1e-6);
                }
            }
            let s = patch(&m, &a.succ);
            let (mut x, mut len) = (0, 0);
            loop {
                x = s[x];
                len += 1;
                if x == 0 {
                    break;
                }
            }
            assert_eq!(len, n);
        }
        assert!(assignment(&crate::test_util::random_matrix(1, 1, 10)).is_none());
    }
}
