//! Incremental frontier cells and their clusters.

use std::collections::BTreeMap;

use nalgebra::{Matrix3, Point3, SymmetricEigen, Vector3};
use rustc_hash::FxHashSet;

use crate::grid::{Cell, FACES, Grid, MAX_CELLS_PER_AXIS, NEIGHBOURS_26};
use crate::map::{CellState, FrameUpdate, VoxelMap};
use crate::owners::Owners;
use crate::{FrontierError, Result};

/// Settings of frontier clustering. Defaults follow FUEL (clusters split until every cell is
/// within 2 m of the centre; small clusters ignored).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrontierConfig {
    /// Clusters with fewer cells are tracked but ignored by [`Frontiers::clusters`] and the
    /// viewpoint stage; default 20 (0.8 m² of frontier surface at 0.2 m, as FUEL's minimum of
    /// 100 cells at 0.1 m is 1 m²).
    pub min_cluster_cells: usize,
    /// Largest distance \[m\] from a cluster's centre to any of its cell centres; larger
    /// clusters are split in two along their principal axis, recursively.
    pub max_cluster_radius: f64,
}

impl Default for FrontierConfig {
    fn default() -> Self {
        Self {
            min_cluster_cells: 20,
            max_cluster_radius: 2.0,
        }
    }
}

impl FrontierConfig {
    /// Checks every setting.
    ///
    /// # Errors
    /// [`FrontierError::InvalidConfig`] for a radius that is not positive and finite.
    pub fn validate(&self) -> Result<()> {
        if !(self.max_cluster_radius.is_finite() && self.max_cluster_radius > 0.0) {
            return Err(FrontierError::InvalidConfig {
                what: "max_cluster_radius",
                value: self.max_cluster_radius,
                reason: "must be positive and finite [m]",
            });
        }
        Ok(())
    }
}

/// Identifies a cluster for as long as it exists; a re-grown cluster gets a new id.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct ClusterId(pub u64);

/// A connected set of frontier cells and its shape.
#[derive(Debug, Clone, PartialEq)]
pub struct Cluster {
    id: ClusterId,
    cells: Vec<Cell>,
    center: Point3<f64>,
    axes: Matrix3<f64>,
    variances: Vector3<f64>,
    normal: Vector3<f64>,
    min: Point3<f64>,
    max: Point3<f64>,
}

impl Cluster {
    /// The cluster's id.
    pub fn id(&self) -> ClusterId {
        self.id
    }

    /// Its frontier cells, sorted.
    pub fn cells(&self) -> &[Cell] {
        &self.cells
    }

    /// The centre c: the mean of the cell centres \[m\].
    pub fn center(&self) -> Point3<f64> {
        self.center
    }

    /// Principal axes as the columns of a rotation, by decreasing variance.
    pub fn axes(&self) -> &Matrix3<f64> {
        &self.axes
    }

    /// Variances of the cell centres along [`Cluster::axes`] \[m²\], decreasing.
    pub fn variances(&self) -> Vector3<f64> {
        self.variances
    }

    /// The dominant normal n: a unit vector pointing from the unknown side into known free space.
    ///
    /// For a planar cluster (at least 3 cells, least variance under a quarter of the middle one)
    /// it is the least-variance axis (EPIC's PCA normal); otherwise the mean direction from the
    /// cells' unknown face neighbours to their free ones. Either way it is oriented to agree with
    /// that mean direction.
    pub fn normal(&self) -> Vector3<f64> {
        self.normal
    }

    /// The intensity score s: the number of frontier cells.
    pub fn score(&self) -> f64 {
        // Cell counts are far below 2^53.
        #[allow(clippy::cast_precision_loss)]
        let s = self.cells.len() as f64;
        s
    }

    /// Lower corner of the bounding box of its cells \[m\].
    pub fn bbox_min(&self) -> Point3<f64> {
        self.min
    }

    /// Upper corner of the bounding box of its cells \[m\].
    pub fn bbox_max(&self) -> Point3<f64> {
        self.max
    }

    /// Largest distance from the centre to a cell centre \[m\].
    pub fn radius(&self, grid: &Grid) -> f64 {
        self.cells
            .iter()
            .map(|c| (grid.center(*c) - self.center).norm())
            .fold(0.0, f64::max)
    }
}

/// What an update changed, for callers that cache per-cluster work.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct FrontierDelta {
    /// Clusters that no longer exist.
    pub removed: Vec<ClusterId>,
    /// Clusters created, in id order.
    pub added: Vec<ClusterId>,
    /// Cells whose frontier status was examined.
    pub examined: usize,
}

