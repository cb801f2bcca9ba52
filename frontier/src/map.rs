//! The sparse block-based log-odds occupancy map.

use nalgebra::{Point3, Vector3};

use crate::grid::{Bounds, Cell, Grid};
use crate::raycast::{Walk, traverse};
use crate::{FrontierError, Result};

/// Cells per block edge (blocks hold 8 × 8 × 8 cells).
const BLOCK_BITS: u32 = 3;
const BLOCK_EDGE: u32 = 1 << BLOCK_BITS;
const BLOCK_MASK: u32 = BLOCK_EDGE - 1;
const BLOCK_CELLS: usize = 1 << (3 * BLOCK_BITS);
const WORDS: usize = BLOCK_CELLS / 64;
const NO_BLOCK: u32 = u32::MAX;

/// Log-odds are stored as `i8` in units of 1/32: one byte per cell, probabilities up to
/// 1 − 0.019 (log-odds ±3.97), steps of 0.03 in log-odds.
const SCALE: f64 = 32.0;
/// Largest stored magnitude (the value −128 means unknown).
const MAX_Q: f64 = 127.0;
/// The stored value of a cell never observed.
const UNKNOWN: i8 = i8::MIN;

/// The occupancy state of a cell.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum CellState {
    /// Never observed (or outside the map).
    Unknown,
    /// Observed, occupancy probability below one half.
    Free,
    /// Observed, occupancy probability at least one half.
    Occupied,
}

/// Settings of a [`VoxelMap`]. Defaults: 0.2 m cells (as the issue and FUEL use), OctoMap's
/// sensor model (hit 0.7, miss 0.4, clamping to [0.1192, 0.971]) and a 20 m range.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MapConfig {
    /// Cell edge \[m\].
    pub resolution: f64,
    /// Occupancy probability after one hit on an unknown cell, in (0.5, 1).
    pub prob_hit: f64,
    /// Occupancy probability after one miss on an unknown cell, in (0, 0.5).
    pub prob_miss: f64,
    /// Lower clamping probability, in (0, prob_miss].
    pub clamp_min: f64,
    /// Upper clamping probability, in [prob_hit, 1).
    pub clamp_max: f64,
    /// Sensor range \[m\]: longer rays clear free space up to this range and mark no hit.
    pub max_range: f64,
}

impl Default for MapConfig {
    fn default() -> Self {
        Self {
            resolution: 0.2,
            prob_hit: 0.7,
            prob_miss: 0.4,
            clamp_min: 0.1192,
            clamp_max: 0.971,
            max_range: 20.0,
        }
    }
}

fn logit(p: f64) -> f64 {
    (p / (1.0 - p)).ln()
}

fn quantize(l: f64) -> i8 {
    // Clamped into the i8 range first; validation rejects values that would be clamped.
    #[allow(clippy::cast_possible_truncation)]
    let q = (l * SCALE).round().clamp(-MAX_Q, MAX_Q) as i8;
    q
}

/// Probabilities whose log-odds fit the storage: [0.02, 0.98].
fn storable(p: f64) -> bool {
    (0.02..=0.98).contains(&p)
}

impl MapConfig {
    /// Checks every setting.
    ///
    /// # Errors
    /// [`FrontierError::InvalidConfig`] naming the first setting out of range. Log-odds are
    /// stored in one byte (units of 1/32), so probabilities must lie in [0.02, 0.98] and hit and
    /// miss must change the log-odds by at least 1/64.
    pub fn validate(&self) -> Result<()> {
        let bad = |what, value, reason| {
            Err(FrontierError::InvalidConfig {
                what,
                value,
                reason,
            })
        };
        if !(self.resolution.is_finite() && self.resolution > 0.0) {
            return bad(
                "resolution",
                self.resolution,
                "must be positive and finite [m]",
            );
        }
        let p = storable;
        if !(p(self.prob_hit) && self.prob_hit > 0.5 && quantize(logit(self.prob_hit)) > 0) {
            return bad("prob_hit", self.prob_hit, "must be in (0.504, 0.98]");
        }
        if !(p(self.prob_miss) && self.prob_miss < 0.5 && quantize(logit(self.prob_miss)) < 0) {
            return bad("prob_miss", self.prob_miss, "must be in [0.02, 0.496)");
        }
        if !(p(self.clamp_min) && self.clamp_min <= self.prob_miss) {
            return bad("clamp_min", self.clamp_min, "must be in [0.02, prob_miss]");
        }
        if !(p(self.clamp_max) && self.clamp_max >= self.prob_hit) {
            return bad("clamp_max", self.clamp_max, "must be in [prob_hit, 0.98]");
        }
        if !(self.max_range.is_finite() && self.max_range > 0.0) {
            return bad(
                "max_range",
                self.max_range,
                "must be positive and finite [m]",
            );
        }
        Ok(())
    }
}

