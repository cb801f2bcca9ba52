//! Exact K nearest neighbours of every point of a cloud, on a uniform grid.
//!
//! Every point of the cloud is also a query, so a grid over the cloud's own bounding box
//! answers them faster than a k-d tree: the points of the 27 cells around a cell are gathered
//! once, and each point of the cell takes its K nearest among them with no branch per
//! candidate; when a point outside those cells could be nearer than its K-th, the query walks
//! shells of cells around its own until its K-th nearest point is closer than any cell not yet
//! walked. The neighbours are the K smallest (squared distance, index) pairs, so ties are
//! broken by index and the answer does not depend on the order the cells are walked in.

use rayon::prelude::*;

/// Grid cells per parallel task of [`map_neighbours`].
const CELL_CHUNK: usize = 256;

/// Buffers of one thread's cell queries.
#[derive(Default)]
struct Scratch {
    /// The 27-cell neighbourhood's points (structure of arrays) and indices.
    xs: Vec<f64>,
    ys: Vec<f64>,
    zs: Vec<f64>,
    ids: Vec<usize>,
    d2: Vec<f64>,
    /// Candidates within the threshold: (bits of d², index).
    sel: Vec<(u64, usize)>,
    best: Vec<(f64, usize)>,
    idx: Vec<usize>,
}

/// The grid: points sorted by cell, and where each cell's points start.
struct Grid {
    lo: [f64; 3],
    inv_cell: f64,
    cell: f64,
    /// 1e-9 of the coordinates' magnitude: the stopping test's margin for rounding.
    margin: f64,
    dims: [usize; 3],
    /// `starts[c]..starts[c + 1]` are cell c's entries of `order`.
    starts: Vec<usize>,
    /// Point indices in cell order.
    order: Vec<usize>,
    /// The points in cell order (a copy, so a cell's points are contiguous in memory).
    sorted: Vec<[f64; 3]>,
}