/// The frontier of a [`VoxelMap`]: known-free cells with an unknown face neighbour, grouped
/// into clusters, and kept up to date incrementally (FUEL's incremental frontier structure).
///
/// Cells outside the map bounds count as neither free nor unknown, so the map's border is no
/// frontier. Clusters are 26-connected regions of frontier cells, split along their principal
/// axis until they satisfy [`FrontierConfig::max_cluster_radius`]. An update re-examines only
/// the changed cells and their face neighbours; clusters that lost a cell, or touch a new
/// frontier cell, are dissolved and re-grown with the new cells.
///
/// # Example
/// ```
/// use frontier::{Bounds, FrontierConfig, Frontiers, MapConfig, VoxelMap};
/// use nalgebra::Point3;
///
/// let bounds = Bounds::new(Point3::new(0.0, 0.0, 0.0), Point3::new(10.0, 10.0, 3.0)).unwrap();
/// let mut map = VoxelMap::new(bounds, MapConfig::default()).unwrap();
/// let mut frontiers = Frontiers::new(FrontierConfig::default()).unwrap();
/// // A fan of rays in the plane z = 1.5 leaves frontiers on all its sides.
/// let origin = Point3::new(5.0, 5.0, 1.5);
/// let points: Vec<_> = (0..360)
///     .map(|i| {
///         let a = f64::from(i).to_radians();
///         origin + nalgebra::Vector3::new(3.0 * a.cos(), 3.0 * a.sin(), 0.0)
///     })
///     .collect();
/// let update = map.insert_frame(&origin, &points).unwrap();
/// frontiers.update(&map, &update);
/// assert!(frontiers.frontier_len() > 100);
/// assert!(frontiers.clusters().count() > 1);
/// ```
#[derive(Debug, Clone)]
pub struct Frontiers {
    config: FrontierConfig,
    clusters: BTreeMap<ClusterId, Cluster>,
    /// Every frontier cell and the handle of its cluster.
    owners: Owners,
    /// The cluster of each handle in use.
    handles: Vec<ClusterId>,
    /// Handles of removed clusters, ready for reuse.
    free_handles: Vec<u32>,
    next_id: u64,
}

impl Frontiers {
    /// An empty frontier.
    ///
    /// # Errors
    /// The first invalid setting (see [`FrontierConfig::validate`]).
    pub fn new(config: FrontierConfig) -> Result<Self> {
        config.validate()?;
        Ok(Self {
            config,
            clusters: BTreeMap::new(),
            owners: Owners::default(),
            handles: Vec::new(),
            free_handles: Vec::new(),
            next_id: 0,
        })
    }

    /// The settings.
    pub fn config(&self) -> &FrontierConfig {
        &self.config
    }

    /// Whether `c` is a frontier cell of `map`: known free with an unknown face neighbour.
    pub fn is_frontier_in(map: &VoxelMap, c: Cell) -> bool {
        map.cell_state(c) == CellState::Free
            && FACES.iter().any(|d| {
                map.grid()
                    .offset(c, *d)
                    .is_some_and(|n| map.cell_state(n) == CellState::Unknown)
            })
    }

    /// Whether `c` is currently a tracked frontier cell.
    pub fn is_frontier(&self, c: Cell) -> bool {
        self.owners.get(c).is_some()
    }

    /// Number of frontier cells.
    pub fn frontier_len(&self) -> usize {
        self.owners.len()
    }

    /// Every frontier cell, sorted.
    pub fn frontier_cells(&self) -> Vec<Cell> {
        let mut v = Vec::with_capacity(self.owners.len());
        self.owners.for_each(|c, _| v.push(c));
        v.sort_unstable();
        v
    }

    /// The clusters with at least [`FrontierConfig::min_cluster_cells`] cells, by id.
    pub fn clusters(&self) -> impl Iterator<Item = &Cluster> {
        let min = self.config.min_cluster_cells;
        self.clusters.values().filter(move |c| c.cells.len() >= min)
    }

    /// Every cluster, tiny ones included, by id: they partition the frontier cells.
    pub fn all_clusters(&self) -> impl Iterator<Item = &Cluster> {
        self.clusters.values()
    }

    /// A cluster by id.
    pub fn cluster(&self, id: ClusterId) -> Option<&Cluster> {
        self.clusters.get(&id)
    }

    /// The cluster a frontier cell belongs to.
    pub fn owner(&self, c: Cell) -> Option<ClusterId> {
        self.owners
            .get(c)
            .and_then(|h| self.handles.get(h as usize).copied())
    }