/// An inclusive box of cells.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CellBox {
    /// Lowest cell on every axis.
    pub min: Cell,
    /// Highest cell on every axis.
    pub max: Cell,
}

impl CellBox {
    fn point(c: Cell) -> Self {
        Self { min: c, max: c }
    }

    fn grow(&mut self, c: Cell) {
        self.min = Cell::new(
            self.min.x.min(c.x),
            self.min.y.min(c.y),
            self.min.z.min(c.z),
        );
        self.max = Cell::new(
            self.max.x.max(c.x),
            self.max.y.max(c.y),
            self.max.z.max(c.z),
        );
    }

    /// Whether `c` is inside the box.
    pub fn contains(&self, c: Cell) -> bool {
        (self.min.x..=self.max.x).contains(&c.x)
            && (self.min.y..=self.max.y).contains(&c.y)
            && (self.min.z..=self.max.z).contains(&c.z)
    }
}

/// A cell whose state changed in a frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CellChange {
    /// The cell.
    pub cell: Cell,
    /// Its state before the frame.
    pub before: CellState,
    /// Its state after the frame.
    pub after: CellState,
}

/// What inserting one frame did: the input for incremental frontier updates.
///
/// Bad points are counted and skipped, never an error: NaN or infinite points in
/// `skipped_non_finite`; rays leaving the map bounds are cut at the boundary (free space up to
/// it, no hit) and counted in `clipped`; rays longer than the range are cut at the range and
/// counted in `truncated`.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct FrameUpdate {
    /// Cells whose state changed, each once, in the order they were updated.
    pub changed: Vec<CellChange>,
    /// The box of every cell updated (changed or not), `None` for an empty frame.
    pub bbox: Option<CellBox>,
    /// Rays inserted.
    pub rays: usize,
    /// Cells updated as hits.
    pub hit_cells: usize,
    /// Cells updated as misses (each at most once per frame).
    pub free_cells: usize,
    /// Points skipped for being NaN or infinite.
    pub skipped_non_finite: usize,
    /// Rays cut at the map bounds.
    pub clipped: usize,
    /// Rays cut at the maximum range.
    pub truncated: usize,
}

/// A sparse log-odds occupancy map over fixed bounds.
///
/// Storage is a directory of 8 × 8 × 8-cell blocks over the bounds; a block is allocated when
/// a ray first touches it, and holds one `i8` log-odds value (units of 1/32) per cell: 1 byte
/// per cell, see [`VoxelMap::memory_bytes`]. Rays are inserted by 3-D DDA, each cell updated at
/// most once per frame (a hit wins over a miss, as in OctoMap).
///
/// # Example
/// ```
/// use frontier::{Bounds, CellState, MapConfig, VoxelMap};
/// use nalgebra::Point3;
///
/// let bounds = Bounds::new(Point3::new(0.0, 0.0, 0.0), Point3::new(10.0, 10.0, 3.0)).unwrap();
/// let mut map = VoxelMap::new(bounds, MapConfig::default()).unwrap();
/// let origin = Point3::new(1.0, 1.0, 1.0);
/// let update = map.insert_frame(&origin, &[Point3::new(5.0, 1.0, 1.0)]).unwrap();
/// assert_eq!(map.state(&Point3::new(5.0, 1.0, 1.0)), CellState::Occupied);
/// assert_eq!(map.state(&Point3::new(3.0, 1.0, 1.0)), CellState::Free);
/// assert_eq!(map.state(&Point3::new(3.0, 5.0, 1.0)), CellState::Unknown);
/// assert!(update.changed.len() > 10);
/// ```
#[derive(Debug, Clone)]
pub struct VoxelMap {
    config: MapConfig,
    grid: Grid,
    hit: i8,
    miss: i8,
    lo: i8,
    hi: i8,
    block_dims: [u32; 3],
    /// Block slot per directory entry, or `NO_BLOCK`.
    directory: Vec<u32>,
    /// The log-odds of each allocated block's cells.
    cells: Vec<[i8; BLOCK_CELLS]>,
    /// Known and occupied cells per allocated block.
    known: Vec<u16>,
    occupied: Vec<u16>,
    /// Per-frame marks, one bit per cell updated in this frame; a block's marks are valid
    /// while its epoch is the current frame.
    epoch: Vec<u32>,
    marks: Vec<[u64; WORDS]>,
    frame: u32,
    rays: Vec<(Point3<f64>, bool)>,
}

/// Where a cell lives: block slot and index inside the block.
#[derive(Clone, Copy)]
struct Slot {
    block: usize,
    index: usize,
}

