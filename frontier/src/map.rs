//! The sparse block-based log-odds occupancy map.

use nalgebra::{Point3, Vector3};

use crate::grid::{Bounds, Cell, Grid};
use crate::raycast::{Walk, traverse};
use crate::{FrontierError, Result};

/// Cells per block edge (blocks hold 8 × 8 × 8 cells).
pub(crate) const BLOCK_BITS: u32 = 3;
const BLOCK_EDGE: u32 = 1 << BLOCK_BITS;
pub(crate) const BLOCK_MASK: u32 = BLOCK_EDGE - 1;
pub(crate) const BLOCK_CELLS: usize = 1 << (3 * BLOCK_BITS);
pub(crate) const NO_BLOCK: u32 = u32::MAX;
/// Layers of 64 cells per block (one `u64` of per-frame marks each).
const LAYERS: usize = BLOCK_CELLS / 64;
/// Largest per-frame mark bitsets, in words (16 MiB, three bits per cell of the frame's box);
/// larger frames are marked slab by slab.
const MAX_FRAME_WORDS: usize = 1 << 21;
/// Frames of at least this many rays are marked by two threads.
const PARALLEL_RAYS: usize = 4096;

/// Largest number of 8 × 8 × 8-cell blocks a [`VoxelMap`] may cover: 2^30 (2^26 where pointers
/// are narrower than 64 bits).
///
/// The map keeps a 4-byte directory entry for every block of its bounds, allocated up front
/// (4 GiB at the limit, and as much again for a [`Frontiers`](crate::Frontiers) tracking it):
/// 2^30 blocks are 2^39 cells, e.g. 5 km × 5 km × 100 m at 0.2 m.
pub const MAX_BLOCKS: u64 = if usize::BITS >= 64 { 1 << 30 } else { 1 << 26 };