    /// Recomputes everything from the whole map.
    pub fn rebuild(&mut self, map: &VoxelMap) -> FrontierDelta {
        let removed = self.clusters.keys().copied().collect();
        self.clusters.clear();
        self.owners.reset(map.grid().dims());
        self.handles.clear();
        self.free_handles.clear();
        let mut pool = Vec::new();
        let mut examined = 0;
        map.for_each_known(|c, s| {
            examined += 1;
            if s == CellState::Free && Self::is_frontier_in(map, c) {
                pool.push(c.key());
            }
        });
        let added = self.grow(map, pool);
        FrontierDelta {
            removed,
            added,
            examined,
        }
    }

    /// Brings the frontier up to date after `map` absorbed `update` (the value
    /// [`VoxelMap::insert_frame`] returned). Updates must be passed in order, none skipped;
    /// after a skipped one, call [`Frontiers::rebuild`]. A frontier that tracks a map with
    /// another grid size is rebuilt from `map` instead. Changes of cells outside `map`'s grid,
    /// which `insert_frame` never reports, are ignored.
    pub fn update(&mut self, map: &VoxelMap, update: &FrameUpdate) -> FrontierDelta {
        let grid = map.grid();
        if self.owners.dims() != grid.dims() {
            if self.clusters.is_empty() {
                // First use.
                self.owners.reset(grid.dims());
            } else {
                // A map of another size: nothing tracked belongs to it.
                return self.rebuild(map);
            }
        }
        // The changed cells and their face neighbours, each once, in a deterministic order.
        // Cells outside the grid would overflow the box below and alias other cells' keys.
        let [nx, ny, nz] = grid.dims();
        let changed = || {
            update
                .changed
                .iter()
                .filter(move |ch| ch.cell.x < nx && ch.cell.y < ny && ch.cell.z < nz)
        };
        let mut lo = [u32::MAX; 3];
        let mut hi = [0u32; 3];
        for ch in changed() {
            for (k, v) in [ch.cell.x, ch.cell.y, ch.cell.z].into_iter().enumerate() {
                lo[k] = lo[k].min(v.saturating_sub(1));
                hi[k] = hi[k].max(v + 1);
            }
        }
        let mut seen = CellSet::empty(lo, hi);
        let mut keys = Vec::with_capacity(2 * update.changed.len());
        for ch in changed() {
            if seen.insert(ch.cell) {
                keys.push(ch.cell.key());
            }
            for d in &FACES {
                if let Some(n) = grid.offset(ch.cell, *d)
                    && seen.insert(n)
                {
                    keys.push(n.key());
                }
            }
        }
        let examined = keys.len();
        // The clusters to dissolve, one flag per handle (handles are small dense integers).
        let mut dirty = vec![false; self.handles.len()];
        let mut mark = |h: u32| {
            if let Some(d) = dirty.get_mut(h as usize) {
                *d = true;
            }
        };
        let mut pool = Vec::new();
        for k in keys {
            let c = Cell::from_key(k);
            let now = Self::is_frontier_in(map, c);
            match (self.owners.get(c), now) {
                (Some(h), false) => {
                    self.owners.remove(c);
                    mark(h);
                }
                (None, true) => {
                    pool.push(k);
                    self.owners.for_each_neighbour(c, &mut mark);
                }
                _ => {}
            }
        }
        // Handles index `handles`, a u32-sized table.
        #[allow(clippy::cast_possible_truncation)]
        let mut dirty: Vec<u32> = (0..dirty.len())
            .filter(|&h| dirty[h])
            .map(|h| h as u32)
            .collect();
        // By id, so that the pool's order, and with it every new id, is deterministic.
        dirty.sort_unstable_by_key(|h| self.handles.get(*h as usize).copied());
        let mut removed = Vec::with_capacity(dirty.len());
        for h in dirty {
            let Some(&id) = self.handles.get(h as usize) else {
                continue;
            };
            if let Some(cl) = self.clusters.remove(&id) {
                // Cells still owned by the dissolved cluster are still frontier cells; their
                // owners are overwritten when they are grown again.
                pool.extend(
                    cl.cells
                        .iter()
                        .filter(|c| self.owners.get(**c) == Some(h))
                        .map(|c| c.key()),
                );
                self.free_handles.push(h);
                removed.push(id);
            }
        }
        let added = self.grow(map, pool);
        FrontierDelta {
            removed,
            added,
            examined,
        }
    }

    /// A handle for the new cluster `id`, reusing a free one if any.
    fn handle(&mut self, id: ClusterId) -> u32 {
        if let Some(h) = self.free_handles.pop() {
            self.handles[h as usize] = id;
            return h;
        }
        self.handles.push(id);
        // One handle per live cluster, each with at least one cell: far below 2^32.
        #[allow(clippy::cast_possible_truncation)]
        let h = (self.handles.len() - 1) as u32;
        h
    }

