//! Scenes the simulator flies in: solid boxes inside bounds, a start position, and the
//! ground-truth explorable free space for the coverage metric.

use std::collections::VecDeque;

use nalgebra::{Point3, Vector3};

use crate::rng::Rng;
use crate::world::{World, WorldError};

/// A solid box by its min and max corners \[m\].
pub type Aabb = (Point3<f64>, Point3<f64>);

/// A scene of solid boxes.
#[derive(Debug, Clone, PartialEq)]
pub struct Scene {
    /// Short name, e.g. `"maze"`.
    pub name: String,
    /// Lower corner of the explorable region \[m\].
    pub min: Point3<f64>,
    /// Upper corner of the explorable region \[m\].
    pub max: Point3<f64>,
    /// Where the UAV starts \[m\].
    pub start: Point3<f64>,
    /// The solid boxes.
    pub boxes: Vec<Aabb>,
}

fn aabb(x0: f64, y0: f64, z0: f64, x1: f64, y1: f64, z1: f64) -> Aabb {
    (Point3::new(x0, y0, z0), Point3::new(x1, y1, z1))
}

/// Floor, ceiling and four walls around `[0, sx] × [0, sy] × [0, sz]`, 0.2 m thick, outside.
fn shell(sx: f64, sy: f64, sz: f64) -> Vec<Aabb> {
    let t = 0.2;
    vec![
        aabb(-t, -t, -t, sx + t, sy + t, 0.0),
        aabb(-t, -t, sz, sx + t, sy + t, sz + t),
        aabb(-t, -t, 0.0, 0.0, sy + t, sz),
        aabb(sx, -t, 0.0, sx + t, sy + t, sz),
        aabb(0.0, -t, 0.0, sx, 0.0, sz),
        aabb(0.0, sy, 0.0, sx, sy + t, sz),
    ]
}

impl Scene {
    /// A small two-room scene for tests: 12 × 8 × 3 m, a dividing wall with a door, a pillar
    /// and a table-like block; `seed` moves the door and the pillar.
    pub fn small(seed: u64) -> Self {
        let mut r = Rng::new(seed);
        let mut boxes = shell(12.0, 8.0, 3.0);
        let door = r.range(1.5, 5.5);
        boxes.push(aabb(5.9, 0.0, 0.0, 6.1, door, 3.0));
        boxes.push(aabb(5.9, door + 1.2, 0.0, 6.1, 8.0, 3.0));
        let (px, py) = (r.range(8.0, 10.5), r.range(1.5, 6.0));
        boxes.push(aabb(px, py, 0.0, px + 0.5, py + 0.5, 3.0));
        boxes.push(aabb(2.0, 5.5, 0.0, 3.5, 6.5, 0.8));
        Self {
            name: "small".into(),
            min: Point3::origin(),
            max: Point3::new(12.0, 8.0, 3.0),
            start: Point3::new(1.5, 1.5, 1.2),
            boxes,
        }
    }