impl VoxelMap {
    /// An empty (all unknown) map over `bounds`.
    ///
    /// # Errors
    /// The first invalid setting of `config` (see [`MapConfig::validate`]), or
    /// [`FrontierError::TooManyCells`].
    pub fn new(bounds: Bounds, config: MapConfig) -> Result<Self> {
        config.validate()?;
        let grid = Grid::new(bounds, config.resolution)?;
        let dims = grid.dims();
        let block_dims = dims.map(|n| n.div_ceil(BLOCK_EDGE));
        let blocks = block_dims.iter().map(|&b| b as usize).product::<usize>();
        Ok(Self {
            hit: quantize(logit(config.prob_hit)),
            miss: quantize(logit(config.prob_miss)),
            lo: quantize(logit(config.clamp_min)),
            hi: quantize(logit(config.clamp_max)),
            config,
            grid,
            block_dims,
            directory: vec![NO_BLOCK; blocks],
            cells: Vec::new(),
            known: Vec::new(),
            occupied: Vec::new(),
            epoch: Vec::new(),
            marks: Vec::new(),
            frame: 0,
            rays: Vec::new(),
        })
    }

    /// The settings.
    pub fn config(&self) -> &MapConfig {
        &self.config
    }

    /// The cell grid (bounds, resolution, cell counts, conversions).
    pub fn grid(&self) -> &Grid {
        &self.grid
    }

    /// The map bounds.
    pub fn bounds(&self) -> &Bounds {
        self.grid.bounds()
    }

    #[inline]
    fn directory_index(&self, c: Cell) -> usize {
        let [bx, by, _] = self.block_dims;
        let (x, y, z) = (c.x >> BLOCK_BITS, c.y >> BLOCK_BITS, c.z >> BLOCK_BITS);
        x as usize + bx as usize * (y as usize + by as usize * z as usize)
    }

    #[inline]
    fn index_in_block(c: Cell) -> usize {
        ((c.x & BLOCK_MASK)
            | ((c.y & BLOCK_MASK) << BLOCK_BITS)
            | ((c.z & BLOCK_MASK) << (2 * BLOCK_BITS))) as usize
    }

    #[inline]
    fn slot(&self, c: Cell) -> Option<Slot> {
        let b = *self.directory.get(self.directory_index(c))?;
        (b != NO_BLOCK).then_some(Slot {
            block: b as usize,
            index: Self::index_in_block(c),
        })
    }

    fn state_of(v: i8) -> CellState {
        if v == UNKNOWN {
            CellState::Unknown
        } else if v >= 0 {
            CellState::Occupied
        } else {
            CellState::Free
        }
    }

    /// The state of a cell; [`CellState::Unknown`] outside the grid.
    #[inline]
    pub fn cell_state(&self, c: Cell) -> CellState {
        let [nx, ny, nz] = self.grid.dims();
        if c.x >= nx || c.y >= ny || c.z >= nz {
            return CellState::Unknown;
        }
        match self.slot(c) {
            Some(s) => Self::state_of(self.cells[s.block][s.index]),
            None => CellState::Unknown,
        }
    }

    /// The state at a point; [`CellState::Unknown`] outside the bounds or for NaN.
    pub fn state(&self, p: &Point3<f64>) -> CellState {
        self.grid
            .cell_of(p)
            .map_or(CellState::Unknown, |c| self.cell_state(c))
    }

    /// The occupancy probability of a cell, `None` if it is unknown or outside the grid.
    pub fn probability(&self, c: Cell) -> Option<f64> {
        if self.cell_state(c) == CellState::Unknown {
            return None;
        }
        let s = self.slot(c)?;
        let l = f64::from(self.cells[s.block][s.index]) / SCALE;
        Some(1.0 / (1.0 + (-l).exp()))
    }

    /// Number of observed (free or occupied) cells.
    pub fn known_cells(&self) -> usize {
        self.known.iter().map(|&k| usize::from(k)).sum()
    }

    /// Number of occupied cells.
    pub fn occupied_cells(&self) -> usize {
        self.occupied.iter().map(|&k| usize::from(k)).sum()
    }

    /// Number of allocated blocks (8 × 8 × 8 cells each).
    pub fn allocated_blocks(&self) -> usize {
        self.known.len()
    }

    /// Bytes the map holds on the heap: cell storage (1 byte per cell of an allocated block),
    /// the block directory, per-block counters, the per-frame marks and the ray buffer.
    pub fn memory_bytes(&self) -> usize {
        use core::mem::size_of;
        self.cells.capacity() * size_of::<[i8; BLOCK_CELLS]>()
            + self.directory.capacity() * size_of::<u32>()
            + (self.known.capacity() + self.occupied.capacity()) * size_of::<u16>()
            + self.epoch.capacity() * size_of::<u32>()
            + self.marks.capacity() * size_of::<[u64; WORDS]>()
            + self.rays.capacity() * size_of::<(Point3<f64>, bool)>()
    }