    /// Groups the pool (distinct frontier cells without a live cluster) into 26-connected
    /// regions, splits them, and records the clusters.
    fn grow(&mut self, map: &VoxelMap, seeds: Vec<u64>) -> Vec<ClusterId> {
        let grid = map.grid();
        let mut pool = CellSet::new(&seeds);
        let mut added = Vec::new();
        let mut stack = Vec::new();
        let mut parts = Vec::new();
        let radius = self.config.max_cluster_radius / grid.resolution();
        for seed in seeds {
            let seed = Cell::from_key(seed);
            if !pool.remove(seed) {
                continue;
            }
            let mut region = vec![seed];
            stack.push(seed);
            while let Some(c) = stack.pop() {
                let before = region.len();
                pool.take_neighbours(c, &mut region);
                stack.extend_from_slice(&region[before..]);
            }
            parts.clear();
            split(&mut region, 0, radius, &mut parts);
            for (range, moments) in &parts {
                let mut keys: Vec<u64> = region[range.clone()].iter().map(sort_key).collect();
                keys.sort_unstable();
                let cells: Vec<Cell> = keys.into_iter().map(from_sort_key).collect();
                let id = ClusterId(self.next_id);
                self.next_id += 1;
                let h = self.handle(id);
                for c in &cells {
                    // Pool cells come from the map's grid, the size of `owners`.
                    self.owners.insert(*c, h);
                }
                self.clusters.insert(id, shape(map, id, cells, moments));
                added.push(id);
            }
        }
        added
    }
}

/// A set of cells for region growing: a bitset over the bounding box of its cells when that
/// box is small enough, else a hash set.
enum CellSet {
    Bits {
        min: [u32; 3],
        dims: [usize; 3],
        bits: Vec<u64>,
    },
    Hash(FxHashSet<u64>),
}

impl CellSet {
    /// Largest box, in cells, kept as a bitset (8 MiB).
    const MAX_BITS: usize = 1 << 26;

    /// The set of the cells of `keys`.
    fn new(keys: &[u64]) -> Self {
        let mut min = [u32::MAX; 3];
        let mut max = [0u32; 3];
        for k in keys {
            let c = Cell::from_key(*k);
            for (i, v) in [c.x, c.y, c.z].into_iter().enumerate() {
                min[i] = min[i].min(v);
                max[i] = max[i].max(v);
            }
        }
        let mut set = Self::empty(min, max);
        for k in keys {
            set.insert(Cell::from_key(*k));
        }
        set
    }

    /// An empty set for cells in the box from `min` to `max` (inclusive; an empty box when
    /// `min` exceeds `max`).
    fn empty(min: [u32; 3], max: [u32; 3]) -> Self {
        let dims = [0, 1, 2].map(|i| (max[i].saturating_sub(min[i]) as usize) + 1);
        let volume = dims[0].saturating_mul(dims[1]).saturating_mul(dims[2]);
        if (0..3).any(|i| min[i] > max[i]) || volume > Self::MAX_BITS {
            return Self::Hash(FxHashSet::default());
        }
        Self::Bits {
            min,
            dims,
            bits: vec![0u64; volume.div_ceil(64)],
        }
    }

    /// The bit of `c`, if it lies in the box.
    #[inline]
    fn bit(min: &[u32; 3], dims: &[usize; 3], c: Cell) -> Option<(usize, u64)> {
        let (x, y, z) = (
            c.x.checked_sub(min[0])? as usize,
            c.y.checked_sub(min[1])? as usize,
            c.z.checked_sub(min[2])? as usize,
        );
        if x >= dims[0] || y >= dims[1] || z >= dims[2] {
            return None;
        }
        let i = x + dims[0] * (y + dims[1] * z);
        Some((i >> 6, 1u64 << (i & 63)))
    }

    /// Adds `c` (which must lie in the box of a bitset); whether it was new.
    #[inline]
    fn insert(&mut self, c: Cell) -> bool {
        match self {
            Self::Bits { min, dims, bits } => match Self::bit(min, dims, c) {
                Some((w, bit)) => {
                    let new = bits[w] & bit == 0;
                    bits[w] |= bit;
                    new
                }
                None => false,
            },
            Self::Hash(h) => h.insert(c.key()),
        }
    }