    /// The Spatial Maze of the paper's Section VI at its size, 119 × 20 × 8 m: two levels
    /// separated by a slab at 4 m with openings (vertically separated passages), barriers
    /// across the maze with gaps on each level whose heights vary, and stair ramps between
    /// the levels. Seeded: the same seed gives the same maze.
    pub fn maze(seed: u64) -> Self {
        let (sx, sy, sz) = (119.0, 20.0, 8.0);
        let mut r = Rng::new(seed);
        let mut boxes = shell(sx, sy, sz);
        // The slab between the levels, with an opening every ~20 m.
        let slab = (3.8, 4.2);
        let mut x = 0.0;
        while x < sx {
            let len = r.range(12.0, 20.0).min(sx - x);
            let hole = r.range(2.5, 4.0).min(len);
            let hy = r.range(1.0, sy - 5.0);
            // The slab piece [x, x + len − hole], then a hole of width `hole` spanning
            // part of y.
            boxes.push(aabb(x, 0.0, slab.0, x + len - hole, sy, slab.1));
            boxes.push(aabb(x + len - hole, 0.0, slab.0, x + len, hy, slab.1));
            boxes.push(aabb(x + len - hole, hy + 4.0, slab.0, x + len, sy, slab.1));
            x += len;
        }
        // Barriers across y every 6–10 m, one per level, with a gap and varying height.
        let mut x = 6.0;
        while x < sx - 4.0 {
            for (z0, z1) in [(0.0, slab.0), (slab.1, sz)] {
                let gap = r.range(1.6, 3.0);
                let gy = r.range(0.5, sy - gap - 0.5);
                let top = z0 + (z1 - z0) * r.range(0.55, 1.0);
                boxes.push(aabb(x, 0.0, z0, x + 0.3, gy, top));
                boxes.push(aabb(x, gy + gap, z0, x + 0.3, sy, top));
            }
            x += r.range(6.0, 10.0);
        }
        // Stair ramps up to the slab at three places.
        for k in 0..3 {
            let x0 = 20.0 + 35.0 * f64::from(k) + r.range(-3.0, 3.0);
            let y0 = r.range(1.0, sy - 3.0);
            for step in 0..8 {
                let h = 0.5 * f64::from(step + 1);
                let xs = x0 + 0.6 * f64::from(step);
                boxes.push(aabb(xs, y0, 0.0, xs + 0.6, y0 + 2.0, h.min(slab.0)));
            }
        }
        Self {
            name: "maze".into(),
            min: Point3::origin(),
            max: Point3::new(sx, sy, sz),
            start: Point3::new(2.0, sy / 2.0, 1.5),
            boxes,
        }
    }

    /// The Sinkhole of the paper's Section VI at its size, 70 × 45 × 13.5 m: flat ground at
    /// 9 m around an open pit down to 0.5 m whose walls are irregular, 1 m layers of random
    /// extent (a layer narrower than the one below is an overhang). The start is above the
    /// ground at one end. Seeded.
    pub fn sinkhole(seed: u64) -> Self {
        let (sx, sy, sz) = (70.0, 45.0, 13.5);
        let ground = 9.0;
        let mut r = Rng::new(seed);
        let mut boxes = shell(sx, sy, sz);
        // The pit's floor.
        boxes.push(aabb(0.0, 0.0, 0.0, sx, sy, 0.5));
        let (cx, cy) = (sx / 2.0, sy / 2.0);
        let mut z: f64 = 0.5;
        while z < ground {
            let top = (z + 1.0).min(ground);
            // The hole of this layer: a rectangle around the centre with random extents.
            let (x0, x1) = (cx - r.range(12.0, 22.0), cx + r.range(12.0, 22.0));
            let (y0, y1) = (cy - r.range(8.0, 15.0), cy + r.range(8.0, 15.0));
            boxes.push(aabb(0.0, 0.0, z, x0, sy, top));
            boxes.push(aabb(x1, 0.0, z, sx, sy, top));
            boxes.push(aabb(x0, 0.0, z, x1, y0, top));
            boxes.push(aabb(x0, y1, z, x1, sy, top));
            z = top;
        }
        Self {
            name: "sinkhole".into(),
            min: Point3::origin(),
            max: Point3::new(sx, sy, sz),
            start: Point3::new(3.0, cy, 11.0),
            boxes,
        }
    }

