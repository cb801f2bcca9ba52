//! Map bounds and the regular cell grid inside them.

use nalgebra::{Point3, Vector3};

use crate::{FrontierError, Result};

/// Largest number of cells along one axis (cell keys pack each coordinate into 21 bits).
pub const MAX_CELLS_PER_AXIS: u32 = 1 << 20;

/// An axis-aligned box in the world frame \[m\]: the region a map covers.
///
/// # Example
/// ```
/// use frontier::Bounds;
/// use nalgebra::Point3;
///
/// let b = Bounds::new(Point3::new(0.0, 0.0, 0.0), Point3::new(10.0, 5.0, 3.0)).unwrap();
/// assert!(b.contains(&Point3::new(1.0, 1.0, 1.0)));
/// assert!(Bounds::new(Point3::new(1.0, 0.0, 0.0), Point3::new(0.0, 1.0, 1.0)).is_err());
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Bounds {
    min: Point3<f64>,
    max: Point3<f64>,
}

impl Bounds {
    /// A box from its corners.
    ///
    /// # Errors
    /// [`FrontierError::InvalidBounds`] unless both corners are finite and `min < max` on every
    /// axis.
    pub fn new(min: Point3<f64>, max: Point3<f64>) -> Result<Self> {
        let ok = (0..3).all(|k| min[k].is_finite() && max[k].is_finite() && min[k] < max[k]);
        if ok {
            Ok(Self { min, max })
        } else {
            Err(FrontierError::InvalidBounds)
        }
    }

    /// The lower corner \[m\].
    pub fn min(&self) -> Point3<f64> {
        self.min
    }

    /// The upper corner \[m\].
    pub fn max(&self) -> Point3<f64> {
        self.max
    }

    /// Whether `p` lies in the box (closed at both ends); `false` for NaN.
    pub fn contains(&self, p: &Point3<f64>) -> bool {
        (0..3).all(|k| p[k] >= self.min[k] && p[k] <= self.max[k])
    }
}

/// A cell of the grid: integer coordinates counted from the lower corner of the map bounds.
///
/// Cell `(x, y, z)` covers `min + res·[x, x + 1) × …`. Coordinates are always inside the
/// map's grid when a cell comes from this crate.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct Cell {
    /// Index along x.
    pub x: u32,
    /// Index along y.
    pub y: u32,
    /// Index along z.
    pub z: u32,
}

impl Cell {
    /// A cell from its coordinates.
    pub const fn new(x: u32, y: u32, z: u32) -> Self {
        Self { x, y, z }
    }

    /// The cell as one integer (21 bits per axis), ordered like `(z, y, x)`.
    #[inline]
    pub(crate) fn key(self) -> u64 {
        u64::from(self.x) | (u64::from(self.y) << 21) | (u64::from(self.z) << 42)
    }

    /// Inverse of [`Cell::key`].
    #[inline]
    pub(crate) fn from_key(k: u64) -> Self {
        let m = (1u64 << 21) - 1;
        // Each field has at most 21 bits, so the casts are exact.
        Self::new((k & m) as u32, ((k >> 21) & m) as u32, (k >> 42) as u32)
    }
}

/// The regular grid of a map: bounds, resolution and cell counts.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Grid {
    origin: Point3<f64>,
    resolution: f64,
    inv_resolution: f64,
    dims: [u32; 3],
    bounds: Bounds,
}

impl Grid {
    /// The grid covering `bounds` with cubic cells of edge `resolution` \[m\]; the last cell of an
    /// axis may extend past the upper bound.
    ///
    /// # Errors
    /// [`FrontierError::InvalidConfig`] for a resolution that is not positive and finite;
    /// [`FrontierError::TooManyCells`] above [`MAX_CELLS_PER_AXIS`] cells along an axis.
    pub fn new(bounds: Bounds, resolution: f64) -> Result<Self> {
        if !(resolution.is_finite() && resolution > 0.0) {
            return Err(FrontierError::InvalidConfig {
                what: "resolution",
                value: resolution,
                reason: "must be positive and finite [m]",
            });
        }
        let mut dims = [0u32; 3];
        for k in 0..3 {
            let n = ((bounds.max[k] - bounds.min[k]) / resolution)
                .ceil()
                .max(1.0);
            if n > f64::from(MAX_CELLS_PER_AXIS) {
                return Err(FrontierError::TooManyCells {
                    cells: n,
                    max: MAX_CELLS_PER_AXIS,
                });
            }
            // n is a positive integer below 2^20.
            dims[k] = n as u32;
        }
        Ok(Self {
            origin: bounds.min,
            resolution,
            inv_resolution: 1.0 / resolution,
            dims,
            bounds,
        })
    }

    /// Cell edge \[m\].
    pub fn resolution(&self) -> f64 {
        self.resolution
    }

    /// Cells along x, y and z.
    pub fn dims(&self) -> [u32; 3] {
        self.dims
    }

    /// The map bounds.
    pub fn bounds(&self) -> &Bounds {
        &self.bounds
    }

    /// The lower corner of cell (0, 0, 0) \[m\].
    pub fn origin(&self) -> Point3<f64> {
        self.origin
    }

    /// The cell containing `p`, or `None` outside the bounds or for NaN.
    pub fn cell_of(&self, p: &Point3<f64>) -> Option<Cell> {
        if !self.bounds.contains(p) {
            return None;
        }
        let g = (p - self.origin) * self.inv_resolution;
        Some(self.clamp_cell(g))
    }

    /// The cell containing grid coordinates `g` (cell units from the origin), clamped into the
    /// grid; `g` must be finite.
    #[inline]
    pub(crate) fn clamp_cell(&self, g: Vector3<f64>) -> Cell {
        let c = |k: usize| {
            // Clamping first and truncating gives the floor inside [0, dims − 1] without a call
            // to libm's floor (NaN becomes 0).
            g[k].clamp(0.0, f64::from(self.dims[k] - 1)) as u32
        };
        Cell::new(c(0), c(1), c(2))
    }