/// Log-odds are stored as `i8` in units of 1/32: one byte per cell, probabilities up to
/// 1 − 0.019 (log-odds ±3.97), steps of 0.03 in log-odds.
const SCALE: f64 = 32.0;
/// Largest stored magnitude (the value −128 means unknown).
const MAX_Q: f64 = 127.0;
/// The stored value of a cell never observed.
const UNKNOWN: i8 = i8::MIN;
/// The values of a block never allocated: every cell unknown.
static ALL_UNKNOWN: [i8; BLOCK_CELLS] = [UNKNOWN; BLOCK_CELLS];

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
    /// Cells whose state changed, each once, block by block (a deterministic order).
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
/// most once per frame (a hit wins over a miss, as in OctoMap); see
/// [`VoxelMap::insert_frame`] for how, and [`VoxelMap::scratch_bytes`] for the working memory
/// it keeps.
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
    model: Model,
    block_dims: [u32; 3],
    /// Block slot per directory entry, or `NO_BLOCK`.
    directory: Vec<u32>,
    /// The log-odds of each allocated block's cells.
    cells: Vec<[i8; BLOCK_CELLS]>,
    /// Known and occupied cells per allocated block.
    known: Vec<u16>,
    occupied: Vec<u16>,
    /// Two bits per cell of the frame's box or slab (ray passed, ray ended), block by block:
    /// a block's 8 words of passed marks (one per layer of 64 cells), then its 8 words of hits.
    /// All zero between frames.
    marks: Vec<u64>,
    /// The second thread's marks of the rays passed, one bit per cell, block by block.
    spare: Vec<u64>,
    /// Frames of at least this many rays are split between two threads
    /// ([`PARALLEL_RAYS`]; tests lower it).
    parallel_rays: usize,
    /// The largest mark bitset in words ([`MAX_FRAME_WORDS`]; tests lower it).
    max_frame_words: usize,
    /// The blocks a frame marked: slot, block in the slab, lowest cell.
    work: Vec<(usize, usize, Cell)>,
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
    /// The first invalid setting of `config` (see [`MapConfig::validate`]),
    /// [`FrontierError::TooManyCells`] above [`MAX_CELLS_PER_AXIS`](crate::MAX_CELLS_PER_AXIS)
    /// cells along an axis, or [`FrontierError::TooManyBlocks`] above [`MAX_BLOCKS`] blocks.
    pub fn new(bounds: Bounds, config: MapConfig) -> Result<Self> {
        config.validate()?;
        let grid = Grid::new(bounds, config.resolution)?;
        let dims = grid.dims();
        let block_dims = dims.map(|n| n.div_ceil(BLOCK_EDGE));
        // At most 2^17 blocks per axis: the product fits u64, and the directory must fit memory.
        let blocks = block_dims.iter().map(|&b| u64::from(b)).product::<u64>();
        if blocks > MAX_BLOCKS {
            return Err(FrontierError::TooManyBlocks {
                blocks,
                max: MAX_BLOCKS,
            });
        }
        // Below MAX_BLOCKS, so the cast is exact.
        #[allow(clippy::cast_possible_truncation)]
        let blocks = blocks as usize;
        Ok(Self {
            model: Model {
                hit: quantize(logit(config.prob_hit)),
                miss: quantize(logit(config.prob_miss)),
                lo: quantize(logit(config.clamp_min)),
                hi: quantize(logit(config.clamp_max)),
            },
            config,
            grid,
            block_dims,
            directory: vec![NO_BLOCK; blocks],
            cells: Vec::new(),
            known: Vec::new(),
            occupied: Vec::new(),
            marks: Vec::new(),
            spare: Vec::new(),
            parallel_rays: PARALLEL_RAYS,
            max_frame_words: MAX_FRAME_WORDS,
            work: Vec::new(),
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

    /// The index of a cell in its block: x fastest, then y, then z; each z layer of 64 cells
    /// is one cache line and one word of per-frame marks.
    #[inline]
    pub(crate) fn index_in_block(c: Cell) -> usize {
        ((c.x & BLOCK_MASK)
            | ((c.y & BLOCK_MASK) << BLOCK_BITS)
            | ((c.z & BLOCK_MASK) << (2 * BLOCK_BITS))) as usize
    }

    /// The cell at `index` of the block whose lowest cell is `corner`.
    #[inline]
    pub(crate) fn cell_in_block(corner: Cell, index: u32) -> Cell {
        Cell::new(
            corner.x | (index & BLOCK_MASK),
            corner.y | ((index >> BLOCK_BITS) & BLOCK_MASK),
            corner.z | (index >> (2 * BLOCK_BITS)),
        )
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

    /// Bytes the map's storage holds on the heap: the cells (1 byte per cell of an allocated
    /// block), the block directory and the per-block counters. See also
    /// [`VoxelMap::scratch_bytes`].
    pub fn memory_bytes(&self) -> usize {
        use core::mem::size_of;
        self.cells.capacity() * size_of::<[i8; BLOCK_CELLS]>()
            + self.directory.capacity() * size_of::<u32>()
            + (self.known.capacity() + self.occupied.capacity()) * size_of::<u16>()
    }

    /// Bytes of working memory kept between frames for inserting the next one: the marks of
    /// the largest frame so far (three bits per cell of its box, at most 16 MiB unless one layer
    /// of blocks of the box needs more: 24 bits per cell of the box's x–y extent, e.g. 12 MB
    /// for a frame 100 m across at 5 cm), the list of its blocks and the ray buffer.
    pub fn scratch_bytes(&self) -> usize {
        use core::mem::size_of;
        (self.marks.capacity() + self.spare.capacity()) * size_of::<u64>()
            + self.work.capacity() * size_of::<(usize, usize, Cell)>()
            + self.rays.capacity() * size_of::<(Point3<f64>, bool)>()
    }

    fn allocate(&mut self, dir: usize) -> usize {
        let b = self.known.len();
        // Block counts are bounded by the directory, far below u32::MAX.
        #[allow(clippy::cast_possible_truncation)]
        {
            self.directory[dir] = b as u32;
        }
        self.reserve_blocks(1);
        self.cells.push([UNKNOWN; BLOCK_CELLS]);
        self.known.push(0);
        self.occupied.push(0);
        b
    }

    /// Room for `n` more blocks.
    fn reserve_blocks(&mut self, n: usize) {
        if self.cells.capacity() - self.cells.len() < n {
            // Grow by a quarter rather than double: cell storage dominates the map's memory.
            let more = (self.cells.len() / 4).max(16).max(n);
            self.cells.reserve_exact(more);
        }
    }

    /// Inserts one frame: a sensor origin and the measured points, both in the world frame \[m\].
    ///
    /// Every cell a ray passes through before its end point is updated as free, the end point's
    /// cell as occupied; rays longer than [`MapConfig::max_range`] clear free space up to the
    /// range and mark no hit; rays leaving the bounds stop there and mark no hit. Each cell is
    /// updated at most once per frame, a hit taking precedence over a miss.
    ///
    /// The rays' cells are first marked in a bitset over the frame's box (by 3-D DDA), then
    /// every marked cell is updated once, block by block in storage order. Frames of at least
    /// 4096 rays are marked and updated by two threads of rayon's pool; the result is the
    /// same, bit for bit, for any split and any number of threads. A bitset larger than
    /// 16 MiB is not kept: such frames are marked in slabs of whole block layers (one layer at
    /// the thinnest, see [`VoxelMap::scratch_bytes`]), each walking the rays that reach it.
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
                end = if len.is_finite() {
                    origin + d * (range / len)
                } else {
                    // A point so far out (about 1e154 m and beyond) that its squared distance,
                    // or the offset itself, overflows: the same direction, scaled first.
                    let s = p.coords.amax().max(origin.coords.amax());
                    let u = p.coords / s - origin.coords / s;
                    origin + u * (range / u.norm())
                };
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
        if rays.is_empty() {
            self.rays = rays;
            return Ok(out);
        }
        out.bbox = Some(bbox);
        // The frame's box in blocks, marked in slabs of whole block layers.
        let lo = [bbox.min.x, bbox.min.y, bbox.min.z].map(|v| v >> BLOCK_BITS);
        let hi = [bbox.max.x, bbox.max.y, bbox.max.z].map(|v| v >> BLOCK_BITS);
        let dims = [0, 1, 2].map(|k| (hi[k] - lo[k] + 1) as usize);
        let depth = (self.max_frame_words / (3 * LAYERS * dims[0] * dims[1])).clamp(1, dims[2]);
        // Depths are at most the box's block count along z, a u32.
        #[allow(clippy::cast_possible_truncation)]
        let depth = depth as u32;
        let mut z0 = lo[2];
        while z0 <= hi[2] {
            let z1 = z0.saturating_add(depth - 1).min(hi[2]);
            let slab = Slab {
                lo: [lo[0], lo[1], z0],
                dims: [dims[0], dims[1], (z1 - z0 + 1) as usize],
            };
            self.insert_slab(origin, &rays, &slab, &mut out);
            z0 = z1 + 1;
        }
        self.rays = rays;
        Ok(out)
    }

    /// Updates the cells of a frame that lie in one slab of its box: marks the cells of every
    /// ray, updates the marked cells layer by layer as misses, then the hit cells. Marking
    /// alone keeps the walk in the small bitset; the log-odds are then read and written once
    /// per cell, in memory order.
    fn insert_slab(
        &mut self,
        origin: &Point3<f64>,
        rays: &[(Point3<f64>, bool)],
        slab: &Slab,
        out: &mut FrameUpdate,
    ) {
        let grid = self.grid;
        let mut marks = core::mem::take(&mut self.marks);
        let mut spare = core::mem::take(&mut self.spare);
        marks.resize(2 * LAYERS * slab.blocks(), 0);
        // Large frames are marked and updated by two threads; the union of the marks, and so
        // the result, does not depend on how the work is split.
        let split = rays.len() >= self.parallel_rays;
        if split {
            spare.resize(LAYERS * slab.blocks(), 0);
            let (first, second) = rays.split_at(rays.len() / 2);
            rayon::join(
                || mark_rays(&grid, origin, first, slab, &mut marks, 2 * LAYERS),
                || mark_rays(&grid, origin, second, slab, &mut spare, LAYERS),
            );
        } else {
            mark_rays(&grid, origin, rays, slab, &mut marks, 2 * LAYERS);
        }
        for (end, _) in rays.iter().filter(|(_, hit)| *hit) {
            if let Some((block, layer, bit)) = slab.mark(grid.clamp_cell(grid.grid_coords(end))) {
                marks[2 * LAYERS * block + LAYERS + layer] |= bit;
            }
        }
        let words = |block: usize| {
            let own = &marks[2 * LAYERS * block..2 * LAYERS * (block + 1)];
            let mut passed = [0; LAYERS];
            let mut hits = [0; LAYERS];
            for layer in 0..LAYERS {
                passed[layer] = own[layer];
                hits[layer] = own[LAYERS + layer];
                if split {
                    passed[layer] |= spare[LAYERS * block + layer];
                }
            }
            (passed, hits)
        };
        // The blocks with marks, updated in the order of their storage so that memory is read
        // forwards.
        let mut work = core::mem::take(&mut self.work);
        work.clear();
        for block in 0..slab.blocks() {
            let (passed, hits) = words(block);
            if passed.iter().chain(&hits).fold(0, |a, &m| a | m) == 0 {
                continue;
            }
            let corner = slab.corner(block);
            work.push((
                self.directory[self.directory_index(corner)] as usize,
                block,
                corner,
            ));
        }
        // New blocks, with the storage grown once for all of them.
        let new = work.iter().filter(|w| w.0 == NO_BLOCK as usize).count();
        if new > 0 {
            self.reserve_blocks(new);
            for w in work.iter_mut().filter(|w| w.0 == NO_BLOCK as usize) {
                w.0 = self.allocate(self.directory_index(w.2));
            }
        }
        work.sort_unstable_by_key(|&(b, _, _)| b);
        let model = self.model;
        // Updates the blocks of `work`, whose storage starts at slot `first`.
        let update = |work: &[(usize, usize, Cell)],
                      cells: &mut [[i8; BLOCK_CELLS]],
                      known: &mut [u16],
                      occupied: &mut [u16],
                      first: usize| {
            let mut done = Updated::default();
            // Every marked cell of a block never seen before changes: room for them at once.
            let fresh: usize = work
                .iter()
                .filter(|w| known[w.0 - first] == 0)
                .map(|&(_, block, _)| {
                    let (passed, hits) = words(block);
                    passed
                        .iter()
                        .zip(&hits)
                        .map(|(p, h)| (p | h).count_ones() as usize)
                        .sum::<usize>()
                })
                .sum();
            done.changed.reserve(fresh);
            for &(b, block, corner) in work {
                let (passed, hits) = words(block);
                let mut storage = BlockMut {
                    cells: &mut cells[b - first],
                    known: &mut known[b - first],
                    occupied: &mut occupied[b - first],
                };
                update_block(&mut storage, corner, &passed, &hits, model, &mut done);
            }
            done
        };
        let done = if split && work.len() >= 2 {
            let (first, second) = work.split_at(work.len() / 2);
            let at = second[0].0;
            let (c0, c1) = self.cells.split_at_mut(at);
            let (k0, k1) = self.known.split_at_mut(at);
            let (o0, o1) = self.occupied.split_at_mut(at);
            let (mut a, b) = rayon::join(
                || update(first, c0, k0, o0, 0),
                || update(second, c1, k1, o1, at),
            );
            a.append(b);
            a
        } else {
            update(
                &work,
                &mut self.cells,
                &mut self.known,
                &mut self.occupied,
                0,
            )
        };
        out.free_cells += done.free;
        out.hit_cells += done.hits;
        if out.changed.is_empty() {
            out.changed = done.changed;
        } else {
            out.changed.extend(done.changed);
        }
        for &(_, block, _) in &work {
            marks[2 * LAYERS * block..2 * LAYERS * (block + 1)].fill(0);
            if split {
                spare[LAYERS * block..LAYERS * (block + 1)].fill(0);
            }
        }
        self.work = work;
        self.marks = marks;
        self.spare = spare;
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
        let walk = Walk::new(&self.grid, from, &to);
        let [bx, by, _] = self.block_dims.map(|v| v as usize);
        let entry = self.directory_index(walk.cell());
        let block = |entry: usize| match self.directory[entry] {
            NO_BLOCK => &ALL_UNKNOWN,
            b => &self.cells[b as usize],
        };
        // The first cell (the viewpoint's) and the last (the target) are not tested.
        walk.any_inner(entry, [1, bx, bx * by], block, |v| {
            if v == UNKNOWN {
                unknown_occludes
            } else {
                v >= 0
            }
        })
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
            let corner = Cell::new(x0 << BLOCK_BITS, y0 << BLOCK_BITS, z0 << BLOCK_BITS);
            for (i, &v) in self.cells[b as usize].iter().enumerate() {
                if v == UNKNOWN {
                    continue;
                }
                // Block indices are below 512.
                #[allow(clippy::cast_possible_truncation)]
                let c = Self::cell_in_block(corner, i as u32);
                f(c, Self::state_of(v));
            }
        }
    }
}

/// One slab of a frame's box, in blocks: the part whose marks are held at once, one `u64`
/// per layer of 64 cells, block by block.
struct Slab {
    /// Lowest block on every axis.
    lo: [u32; 3],
    /// Blocks along every axis.
    dims: [usize; 3],
}

impl Slab {
    /// Blocks in the slab.
    fn blocks(&self) -> usize {
        self.dims.iter().product()
    }

    /// The lowest cell of block `block` of the slab.
    fn corner(&self, block: usize) -> Cell {
        let [nx, ny, _] = self.dims;
        // Block coordinates come from u32 cell coordinates.
        #[allow(clippy::cast_possible_truncation)]
        let c = Cell::new(
            (self.lo[0] + (block % nx) as u32) << BLOCK_BITS,
            (self.lo[1] + ((block / nx) % ny) as u32) << BLOCK_BITS,
            (self.lo[2] + (block / (nx * ny)) as u32) << BLOCK_BITS,
        );
        c
    }

    /// The block (in the slab), layer and bit of cell `c`'s mark, `None` outside the slab.
    #[inline(always)]
    fn mark(&self, c: Cell) -> Option<(usize, usize, u64)> {
        let r = |v: u32, k: usize| (v >> BLOCK_BITS).wrapping_sub(self.lo[k]) as usize;
        let (x, y, z) = (r(c.x, 0), r(c.y, 1), r(c.z, 2));
        if x >= self.dims[0] || y >= self.dims[1] || z >= self.dims[2] {
            return None;
        }
        let block = x + self.dims[0] * (y + self.dims[1] * z);
        let i = VoxelMap::index_in_block(c);
        Some((block, i >> 6, 1u64 << (i & 63)))
    }
}

/// Marks the cells of the rays from `origin` to each end that lie in `slab`: the bit of a cell
/// in word `stride · block + layer` of `words`.
fn mark_rays(
    grid: &Grid,
    origin: &Point3<f64>,
    rays: &[(Point3<f64>, bool)],
    slab: &Slab,
    words: &mut [u64],
    stride: usize,
) {
    let oz = grid.clamp_cell(grid.grid_coords(origin)).z >> BLOCK_BITS;
    let (z0, depth) = (slab.lo[2], slab.dims[2]);
    let lo = Cell::new(
        slab.lo[0] << BLOCK_BITS,
        slab.lo[1] << BLOCK_BITS,
        z0 << BLOCK_BITS,
    );
    for (end, _) in rays {
        let ez = grid.clamp_cell(grid.grid_coords(end)).z >> BLOCK_BITS;
        // The cells of a segment lie in the box of its end cells.
        if oz.max(ez) < z0 || (oz.min(ez).max(z0) - z0) as usize >= depth {
            continue;
        }
        Walk::new(grid, origin, end).mark_blocked(lo, [slab.dims[0], slab.dims[1]], stride, words);
    }
}

/// The byte mask of a bit mask: lane `j` is `0xff` when bit `j` is set.
fn expand(mask: u64) -> [u8; 64] {
    /// The eight lanes of each byte of a mask.
    const LANES: [u64; 256] = {
        let mut t = [0u64; 256];
        let mut byte = 0;
        while byte < 256 {
            let mut bit = 0;
            while bit < 8 {
                if byte >> bit & 1 == 1 {
                    t[byte] |= 0xff << (8 * bit);
                }
                bit += 1;
            }
            byte += 1;
        }
        t
    };
    let mut out = [0u8; 64];
    for (lanes, byte) in out.chunks_exact_mut(8).zip(mask.to_le_bytes()) {
        lanes.copy_from_slice(&LANES[usize::from(byte)].to_le_bytes());
    }
    out
}

/// 0 for unknown, 1 for free, 2 for occupied (see [`VoxelMap::state_of`]).
#[inline(always)]
fn class(v: i8) -> u8 {
    u8::from(v != UNKNOWN) + u8::from(v >= 0)
}

/// The quantised sensor model: log-odds steps and clamps, in units of 1/32.
#[derive(Debug, Clone, Copy)]
struct Model {
    hit: i8,
    miss: i8,
    lo: i8,
    hi: i8,
}

/// One block's storage, borrowed for an update.
struct BlockMut<'a> {
    cells: &'a mut [i8; BLOCK_CELLS],
    known: &'a mut u16,
    occupied: &'a mut u16,
}