    /// The Lava Tube of the paper's Section VI at its size, 315 × 53.5 × 27 m: a long tunnel
    /// that winds in y and z through solid rock, its width (6–12 m) and height (5–10 m)
    /// changing every 5 m slice, smoothly. The start is inside the tube at one end. Seeded.
    pub fn lava_tube(seed: u64) -> Self {
        let (sx, sy, sz) = (315.0, 53.5, 27.0);
        let mut r = Rng::new(seed);
        let mut boxes = shell(sx, sy, sz);
        let slice = 5.0;
        let (mut yc, mut zc) = (sy / 2.0, sz / 2.0);
        let (mut w, mut h) = (9.0f64, 7.0f64);
        let mut start = Point3::new(2.5, yc, zc);
        let mut x = 0.0;
        let mut first = true;
        while x < sx {
            let x1 = (x + slice).min(sx);
            yc = (yc + r.range(-1.5, 1.5)).clamp(8.0, sy - 8.0);
            zc = (zc + r.range(-0.8, 0.8)).clamp(6.0, sz - 6.0);
            w = (w + r.range(-1.0, 1.0)).clamp(6.0, 12.0);
            h = (h + r.range(-0.8, 0.8)).clamp(5.0, 10.0);
            let (y0, y1, z0, z1) = (yc - w / 2.0, yc + w / 2.0, zc - h / 2.0, zc + h / 2.0);
            boxes.push(aabb(x, 0.0, 0.0, x1, sy, z0));
            boxes.push(aabb(x, 0.0, z1, x1, sy, sz));
            boxes.push(aabb(x, 0.0, z0, x1, y0, z1));
            boxes.push(aabb(x, y1, z0, x1, sy, z1));
            if first {
                start = Point3::new(2.5, yc, zc);
                first = false;
            }
            x = x1;
        }
        Self {
            name: "lavatube".into(),
            min: Point3::origin(),
            max: Point3::new(sx, sy, sz),
            start,
            boxes,
        }
    }

    /// The world of this scene.
    ///
    /// # Errors
    /// As [`World::from_boxes`].
    pub fn world(&self) -> Result<World, WorldError> {
        World::from_boxes(&self.boxes)
    }

    /// The ground-truth explorable free space at `resolution` \[m\]: the cells of the bounds
    /// that no box touches and that are 6-connected to the start's cell.
    pub fn explorable(&self, resolution: f64) -> Explorable {
        let ext = self.max - self.min;
        let dims = ext.map(|e| (e / resolution).ceil().max(1.0));
        // Scene extents are metres over centimetres: the counts fit usize.
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        let [nx, ny, nz] = [dims.x as usize, dims.y as usize, dims.z as usize];
        let mut solid = vec![false; nx * ny * nz];
        let at = |x: usize, y: usize, z: usize| x + nx * (y + ny * z);
        let cell = |v: f64, k: usize, n: usize| {
            let c = ((v - self.min[k]) / resolution).floor();
            #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
            let c = c.clamp(0.0, (n - 1) as f64) as usize;
            c
        };
        for (lo, hi) in &self.boxes {
            if (0..3).any(|k| hi[k] <= self.min[k] || lo[k] >= self.max[k]) {
                continue;
            }
            // Cells whose open interior meets the box.
            let r = |k: usize, n: usize| {
                let a = cell(lo[k] + 1e-9, k, n);
                let b = cell(hi[k] - 1e-9, k, n);
                a..=b
            };
            for z in r(2, nz) {
                for y in r(1, ny) {
                    for x in r(0, nx) {
                        solid[at(x, y, z)] = true;
                    }
                }
            }
        }
        let s = [
            cell(self.start.x, 0, nx),
            cell(self.start.y, 1, ny),
            cell(self.start.z, 2, nz),
        ];
        let (reached, count) = flood([nx, ny, nz], &solid, s);
        Explorable {
            resolution,
            dims: [nx, ny, nz],
            origin: self.min,
            reached,
            count,
        }
    }
}