impl Grid {
    /// A grid whose cells hold about one point per cell of the bounding box's volume: for the
    /// surfaces LiDAR clouds are made of, a cell is then about as wide as the distance to the
    /// tenth neighbour. At most 8n + 64 cells (wider cells otherwise).
    fn new(points: &[[f64; 3]]) -> Self {
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        for p in points {
            for d in 0..3 {
                lo[d] = lo[d].min(p[d]);
                hi[d] = hi[d].max(p[d]);
            }
        }
        let ext = [hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]];
        let largest = ext.iter().copied().fold(0.0, f64::max);
        // Counts are far below 2^53.
        #[allow(clippy::cast_precision_loss)]
        let n = points.len() as f64;
        let mut cell = if largest > 0.0 {
            // A flat cloud still gets cells of finite size: each extent floored at 1e-3 of
            // the largest.
            let v: f64 = ext.iter().map(|e| e.max(1e-3 * largest)).product();
            (v / n).cbrt()
        } else {
            1.0
        };
        if !(cell.is_finite() && cell > 0.0) {
            // A volume that underflows (extents near 1e-200) or overflows: one cell as wide
            // as the cloud, or a unit cell.
            cell = if largest.is_finite() && largest > 0.0 {
                largest
            } else {
                1.0
            };
        }
        let max_cells = 8.0 * n + 64.0;
        let mut dims = [1usize; 3];
        for _ in 0..64 {
            let count = |e: f64| (e / cell).floor() + 1.0;
            let total = count(ext[0]) * count(ext[1]) * count(ext[2]);
            if total <= max_cells {
                for d in 0..3 {
                    // At most 8n + 64 cells in all, so each count fits.
                    #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
                    let c = count(ext[d]) as usize;
                    dims[d] = c;
                }
                break;
            }
            cell *= (total / max_cells).cbrt().max(1.01);
        }
        let inv_cell = 1.0 / cell;
        let magnitude = lo.iter().chain(&hi).fold(0.0f64, |m, v| m.max(v.abs()));
        let mut grid = Self {
            lo,
            inv_cell,
            cell,
            margin: 1e-9 * (1.0 + magnitude),
            dims,
            starts: Vec::new(),
            order: Vec::new(),
            sorted: Vec::new(),
        };
        // Counting sort by cell.
        let total = dims[0] * dims[1] * dims[2];
        let cells: Vec<usize> = points.iter().map(|p| grid.cell_index(p)).collect();
        let mut starts = vec![0usize; total + 1];
        for &c in &cells {
            starts[c + 1] += 1;
        }
        for c in 0..total {
            starts[c + 1] += starts[c];
        }
        let mut next = starts.clone();
        let mut order = vec![0usize; points.len()];
        for (i, &c) in cells.iter().enumerate() {
            order[next[c]] = i;
            next[c] += 1;
        }
        grid.sorted = order.iter().map(|&i| points[i]).collect();
        grid.starts = starts;
        grid.order = order;
        grid
    }

    /// The cell coordinates of a point (clamped into the grid).
    fn coords(&self, p: &[f64; 3]) -> [usize; 3] {
        let mut c = [0usize; 3];
        for d in 0..3 {
            // Non-negative and below dims[d] after the clamp; the cast saturates anyway.
            #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
            let x = ((p[d] - self.lo[d]) * self.inv_cell).floor().max(0.0) as usize;
            c[d] = x.min(self.dims[d] - 1);
        }
        c
    }

    fn cell_index(&self, p: &[f64; 3]) -> usize {
        let c = self.coords(p);
        (c[2] * self.dims[1] + c[1]) * self.dims[0] + c[0]
    }

    /// The K nearest points to `q` into `best`, sorted by
    /// (squared distance, index); `k` ≤ the number of points.
    fn query(&self, q: &[f64; 3], k: usize, best: &mut Vec<(f64, usize)>) {
        best.clear();
        let c = self.coords(q);
        let dims = self.dims;
        // Signed coordinates: the cell counts are at most 8n + 64, far below i64::MAX.
        #[allow(clippy::cast_possible_wrap)]
        let (ci, dimi) = (
            [c[0] as i64, c[1] as i64, c[2] as i64],
            [dims[0] as i64, dims[1] as i64, dims[2] as i64],
        );
        let mut r: i64 = 0;
        loop {
            let z0 = (ci[2] - r).max(0);
            let z1 = (ci[2] + r).min(dimi[2] - 1);
            let y0 = (ci[1] - r).max(0);
            let y1 = (ci[1] + r).min(dimi[1] - 1);
            for z in z0..=z1 {
                let gz = self.gap2(q, 2, z);
                if self.beyond(best, k, gz) {
                    continue;
                }
                let z_shell = (z - ci[2]).abs() == r;
                for y in y0..=y1 {
                    let gzy = gz + self.gap2(q, 1, y);
                    if self.beyond(best, k, gzy) {
                        continue;
                    }
                    // The indices are in the grid here, so the casts are exact.
                    #[allow(clippy::cast_sign_loss, clippy::cast_possible_truncation)]
                    let row = (z as usize * dims[1] + y as usize) * dims[0];
                    let mut visit = |x: i64| {
                        if self.beyond(best, k, gzy + self.gap2(q, 0, x)) {
                            return;
                        }
                        #[allow(clippy::cast_sign_loss, clippy::cast_possible_truncation)]
                        let cell = row + x as usize;
                        let (a, b) = (self.starts[cell], self.starts[cell + 1]);
                        self.scan(q, k, a, b, best);
                    };
                    if z_shell || (y - ci[1]).abs() == r {
                        // A whole row of the shell's faces.
                        for x in (ci[0] - r).max(0)..=(ci[0] + r).min(dimi[0] - 1) {
                            visit(x);
                        }
                    } else {
                        // Inside the faces only the two x ends are new.
                        for x in [ci[0] - r, ci[0] + r] {
                            if x >= 0 && x < dimi[0] {
                                visit(x);
                            }
                        }
                    }
                }
            }
            let bound = self.block_bound(q, ci, r);
            if bound == f64::INFINITY {
                return;
            }
            // With K found and the K-th nearer than any cell not walked (less a margin far
            // above the rounding of the cell coordinates), no other point can enter.
            if best.len() == k {
                let worst = best[k - 1].0;
                let b = bound - self.margin;
                if b > 0.0 && worst < b * b {
                    return;
                }
            }
            r += 1;
        }
    }

    /// `f` of the K nearest neighbours of each point of cell `c`, in the grid's order.
    fn cell_queries<T, F>(&self, c: usize, k: usize, s: &mut Scratch, f: &F) -> Vec<T>
    where
        F: Fn(&[usize]) -> T,
    {
        let (a, b) = (self.starts[c], self.starts[c + 1]);
        if a == b {
            return Vec::new();
        }
        let dims = self.dims;
        let cx = c % dims[0];
        let cy = (c / dims[0]) % dims[1];
        let cz = c / (dims[0] * dims[1]);
        s.xs.clear();
        s.ys.clear();
        s.zs.clear();
        s.ids.clear();
        let (x0, x1) = (cx.saturating_sub(1), (cx + 1).min(dims[0] - 1));
        for z in cz.saturating_sub(1)..=(cz + 1).min(dims[2] - 1) {
            for y in cy.saturating_sub(1)..=(cy + 1).min(dims[1] - 1) {
                let row = (z * dims[1] + y) * dims[0];
                let (ra, rb) = (self.starts[row + x0], self.starts[row + x1 + 1]);
                for p in &self.sorted[ra..rb] {
                    s.xs.push(p[0]);
                    s.ys.push(p[1]);
                    s.zs.push(p[2]);
                }
                s.ids.extend_from_slice(&self.order[ra..rb]);
            }
        }
        let m = s.ids.len();
        s.d2.resize(m, 0.0);
        // One slot more than the candidates: the compaction writes before it counts.
        s.sel.resize(m + 1, (0, 0));
        // Cell coordinates are far below i64::MAX.
        #[allow(clippy::cast_possible_wrap)]
        let ci = [cx as i64, cy as i64, cz as i64];
        let mut out = Vec::with_capacity(b - a);
        // The threshold starts at a quarter cell and then follows the last K-th distance.
        let mut tau = 0.25 * self.cell * self.cell;
        for q in &self.sorted[a..b] {
            for (((d, x), y), z) in s.d2.iter_mut().zip(&s.xs).zip(&s.ys).zip(&s.zs) {
                let (dx, dy, dz) = (x - q[0], y - q[1], z - q[2]);
                *d = dx * dx + dy * dy + dz * dz;
            }
            // The candidates within τ, τ growing until there are K of them (all m if
            // fewer); then the K smallest (d², index) of those.
            let mut found = m >= k;
            if found {
                let mut n;
                loop {
                    // Branch-free compaction of the candidates within τ. Squared distances
                    // are non-negative (never −0.0), so their bit patterns sort as the
                    // numbers do: (bits, index) pairs sort as (d², index).
                    n = 0;
                    for (d, &i) in s.d2.iter().zip(&s.ids) {
                        s.sel[n] = (d.to_bits(), i);
                        n += usize::from(*d <= tau);
                    }
                    if n >= k || tau == f64::INFINITY {
                        break;
                    }
                    tau = if tau > 0.0 {
                        tau * 4.0
                    } else {
                        self.cell * self.cell
                    };
                    // A NaN or non-positive threshold (cells of extreme size) would never
                    // grow: take every candidate instead.
                    if !(tau > 0.0 && tau <= 1e300) {
                        tau = f64::INFINITY;
                    }
                }
                // The K smallest in front, the K-th at k − 1: the neighbours need no order.
                let sel = &mut s.sel[..n];
                sel.select_nth_unstable(k - 1);
                let kth = f64::from_bits(sel[k - 1].0);
                // Exact only if no point outside the 27 cells can be nearer.
                let bound = self.block_bound(q, ci, 1) - self.margin;
                found = bound == f64::INFINITY || (bound > 0.0 && kth < bound * bound);
                tau = kth * 1.3;
            }
            s.idx.clear();
            if found {
                s.idx.extend(s.sel[..k].iter().map(|&(_, j)| j));
            } else {
                self.query(q, k, &mut s.best);
                s.idx.extend(s.best.iter().map(|&(_, j)| j));
            }
            out.push(f(&s.idx));
        }
        out
    }

    /// Distance from `q` to the nearest face, with cells beyond it, of the block of cells
    /// within `r` of cell `ci`; infinite when the block covers the grid.
    fn block_bound(&self, q: &[f64; 3], ci: [i64; 3], r: i64) -> f64 {
        let mut bound = f64::INFINITY;
        for d in 0..3 {
            // Grid coordinates are far below 2^53; dims are far below i64::MAX.
            #[allow(clippy::cast_precision_loss, clippy::cast_possible_wrap)]
            {
                if ci[d] - r > 0 {
                    let face = self.lo[d] + (ci[d] - r) as f64 * self.cell;
                    bound = bound.min(q[d] - face);
                }
                if ci[d] + r < self.dims[d] as i64 - 1 {
                    let face = self.lo[d] + (ci[d] + r + 1) as f64 * self.cell;
                    bound = bound.min(face - q[d]);
                }
            }
        }
        bound
    }

    /// The squared gap along axis `d` between `q` and the slab of cells with coordinate `c`,
    /// less the rounding margin: no point of those cells is nearer along that axis.
    #[inline]
    fn gap2(&self, q: &[f64; 3], d: usize, c: i64) -> f64 {
        // Grid coordinates are far below 2^53.
        #[allow(clippy::cast_precision_loss)]
        let (a, b) = (
            self.lo[d] + c as f64 * self.cell,
            self.lo[d] + (c + 1) as f64 * self.cell,
        );
        let gap = (a - q[d]).max(q[d] - b) - self.margin;
        if gap > 0.0 { gap * gap } else { 0.0 }
    }

    /// Whether cells at squared distance `g2` cannot hold a neighbour: K found, all nearer.
    #[inline]
    fn beyond(&self, best: &[(f64, usize)], k: usize, g2: f64) -> bool {
        best.len() == k && g2 > best[k - 1].0
    }

    /// Offers the sorted entries `a..b` to `best`.
    fn scan(&self, q: &[f64; 3], k: usize, a: usize, b: usize, best: &mut Vec<(f64, usize)>) {
        for (p, &i) in self.sorted[a..b].iter().zip(&self.order[a..b]) {
            let (dx, dy, dz) = (p[0] - q[0], p[1] - q[1], p[2] - q[2]);
            let d2 = dx * dx + dy * dy + dz * dz;
            if best.len() == k {
                let (wd, wi) = best[k - 1];
                if d2 > wd || (d2 == wd && i > wi) {
                    continue;
                }
                best.pop();
            }
            // Insertion keeps `best` sorted by (d², index); K is small.
            best.push((d2, i));
            let mut at = best.len() - 1;
            while at > 0 {
                let (pd, pi) = best[at - 1];
                if pd < d2 || (pd == d2 && pi < i) {
                    break;
                }
                best[at] = best[at - 1];
                at -= 1;
            }
            best[at] = (d2, i);
        }
    }
}