    fn allocate(&mut self, dir: usize) -> usize {
        let b = self.known.len();
        // Block counts are bounded by the directory, far below u32::MAX.
        #[allow(clippy::cast_possible_truncation)]
        {
            self.directory[dir] = b as u32;
        }
        if self.cells.capacity() == self.cells.len() {
            // Grow by a quarter rather than double: cell storage dominates the map's memory.
            let more = (self.cells.len() / 4).max(16);
            self.cells.reserve_exact(more);
            self.marks.reserve_exact(more);
        }
        self.cells.push([UNKNOWN; BLOCK_CELLS]);
        self.known.push(0);
        self.occupied.push(0);
        self.epoch.push(0);
        self.marks.push([0; WORDS]);
        b
    }

    /// The block behind directory entry `dir`, allocated if needed, with its marks valid for
    /// this frame.
    #[inline]
    fn frame_block(&mut self, dir: usize) -> usize {
        let b = match self.directory[dir] {
            NO_BLOCK => self.allocate(dir),
            b => b as usize,
        };
        if self.epoch[b] != self.frame {
            self.epoch[b] = self.frame;
            self.marks[b] = [0; WORDS];
        }
        b
    }

    /// Applies one hit or miss to a cell of block `b`; returns the change, if any.
    #[inline(always)]
    fn apply(&mut self, b: usize, index: usize, hit: bool) -> Option<(CellState, CellState)> {
        let v = &mut self.cells[b][index];
        let old = *v;
        let new = match (old == UNKNOWN, hit) {
            (true, true) => self.hit.min(self.hi),
            (true, false) => self.miss.max(self.lo),
            (false, true) => old.saturating_add(self.hit).min(self.hi),
            (false, false) => old.saturating_add(self.miss).max(self.lo),
        };
        *v = new;
        let (before, after) = (Self::state_of(old), Self::state_of(new));
        if before == after {
            return None;
        }
        if before == CellState::Unknown {
            self.known[b] += 1;
        }
        if before == CellState::Occupied {
            self.occupied[b] -= 1;
        }
        if after == CellState::Occupied {
            self.occupied[b] += 1;
        }
        Some((before, after))
    }

    /// Inserts one frame: a sensor origin and the measured points, both in the world frame \[m\].
    ///
    /// Every cell a ray passes through before its end point is updated as free, the end point's
    /// cell as occupied; rays longer than [`MapConfig::max_range`] clear free space up to the
    /// range and mark no hit; rays leaving the bounds stop there and mark no hit. Each cell is
    /// updated at most once per frame, a hit taking precedence over a miss.
    ///
    /// # Errors
    /// [`FrontierError::NonFinite`] for a NaN or infinite origin,
    /// [`FrontierError::OriginOutsideBounds`] for an origin outside the bounds. Bad points are
    /// counted and skipped (see [`FrameUpdate`]).
    pub fn insert_frame(
        &mut self,
        origin: &Point3<f64>,
        points: &[Point3<f64>],
    ) -> Result<FrameUpdate> {
        if !origin.iter().all(|v| v.is_finite()) {
            return Err(FrontierError::NonFinite {
                what: "sensor origin",
            });
        }
        if !self.grid.bounds().contains(origin) {
            return Err(FrontierError::OriginOutsideBounds);
        }
        self.frame = self.frame.wrapping_add(1);
        if self.frame == 0 {
            // Epochs wrapped: forget every old mark.
            self.epoch.fill(0);
            self.frame = 1;
        }
        let mut out = FrameUpdate::default();
        let mut rays = core::mem::take(&mut self.rays);
        rays.clear();
        let range = self.config.max_range;
        for p in points {
            if !p.iter().all(|v| v.is_finite()) {
                out.skipped_non_finite += 1;
                continue;
            }
            let d = p - origin;
            let len = d.norm();
            let (mut end, mut hit) = (*p, true);
            if len > range {
                end = origin + d * (range / len);
                hit = false;
                out.truncated += 1;
            }
            if !self.grid.bounds().contains(&end) {
                let t1 = self.grid.clip(origin, &end).map_or(0.0, |(_, t1)| t1);
                end = origin + (end - origin) * t1;
                hit = false;
                out.clipped += 1;
            }
            rays.push((end, hit));
        }
        out.rays = rays.len();
        // The cells of a segment lie in the box of its end cells.
        let oc = self.grid.clamp_cell(self.grid.grid_coords(origin));
        let mut bbox = CellBox::point(oc);
        for (end, _) in &rays {
            bbox.grow(self.grid.clamp_cell(self.grid.grid_coords(end)));
        }
        if !rays.is_empty() {
            out.bbox = Some(bbox);
        }
        // Hits first, so a cell hit in this frame is not also cleared by another ray.
        for &(end, hit) in &rays {
            if hit {
                let c = self.grid.clamp_cell(self.grid.grid_coords(&end));
                let b = self.frame_block(self.directory_index(c));
                self.mark_and_apply(b, c, true, &mut out);
            }
        }
        // Walk rays in the order of their end blocks (Morton order): neighbouring rays share
        // blocks and cache lines, whatever order the sensor delivered them in.
        let grid = self.grid;
        rays.sort_by_cached_key(|(end, _)| morton(grid.clamp_cell(grid.grid_coords(end))));
        for (end, _) in &rays {
            self.walk_free(origin, end, &mut out);
        }
        self.rays = rays;
        Ok(out)
    }