    /// Removes the 26 neighbours of `c` that are in the set and appends them to `out`.
    fn take_neighbours(&mut self, c: Cell, out: &mut Vec<Cell>) {
        match self {
            Self::Bits { min, dims, bits } => {
                // The range of local coordinates within one of `c` along axis k, clipped to
                // the box (empty when `c` is further out).
                let span = |k: usize, v: u32| {
                    let l = i64::from(v) - i64::from(min[k]);
                    let hi = (l + 1).min(dims[k] as i64 - 1);
                    // Clipped to [0, dims − 1], so the casts are exact.
                    #[allow(clippy::cast_sign_loss, clippy::cast_possible_truncation)]
                    let r = ((l - 1).max(0) as usize, hi as usize, hi >= (l - 1).max(0));
                    r
                };
                let ((x0, x1, xs), (y0, y1, ys), (z0, z1, zs)) =
                    (span(0, c.x), span(1, c.y), span(2, c.z));
                if !(xs && ys && zs) {
                    return;
                }
                // The up to three neighbours along x in each of the nine rows are adjacent
                // bits: one window per row.
                let width = x1 - x0 + 1;
                let local = |k: usize, v: u32| v.wrapping_sub(min[k]) as usize;
                let (lx, ly, lz) = (local(0, c.x), local(1, c.y), local(2, c.z));
                // The bit of `c` in its row's window, when `c` is in the box.
                let centre = (lx >= x0 && lx <= x1).then(|| lx - x0);
                for z in z0..=z1 {
                    for y in y0..=y1 {
                        let i0 = x0 + dims[0] * (y + dims[1] * z);
                        let (w, off) = (i0 >> 6, i0 & 63);
                        let mut window = bits[w] >> off;
                        if off + width > 64 {
                            window |= bits[w + 1] << (64 - off);
                        }
                        window &= (1u64 << width) - 1;
                        if let Some(j) = centre.filter(|_| (y, z) == (ly, lz)) {
                            // `c` itself is no neighbour.
                            window &= !(1u64 << j);
                        }
                        while window != 0 {
                            let j = window.trailing_zeros() as usize;
                            window &= window - 1;
                            let i = i0 + j;
                            bits[i >> 6] &= !(1u64 << (i & 63));
                            // Inside the box: below the grid's u32 sizes, so the casts are exact.
                            #[allow(clippy::cast_possible_truncation)]
                            out.push(Cell::new(
                                min[0] + (x0 + j) as u32,
                                min[1] + y as u32,
                                min[2] + z as u32,
                            ));
                        }
                    }
                }
            }
            Self::Hash(h) => {
                for d in &NEIGHBOURS_26 {
                    let (Some(x), Some(y), Some(z)) = (
                        c.x.checked_add_signed(d[0]),
                        c.y.checked_add_signed(d[1]),
                        c.z.checked_add_signed(d[2]),
                    ) else {
                        continue;
                    };
                    let n = Cell::new(x, y, z);
                    // Pool cells are grid cells, far below the 21-bit key limit.
                    if x < MAX_CELLS_PER_AXIS
                        && y < MAX_CELLS_PER_AXIS
                        && z < MAX_CELLS_PER_AXIS
                        && h.remove(&n.key())
                    {
                        out.push(n);
                    }
                }
            }
        }
    }

    /// Removes `c`; whether it was there.
    #[inline]
    fn remove(&mut self, c: Cell) -> bool {
        match self {
            Self::Bits { min, dims, bits } => match Self::bit(min, dims, c) {
                Some((w, bit)) => {
                    let was = bits[w] & bit != 0;
                    bits[w] &= !bit;
                    was
                }
                None => false,
            },
            Self::Hash(h) => h.remove(&c.key()),
        }
    }
}

/// Mean and covariance of a set of cell centres, in cell units from the centre of `base`.
#[derive(Debug, Clone, Copy)]
struct Moments {
    base: Cell,
    mean: Vector3<f64>,
    cov: Matrix3<f64>,
}

impl Moments {
    /// The moments of `cells` (not empty), in one pass over exact integer offsets.
    fn of(cells: &[Cell]) -> Self {
        let base = cells.first().copied().unwrap_or(Cell::new(0, 0, 0));
        let mut s = [0.0f64; 3];
        let mut ss = [0.0f64; 6];
        for c in cells {
            let d = offset(base, *c);
            s = [s[0] + d[0], s[1] + d[1], s[2] + d[2]];
            ss[0] += d[0] * d[0];
            ss[1] += d[0] * d[1];
            ss[2] += d[0] * d[2];
            ss[3] += d[1] * d[1];
            ss[4] += d[1] * d[2];
            ss[5] += d[2] * d[2];
        }
        // Cell counts are far below 2^53.
        #[allow(clippy::cast_precision_loss)]
        let n = cells.len().max(1) as f64;
        let m = Vector3::new(s[0], s[1], s[2]) / n;
        // E[d dᵀ] − m mᵀ, with offsets from a member cell so the subtraction loses little.
        let e = |k: usize| ss[k] / n;
        let cov = Matrix3::new(
            e(0) - m.x * m.x,
            e(1) - m.x * m.y,
            e(2) - m.x * m.z,
            e(1) - m.x * m.y,
            e(3) - m.y * m.y,
            e(4) - m.y * m.z,
            e(2) - m.x * m.z,
            e(4) - m.y * m.z,
            e(5) - m.z * m.z,
        );
        Self { base, mean: m, cov }
    }

