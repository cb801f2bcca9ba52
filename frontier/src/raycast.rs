//! 3-D DDA ray traversal of the grid (Amanatides & Woo, "A fast voxel traversal algorithm
//! for ray tracing", 1987).

use nalgebra::Point3;

use crate::grid::{Cell, Grid};
use crate::map::{BLOCK_BITS, BLOCK_CELLS, BLOCK_MASK};

/// A DDA walk over the cells of a segment, one face-adjacent step at a time.
///
/// Both end points must be finite and inside the grid's bounds (points on the upper bound
/// belong to the last cell). The walk takes exactly one step per cell boundary between the two
/// end cells, so it always ends in the cell of the end point, even when rounding puts a
/// crossing a hair early or late. Outside that contract it still stays in the grid: finite
/// points outside the bounds walk between their clamped cells, and a point whose grid
/// coordinates are not finite gives a walk of the first cell alone.
pub(crate) struct Walk {
    /// Current cell, end cell, step direction, next crossing and crossing spacing, per axis.
    pub(crate) x: u32,
    pub(crate) y: u32,
    pub(crate) z: u32,
    end: [u32; 3],
    pub(crate) step: [i32; 3],
    tx: f64,
    ty: f64,
    tz: f64,
    dt: [f64; 3],
    remaining: u64,
}

impl Walk {
    /// The walk from `a` to `b`, standing in the cell of `a`.
    #[inline]
    pub(crate) fn new(grid: &Grid, a: &Point3<f64>, b: &Point3<f64>) -> Self {
        let ga = grid.grid_coords(a);
        let gb = grid.grid_coords(b);
        let start = grid.clamp_cell(ga);
        // NaN crossing times would step axes that are already in their end cell, out of the
        // grid.
        let finite = ga.iter().chain(gb.iter()).all(|v| v.is_finite());
        let end = if finite { grid.clamp_cell(gb) } else { start };
        let (s, e) = ([start.x, start.y, start.z], [end.x, end.y, end.z]);
        let d = gb - ga;
        let mut t = [f64::INFINITY; 3];
        let mut step = [0; 3];
        let mut dt = [0.0; 3];
        let mut remaining = 0;
        for k in 0..3 {
            remaining += u64::from(s[k].abs_diff(e[k]));
            if s[k] == e[k] {
                // An axis already in its end cell never steps.
                continue;
            }
            step[k] = if e[k] > s[k] { 1 } else { -1 };
            if d[k] == 0.0 {
                // Only reachable through clamping at the upper bound: take these steps first.
                t[k] = 0.0;
            } else {
                let boundary = if e[k] > s[k] { s[k] + 1 } else { s[k] };
                t[k] = (f64::from(boundary) - ga[k]) / d[k];
                dt[k] = 1.0 / d[k].abs();
            }
        }
        Self {
            x: s[0],
            y: s[1],
            z: s[2],
            end: e,
            step,
            tx: t[0],
            ty: t[1],
            tz: t[2],
            dt,
            remaining,
        }
    }

    /// The current cell.
    #[inline(always)]
    pub(crate) fn cell(&self) -> Cell {
        Cell::new(self.x, self.y, self.z)
    }

    /// Steps into the next cell and returns the axis it moved along, or `None` at the end.
    #[inline(always)]
    pub(crate) fn advance(&mut self) -> Option<usize> {
        if self.remaining == 0 {
            return None;
        }
        self.remaining -= 1;
        // Scalars per axis rather than arrays indexed by the axis keep the walk in registers.
        if self.tx <= self.ty && self.tx <= self.tz {
            self.x = self.x.wrapping_add_signed(self.step[0]);
            self.tx = if self.x == self.end[0] {
                f64::INFINITY
            } else {
                self.tx + self.dt[0]
            };
            Some(0)
        } else if self.ty <= self.tz {
            self.y = self.y.wrapping_add_signed(self.step[1]);
            self.ty = if self.y == self.end[1] {
                f64::INFINITY
            } else {
                self.ty + self.dt[1]
            };
            Some(1)
        } else {
            self.z = self.z.wrapping_add_signed(self.step[2]);
            self.tz = if self.z == self.end[2] {
                f64::INFINITY
            } else {
                self.tz + self.dt[2]
            };
            Some(2)
        }
    }
}