/// Applies `f` to each point's K nearest neighbours (itself included; ties in distance go to
/// the lower index; the indices in no particular order, the same on every run) and returns
/// the results in point order. K is capped at the
/// number of points; `k = 0` or an empty cloud gives `f(&[])` per point. The points must be
/// finite. Runs on rayon's threads in fixed chunks: the result does not depend on the thread
/// count.
pub(crate) fn map_neighbours<T, F>(points: &[[f64; 3]], k: usize, f: F) -> Vec<T>
where
    T: Send,
    F: Fn(&[usize]) -> T + Sync,
{
    let k = k.min(points.len());
    if k == 0 {
        return points.iter().map(|_| f(&[])).collect();
    }
    let grid = Grid::new(points);
    let cells = grid.dims[0] * grid.dims[1] * grid.dims[2];
    // Cell by cell: the points of the 27 cells around a cell are gathered once, and each
    // of its points takes its K nearest among them with no branch per candidate.
    let per_cell: Vec<Vec<T>> = (0..cells)
        .into_par_iter()
        .with_min_len(CELL_CHUNK)
        .map_init(Scratch::default, |s, c| grid.cell_queries(c, k, s, &f))
        .collect();
    let in_cell_order = per_cell.into_iter().flatten();
    let mut slots: Vec<Option<T>> = (0..points.len()).map(|_| None).collect();
    for (&i, t) in grid.order.iter().zip(in_cell_order) {
        slots[i] = Some(t);
    }
    slots.into_iter().flatten().collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn brute(points: &[[f64; 3]], k: usize) -> Vec<Vec<usize>> {
        points
            .iter()
            .map(|q| {
                let mut d: Vec<(f64, usize)> = points
                    .iter()
                    .enumerate()
                    .map(|(i, p)| {
                        let (dx, dy, dz) = (p[0] - q[0], p[1] - q[1], p[2] - q[2]);
                        (dx * dx + dy * dy + dz * dz, i)
                    })
                    .collect();
                d.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
                d.iter().take(k).map(|&(_, i)| i).collect()
            })
            .collect()
    }

    /// The neighbour set as sorted indices.
    fn sorted(v: &[usize]) -> Vec<usize> {
        let mut v = v.to_vec();
        v.sort_unstable();
        v
    }

    proptest! {
        /// The grid's neighbours are exactly the brute force's, ties by index included: points
        /// on a coarse lattice (many ties and duplicates), spread or flat.
        #[test]
        fn grid_neighbours_equal_brute_force(
            raw in proptest::collection::vec((0i32..12, 0i32..12, 0i32..12), 0..160),
            k in 0usize..14,
            scale in prop_oneof![Just(0.0), Just(0.01), Just(0.37), Just(5.0)],
            flat in any::<bool>(),
        ) {
            let points: Vec<[f64; 3]> = raw
                .iter()
                .map(|&(x, y, z)| {
                    let z = if flat { 0.0 } else { f64::from(z) * scale };
                    [f64::from(x) * scale, f64::from(y) * scale * 0.5, z]
                })
                .collect();
            let got = map_neighbours(&points, k, sorted);
            let want: Vec<Vec<usize>> =
                brute(&points, k.min(points.len())).iter().map(|v| sorted(v)).collect();
            prop_assert_eq!(got.len(), points.len());
            if k == 0 || points.is_empty() {
                prop_assert!(got.iter().all(Vec::is_empty));
            } else {
                prop_assert_eq!(got, want);
            }
        }

        /// Clustered clouds far apart: a query must walk many empty shells.
        #[test]
        fn distant_clusters_are_searched_through(
            a in proptest::collection::vec((-1.0f64..1.0, -1.0f64..1.0, -1.0f64..1.0), 1..30),
            b in proptest::collection::vec((-1.0f64..1.0, -1.0f64..1.0, -1.0f64..1.0), 1..30),
            k in 1usize..12,
        ) {
            let points: Vec<[f64; 3]> = a
                .iter()
                .map(|&(x, y, z)| [x, y, z])
                .chain(b.iter().map(|&(x, y, z)| [x + 90.0, y - 40.0, z * 0.01]))
                .collect();
            let got = map_neighbours(&points, k, sorted);
            let want: Vec<Vec<usize>> =
                brute(&points, k.min(points.len())).iter().map(|v| sorted(v)).collect();
            prop_assert_eq!(got, want);
        }
    }

    /// Clouds whose box volume underflows or whose extents overflow still get the exact
    /// neighbours (the cell size once came out NaN or zero and the search never ended).
    #[test]
    fn extreme_extents_end_with_the_exact_neighbours() {
        let clouds = [
            vec![
                [0.0, 0.0, 0.0],
                [1e-200, 0.0, 0.0],
                [0.0, 1e-200, 0.0],
                [0.0, 0.0, 1e-200],
            ],
            vec![[0.0; 3], [0.0; 3], [0.0; 3], [5e-324, 0.0, 0.0]],
            vec![
                [-1e308, 0.0, 0.0],
                [1e308, 1.0, 0.0],
                [0.0, -1e308, 2.0],
                [3.0, 1e308, 1e308],
            ],
            vec![
                [1e-160, 2e-160, 0.0],
                [3e-160, 0.0, 1e-160],
                [0.0, 0.0, 0.0],
                [1e-160; 3],
            ],
        ];
        for points in &clouds {
            for k in 1..=points.len() {
                let got = map_neighbours(points, k, sorted);
                let want: Vec<Vec<usize>> = brute(points, k).iter().map(|v| sorted(v)).collect();
                assert_eq!(got, want, "{points:?}, k = {k}");
            }
        }
    }
}