    /// The largest squared distance from the mean to a cell centre of `cells` \[cells²\].
    fn radius2(&self, cells: &[Cell]) -> f64 {
        cells
            .iter()
            .map(|c| (Vector3::from(offset(self.base, *c)) - self.mean).norm_squared())
            .fold(0.0, f64::max)
    }

    /// The mean as a world point and the covariance in m².
    fn world(&self, grid: &Grid) -> (Point3<f64>, Matrix3<f64>) {
        let r = grid.resolution();
        (grid.center(self.base) + self.mean * r, self.cov * (r * r))
    }
}

/// The offset from `base` to `c` in cells, exact.
#[inline]
fn offset(base: Cell, c: Cell) -> [f64; 3] {
    [
        f64::from(c.x) - f64::from(base.x),
        f64::from(c.y) - f64::from(base.y),
        f64::from(c.z) - f64::from(base.z),
    ]
}

/// Principal axes (columns) and variances, by decreasing variance.
fn principal(cov: &Matrix3<f64>) -> (Matrix3<f64>, Vector3<f64>) {
    let eig = SymmetricEigen::new(*cov);
    let mut order = [0usize, 1, 2];
    order.sort_by(|a, b| eig.eigenvalues[*b].total_cmp(&eig.eigenvalues[*a]));
    let axes = Matrix3::from_columns(&order.map(|k| eig.eigenvectors.column(k).into_owned()));
    let vars = Vector3::from(order.map(|k| eig.eigenvalues[k].max(0.0)));
    (axes, vars)
}

/// Splits `cells` in place along the principal axis until every part has radius ≤
/// `max_radius` (in cells); appends each part as its range in `cells` (offset by `start`) with
/// its moments.
fn split(
    cells: &mut [Cell],
    start: usize,
    max_radius: f64,
    out: &mut Vec<(core::ops::Range<usize>, Moments)>,
) {
    let m = Moments::of(cells);
    if cells.len() < 2 || m.radius2(cells) <= max_radius * max_radius {
        out.push((start..start + cells.len(), m));
        return;
    }
    let (axes, _) = principal(&m.cov);
    let axis = axes.column(0).into_owned();
    let ahead = |c: &Cell| (Vector3::from(offset(m.base, *c)) - m.mean).dot(&axis) >= 0.0;
    // In-place partition: the cells ahead of the mean first.
    let mut k = 0;
    for i in 0..cells.len() {
        if ahead(&cells[i]) {
            cells.swap(i, k);
            k += 1;
        }
    }
    if k == 0 || k == cells.len() {
        out.push((start..start + cells.len(), m));
        return;
    }
    let (a, b) = cells.split_at_mut(k);
    split(a, start, max_radius, out);
    split(b, start + k, max_radius, out);
}

/// The order of [`Cell`]'s `Ord` (x, then y, then z) as one integer, which sorts faster.
#[inline]
fn sort_key(c: &Cell) -> u64 {
    (u64::from(c.x) << 42) | (u64::from(c.y) << 21) | u64::from(c.z)
}

/// Inverse of [`sort_key`].
#[inline]
fn from_sort_key(k: u64) -> Cell {
    let m = (1u64 << 21) - 1;
    // Each field has at most 21 bits, so the casts are exact.
    #[allow(clippy::cast_possible_truncation)]
    Cell::new((k >> 42) as u32, ((k >> 21) & m) as u32, (k & m) as u32)
}