impl Walk {
    /// Sets, in `words`, the bit of every cell of the walk that lies in a block-major bitset:
    /// blocks of 8 × 8 × 8 cells counted from the block of `lo` (x fastest, `blocks` per row
    /// and per layer), `stride` words per block, the 64 bits of each z layer of a block in one
    /// word (x fastest, then y). Cells whose word falls outside `words` are skipped.
    ///
    /// The cells are those [`Walk::advance`] visits; the bit position is carried from cell to
    /// cell (one add per step, another when the step enters a new block) instead of being
    /// recomputed from the coordinates. Choosing the axis without branches, or cutting the
    /// segment into independent slices across its major axis, measured slower.
    #[inline]
    pub(crate) fn mark_blocked(
        self,
        lo: Cell,
        blocks: [usize; 2],
        stride: usize,
        words: &mut [u64],
    ) {
        let edge = 1i64 << BLOCK_BITS;
        let unit = [1, edge, edge * edge];
        let row = 64 * stride as i64;
        let bunit = [
            row,
            row * blocks[0] as i64,
            row * (blocks[0] * blocks[1]) as i64,
        ];
        let c = [self.x, self.y, self.z];
        let l = [lo.x, lo.y, lo.z].map(|v| v >> BLOCK_BITS);
        let mut pos = 0i64;
        for k in 0..3 {
            pos += (i64::from(c[k] >> BLOCK_BITS) - i64::from(l[k])) * bunit[k]
                + i64::from(c[k] & BLOCK_MASK) * unit[k];
        }
        let len = 64 * words.len() as u64;
        let mut mark = |pos: i64| {
            // A position below the slab wraps to a large unsigned value.
            #[allow(clippy::cast_sign_loss)]
            let p = pos as u64;
            if p < len {
                words[(p >> 6) as usize] |= 1 << (p & 63);
            }
        };
        mark(pos);
        let step = self.step.map(i64::from);
        // Position increments for a step inside a block and for one into the next block.
        let inc = [0, 1, 2].map(|k| step[k] * unit[k]);
        let last = i64::from(BLOCK_MASK);
        let winc = [0, 1, 2].map(|k| step[k] * (bunit[k] - last * unit[k]));
        // The in-block coordinate right after a step into the next block.
        let wrap = self.step.map(|s| if s > 0 { 0u32 } else { BLOCK_MASK });
        let [mut x, mut y, mut z] = c;
        let (mut tx, mut ty, mut tz) = (self.tx, self.ty, self.tz);
        let [sx, sy, sz] = self.step.map(|s| s as u32);
        for _ in 0..self.remaining {
            let ax = tx <= ty && tx <= tz;
            let ay = !ax && ty <= tz;
            let d = if ax {
                x = x.wrapping_add(sx);
                tx = if x == self.end[0] {
                    f64::INFINITY
                } else {
                    tx + self.dt[0]
                };
                if x & BLOCK_MASK == wrap[0] {
                    winc[0]
                } else {
                    inc[0]
                }
            } else if ay {
                y = y.wrapping_add(sy);
                ty = if y == self.end[1] {
                    f64::INFINITY
                } else {
                    ty + self.dt[1]
                };
                if y & BLOCK_MASK == wrap[1] {
                    winc[1]
                } else {
                    inc[1]
                }
            } else {
                z = z.wrapping_add(sz);
                tz = if z == self.end[2] {
                    f64::INFINITY
                } else {
                    tz + self.dt[2]
                };
                if z & BLOCK_MASK == wrap[2] {
                    winc[2]
                } else {
                    inc[2]
                }
            };
            pos += d;
            mark(pos);
        }
    }
}