    /// Updates every cell from `origin` to `end` as free, unless this frame updated it already.
    fn walk_free(&mut self, origin: &Point3<f64>, end: &Point3<f64>, out: &mut FrameUpdate) {
        let mut w = BlockWalk::new(self, origin, end);
        let mut b = self.frame_block(w.dir);
        self.mark_and_apply(b, w.walk.cell(), false, out);
        while let Some(entered) = w.advance() {
            if entered {
                b = self.frame_block(w.dir);
            }
            self.mark_and_apply(b, w.walk.cell(), false, out);
        }
    }

    /// Updates cell `c` of block `b` unless this frame updated it already.
    #[inline(always)]
    fn mark_and_apply(&mut self, b: usize, c: Cell, hit: bool, out: &mut FrameUpdate) {
        let i = Self::index_in_block(c);
        let (w, bit) = (i >> 6, 1u64 << (i & 63));
        let marks = &mut self.marks[b][w];
        if *marks & bit != 0 {
            return;
        }
        *marks |= bit;
        if hit {
            out.hit_cells += 1;
        } else {
            out.free_cells += 1;
        }
        if let Some((before, after)) = self.apply(b, i, hit) {
            out.changed.push(CellChange {
                cell: c,
                before,
                after,
            });
        }
    }

    /// Whether the segment from `a` to `b` passes only through known-free cells (both end cells
    /// included); `false` if either point is outside the bounds or not finite.
    pub fn line_of_sight(&self, a: &Point3<f64>, b: &Point3<f64>) -> bool {
        if !(self.grid.bounds().contains(a) && self.grid.bounds().contains(b)) {
            return false;
        }
        traverse(&self.grid, a, b, |c| self.cell_state(c) == CellState::Free)
    }

    /// Whether a cell between `from` and the cell `target` blocks the view: an occupied cell, or
    /// also an unknown one when `unknown_occludes`. The cells of `from` and of `target` are not
    /// tested. `from` must be finite and inside the bounds.
    pub(crate) fn occluded(
        &self,
        from: &Point3<f64>,
        target: Cell,
        unknown_occludes: bool,
    ) -> bool {
        let to = self.grid.center(target);
        let mut w = BlockWalk::new(self, from, &to);
        let block = |dir: usize| match self.directory[dir] {
            NO_BLOCK => None,
            b => Some(b as usize),
        };
        let mut base = block(w.dir);
        // The first cell (the viewpoint's) is not tested; the last one is the target.
        while let Some(entered) = w.advance() {
            if entered {
                base = block(w.dir);
            }
            let c = w.walk.cell();
            if c == target {
                break;
            }
            let v = base.map_or(UNKNOWN, |b| self.cells[b][Self::index_in_block(c)]);
            let blocked = if v == UNKNOWN {
                unknown_occludes
            } else {
                v >= 0
            };
            if blocked {
                return true;
            }
        }
        false
    }

    /// Distance from `p` to the nearest occupied cell (to the closest point of its cube) \[m\],
    /// capped at `cap`. Unknown cells are not obstacles. A point outside the bounds or not
    /// finite has clearance 0; a negative or NaN `cap` gives 0.
    ///
    /// Blocks without occupied cells are skipped whole, so open space is cheap.
    pub fn clearance(&self, p: &Point3<f64>, cap: f64) -> f64 {
        self.nearest_occupied(p, cap, false)
    }

    /// Whether no occupied cell lies within `distance` of `p` \[m\] (the clearance is at least
    /// `distance`); `false` outside the bounds or for a non-finite point. Stops at the first
    /// occupied cell that is too close, so it is cheaper than [`VoxelMap::clearance`].
    pub fn is_clear(&self, p: &Point3<f64>, distance: f64) -> bool {
        if distance.is_nan() || distance <= 0.0 {
            return self.grid.cell_of(p).is_some();
        }
        self.nearest_occupied(p, distance, true) >= distance
    }