/// The shape of a cluster: centre, axes, normal, bounding box.
fn shape(map: &VoxelMap, id: ClusterId, cells: Vec<Cell>, moments: &Moments) -> Cluster {
    let grid = map.grid();
    let (center, cov) = moments.world(grid);
    let (axes, variances) = principal(&cov);
    // Mean direction from unknown face neighbours to free ones.
    let mut g = Vector3::zeros();
    for c in &cells {
        for d in &FACES {
            let dir = Vector3::new(f64::from(d[0]), f64::from(d[1]), f64::from(d[2]));
            match grid.offset(*c, *d).map(|n| map.cell_state(n)) {
                Some(CellState::Unknown) => g -= dir,
                Some(CellState::Free) => g += dir,
                _ => {}
            }
        }
    }
    let least = axes.column(2).into_owned();
    let planar = cells.len() >= 3 && variances[2] <= 0.25 * variances[1];
    let mut normal = if planar || g.norm() < 1e-9 {
        least
    } else {
        g.normalize()
    };
    if normal.dot(&g) < 0.0 {
        normal = -normal;
    }
    let h = Vector3::repeat(0.5 * grid.resolution());
    let (mut min, mut max) = (center, center);
    for c in &cells {
        let p = grid.center(*c);
        min = min.inf(&(p - h));
        max = max.sup(&(p + h));
    }
    Cluster {
        id,
        cells,
        center,
        axes,
        variances,
        normal,
        min,
        max,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{Bounds, MapConfig};
    use proptest::prelude::*;

    proptest! {
        /// The one-pass moments equal the two-pass mean and covariance of the cell centres.
        #[test]
        fn moments_match_two_passes(
            cells in proptest::collection::vec((0u32..2000, 0u32..2000, 0u32..300), 1..60),
        ) {
            let b = Bounds::new(Point3::new(-5.0, 0.0, 1.0), Point3::new(395.0, 400.0, 61.0)).unwrap();
            let grid = Grid::new(b, 0.2).unwrap();
            let cells: Vec<Cell> = cells.into_iter().map(|(x, y, z)| Cell::new(x, y, z)).collect();
            let n = cells.len() as f64;
            let mean = cells.iter().fold(Vector3::zeros(), |s, c| s + grid.center(*c).coords) / n;
            let cov = cells.iter().fold(Matrix3::zeros(), |s, c| {
                let d = grid.center(*c).coords - mean;
                s + d * d.transpose()
            }) / n;
            let (m, c) = Moments::of(&cells).world(&grid);
            prop_assert!((m.coords - mean).norm() < 1e-9);
            prop_assert!((c - cov).norm() < 1e-9 * (1.0 + cov.norm()));
            let r2 = Moments::of(&cells).radius2(&cells) * 0.04;
            let r = cells.iter().map(|c| (grid.center(*c).coords - mean).norm()).fold(0.0, f64::max);
            prop_assert!((r2.sqrt() - r).abs() < 1e-9);
        }

        /// The packed sort key orders cells as `Cell`'s `Ord` does, and round-trips.
        #[test]
        fn sort_keys_order_like_cells(
            a in (0u32..1 << 20, 0u32..1 << 20, 0u32..1 << 20),
            b in (0u32..1 << 20, 0u32..1 << 20, 0u32..1 << 20),
        ) {
            let (a, b) = (Cell::new(a.0, a.1, a.2), Cell::new(b.0, b.1, b.2));
            prop_assert_eq!(sort_key(&a).cmp(&sort_key(&b)), a.cmp(&b));
            prop_assert_eq!(from_sort_key(sort_key(&a)), a);
        }

        /// The bitset and the hash set agree with a plain set on insertions, removals and
        /// neighbour takes.
        #[test]
        fn cell_sets_agree(
            cells in proptest::collection::vec((0u32..12, 0u32..12, 0u32..6), 1..80),
            probes in proptest::collection::vec((0u32..14, 0u32..14, 0u32..8), 1..40),
        ) {
            let cells: Vec<Cell> = cells.into_iter().map(|(x, y, z)| Cell::new(x, y, z)).collect();
            let mut keys: Vec<u64> = cells.iter().map(|c| c.key()).collect();
            keys.sort_unstable();
            keys.dedup();
            let mut bits = CellSet::new(&keys);
            let is_bits = matches!(bits, CellSet::Bits { .. });
            prop_assert!(is_bits);
            let mut hash = CellSet::Hash(keys.iter().copied().collect());
            let mut reference: FxHashSet<u64> = keys.iter().copied().collect();
            for (x, y, z) in probes {
                let c = Cell::new(x, y, z);
                let (mut a, mut b) = (Vec::new(), Vec::new());
                bits.take_neighbours(c, &mut a);
                hash.take_neighbours(c, &mut b);
                let mut expected: Vec<Cell> = NEIGHBOURS_26
                    .iter()
                    .filter_map(|d| {
                        let n = Cell::new(
                            x.checked_add_signed(d[0])?,
                            y.checked_add_signed(d[1])?,
                            z.checked_add_signed(d[2])?,
                        );
                        reference.remove(&n.key()).then_some(n)
                    })
                    .collect();
                a.sort_unstable();
                b.sort_unstable();
                expected.sort_unstable();
                prop_assert_eq!(&a, &expected);
                prop_assert_eq!(&b, &expected);
                let was = reference.remove(&c.key());
                prop_assert_eq!(bits.remove(c), was);
                prop_assert_eq!(hash.remove(c), was);
            }
        }
    }

    fn fan(map: &mut VoxelMap, o: Point3<f64>, r: f64) -> FrameUpdate {
        let pts: Vec<_> = (0..720)
            .map(|i| {
                let a = f64::from(i).to_radians() * 0.5;
                o + Vector3::new(r * a.cos(), r * a.sin(), 0.3 * (3.0 * a).sin())
            })
            .collect();
        map.insert_frame(&o, &pts).unwrap()
    }

    #[test]
    fn incremental_equals_rebuild_and_clusters_partition() {
        let b = Bounds::new(Point3::new(0.0, 0.0, 0.0), Point3::new(12.0, 12.0, 3.0)).unwrap();
        let mut map = VoxelMap::new(b, MapConfig::default()).unwrap();
        let mut inc = Frontiers::new(FrontierConfig::default()).unwrap();
        for (i, o) in [(4.0, 4.0), (6.0, 5.0), (8.0, 7.0), (5.0, 8.0)]
            .iter()
            .enumerate()
        {
            let u = fan(
                &mut map,
                Point3::new(o.0, o.1, 1.5),
                2.5 + f64::from(i as u32) * 0.5,
            );
            inc.update(&map, &u);
        }
        let mut full = Frontiers::new(FrontierConfig::default()).unwrap();
        full.rebuild(&map);
        assert_eq!(inc.frontier_cells(), full.frontier_cells());
        assert!(inc.frontier_len() > 100);
        let mut seen = FxHashSet::default();
        for cl in inc.all_clusters() {
            assert!(cl.radius(map.grid()) <= 2.0 + 1e-9);
            for c in cl.cells() {
                assert!(seen.insert(*c), "cell in two clusters");
                assert_eq!(inc.owner(*c), Some(cl.id()));
            }
            assert!((cl.normal().norm() - 1.0).abs() < 1e-9);
        }
        assert_eq!(seen.len(), inc.frontier_len());
    }

    #[test]
    fn a_map_of_another_size_is_rebuilt() {
        let small = Bounds::new(Point3::new(0.0, 0.0, 0.0), Point3::new(8.0, 8.0, 3.0)).unwrap();
        let large = Bounds::new(Point3::new(0.0, 0.0, 0.0), Point3::new(12.0, 12.0, 3.0)).unwrap();
        let mut a = VoxelMap::new(small, MapConfig::default()).unwrap();
        let mut b = VoxelMap::new(large, MapConfig::default()).unwrap();
        let mut f = Frontiers::new(FrontierConfig::default()).unwrap();
        let ua = fan(&mut a, Point3::new(4.0, 4.0, 1.5), 2.5);
        f.update(&a, &ua);
        assert!(f.frontier_len() > 0);
        // Cells of the small map's frontier mean other places in the large map.
        fan(&mut b, Point3::new(6.0, 6.0, 1.5), 3.0);
        let ub = fan(&mut b, Point3::new(9.0, 8.0, 1.5), 2.0);
        let delta = f.update(&b, &ub);
        let mut full = Frontiers::new(FrontierConfig::default()).unwrap();
        full.rebuild(&b);
        assert_eq!(f.frontier_cells(), full.frontier_cells());
        assert!(!delta.removed.is_empty());
        for cl in f.all_clusters() {
            for c in cl.cells() {
                assert_eq!(f.owner(*c), Some(cl.id()));
            }
        }
    }

    #[test]
    fn normals_point_into_free_space() {
        // A range-limited sensor at x ≈ 0 clears x ∈ [0, 3]: the frontier at x = 3 has unknown
        // space on its +x side, so its normal points to −x.
        let b = Bounds::new(Point3::new(0.0, 0.0, 0.0), Point3::new(6.0, 4.0, 2.0)).unwrap();
        let cfg = MapConfig {
            max_range: 3.0,
            ..Default::default()
        };
        let mut map = VoxelMap::new(b, cfg).unwrap();
        let o = Point3::new(0.1, 2.0, 1.0);
        let pts: Vec<_> = (0..20)
            .flat_map(|i| {
                (0..10).map(move |k| {
                    Point3::new(30.0, f64::from(i) * 0.2 + 0.1, f64::from(k) * 0.2 + 0.1)
                })
            })
            .collect();
        let mut f = Frontiers::new(FrontierConfig::default()).unwrap();
        let u = map.insert_frame(&o, &pts).unwrap();
        f.update(&map, &u);
        let big = f.clusters().max_by_key(|c| c.cells().len()).unwrap();
        assert!(big.normal().x < -0.5, "{:?}", big.normal());
    }

    #[test]
    fn bad_config() {
        let c = FrontierConfig {
            max_cluster_radius: 0.0,
            ..Default::default()
        };
        assert!(Frontiers::new(c).is_err());
    }
}