/// What updating a run of blocks did.
#[derive(Debug, Default)]
struct Updated {
    changed: Vec<CellChange>,
    free: usize,
    hits: usize,
}

impl Updated {
    fn append(&mut self, other: Self) {
        self.changed.extend(other.changed);
        self.free += other.free;
        self.hits += other.hits;
    }
}

/// Updates the marked cells of one block (lowest cell `corner`): a hit for the cells marked
/// in `hits`, a miss for the others marked in `passed` (a hit wins over a miss, as in OctoMap).
fn update_block(
    block: &mut BlockMut<'_>,
    corner: Cell,
    passed: &[u64; LAYERS],
    hits: &[u64; LAYERS],
    model: Model,
    out: &mut Updated,
) {
    // A block with no known cell: every cell is unknown before the update, so the changes are
    // the marks themselves (the values below are those of the general rule for UNKNOWN).
    let fresh = *block.known == 0;
    let (layers, _) = block.cells.as_chunks_mut::<64>();
    for (layer, cells) in layers.iter_mut().enumerate() {
        let (h, m) = (hits[layer], passed[layer] & !hits[layer]);
        if h | m == 0 {
            continue;
        }
        out.hits += h.count_ones() as usize;
        out.free += m.count_ones() as usize;
        if fresh {
            let (hit, missed) = (model.hit.min(model.hi), model.miss.max(model.lo));
            let mut changed = 0;
            if class(hit) != 0 {
                changed |= h;
            }
            if class(missed) != 0 {
                changed |= m;
            }
            let states = [VoxelMap::state_of(missed), VoxelMap::state_of(hit)];
            // At most 64 cells a layer.
            #[allow(clippy::cast_possible_truncation)]
            {
                *block.known += changed.count_ones() as u16;
                *block.occupied += (changed & h).count_ones() as u16
                    * u16::from(states[1] == CellState::Occupied)
                    + (changed & m).count_ones() as u16
                        * u16::from(states[0] == CellState::Occupied);
            }
            while changed != 0 {
                let j = changed.trailing_zeros() as usize;
                changed &= changed - 1;
                let is_hit = usize::from(h >> j & 1 == 1);
                cells[j] = if is_hit == 1 { hit } else { missed };
                let after = states[is_hit];
                // Layer and lane indices are below 512.
                #[allow(clippy::cast_possible_truncation)]
                let index = ((layer << 6) | j) as u32;
                out.changed.push(CellChange {
                    cell: VoxelMap::cell_in_block(corner, index),
                    before: CellState::Unknown,
                    after,
                });
            }
            continue;
        }
        let old = *cells;
        let (hit_lanes, miss_lanes) = (expand(h), expand(m));
        // Lane by lane without branches, so the compiler can use vector instructions.
        let mut changed = [0u8; 64];
        for j in 0..64 {
            let v = old[j];
            let missed = if v == UNKNOWN {
                model.miss.max(model.lo)
            } else {
                v.saturating_add(model.miss).max(model.lo)
            };
            let hit = if v == UNKNOWN {
                model.hit.min(model.hi)
            } else {
                v.saturating_add(model.hit).min(model.hi)
            };
            let new = if hit_lanes[j] != 0 {
                hit
            } else if miss_lanes[j] != 0 {
                missed
            } else {
                v
            };
            cells[j] = new;
            changed[j] = u8::from(class(v) != class(new));
        }
        if changed.iter().all(|&c| c == 0) {
            continue;
        }
        for j in 0..64 {
            if changed[j] == 0 {
                continue;
            }
            let (before, after) = (VoxelMap::state_of(old[j]), VoxelMap::state_of(cells[j]));
            if before == CellState::Unknown {
                *block.known += 1;
            }
            if before == CellState::Occupied {
                *block.occupied -= 1;
            }
            if after == CellState::Occupied {
                *block.occupied += 1;
            }
            // Layer and lane indices are below 512.
            #[allow(clippy::cast_possible_truncation)]
            let index = ((layer << 6) | j) as u32;
            out.changed.push(CellChange {
                cell: VoxelMap::cell_in_block(corner, index),
                before,
                after,
            });
        }
    }
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

    /// Everything an insertion leaves: the known cells with their log-odds, and the update
    /// with its changes as a set.
    fn outcome(m: &VoxelMap, u: &FrameUpdate) -> (Vec<(Cell, Option<f64>)>, Vec<String>) {
        let mut cells = Vec::new();
        m.for_each_known(|c, _| cells.push((c, m.probability(c))));
        cells.sort_by_key(|(c, _)| *c);
        let mut changes: Vec<String> = u.changed.iter().map(|c| format!("{c:?}")).collect();
        changes.sort();
        let counts = format!("{} {} {} {:?}", u.rays, u.hit_cells, u.free_cells, u.bbox);
        changes.push(counts);
        (cells, changes)
    }

    proptest::proptest! {
        /// Two threads and a bitset cut into slabs give the same map and the same changes as
        /// one thread and one bitset.
        #[test]
        fn threads_and_slabs_change_nothing(
            seed in 0u64..1000,
            origins in proptest::collection::vec((0.5f64..7.5, 0.5f64..5.5, 0.2f64..2.8), 1..4),
            rays in 1usize..400,
            slab_words in 1usize..2000,
        ) {
            let mut one = map();
            let mut split = map();
            split.parallel_rays = 1;
            split.max_frame_words = slab_words;
            let mut state = seed;
            for &(x, y, z) in &origins {
                let o = Point3::new(x, y, z);
                let points: Vec<Point3<f64>> = (0..rays)
                    .map(|_| {
                        // A small LCG: points anywhere, some beyond the bounds or the range.
                        let mut next = || {
                            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                            (state >> 11) as f64 / (1u64 << 53) as f64
                        };
                        Point3::new(-30.0 + 70.0 * next(), -30.0 + 70.0 * next(), -3.0 + 9.0 * next())
                    })
                    .collect();
                let a = one.insert_frame(&o, &points).unwrap();
                let b = split.insert_frame(&o, &points).unwrap();
                proptest::prop_assert_eq!(outcome(&one, &a), outcome(&split, &b));
            }
        }
    }

    proptest::proptest! {
        /// The bits `mark_blocked` sets are those of the walk's cells in the slab, found cell
        /// by cell with `Slab::mark`.
        #[test]
        fn block_marks_are_the_walks_cells_in_the_slab(
            a in (0.0f64..8.0, 0.0f64..6.0, 0.0f64..3.0),
            b in (0.0f64..8.0, 0.0f64..6.0, 0.0f64..3.0),
            z0 in 0u32..2,
            depth in 1usize..3,
            stride in 1usize..3,
        ) {
            let m = map();
            let grid = m.grid;
            let (a, b) = (Point3::new(a.0, a.1, a.2), Point3::new(b.0, b.1, b.2));
            let [nx, ny, _] = m.block_dims.map(|v| v as usize);
            let slab = Slab { lo: [0, 0, z0], dims: [nx, ny, depth] };
            let mut got = vec![0u64; stride * LAYERS * slab.blocks()];
            let lo = Cell::new(0, 0, z0 << BLOCK_BITS);
            Walk::new(&grid, &a, &b).mark_blocked(lo, [nx, ny], stride * LAYERS, &mut got);
            let mut want = vec![0u64; got.len()];
            let mut walk = Walk::new(&grid, &a, &b);
            loop {
                if let Some((block, layer, bit)) = slab.mark(walk.cell()) {
                    want[stride * LAYERS * block + layer] |= bit;
                }
                if walk.advance().is_none() {
                    break;
                }
            }
            proptest::prop_assert_eq!(got, want);
        }
    }

    #[test]
    fn a_large_frame_uses_two_threads_and_matches_one() {
        let mut one = map();
        one.parallel_rays = usize::MAX;
        let mut two = map();
        let o = Point3::new(4.0, 3.0, 1.5);
        let points: Vec<Point3<f64>> = (0..PARALLEL_RAYS + 100)
            .map(|i| {
                let a = 2.399_963 * i as f64;
                let z = 1.0 - 2.0 * (i as f64 + 0.5) / (PARALLEL_RAYS + 100) as f64;
                let r = (1.0 - z * z).sqrt();
                o + 4.0 * Vector3::new(r * a.cos(), r * a.sin(), z)
            })
            .collect();
        let a = one.insert_frame(&o, &points).unwrap();
        let b = two.insert_frame(&o, &points).unwrap();
        assert!(a.free_cells > 1000);
        assert_eq!(outcome(&one, &a), outcome(&two, &b));
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

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(64))]

        /// `occluded` tests exactly the cells a walk visits strictly between the viewpoint's
        /// cell and the target, across allocated, unallocated, free and occupied blocks.
        #[test]
        fn occlusion_equals_a_cell_by_cell_walk(
            origins in proptest::collection::vec((0.5f64..7.5, 0.5f64..5.5, 0.2f64..2.8), 1..3),
            hits in proptest::collection::vec((0.0f64..8.0, 0.0f64..6.0, 0.0f64..3.0), 0..60),
            from in (0.0f64..8.0, 0.0f64..6.0, 0.0f64..3.0),
            to in proptest::collection::vec((0.0f64..8.0, 0.0f64..6.0, 0.0f64..3.0), 1..20),
        ) {
            let mut m = map();
            let pts: Vec<_> = hits.iter().map(|&(x, y, z)| Point3::new(x, y, z)).collect();
            for &(x, y, z) in &origins {
                m.insert_frame(&Point3::new(x, y, z), &pts).unwrap();
            }
            let from = Point3::new(from.0, from.1, from.2);
            // Occupied targets too: the target itself is never tested.
            for &(x, y, z) in to.iter().chain(&hits) {
                let target = m.grid().cell_of(&Point3::new(x, y, z)).unwrap();
                let first = m.grid().cell_of(&from).unwrap();
                for unknown in [false, true] {
                    let mut blocked = false;
                    traverse(&m.grid, &from, &m.grid.center(target), |c| {
                        if c != first && c != target {
                            blocked |= match m.cell_state(c) {
                                CellState::Occupied => true,
                                CellState::Unknown => unknown,
                                CellState::Free => false,
                            };
                        }
                        true
                    });
                    proptest::prop_assert_eq!(m.occluded(&from, target, unknown), blocked);
                }
            }
        }
    }

    #[test]
    fn occlusion_from_outside_the_bounds_stays_in_the_directory() {
        let m = map();
        let target = Cell::new(0, 7, 0);
        for from in [
            Point3::new(1e308, 1.5, 0.1),
            Point3::new(f64::NAN, 1.5, 0.1),
            Point3::new(-1e300, 1e300, 0.1),
            Point3::new(-3.0, 20.0, 9.0),
        ] {
            for unknown in [false, true] {
                let _ = m.occluded(&from, target, unknown);
                let _ = m.occluded(&from, Cell::new(u32::MAX, 0, u32::MAX), unknown);
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