    /// The clearance capped at `cap`; with `first`, returns as soon as one occupied cell is
    /// closer than `cap`.
    fn nearest_occupied(&self, p: &Point3<f64>, cap: f64, first: bool) -> f64 {
        if self.grid.cell_of(p).is_none() || cap.is_nan() || cap <= 0.0 {
            return 0.0;
        }
        let res = self.grid.resolution();
        let g = self.grid.grid_coords(p);
        let dims = self.grid.dims();
        // Only cells whose cube comes within `cap` of p: floor((p ± cap) / res), clamped.
        let r = cap / res;
        let span = |k: usize, v: f64| {
            // Clamped into the grid, so the cast is exact.
            #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
            let c = v.floor().clamp(0.0, f64::from(dims[k] - 1)) as u32;
            c
        };
        let lo = [0, 1, 2].map(|k| span(k, g[k] - r));
        let hi = [0, 1, 2].map(|k| span(k, g[k] + r));
        let mut best2 = cap * cap;
        for bz in lo[2] >> BLOCK_BITS..=hi[2] >> BLOCK_BITS {
            for by in lo[1] >> BLOCK_BITS..=hi[1] >> BLOCK_BITS {
                for bx in lo[0] >> BLOCK_BITS..=hi[0] >> BLOCK_BITS {
                    let corner = Cell::new(bx << BLOCK_BITS, by << BLOCK_BITS, bz << BLOCK_BITS);
                    let Some(s) = self.slot(corner) else { continue };
                    if self.occupied[s.block] == 0 {
                        continue;
                    }
                    let cells = &self.cells[s.block];
                    let r = |b: u32, k: usize| {
                        let start = (b << BLOCK_BITS).max(lo[k]);
                        let end = ((b << BLOCK_BITS) + BLOCK_MASK).min(hi[k]);
                        start..=end
                    };
                    for z in r(bz, 2) {
                        for y in r(by, 1) {
                            for x in r(bx, 0) {
                                let c = Cell::new(x, y, z);
                                let v = cells[Self::index_in_block(c)];
                                if Self::state_of(v) != CellState::Occupied {
                                    continue;
                                }
                                let d = box_distance2(&g, c) * res * res;
                                best2 = best2.min(d);
                                if first && best2 < cap * cap {
                                    return best2.sqrt();
                                }
                            }
                        }
                    }
                }
            }
        }
        best2.sqrt().min(cap)
    }

    /// Calls `f` for every known cell with its state, block by block.
    pub fn for_each_known(&self, mut f: impl FnMut(Cell, CellState)) {
        let [bx, by, _] = self.block_dims;
        for (dir, &b) in self.directory.iter().enumerate() {
            if b == NO_BLOCK {
                continue;
            }
            // Directory indices are below bx·by·bz, which fits the u32 cell coordinates.
            #[allow(clippy::cast_possible_truncation)]
            let (x0, y0, z0) = (
                (dir % bx as usize) as u32,
                ((dir / bx as usize) % by as usize) as u32,
                (dir / (bx as usize * by as usize)) as u32,
            );
            for (i, &v) in self.cells[b as usize].iter().enumerate() {
                if v == UNKNOWN {
                    continue;
                }
                #[allow(clippy::cast_possible_truncation)]
                let i = i as u32;
                let c = Cell::new(
                    (x0 << BLOCK_BITS) | (i & BLOCK_MASK),
                    (y0 << BLOCK_BITS) | ((i >> BLOCK_BITS) & BLOCK_MASK),
                    (z0 << BLOCK_BITS) | (i >> (2 * BLOCK_BITS)),
                );
                f(c, Self::state_of(v));
            }
        }
    }
}

/// A DDA walk that also follows the directory entry of the block it is in, so the cells of a
/// ray are found without a directory lookup per cell.
struct BlockWalk {
    walk: Walk,
    dir: usize,
    stride: [usize; 3],
    /// The in-block coordinate at which a step along each axis has entered a new block.
    wrap: [u32; 3],
}

impl BlockWalk {
    #[inline]
    fn new(map: &VoxelMap, a: &Point3<f64>, b: &Point3<f64>) -> Self {
        let walk = Walk::new(&map.grid, a, b);
        let [bx, by, _] = map.block_dims.map(|v| v as usize);
        Self {
            dir: map.directory_index(walk.cell()),
            stride: [1, bx, bx * by],
            wrap: walk.step.map(|s| if s > 0 { 0 } else { BLOCK_MASK }),
            walk,
        }
    }