impl Walk {
    /// Whether `blocks` a cell strictly between the first and the last cell of the walk, the
    /// cells' values read from 8 × 8 × 8 blocks: `block(entry)` gives the values of the block
    /// at entry `entry` of a block directory (x fastest, `stride` entries per step along each
    /// axis) in which the walk's first cell lies at entry `entry`.
    ///
    /// The cells are those [`Walk::advance`] visits, the last one excepted; the block entry and
    /// the index inside the block are carried from cell to cell instead of being recomputed.
    #[inline]
    pub(crate) fn any_inner<'a>(
        self,
        entry: usize,
        stride: [usize; 3],
        block: impl Fn(usize) -> &'a [i8; BLOCK_CELLS],
        blocks: impl Fn(i8) -> bool,
    ) -> bool {
        let edge = 1usize << BLOCK_BITS;
        let unit = [1, edge, edge * edge];
        let last = BLOCK_MASK as usize;
        // Steps inside a block and into the next one, as wrapping offsets of the index and
        // of the directory entry.
        let (mut inc, mut winc, mut dinc) = ([0usize; 3], [0usize; 3], [0usize; 3]);
        for k in 0..3 {
            if self.step[k] > 0 {
                inc[k] = unit[k];
                winc[k] = (last * unit[k]).wrapping_neg();
                dinc[k] = stride[k];
            } else {
                inc[k] = unit[k].wrapping_neg();
                winc[k] = last * unit[k];
                dinc[k] = stride[k].wrapping_neg();
            }
        }
        let wrap = self.step.map(|s| if s > 0 { 0u32 } else { BLOCK_MASK });
        let mut walk = self;
        let mut index = ((walk.x & BLOCK_MASK)
            | ((walk.y & BLOCK_MASK) << BLOCK_BITS)
            | ((walk.z & BLOCK_MASK) << (2 * BLOCK_BITS))) as usize;
        let mut entry = entry;
        let mut values = block(entry);
        // Every step but the last, which enters the target.
        while walk.remaining > 1 {
            let Some(k) = walk.advance() else { break };
            let coord = match k {
                0 => walk.x,
                1 => walk.y,
                _ => walk.z,
            };
            if coord & BLOCK_MASK == wrap[k] {
                index = index.wrapping_add(winc[k]);
                entry = entry.wrapping_add(dinc[k]);
                values = block(entry);
            } else {
                index = index.wrapping_add(inc[k]);
            }
            if blocks(values[index & (BLOCK_CELLS - 1)]) {
                return true;
            }
        }
        false
    }
}