/// The cells 6-connected to `start` through cells that are not `solid` (x fastest, then y,
/// then z), and their count.
fn flood(dims: [usize; 3], solid: &[bool], start: [usize; 3]) -> (Vec<bool>, usize) {
    let [nx, ny, nz] = dims;
    let at = |x: usize, y: usize, z: usize| x + nx * (y + ny * z);
    let mut reached = vec![false; nx * ny * nz];
    let mut queue = VecDeque::new();
    let [sx, sy, sz] = start;
    if !solid[at(sx, sy, sz)] {
        reached[at(sx, sy, sz)] = true;
        queue.push_back((sx, sy, sz));
    }
    let mut count = 0usize;
    while let Some((x, y, z)) = queue.pop_front() {
        count += 1;
        let mut visit = |x: usize, y: usize, z: usize| {
            let i = at(x, y, z);
            if !solid[i] && !reached[i] {
                reached[i] = true;
                queue.push_back((x, y, z));
            }
        };
        if x > 0 {
            visit(x - 1, y, z);
        }
        if x + 1 < nx {
            visit(x + 1, y, z);
        }
        if y > 0 {
            visit(x, y - 1, z);
        }
        if y + 1 < ny {
            visit(x, y + 1, z);
        }
        if z > 0 {
            visit(x, y, z - 1);
        }
        if z + 1 < nz {
            visit(x, y, z + 1);
        }
    }
    (reached, count)
}

/// [`Explorable::coverage`] over a run, for a map in which a known cell stays known (as in
/// `frontier::VoxelMap`, whose log-odds are clamped off the unknown value): the cells found
/// known are not tested again, so a run's coverage curve costs far less than a full count
/// per point.
///
/// Two ways to learn: [`CoverageCounter::update`] tests every cell not yet known, and
/// [`CoverageCounter::reveal`] only those whose centre lies in a box (the cells of a map cell
/// that has just become known), so a map that reports its changes costs work in proportion
/// to them.
#[derive(Debug, Clone)]
pub struct CoverageCounter<'a> {
    explorable: &'a Explorable,
    /// One bit per cell of the grid: explorable and not yet known.
    pending: Vec<u64>,
    /// Set bits of `pending`.
    left: usize,
}

impl CoverageCounter<'_> {
    /// The coverage now: [`Explorable::coverage`] of `known`, provided every cell an earlier
    /// call found known is still known.
    pub fn update(&mut self, known: impl Fn(&Point3<f64>) -> bool) -> f64 {
        let e = self.explorable;
        for w in 0..self.pending.len() {
            let mut bits = self.pending[w];
            while bits != 0 {
                let b = bits.trailing_zeros() as usize;
                bits &= bits - 1;
                if known(&e.centre(64 * w + b)) {
                    self.take(64 * w + b);
                }
            }
        }
        self.share()
    }

    /// Tests the cells not yet known whose centre lies in the box `[lo, hi]` (widened by a
    /// cell on each side, so rounding at its faces loses none) and returns the coverage.
    ///
    /// When the map tells which of its cells became known, revealing each one's box after
    /// every change keeps the count equal to [`CoverageCounter::update`]'s: a cell becomes
    /// known exactly when the map cell holding its centre does.
    pub fn reveal(
        &mut self,
        lo: &Point3<f64>,
        hi: &Point3<f64>,
        known: impl Fn(&Point3<f64>) -> bool,
    ) -> f64 {
        let e = self.explorable;
        let mut range = [(0usize, 0usize); 3];
        for k in 0..3 {
            // Centres sit at origin + (i + ½) r.
            let a = ((lo[k] - e.origin[k]) / e.resolution - 0.5).floor() - 1.0;
            let b = ((hi[k] - e.origin[k]) / e.resolution - 0.5).ceil() + 1.0;
            #[allow(clippy::cast_precision_loss)]
            let top = e.dims[k] as f64 - 1.0;
            if !(a <= top && b >= 0.0) {
                // Outside the grid, or NaN.
                return self.share();
            }
            // Clamped into [0, dims − 1], so the casts are exact.
            #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
            let r = (a.max(0.0) as usize, b.min(top) as usize);
            range[k] = r;
        }
        let [nx, ny, _] = e.dims;
        for z in range[2].0..=range[2].1 {
            for y in range[1].0..=range[1].1 {
                for x in range[0].0..=range[0].1 {
                    let i = x + nx * (y + ny * z);
                    if self.pending[i >> 6] & (1u64 << (i & 63)) != 0 && known(&e.centre(i)) {
                        self.take(i);
                    }
                }
            }
        }
        self.share()
    }

    /// Marks pending cell `i` known.
    fn take(&mut self, i: usize) {
        self.pending[i >> 6] &= !(1u64 << (i & 63));
        self.left -= 1;
    }

    /// The coverage as of the last call.
    pub fn share(&self) -> f64 {
        let e = self.explorable;
        if e.count == 0 {
            return 1.0;
        }
        #[allow(clippy::cast_precision_loss)]
        let share = (e.count - self.left) as f64 / e.count as f64;
        share
    }
}