    /// The centre of a cell \[m\].
    pub fn center(&self, c: Cell) -> Point3<f64> {
        let r = self.resolution;
        Point3::new(
            self.origin.x + (f64::from(c.x) + 0.5) * r,
            self.origin.y + (f64::from(c.y) + 0.5) * r,
            self.origin.z + (f64::from(c.z) + 0.5) * r,
        )
    }

    /// The neighbour of `c` at offset `d`, if it is inside the grid.
    #[inline]
    pub fn offset(&self, c: Cell, d: [i32; 3]) -> Option<Cell> {
        let f = |v: u32, dv: i32, n: u32| {
            let w = i64::from(v) + i64::from(dv);
            // Inside [0, n), so the cast is exact.
            (0..i64::from(n)).contains(&w).then_some(w as u32)
        };
        Some(Cell::new(
            f(c.x, d[0], self.dims[0])?,
            f(c.y, d[1], self.dims[1])?,
            f(c.z, d[2], self.dims[2])?,
        ))
    }

    /// Grid coordinates (cell units from the origin) of a world point.
    #[inline]
    pub(crate) fn grid_coords(&self, p: &Point3<f64>) -> Vector3<f64> {
        (p - self.origin) * self.inv_resolution
    }

    /// The part `[t0, t1]` of the segment `a + t (b − a)`, t ∈ [0, 1], inside the bounds, or
    /// `None` when it misses them. Both points must be finite.
    pub(crate) fn clip(&self, a: &Point3<f64>, b: &Point3<f64>) -> Option<(f64, f64)> {
        let d = b - a;
        let (mut t0, mut t1) = (0.0f64, 1.0f64);
        for k in 0..3 {
            let (lo, hi) = (self.bounds.min[k], self.bounds.max[k]);
            if d[k] == 0.0 {
                if a[k] < lo || a[k] > hi {
                    return None;
                }
            } else {
                let inv = 1.0 / d[k];
                let (mut ta, mut tb) = ((lo - a[k]) * inv, (hi - a[k]) * inv);
                if ta > tb {
                    core::mem::swap(&mut ta, &mut tb);
                }
                t0 = t0.max(ta);
                t1 = t1.min(tb);
            }
        }
        (t0 <= t1).then_some((t0, t1))
    }
}

/// The six face neighbours.
pub(crate) const FACES: [[i32; 3]; 6] = [
    [-1, 0, 0],
    [1, 0, 0],
    [0, -1, 0],
    [0, 1, 0],
    [0, 0, -1],
    [0, 0, 1],
];

/// The 26 neighbours sharing a face, an edge or a corner.
pub(crate) const NEIGHBOURS_26: [[i32; 3]; 26] = {
    let mut out = [[0; 3]; 26];
    let mut n = 0;
    let mut z = -1;
    while z <= 1 {
        let mut y = -1;
        while y <= 1 {
            let mut x = -1;
            while x <= 1 {
                if x != 0 || y != 0 || z != 0 {
                    out[n] = [x, y, z];
                    n += 1;
                }
                x += 1;
            }
            y += 1;
        }
        z += 1;
    }
    out
};

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keys_round_trip() {
        let c = Cell::new(1_048_575, 3, 77);
        assert_eq!(Cell::from_key(c.key()), c);
    }

    #[test]
    fn cells_and_centres() {
        let b = Bounds::new(Point3::new(-1.0, 0.0, 0.0), Point3::new(1.0, 1.0, 0.5)).unwrap();
        let g = Grid::new(b, 0.2).unwrap();
        assert_eq!(g.dims(), [10, 5, 3]);
        let c = g.cell_of(&Point3::new(-0.95, 0.05, 0.45)).unwrap();
        assert_eq!(c, Cell::new(0, 0, 2));
        assert!((g.center(c) - Point3::new(-0.9, 0.1, 0.5)).norm() < 1e-12);
        // The upper bound belongs to the last cell.
        assert_eq!(
            g.cell_of(&Point3::new(1.0, 1.0, 0.5)),
            Some(Cell::new(9, 4, 2))
        );
        assert_eq!(g.cell_of(&Point3::new(f64::NAN, 0.0, 0.0)), None);
        assert_eq!(g.offset(Cell::new(0, 0, 0), [-1, 0, 0]), None);
        assert!(Grid::new(b, 0.0).is_err());
        assert!(Grid::new(b, f64::NAN).is_err());
        assert!(Grid::new(b, 1e-9).is_err());
    }

    #[test]
    fn clipping() {
        let b = Bounds::new(Point3::new(0.0, 0.0, 0.0), Point3::new(1.0, 1.0, 1.0)).unwrap();
        let g = Grid::new(b, 0.1).unwrap();
        let (t0, t1) = g
            .clip(&Point3::new(0.5, 0.5, 0.5), &Point3::new(2.5, 0.5, 0.5))
            .unwrap();
        assert_eq!(t0, 0.0);
        assert!((t1 - 0.25).abs() < 1e-12);
        assert!(
            g.clip(&Point3::new(2.0, 2.0, 2.0), &Point3::new(3.0, 2.0, 2.0))
                .is_none()
        );
    }

    #[test]
    fn neighbour_tables() {
        assert_eq!(NEIGHBOURS_26.len(), 26);
        assert!(NEIGHBOURS_26.iter().all(|d| d != &[0, 0, 0]));
        assert_eq!(
            FACES.iter().filter(|d| NEIGHBOURS_26.contains(d)).count(),
            6
        );
    }
}