    /// Steps into the next cell: `Some(true)` if it lies in another block than the last,
    /// `None` at the end.
    #[inline(always)]
    fn advance(&mut self) -> Option<bool> {
        let k = self.walk.advance()?;
        let coord = match k {
            0 => self.walk.x,
            1 => self.walk.y,
            _ => self.walk.z,
        };
        let entered = coord & BLOCK_MASK == self.wrap[k];
        if entered {
            self.dir = if self.walk.step[k] > 0 {
                self.dir + self.stride[k]
            } else {
                self.dir - self.stride[k]
            };
        }
        Some(entered)
    }
}

/// The Morton (Z-order) code of a cell's block.
fn morton(c: Cell) -> u64 {
    fn spread(v: u32) -> u64 {
        // Interleave the 21 low bits of v with two zero bits each.
        let mut x = u64::from(v) & 0x1f_ffff;
        x = (x | (x << 32)) & 0x001f_0000_0000_ffff;
        x = (x | (x << 16)) & 0x001f_0000_ff00_00ff;
        x = (x | (x << 8)) & 0x100f_00f0_0f00_f00f;
        x = (x | (x << 4)) & 0x10c3_0c30_c30c_30c3;
        x = (x | (x << 2)) & 0x1249_2492_4924_9249;
        x
    }
    spread(c.x >> BLOCK_BITS) | (spread(c.y >> BLOCK_BITS) << 1) | (spread(c.z >> BLOCK_BITS) << 2)
}

/// Squared distance, in cell units, from grid point `g` to the cube of cell `c`.
fn box_distance2(g: &Vector3<f64>, c: Cell) -> f64 {
    let d = |v: f64, k: u32| {
        let lo = f64::from(k);
        (lo - v).max(0.0).max(v - lo - 1.0)
    };
    let (dx, dy, dz) = (d(g.x, c.x), d(g.y, c.y), d(g.z, c.z));
    dx * dx + dy * dy + dz * dz
}

#[cfg(test)]
mod tests {
    use super::*;

    fn map() -> VoxelMap {
        let b = Bounds::new(Point3::new(0.0, 0.0, 0.0), Point3::new(8.0, 6.0, 3.0)).unwrap();
        VoxelMap::new(b, MapConfig::default()).unwrap()
    }

    #[test]
    fn config_validation() {
        assert!(MapConfig::default().validate().is_ok());
        let bad = [
            MapConfig {
                resolution: -0.1,
                ..Default::default()
            },
            MapConfig {
                prob_hit: 0.5,
                ..Default::default()
            },
            MapConfig {
                prob_hit: 0.5001,
                ..Default::default()
            },
            MapConfig {
                prob_miss: 0.6,
                ..Default::default()
            },
            MapConfig {
                clamp_min: 0.45,
                ..Default::default()
            },
            MapConfig {
                clamp_max: 0.6,
                ..Default::default()
            },
            MapConfig {
                max_range: f64::INFINITY,
                ..Default::default()
            },
            MapConfig {
                prob_hit: f64::NAN,
                ..Default::default()
            },
        ];
        for c in bad {
            assert!(
                matches!(c.validate(), Err(FrontierError::InvalidConfig { .. })),
                "{c:?}"
            );
        }
    }

    #[test]
    fn repeated_hits_clamp_and_misses_clear() {
        let mut m = map();
        let o = Point3::new(1.0, 1.0, 1.0);
        let p = Point3::new(4.05, 1.05, 1.05);
        let c = m.grid().cell_of(&p).unwrap();
        for _ in 0..20 {
            m.insert_frame(&o, &[p]).unwrap();
        }
        let pmax = m.probability(c).unwrap();
        assert!((pmax - 0.971).abs() < 1e-3, "{pmax}");
        // Passing through clears it again after enough misses.
        let far = Point3::new(6.05, 1.05, 1.05);
        let mut frames = 0;
        while m.cell_state(c) == CellState::Occupied {
            m.insert_frame(&o, &[far]).unwrap();
            frames += 1;
            assert!(frames < 100);
        }
        assert!(frames > 3);
    }

    #[test]
    fn one_update_per_cell_per_frame_and_hit_wins() {
        let mut m = map();
        let o = Point3::new(1.0, 1.0, 1.0);
        // Two rays through the same cells; the first ends where the second passes.
        let a = Point3::new(3.05, 1.05, 1.05);
        let b = Point3::new(5.05, 1.05, 1.05);
        let u = m.insert_frame(&o, &[a, b, b]).unwrap();
        assert_eq!(m.state(&a), CellState::Occupied);
        assert_eq!(u.hit_cells, 2);
        let free_once = m.grid().cell_of(&Point3::new(2.0, 1.05, 1.05)).unwrap();
        let l = m.probability(free_once).unwrap();
        assert!((l - 0.4).abs() < 1e-3, "{l}");
        assert_eq!(u.changed.len(), u.hit_cells + u.free_cells);
    }