/// The centre of cell `i` (x fastest) of a grid with lower corner `origin`, cells of edge
/// `resolution` and `nx × ny` cells per layer.
fn cell_centre(
    origin: Point3<f64>,
    resolution: f64,
    [nx, ny]: [usize; 2],
    i: usize,
) -> Point3<f64> {
    // Cell indices are far below 2^53.
    #[allow(clippy::cast_precision_loss)]
    let c = Vector3::new(
        (i % nx) as f64,
        ((i / nx) % ny) as f64,
        (i / (nx * ny)) as f64,
    );
    origin + (c + Vector3::repeat(0.5)) * resolution
}

/// The explorable free cells of a scene.
#[derive(Debug, Clone, PartialEq)]
pub struct Explorable {
    /// Cell edge \[m\].
    pub resolution: f64,
    /// Cells along x, y, z.
    pub dims: [usize; 3],
    /// Lower corner of cell (0, 0, 0) \[m\].
    pub origin: Point3<f64>,
    reached: Vec<bool>,
    /// Number of explorable cells.
    pub count: usize,
}

impl Explorable {
    /// The cells of `[min, max]` at `resolution` \[m\] whose centre `solid` rejects and
    /// that are 6-connected to the cell of `start`: the explorable space of a scene known only
    /// through a query (e.g. a point-cloud world: centres at least a voxel from the cloud).
    /// Empty for a start outside the region; at least one cell per axis.
    pub fn from_fn(
        min: Point3<f64>,
        max: Point3<f64>,
        start: &Point3<f64>,
        resolution: f64,
        solid: impl Fn(&Point3<f64>) -> bool + Sync,
    ) -> Self {
        let ext = max - min;
        let dims = ext.map(|e| (e / resolution).ceil().max(1.0));
        // Scene extents are metres over centimetres: the counts fit usize.
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        let [nx, ny, nz] = [dims.x as usize, dims.y as usize, dims.z as usize];
        let centre = |i: usize| cell_centre(min, resolution, [nx, ny], i);
        use rayon::prelude::*;
        let solid: Vec<bool> = (0..nx * ny * nz)
            .into_par_iter()
            .map(|i| solid(&centre(i)))
            .collect();
        let g = (start - min) / resolution;
        let inside = (0..3).all(|k| g[k] >= 0.0 && g[k] < dims[k]);
        let (reached, count) = if inside {
            // Inside the grid, so the casts are exact.
            #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
            let s = [g.x as usize, g.y as usize, g.z as usize];
            flood([nx, ny, nz], &solid, s)
        } else {
            (vec![false; nx * ny * nz], 0)
        };
        Self {
            resolution,
            dims: [nx, ny, nz],
            origin: min,
            reached,
            count,
        }
    }

    /// Whether the cell containing `p` is explorable.
    pub fn contains(&self, p: &Point3<f64>) -> bool {
        let g: Vector3<f64> = (p - self.origin) / self.resolution;
        #[allow(clippy::cast_precision_loss)]
        if (0..3).any(|k| g[k].is_nan() || g[k] < 0.0 || g[k] >= self.dims[k] as f64) {
            return false;
        }
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        let (x, y, z) = (g.x as usize, g.y as usize, g.z as usize);
        self.reached[x + self.dims[0] * (y + self.dims[1] * z)]
    }