/// Visits, in order, every cell the segment from `a` to `b` passes through, from the cell of
/// `a` to the cell of `b` inclusive (see [`Walk`]); stops early when `visit` returns `false`
/// and then returns `false`.
#[inline]
pub(crate) fn traverse(
    grid: &Grid,
    a: &Point3<f64>,
    b: &Point3<f64>,
    mut visit: impl FnMut(Cell) -> bool,
) -> bool {
    let mut w = Walk::new(grid, a, b);
    if !visit(w.cell()) {
        return false;
    }
    while w.advance().is_some() {
        if !visit(w.cell()) {
            return false;
        }
    }
    true
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Bounds;
    use proptest::prelude::*;
    use std::collections::BTreeSet;

    fn grid() -> Grid {
        let b = Bounds::new(Point3::new(-2.0, -1.0, 0.0), Point3::new(3.0, 2.0, 1.5)).unwrap();
        Grid::new(b, 0.2).unwrap()
    }

    /// Every cell a fine march of the segment touches.
    fn march(g: &Grid, a: &Point3<f64>, b: &Point3<f64>) -> BTreeSet<Cell> {
        let n = 20_000;
        (0..=n)
            .filter_map(|i| g.cell_of(&(a + (b - a) * (f64::from(i) / f64::from(n)))))
            .collect()
    }

    proptest! {
        #[test]
        fn dda_equals_a_fine_march(
            ax in -2.0f64..3.0, ay in -1.0f64..2.0, az in 0.0f64..1.5,
            bx in -2.0f64..3.0, by in -1.0f64..2.0, bz in 0.0f64..1.5,
        ) {
            let g = grid();
            let (a, b) = (Point3::new(ax, ay, az), Point3::new(bx, by, bz));
            let mut cells = Vec::new();
            let done = traverse(&g, &a, &b, |c| {
                cells.push(c);
                true
            });
            prop_assert!(done);
            // Consecutive cells share a face, and no cell repeats.
            for w in cells.windows(2) {
                let d = (w[0].x.abs_diff(w[1].x)) + w[0].y.abs_diff(w[1].y) + w[0].z.abs_diff(w[1].z);
                prop_assert_eq!(d, 1);
            }
            let set: BTreeSet<Cell> = cells.iter().copied().collect();
            prop_assert_eq!(set.len(), cells.len());
            // The march can only miss cells the segment grazes for less than its step.
            let marched = march(&g, &a, &b);
            prop_assert!(marched.is_subset(&set));
            let step = (b - a).norm() / 20_000.0;
            for c in set.difference(&marched) {
                let lo = g.center(*c) - nalgebra::Vector3::repeat(0.1);
                let hi = g.center(*c) + nalgebra::Vector3::repeat(0.1);
                let sub = Grid::new(Bounds::new(lo, hi).unwrap(), 0.2).unwrap();
                let (t0, t1) = sub.clip(&a, &b).unwrap_or((1.0, 0.0));
                prop_assert!((t1 - t0) * (b - a).norm() <= 2.0 * step + 1e-12, "missed {:?}", c);
            }
            prop_assert_eq!(cells.first().copied(), g.cell_of(&a));
            prop_assert_eq!(cells.last().copied(), g.cell_of(&b));
        }
    }

    #[test]
    fn points_outside_the_contract_stay_in_the_grid() {
        let g = grid();
        let dims = g.dims();
        let inside = |c: Cell| c.x < dims[0] && c.y < dims[1] && c.z < dims[2];
        let p = Point3::new(0.3, 0.3, 0.3);
        // Grid coordinates that are not finite: the first cell alone.
        for q in [
            Point3::new(1e308, 0.5, 0.1),
            Point3::new(-1e308, 0.5, 0.1),
            Point3::new(f64::NAN, 0.5, 0.1),
            Point3::new(0.3, f64::INFINITY, 0.1),
        ] {
            for (a, b) in [(q, p), (p, q)] {
                let mut cells = Vec::new();
                assert!(traverse(&g, &a, &b, |c| {
                    cells.push(c);
                    true
                }));
                assert_eq!(cells.len(), 1, "{a:?} {b:?}");
                assert!(inside(cells[0]));
            }
        }
        // Finite points outside the bounds walk between their clamped cells.
        for q in [
            Point3::new(1e300, -1e300, 5.0),
            Point3::new(-7.0, 0.5, -3.0),
            Point3::new(4.0, 9.0, 0.7),
        ] {
            for (a, b) in [(q, p), (p, q)] {
                let mut last = None;
                assert!(traverse(&g, &a, &b, |c| {
                    assert!(inside(c), "{c:?}");
                    last = Some(c);
                    true
                }));
                let end = g.clamp_cell(g.grid_coords(&b));
                assert_eq!(last, Some(end));
            }
        }
    }

    #[test]
    fn degenerate_and_boundary_segments() {
        let g = grid();
        let p = Point3::new(0.3, 0.3, 0.3);
        let mut n = 0;
        assert!(traverse(&g, &p, &p, |_| {
            n += 1;
            true
        }));
        assert_eq!(n, 1);
        // Ending exactly on the upper bound ends in the last cell.
        let mut last = None;
        traverse(&g, &p, &Point3::new(3.0, 2.0, 1.5), |c| {
            last = Some(c);
            true
        });
        assert_eq!(last, Some(Cell::new(24, 14, 7)));
        // Early stop.
        let mut k = 0;
        assert!(!traverse(
            &g,
            &Point3::new(-1.9, 0.0, 0.1),
            &Point3::new(2.9, 0.0, 0.1),
            |_| {
                k += 1;
                k < 3
            }
        ));
        assert_eq!(k, 3);
    }
}