    #[test]
    fn bad_points_are_counted_and_skipped() {
        let mut m = map();
        let o = Point3::new(1.0, 1.0, 1.0);
        let pts = [
            Point3::new(f64::NAN, 1.0, 1.0),
            Point3::new(f64::INFINITY, 1.0, 1.0),
            Point3::new(20.0, 1.0, 1.0),
            Point3::new(1.0, 1.0, 40.0),
        ];
        let u = m.insert_frame(&o, &pts).unwrap();
        assert_eq!(u.skipped_non_finite, 2);
        assert_eq!(u.rays, 2);
        assert_eq!(u.clipped, 2);
        assert_eq!(u.truncated, 1);
        assert_eq!(u.hit_cells, 0);
        assert_eq!(m.state(&Point3::new(7.9, 1.0, 1.0)), CellState::Free);
        assert!(matches!(
            m.insert_frame(&Point3::new(f64::NAN, 0.0, 0.0), &[]),
            Err(FrontierError::NonFinite { .. })
        ));
        assert_eq!(
            m.insert_frame(&Point3::new(-1.0, 0.0, 0.0), &[]),
            Err(FrontierError::OriginOutsideBounds)
        );
        let empty = m.insert_frame(&o, &[]).unwrap();
        assert_eq!(empty.bbox, None);
        assert!(empty.changed.is_empty());
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(64))]

        #[test]
        fn clearance_equals_brute_force(
            hits in proptest::collection::vec((0.5f64..7.5, 0.5f64..5.5, 0.2f64..2.8), 1..30),
            q in (0.0f64..8.0, 0.0f64..6.0, 0.0f64..3.0),
            cap in 0.05f64..2.0,
        ) {
            let mut m = map();
            let o = Point3::new(4.0, 3.0, 1.5);
            let pts: Vec<_> = hits.iter().map(|&(x, y, z)| Point3::new(x, y, z)).collect();
            m.insert_frame(&o, &pts).unwrap();
            let p = Point3::new(q.0, q.1, q.2);
            let g = m.grid().grid_coords(&p);
            let mut truth = f64::INFINITY;
            m.for_each_known(|c, s| {
                if s == CellState::Occupied {
                    truth = truth.min(box_distance2(&g, c).sqrt() * m.grid().resolution());
                }
            });
            let want = truth.min(cap);
            let got = m.clearance(&p, cap);
            proptest::prop_assert!((got - want).abs() < 1e-9, "{} vs {}", got, want);
            // Exactly at the clearance the answer is up to rounding: test just either side.
            for d in [0.5 * cap, cap, truth * (1.0 - 1e-9), truth * (1.0 + 1e-9)] {
                if d.is_finite() && (d - truth).abs() > 1e-12 {
                    proptest::prop_assert_eq!(m.is_clear(&p, d), truth >= d);
                }
            }
        }
    }

    #[test]
    fn clearance_and_line_of_sight() {
        let mut m = map();
        let o = Point3::new(1.0, 1.0, 1.0);
        let wall: Vec<_> = (0..30)
            .flat_map(|i| {
                (0..15).map(move |k| {
                    Point3::new(5.1, f64::from(i) * 0.2 + 0.01, f64::from(k) * 0.2 + 0.01)
                })
            })
            .collect();
        m.insert_frame(&o, &wall).unwrap();
        // The wall's cells span x ∈ [5.0, 5.2).
        let c = m.clearance(&Point3::new(4.0, 1.0, 1.0), 3.0);
        assert!((c - 1.0).abs() < 1e-9, "{c}");
        assert_eq!(m.clearance(&Point3::new(1.0, 1.0, 1.0), 0.5), 0.5);
        assert_eq!(m.clearance(&Point3::new(-1.0, 1.0, 1.0), 0.5), 0.0);
        assert!(m.line_of_sight(&o, &Point3::new(4.5, 1.0, 1.0)));
        assert!(!m.line_of_sight(&o, &Point3::new(5.5, 1.0, 1.0)));
        assert!(!m.line_of_sight(&o, &Point3::new(1.0, 5.0, 1.0)));
        let behind = m.grid().cell_of(&Point3::new(6.0, 1.0, 1.0)).unwrap();
        assert!(m.occluded(&o, behind, false));
        let before = m.grid().cell_of(&Point3::new(4.0, 1.0, 1.0)).unwrap();
        assert!(!m.occluded(&o, before, true));
        assert!(m.known_cells() > 0);
        assert_eq!(m.occupied_cells(), 30 * 15);
        let mut n = 0;
        m.for_each_known(|c, s| {
            n += 1;
            assert_eq!(m.cell_state(c), s);
        });
        assert_eq!(n, m.known_cells());
    }
}