    /// The share (0..1) of the explorable cells whose centre `known` accepts (1 for a scene
    /// with no explorable cell).
    pub fn coverage(&self, known: impl Fn(&Point3<f64>) -> bool) -> f64 {
        if self.count == 0 {
            return 1.0;
        }
        let mut seen = 0usize;
        for (i, _) in self.reached.iter().enumerate().filter(|(_, r)| **r) {
            if known(&self.centre(i)) {
                seen += 1;
            }
        }
        #[allow(clippy::cast_precision_loss)]
        let share = seen as f64 / self.count as f64;
        share
    }

    /// A counter of [`Explorable::coverage`] for a map that only learns: each update tests
    /// only the cells not yet known.
    pub fn coverage_counter(&self) -> CoverageCounter<'_> {
        let mut pending = vec![0u64; self.reached.len().div_ceil(64)];
        for (i, _) in self.reached.iter().enumerate().filter(|(_, r)| **r) {
            pending[i >> 6] |= 1u64 << (i & 63);
        }
        CoverageCounter {
            explorable: self,
            pending,
            left: self.count,
        }
    }

    /// The centre of cell `i` (x fastest).
    fn centre(&self, i: usize) -> Point3<f64> {
        let [nx, ny, _] = self.dims;
        cell_centre(self.origin, self.resolution, [nx, ny], i)
    }

    /// Explorable volume \[m³\].
    pub fn volume(&self) -> f64 {
        #[allow(clippy::cast_precision_loss)]
        let n = self.count as f64;
        n * self.resolution.powi(3)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    proptest::proptest! {
        /// The incremental counter equals a full count at every step while the known set
        /// only grows.
        #[test]
        fn coverage_counter_equals_a_full_count(
            solid_seed in 0u64..1000,
            steps in proptest::collection::vec(0.0f64..1.0, 1..6),
        ) {
            let hash = |p: &Point3<f64>, seed: u64| {
                let k = (p.x * 7.0 + p.y * 131.0 + p.z * 1777.0) as i64 as u64;
                k.wrapping_mul(0x9e37_79b9_7f4a_7c15).wrapping_add(seed).rotate_left(17)
                    .wrapping_mul(0xbf58_476d_1ce4_e5b9)
            };
            let e = Explorable::from_fn(
                Point3::origin(),
                Point3::new(3.0, 2.0, 1.0),
                &Point3::new(0.1, 0.1, 0.1),
                0.2,
                |p| p.x > 0.2 && hash(p, solid_seed) % 5 == 0,
            );
            let mut counter = e.coverage_counter();
            // Known: cells whose hash falls below a growing threshold.
            let mut level = 0.0;
            for s in steps {
                level += s * 0.4;
                let known = |p: &Point3<f64>| {
                    (hash(p, 99) >> 11) as f64 / (1u64 << 53) as f64 <= level
                };
                proptest::prop_assert_eq!(counter.update(known), e.coverage(known));
            }
        }

        /// Revealing the box of each map cell as it becomes known counts what a full count
        /// does, for a map grid of another resolution and origin than the scene's.
        #[test]
        fn revealing_changed_map_cells_equals_a_full_count(
            solid_seed in 0u64..1000,
            res in 0.1f64..0.5,
            off in proptest::array::uniform3(-0.3f64..0.3),
            steps in proptest::collection::vec(proptest::collection::vec(0u32..4000, 0..60), 1..6),
        ) {
            let e = Explorable::from_fn(
                Point3::origin(),
                Point3::new(3.0, 2.0, 1.0),
                &Point3::new(0.1, 0.1, 0.1),
                0.2,
                |p| p.x > 0.2 && (p.x * 17.0 + p.y * 5.0 + p.z * 3.0 + solid_seed as f64) as i64 % 5 == 0,
            );
            let origin = Point3::new(off[0], off[1], off[2]) - Vector3::repeat(0.5);
            let cell_of = |p: &Point3<f64>| -> [i64; 3] {
                let g = (p - origin) / res;
                [g.x.floor() as i64, g.y.floor() as i64, g.z.floor() as i64]
            };
            let mut known_cells = std::collections::BTreeSet::new();
            let mut counter = e.coverage_counter();
            for step in steps {
                for code in step {
                    // A map cell over the scene's box (and a little beyond).
                    let c = [i64::from(code % 20), i64::from(code / 20 % 14), i64::from(code / 280 % 9)];
                    if !known_cells.insert(c) {
                        continue;
                    }
                    let known = |p: &Point3<f64>| known_cells.contains(&cell_of(p));
                    let lo = origin + Vector3::new(c[0] as f64, c[1] as f64, c[2] as f64) * res;
                    let hi = lo + Vector3::repeat(res);
                    counter.reveal(&lo, &hi, known);
                }
                let known = |p: &Point3<f64>| known_cells.contains(&cell_of(p));
                proptest::prop_assert_eq!(counter.share(), e.coverage(known));
            }
        }
    }

    #[test]
    fn scenes_are_deterministic_and_the_start_is_free() {
        for s in [Scene::small(1), Scene::maze(7)] {
            let again = if s.name == "small" {
                Scene::small(1)
            } else {
                Scene::maze(7)
            };
            assert_eq!(s, again);
            let w = s.world().unwrap();
            assert!(w.distance(&s.start) > 0.5, "{}", s.name);
        }
        assert_ne!(Scene::maze(1), Scene::maze(2));
    }

    #[test]
    fn both_maze_levels_are_explorable_from_the_start() {
        let s = Scene::maze(3);
        let e = s.explorable(0.5);
        // The upper level is reached through the ramps and openings.
        let upper = (0..40).any(|i| e.contains(&Point3::new(3.0 * f64::from(i) + 1.0, 10.0, 6.0)));
        assert!(upper);
        assert!(e.contains(&s.start));
        // Most of the volume is explorable; none of it is inside a box.
        let total = 119.0 * 20.0 * 8.0;
        assert!(
            e.volume() > 0.5 * total && e.volume() < total,
            "{}",
            e.volume()
        );
        let w = s.world().unwrap();
        for i in 0..200 {
            let p = Point3::new(
                0.59 * f64::from(i) + 0.3,
                (f64::from(i) * 0.37) % 20.0,
                (f64::from(i) * 0.23) % 8.0,
            );
            if e.contains(&p) {
                assert!(w.distance(&p) > 0.0, "{p}");
            }
        }
    }

    #[test]
    fn the_sinkhole_pit_and_the_far_end_of_the_tube_are_reachable() {
        let s = Scene::sinkhole(5);
        assert!(s.world().unwrap().distance(&s.start) > 0.5);
        let e = s.explorable(0.5);
        // The bottom of the pit, below the ground level.
        assert!(e.contains(&Point3::new(35.0, 22.5, 1.0)));
        // Not inside the rock beside the pit.
        assert!(!e.contains(&Point3::new(2.0, 2.0, 4.0)));
        let t = Scene::lava_tube(5);
        assert!(t.world().unwrap().distance(&t.start) > 1.0);
        let e = t.explorable(0.5);
        let far = (0..54)
            .flat_map(|j| {
                (0..27).map(move |k| Point3::new(312.0, f64::from(j) + 0.25, f64::from(k) + 0.25))
            })
            .any(|p| e.contains(&p));
        assert!(far, "the far end of the tube is reachable");
        // The tube is a small part of the rock.
        assert!(e.volume() < 0.3 * 315.0 * 53.5 * 27.0, "{}", e.volume());
    }

    #[test]
    fn small_scene_rooms_connect_through_the_door() {
        let s = Scene::small(4);
        let e = s.explorable(0.2);
        assert!(e.contains(&Point3::new(10.0, 0.5, 1.5)));
        // A sealed scene (door closed) keeps the second room out.
        let mut sealed = s;
        sealed
            .boxes
            .push((Point3::new(5.9, 0.0, 0.0), Point3::new(6.1, 8.0, 3.0)));
        let e2 = sealed.explorable(0.2);
        assert!(!e2.contains(&Point3::new(10.0, 0.5, 1.5)));
        assert!(e2.count < e.count);
    }
}
