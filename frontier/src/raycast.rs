//! 3-D DDA ray traversal of the grid (Amanatides & Woo, "A fast voxel traversal algorithm
//! for ray tracing", 1987).

use nalgebra::Point3;

use crate::grid::{Cell, Grid};

/// Visits, in order, every cell the segment from `a` to `b` passes through, from the cell of
/// `a` to the cell of `b` inclusive; stops early when `visit` returns `false` and then
/// returns `false`.
///
/// Both points must be finite and inside the grid's bounds (points on the upper bound belong
/// to the last cell). The walk takes exactly one step per cell boundary between the two end
/// cells, so it always ends in the cell of `b`, even when rounding puts a crossing a hair
/// early or late.
#[inline]
pub(crate) fn traverse(
    grid: &Grid,
    a: &Point3<f64>,
    b: &Point3<f64>,
    mut visit: impl FnMut(Cell) -> bool,
) -> bool {
    let ga = grid.grid_coords(a);
    let gb = grid.grid_coords(b);
    let start = grid.clamp_cell(ga);
    let end = grid.clamp_cell(gb);
    let s = [i64::from(start.x), i64::from(start.y), i64::from(start.z)];
    let e = [i64::from(end.x), i64::from(end.y), i64::from(end.z)];
    let d = gb - ga;
    let mut cell = s;
    let mut step = [0i64; 3];
    let mut t_max = [f64::INFINITY; 3];
    let mut t_delta = [f64::INFINITY; 3];
    let mut remaining = 0u64;
    for k in 0..3 {
        step[k] = (e[k] - s[k]).signum();
        remaining += (e[k] - s[k]).unsigned_abs();
        if step[k] != 0 {
            if d[k] == 0.0 {
                // Only reachable through clamping at the upper bound: take these steps first.
                t_max[k] = 0.0;
                t_delta[k] = 0.0;
            } else {
                let boundary = if step[k] > 0 { s[k] + 1 } else { s[k] };
                // i64 → f64 is exact for grid coordinates (< 2^21).
                #[allow(clippy::cast_precision_loss)]
                let boundary = boundary as f64;
                t_max[k] = (boundary - ga[k]) / d[k];
                t_delta[k] = 1.0 / d[k].abs();
            }
        }
    }
    // Axes already in the end cell never step again.
    for k in 0..3 {
        if cell[k] == e[k] {
            t_max[k] = f64::INFINITY;
        }
    }
    if !visit(start) {
        return false;
    }
    for _ in 0..remaining {
        // Branch-free choice of the axis whose boundary comes first.
        let k01 = usize::from(t_max[1] < t_max[0]);
        let k = if t_max[2] < t_max[k01] { 2 } else { k01 };
        cell[k] += step[k];
        t_max[k] = if cell[k] == e[k] {
            f64::INFINITY
        } else {
            t_max[k] + t_delta[k]
        };
        // Every coordinate stays between the start and end cells, both inside the grid.
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        let c = Cell::new(cell[0] as u32, cell[1] as u32, cell[2] as u32);
        if !visit(c) {
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
