//! Point-to-plane scan-to-map registration, the core of the simulator's LiDAR odometry.
//!
//! The map is a k-d tree (kiddo) over registered world points; each scan point is matched to
//! the plane fitted to its nearest map points, and the pose is refined by Gauss–Newton on
//! SE(3) with a Huber kernel.

use std::num::NonZeroUsize;

use fu_mpc_core::least_eigen;
use kiddo::{ImmutableKdTree, SquaredEuclidean};
use nalgebra::{
    Isometry3, Matrix3, Matrix6, Point3, SymmetricEigen, Translation3, UnitQuaternion, Vector3,
    Vector6,
};
use rayon::prelude::*;
use rustc_hash::FxHashMap;

/// Scan points per parallel task of the plane fits.
const PLANE_CHUNK: usize = 256;

/// Settings of the registration.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RegistrationConfig {
    /// Map points per plane fit; default 5 (FAST-LIO's choice).
    pub neighbours: usize,
    /// Largest distance from a scan point to its farthest neighbour \[m\]; default 1.
    pub max_neighbour_distance: f64,
    /// Largest plane-fit residual, as the ratio of least to middle variance; default 0.1.
    pub planarity: f64,
    /// Huber threshold \[m\]; default 0.1.
    pub huber: f64,
    /// Gauss–Newton iterations; default 10.
    pub iterations: usize,
    /// Stop when the update is smaller than this (rotation \[rad\] plus translation \[m\]);
    /// default 1e-6.
    pub tolerance: f64,
    /// Largest Gauss–Newton step \[m\] and \[rad\]: a larger one stops the registration at
    /// the last pose and marks it rejected; default 0.5.
    pub max_step: f64,
    /// Re-fit the planes after an update that moves a point 10 m away by more than this \[m\]
    /// (|v| + 10 |ω|); smaller updates keep the last planes. Default 0.01.
    pub reassociate: f64,
}

impl Default for RegistrationConfig {
    fn default() -> Self {
        Self {
            neighbours: 5,
            max_neighbour_distance: 1.0,
            planarity: 0.1,
            huber: 0.1,
            iterations: 10,
            tolerance: 1e-6,
            reassociate: 0.01,
            max_step: 0.5,
        }
    }
}

/// The result of one registration.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Registration {
    /// The refined pose of the scan frame in the map frame.
    pub pose: Isometry3<f64>,
    /// Scan points matched to a plane in the last iteration.
    pub matched: usize,
    /// Iterations run.
    pub iterations: usize,
    /// JᵀWJ of the matched points in the last iteration (Huber weights W): the information
    /// the scan gives about the pose, in units of one point's squared residual \[m²\], for
    /// the perturbation ξ = [δθ; δp] (a world-frame rotation about the body's position, then
    /// a translation).
    pub hessian: Matrix6<f64>,
    /// Eigenvalues of [`Registration::hessian`], increasing: a small one flags a direction
    /// the geometry does not constrain (the corridor degeneracy).
    pub information: Vector6<f64>,
    /// The unit direction ξ = [δθ; δp] of the smallest eigenvalue: the motion the scan
    /// constrains least.
    pub weakest: Vector6<f64>,
    /// Whether a step was larger than [`RegistrationConfig::max_step`] (the pose is then the
    /// last one before it).
    pub rejected: bool,
}

/// A map of world points for registration.
#[derive(Debug)]
pub struct PlaneMap {
    points: Vec<[f64; 3]>,
    tree: Option<ImmutableKdTree<f64, 3>>,
}

impl PlaneMap {
    /// A map over `points` (non-finite ones are dropped).
    pub fn new(points: &[Point3<f64>]) -> Self {
        let points: Vec<[f64; 3]> = points
            .iter()
            .filter(|p| p.iter().all(|v| v.is_finite()))
            .map(|p| [p.x, p.y, p.z])
            .collect();
        let tree = if points.is_empty() {
            None
        } else {
            ImmutableKdTree::new_from_slice(&points).ok()
        };
        Self { points, tree }
    }

    /// Number of map points.
    pub fn len(&self) -> usize {
        self.points.len()
    }

    /// Whether the map is empty.
    pub fn is_empty(&self) -> bool {
        self.points.is_empty()
    }

    /// Registers `scan` (points in the scan frame) to the map, starting from `initial`: see
    /// [`register`].
    pub fn register(
        &self,
        scan: &[Point3<f64>],
        initial: &Isometry3<f64>,
        cfg: &RegistrationConfig,
    ) -> Registration {
        register(self, scan, initial, cfg)
    }
}

/// A source of nearest map points for the plane fits.
pub trait Neighbours: Sync {
    /// What one thread keeps from one query to the next (say, the storage the last query
    /// looked up), so a run of nearby queries is answered faster; never changes an answer.
    type Memo<'a>: Default
    where
        Self: 'a;

    /// The (at most) `k` map points nearest to `q`, as (squared distance, point), into `out`
    /// (cleared first), in any order.
    fn nearest(&self, q: &Point3<f64>, k: usize, out: &mut Vec<(f64, Point3<f64>)>) {
        self.nearest_with(q, k, out, &mut Self::Memo::default());
    }

    /// [`Neighbours::nearest`], reusing `memo` from earlier queries of this map.
    fn nearest_with<'a>(
        &'a self,
        q: &Point3<f64>,
        k: usize,
        out: &mut Vec<(f64, Point3<f64>)>,
        memo: &mut Self::Memo<'a>,
    );
}

impl Neighbours for PlaneMap {
    type Memo<'a> = ();

    fn nearest_with(
        &self,
        q: &Point3<f64>,
        k: usize,
        out: &mut Vec<(f64, Point3<f64>)>,
        (): &mut (),
    ) {
        out.clear();
        let (Some(tree), Some(k)) = (
            self.tree.as_ref(),
            NonZeroUsize::new(k.min(self.points.len())),
        ) else {
            return;
        };
        let nn = tree
            .query(&[q.x, q.y, q.z])
            .nearest_n::<SquaredEuclidean<f64>>(k)
            .execute();
        out.extend(nn.iter().filter_map(|r| {
            let p = self.points.get(usize::try_from(r.item).ok()?)?;
            Some((r.distance, Point3::new(p[0], p[1], p[2])))
        }));
    }
}

/// A voxel-hashed cloud, one point per voxel (the first), whose neighbour search looks at the
/// 27 voxels around the query's: approximate nearest neighbours in the manner of iVox
/// (Faster-LIO), with no tree to rebuild when points are added.
///
/// Voxels are stored in hashed blocks of 4 × 4 × 4, so the 27 voxels of a search touch a few
/// blocks rather than 27 hash entries.
#[derive(Debug, Clone)]
pub struct VoxelCloud {
    size: f64,
    blocks: FxHashMap<[i64; 3], Box<VoxelBlock>>,
    len: usize,
}

/// 4 × 4 × 4 voxels: a point per used voxel.
#[derive(Debug, Clone)]
struct VoxelBlock {
    used: u64,
    points: [Point3<f64>; 64],
}

/// The voxel of edge `size` holding `p` (aligned with the origin).
pub(crate) fn voxel_key(p: &Point3<f64>, size: f64) -> [i64; 3] {
    // Map coordinates are metres, far inside i64 (and the cast saturates otherwise).
    #[allow(clippy::cast_possible_truncation)]
    p.coords.map(|c| floor_i64(c / size)).into()
}

/// `x.floor() as i64`, bit for bit, without a libm call on CPUs without a rounding
/// instruction in the baseline target (x86-64 before SSE4.1): the truncating cast, one
/// step down where it rounded up. The casts saturate as `as` does, NaN gives 0.
#[inline]
fn floor_i64(x: f64) -> i64 {
    // Saturating casts, as `floor() as i64` does.
    #[allow(clippy::cast_possible_truncation, clippy::cast_precision_loss)]
    let (i, up) = {
        let i = x as i64;
        (i, i as f64 > x)
    };
    if up { i.saturating_sub(1) } else { i }
}

/// The squared radius of a sphere query, or −1 (no point is that near) for a negative or NaN
/// radius, whose square would otherwise read as a sphere of radius |r| or as everything.
fn squared_radius(radius: f64) -> f64 {
    if radius >= 0.0 { radius * radius } else { -1.0 }
}

/// Points per parallel task of [`VoxelCloud::extend_transformed`].
const EXTEND_CHUNK: usize = 4096;

/// The positions of the set bits of `bits`, lowest first.
fn set_bits(mut bits: u64) -> impl Iterator<Item = usize> {
    core::iter::from_fn(move || {
        (bits != 0).then(|| {
            let s = bits.trailing_zeros() as usize;
            bits &= bits - 1;
            s
        })
    })
}

/// The block of a voxel and the voxel's slot in it.
fn block_slot(v: [i64; 3]) -> ([i64; 3], usize) {
    // v & 3 is in 0..4, so the casts are exact.
    #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
    let slot = ((v[0] & 3) | ((v[1] & 3) << 2) | ((v[2] & 3) << 4)) as usize;
    ([v[0] >> 2, v[1] >> 2, v[2] >> 2], slot)
}

impl VoxelCloud {
    /// An empty cloud with voxels of edge `size` \[m\].
    pub fn new(size: f64) -> Self {
        Self {
            size,
            blocks: FxHashMap::default(),
            len: 0,
        }
    }

    fn key(&self, p: &Point3<f64>) -> [i64; 3] {
        voxel_key(p, self.size)
    }

    /// Adds `p` unless its voxel holds a point already (or it is not finite); whether it was
    /// added.
    pub fn insert(&mut self, p: Point3<f64>) -> bool {
        self.extend([p]) == 1
    }

    /// Adds each point, in order, unless its voxel holds a point already (or it is not
    /// finite); the number added.
    ///
    /// Consecutive points of a scan mostly fall in the same block, which is then looked up
    /// once rather than once a point.
    pub fn extend(&mut self, points: impl IntoIterator<Item = Point3<f64>>) -> usize {
        let mut added = 0;
        let mut last: Option<([i64; 3], &mut VoxelBlock)> = None;
        for p in points {
            if !p.iter().all(|c| c.is_finite()) {
                continue;
            }
            let (b, slot) = block_slot(voxel_key(&p, self.size));
            let block = match last {
                Some((key, block)) if key == b => block,
                _ => &mut **self.blocks.entry(b).or_insert_with(|| {
                    Box::new(VoxelBlock {
                        used: 0,
                        points: [Point3::origin(); 64],
                    })
                }),
            };
            if block.used & (1 << slot) == 0 {
                block.used |= 1 << slot;
                block.points[slot] = p;
                added += 1;
            }
            last = Some((b, block));
        }
        self.len += added;
        added
    }

    /// [`VoxelCloud::extend`] with `pose * p` for each of `points`, the transforms and the
    /// lookups of the voxels taken before the call done in parallel (rayon): only the points
    /// that may be added reach the serial insertion, so the same points are added, in the
    /// same order, as by `extend`.
    pub fn extend_transformed(&mut self, pose: &Isometry3<f64>, points: &[Point3<f64>]) -> usize {
        let this = &*self;
        let fresh: Vec<Point3<f64>> = points
            .par_chunks(EXTEND_CHUNK)
            .flat_map_iter(|chunk| {
                // Consecutive points mostly share a block: look each block up once a run.
                let mut last: Option<([i64; 3], u64)> = None;
                chunk.iter().map(|p| pose * p).filter(move |p| {
                    if !p.iter().all(|c| c.is_finite()) {
                        return false;
                    }
                    let (b, slot) = block_slot(this.key(p));
                    let used = match last {
                        Some((key, used)) if key == b => used,
                        _ => {
                            let used = this.blocks.get(&b).map_or(0, |block| block.used);
                            last = Some((b, used));
                            used
                        }
                    };
                    used & (1 << slot) == 0
                })
            })
            .collect();
        self.extend(fresh)
    }

    /// How block `key`'s box (voxels of edge `size`) lies against the sphere of squared
    /// radius `r2` about `centre`: `None` when wholly outside, `Some(false)` when wholly
    /// inside, `Some(true)` when its points must be tested one by one. The relative margins
    /// absorb the rounding of a point's voxel, so whole blocks are decided as the per-point
    /// test would decide each of their points.
    fn block_side(size: f64, key: &[i64; 3], centre: &Point3<f64>, r2: f64) -> Option<bool> {
        let edge = 4.0 * size;
        let (mut near, mut far) = (0.0, 0.0);
        for a in 0..3 {
            // Block coordinates are far below 2^53.
            #[allow(clippy::cast_precision_loss)]
            let lo = key[a] as f64 * edge;
            let (d0, d1) = (centre[a] - lo, lo + edge - centre[a]);
            let gap = (-d0).max(-d1).max(0.0);
            let reach = d0.abs().max(d1.abs());
            near += gap * gap;
            far += reach * reach;
        }
        if near > r2 * (1.0 + 1e-9) {
            None
        } else {
            Some(far >= r2 * (1.0 - 1e-9))
        }
    }

    /// Drops the points farther than `radius` from `centre` (all of them for a negative or
    /// NaN radius: no point is within it).
    pub fn retain_within(&mut self, centre: &Point3<f64>, radius: f64) {
        let r2 = squared_radius(radius);
        let mut len = 0;
        let size = self.size;
        self.blocks.retain(|key, block| {
            let Some(test) = Self::block_side(size, key, centre, r2) else {
                return false;
            };
            if test {
                let mut bits = block.used;
                while bits != 0 {
                    let slot = bits.trailing_zeros() as usize;
                    bits &= bits - 1;
                    if (block.points[slot] - centre).norm_squared() > r2 {
                        block.used &= !(1 << slot);
                    }
                }
            }
            len += block.used.count_ones() as usize;
            block.used != 0
        });
        self.len = len;
    }

    /// The points within `radius` of `centre`: the same points, in the same order, as
    /// filtering [`VoxelCloud::points`] by distance, with whole blocks decided by their boxes
    /// as in [`VoxelCloud::retain_within`]. None for a negative or NaN radius.
    pub fn points_within<'a>(
        &'a self,
        centre: &'a Point3<f64>,
        radius: f64,
    ) -> impl Iterator<Item = &'a Point3<f64>> + 'a {
        let r2 = squared_radius(radius);
        self.blocks.iter().flat_map(move |(key, b)| {
            let (used, test) = match Self::block_side(self.size, key, centre, r2) {
                None => (0, false),
                Some(test) => (b.used, test),
            };
            set_bits(used)
                .map(move |s| &b.points[s])
                .filter(move |p| !test || (*p - centre).norm_squared() <= r2)
        })
    }

    /// Every ⌈n / `max`⌉-th of the n points within `radius` of `centre`, from the first: the
    /// same points, in the same order, as collecting [`VoxelCloud::points_within`] and
    /// stepping through it, without listing the n points (whole blocks inside the sphere are
    /// counted and indexed by their occupancy bits). At most `max` points (`max` = 0 counts
    /// as 1). None for a negative or NaN radius.
    pub fn sample_within(&self, centre: &Point3<f64>, radius: f64, max: usize) -> Vec<Point3<f64>> {
        let r2 = squared_radius(radius);
        let within = |b: &VoxelBlock, s: usize| (b.points[s] - centre).norm_squared() <= r2;
        // The blocks that hold points within, in map order, with whether to test each point.
        let mut blocks: Vec<(&VoxelBlock, bool)> = Vec::new();
        let mut n = 0usize;
        for (key, b) in &self.blocks {
            match Self::block_side(self.size, key, centre, r2) {
                None => {}
                Some(false) => {
                    n += b.used.count_ones() as usize;
                    blocks.push((b, false));
                }
                Some(true) => {
                    let m = set_bits(b.used).filter(|&s| within(b, s)).count();
                    if m > 0 {
                        n += m;
                        blocks.push((b, true));
                    }
                }
            }
        }
        let every = n.div_ceil(max.max(1)).max(1);
        let mut out = Vec::with_capacity(n.div_ceil(every));
        // `index` counts the points within so far; `next` is the index of the next one taken.
        let (mut index, mut next) = (0usize, 0usize);
        for (b, test) in blocks {
            if test {
                for s in set_bits(b.used).filter(|&s| within(b, s)) {
                    if index == next {
                        out.push(b.points[s]);
                        next += every;
                    }
                    index += 1;
                }
            } else {
                let m = b.used.count_ones() as usize;
                while next < index + m {
                    // The (next − index)-th set bit.
                    let mut bits = b.used;
                    for _ in 0..next - index {
                        bits &= bits - 1;
                    }
                    out.push(b.points[bits.trailing_zeros() as usize]);
                    next += every;
                }
                index += m;
            }
        }
        out
    }

    /// Number of points.
    pub fn len(&self) -> usize {
        self.len
    }

    /// Whether the cloud is empty.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// The points, in no particular order.
    pub fn points(&self) -> impl Iterator<Item = &Point3<f64>> {
        self.blocks
            .values()
            .flat_map(|b| set_bits(b.used).map(move |s| &b.points[s]))
    }
}

/// The blocks a [`VoxelCloud`] query looked up last: the next query of the same blocks
/// (most of them, for the points of a scan in order) skips the hash lookups.
#[derive(Debug, Default)]
pub struct NearBlocks<'a> {
    last: Option<Looked<'a>>,
}

/// The lowest block and the extent (0 or 1 along each axis) looked up, with the blocks.
type Looked<'a> = ([i64; 3], [i64; 3], [Option<&'a VoxelBlock>; 8]);

impl Neighbours for VoxelCloud {
    type Memo<'a> = NearBlocks<'a>;

    fn nearest_with<'a>(
        &'a self,
        q: &Point3<f64>,
        k: usize,
        out: &mut Vec<(f64, Point3<f64>)>,
        memo: &mut NearBlocks<'a>,
    ) {
        out.clear();
        if k == 0 {
            return;
        }
        let c = self.key(q);
        // The 27 voxels lie in at most two blocks along each axis: look the (at most eight)
        // blocks up once, then index them by each voxel's offset from the lowest.
        let lo = [(c[0] - 1) >> 2, (c[1] - 1) >> 2, (c[2] - 1) >> 2];
        let span = [
            ((c[0] + 1) >> 2) - lo[0],
            ((c[1] + 1) >> 2) - lo[1],
            ((c[2] + 1) >> 2) - lo[2],
        ];
        let near = match memo.last {
            Some((l, s, near)) if l == lo && s == span => near,
            _ => {
                let mut near: [Option<&VoxelBlock>; 8] = [None; 8];
                for bz in 0..=span[2] {
                    for by in 0..=span[1] {
                        for bx in 0..=span[0] {
                            let key = [lo[0] + bx, lo[1] + by, lo[2] + bz];
                            // Each offset is 0 or 1, so the index is in 0..8.
                            #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
                            let at = (bx | (by << 1) | (bz << 2)) as usize;
                            near[at] = self.blocks.get(&key).map(|x| &**x);
                        }
                    }
                }
                memo.last = Some((lo, span, near));
                near
            }
        };
        for dz in -1..=1 {
            for dy in -1..=1 {
                for dx in -1..=1 {
                    let v = [c[0] + dx, c[1] + dy, c[2] + dz];
                    let (b, slot) = block_slot(v);
                    // As above: offsets of 0 or 1.
                    #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
                    let at =
                        ((b[0] - lo[0]) | ((b[1] - lo[1]) << 1) | ((b[2] - lo[2]) << 2)) as usize;
                    if let Some(block) = near[at]
                        && block.used & (1 << slot) != 0
                    {
                        let p = block.points[slot];
                        out.push(((p - q).norm_squared(), p));
                    }
                }
            }
        }
        if out.len() > k {
            out.select_nth_unstable_by(k - 1, |a, b| a.0.total_cmp(&b.0));
            out.truncate(k);
        }
    }
}

/// The plane (unit normal n, a point on it) fitted to the neighbours of `q`, if they are
/// close enough and planar enough.
fn fit_plane<'a, M: Neighbours>(
    map: &'a M,
    q: &Point3<f64>,
    cfg: &RegistrationConfig,
    (nn, memo): &mut (Vec<(f64, Point3<f64>)>, M::Memo<'a>),
) -> Option<(Vector3<f64>, Point3<f64>)> {
    map.nearest_with(q, cfg.neighbours, nn, memo);
    if nn.len() < 3 || nn.iter().any(|r| r.0 > cfg.max_neighbour_distance.powi(2)) {
        return None;
    }
    // At most `neighbours` points: the count is exact.
    #[allow(clippy::cast_precision_loss)]
    let count = nn.len() as f64;
    let mean = nn.iter().fold(Vector3::zeros(), |m, r| m + r.1.coords) / count;
    let cov = nn.iter().fold(Matrix3::zeros(), |m, r| {
        let d = r.1.coords - mean;
        m + d * d.transpose()
    });
    let (l, n) = least_eigen(&cov)?;
    if l[1].is_nan() || l[1] <= 0.0 || l[0].max(0.0) > cfg.planarity * l[1] {
        return None;
    }
    Some((n, Point3::from(mean)))
}

/// Registers `scan` (points in the scan frame) to `map`, starting from `initial`:
/// Gauss–Newton on SE(3) over point-to-plane residuals with a Huber kernel, the planes re-fitted
/// (in parallel) while the updates are large. Non-finite scan points are skipped; with no
/// matches the initial pose is returned unchanged (`matched == 0`).
pub fn register(
    map: &impl Neighbours,
    scan: &[Point3<f64>],
    initial: &Isometry3<f64>,
    cfg: &RegistrationConfig,
) -> Registration {
    register_with_prior(map, scan, initial, &Matrix6::zeros(), cfg)
}

/// [`register`] with a Gaussian prior on the pose about `initial`: the cost adds
/// ½ eᵀ Λ e for the error e = [log(R R₀⁻¹); t − t₀] of the pose (R, t) from `initial`
/// (R₀, t₀), with `prior` Λ in the units of [`Registration::hessian`] (one matched point's
/// squared residual), so it is the maximum a posteriori pose given a prediction with
/// information Λ (the odometry's filter passes its predicted covariance's inverse times the
/// points' residual variance). A zero Λ gives [`register`], and so does a Λ with a NaN or
/// infinite entry (ignored rather than allowed to poison the pose).
pub fn register_with_prior(
    map: &impl Neighbours,
    scan: &[Point3<f64>],
    initial: &Isometry3<f64>,
    prior: &Matrix6<f64>,
    cfg: &RegistrationConfig,
) -> Registration {
    let mut pose = *initial;
    let mut out = Registration {
        pose,
        matched: 0,
        iterations: 0,
        hessian: Matrix6::zeros(),
        information: Vector6::zeros(),
        weakest: Vector6::zeros(),
        rejected: false,
    };
    let scan: Vec<&Point3<f64>> = scan
        .iter()
        .filter(|p| p.iter().all(|v| v.is_finite()))
        .collect();
    let with_prior = prior.iter().any(|v| *v != 0.0) && prior.iter().all(|v| v.is_finite());
    let mut planes: Vec<Option<(Vector3<f64>, Point3<f64>)>> = vec![None; scan.len()];
    let mut refit = true;
    let mut h = Matrix6::zeros();
    for it in 0..cfg.iterations {
        h = Matrix6::zeros();
        let mut g = Vector6::zeros();
        let mut matched = 0;
        if refit {
            // The plane fits are independent: in parallel, each into its own slot.
            planes
                .par_iter_mut()
                .with_min_len(PLANE_CHUNK)
                .zip(scan.par_iter())
                .for_each_init(Default::default, |scratch, (plane, p)| {
                    *plane = fit_plane(map, &(pose * *p), cfg, scratch);
                });
        }
        let t = pose.translation.vector;
        for (p, plane) in scan.iter().zip(&planes) {
            let x = pose * *p;
            let Some((n, c)) = *plane else {
                continue;
            };
            let r = n.dot(&(x - c));
            // ξ = [δθ; δp] moves x to exp(δθ)(x − t) + t + δp: ∂r/∂ξ = [((x − t) × n)ᵀ, nᵀ].
            let xn = (x.coords - t).cross(&n);
            let j = Vector6::new(xn.x, xn.y, xn.z, n.x, n.y, n.z);
            let w = if r.abs() <= cfg.huber {
                1.0
            } else {
                cfg.huber / r.abs()
            };
            h += w * j * j.transpose();
            g += w * r * j;
            matched += 1;
        }
        out.iterations = it + 1;
        out.matched = matched;
        if matched < 6 && !with_prior {
            break;
        }
        // The prior's residual e = [log(R R₀⁻¹); t − t₀], with ∂e/∂ξ ≈ I for this ξ.
        let (mut a, mut g) = (h, g);
        if with_prior {
            let rr = (pose.rotation * initial.rotation.inverse()).scaled_axis();
            let rt = t - initial.translation.vector;
            a += prior;
            g += prior * Vector6::new(rr.x, rr.y, rr.z, rt.x, rt.y, rt.z);
        }
        // A little Levenberg damping keeps the step defined when the geometry leaves a
        // direction unconstrained (a corridor's axis) and there is no prior: that direction
        // then stays at the initial guess while the others are corrected.
        let damping = 1e-9 * a.trace().max(f64::MIN_POSITIVE);
        let Some(chol) = (a + Matrix6::identity() * damping).cholesky() else {
            break;
        };
        let dx = -chol.solve(&g);
        let omega = Vector3::new(dx[0], dx[1], dx[2]);
        let v = Vector3::new(dx[3], dx[4], dx[5]);
        if v.norm() > cfg.max_step || omega.norm() > cfg.max_step {
            // A step this large comes from geometry too poor to trust: keep the pose.
            out.rejected = true;
            break;
        }
        pose = Isometry3::from_parts(
            Translation3::from(t + v),
            UnitQuaternion::from_scaled_axis(omega) * pose.rotation,
        );
        if omega.norm() + v.norm() < cfg.tolerance {
            break;
        }
        refit = v.norm() + 10.0 * omega.norm() > cfg.reassociate;
    }
    out.hessian = h;
    let eig = SymmetricEigen::new(h);
    let mut order = [0usize, 1, 2, 3, 4, 5];
    order.sort_by(|a, b| eig.eigenvalues[*a].total_cmp(&eig.eigenvalues[*b]));
    out.information = Vector6::from_fn(|i, _| eig.eigenvalues[order[i]]);
    out.weakest = eig.eigenvectors.column(order[0]).into_owned();
    out.pose = pose;
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::Scene;

    /// Points on the surfaces of the small scene, seen from `pose`, in that pose's frame.
    fn scan(scene: &Scene, pose: &Isometry3<f64>, n: u32) -> Vec<Point3<f64>> {
        let world = scene.world().unwrap();
        let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
        let origin = Point3::from(pose.translation.vector);
        (0..n)
            .filter_map(|i| {
                let z = 1.0 - 2.0 * (f64::from(i) + 0.5) / f64::from(n);
                let r = (1.0 - z * z).sqrt();
                let a = golden * f64::from(i);
                let d = Vector3::new(r * a.cos(), r * a.sin(), z);
                let t = world.cast_ray(&origin, &d, 30.0)?;
                Some(pose.inverse() * (origin + d * t))
            })
            .collect()
    }

    #[test]
    fn recovers_a_perturbed_pose() {
        let scene = Scene::small(3);
        let truth = Isometry3::from_parts(
            Translation3::new(3.0, 3.0, 1.4),
            UnitQuaternion::from_euler_angles(0.02, -0.03, 0.7),
        );
        // The map: the scene seen from two other places.
        let mut map_pts = Vec::new();
        for p in [
            Point3::new(2.0, 2.0, 1.5),
            Point3::new(4.0, 5.0, 1.2),
            Point3::new(9.0, 4.0, 1.5),
        ] {
            let pose = Isometry3::translation(p.x, p.y, p.z);
            map_pts.extend(scan(&scene, &pose, 12_000).iter().map(|q| pose * q));
        }
        let tree = PlaneMap::new(&map_pts);
        let mut voxels = VoxelCloud::new(0.1);
        for p in &map_pts {
            voxels.insert(*p);
        }
        let s = scan(&scene, &truth, 3_000);
        let guess = Isometry3::from_parts(
            Translation3::new(0.15, -0.1, 0.05),
            UnitQuaternion::from_euler_angles(0.0, 0.02, 0.06),
        ) * truth;
        // The registration alone, without a prior that would hold it near a guess this far off
        // (a 0.1 s IMU prediction is good to millimetres).
        let cfg = RegistrationConfig {
            iterations: 30,
            ..Default::default()
        };
        // The exact k-d tree neighbours and the voxel-hashed approximate ones.
        for r in [
            tree.register(&s, &guess, &cfg),
            register(&voxels, &s, &guess, &cfg),
        ] {
            let err_t = (r.pose.translation.vector - truth.translation.vector).norm();
            let err_r = r.pose.rotation.angle_to(&truth.rotation);
            assert!(
                err_t < 2e-3 && err_r < 1e-3,
                "{err_t} m, {err_r} rad, {} matched",
                r.matched
            );
            assert!(r.matched > 1000);
            assert!(r.information[0] > 0.0);
        }
    }

    proptest::proptest! {
        /// `floor_i64` is `floor() as i64` for any float, the specials and the cast's ends
        /// included.
        #[test]
        fn floor_i64_is_floor_then_cast(x in proptest::num::f64::ANY) {
            proptest::prop_assert_eq!(floor_i64(x), x.floor() as i64);
        }
    }

    #[test]
    fn floor_i64_at_the_edges() {
        for x in [
            0.0,
            -0.0,
            0.5,
            -0.5,
            -1.0,
            1.0,
            -1e-300,
            2.5e15,
            -2.5e15,
            9.2e18,
            -9.2e18,
            i64::MAX as f64,
            i64::MIN as f64,
            (i64::MAX as f64).next_down(),
            (i64::MIN as f64).next_down(),
            1e19,
            -1e19,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NAN,
            f64::MAX,
            f64::MIN,
        ] {
            assert_eq!(floor_i64(x), x.floor() as i64, "{x}");
        }
    }

    proptest::proptest! {
        #[test]
        fn voxel_neighbours_match_brute_force_within_a_voxel(
            pts in proptest::collection::vec((-2.0f64..2.0, -2.0f64..2.0, -1.0f64..1.0), 1..200),
            q in (-2.0f64..2.0, -2.0f64..2.0, -1.0f64..1.0),
        ) {
            let size = 0.5;
            let mut cloud = VoxelCloud::new(size);
            let mut kept = Vec::new();
            for (x, y, z) in pts {
                let p = Point3::new(x, y, z);
                if cloud.insert(p) {
                    kept.push(p);
                }
            }
            let q = Point3::new(q.0, q.1, q.2);
            let mut got = Vec::new();
            cloud.nearest(&q, 0, &mut got);
            proptest::prop_assert!(got.is_empty());
            cloud.nearest(&q, 5, &mut got);
            let mut d: Vec<f64> = kept.iter().map(|p| (p - q).norm_squared()).collect();
            d.sort_by(f64::total_cmp);
            let mut g: Vec<f64> = got.iter().map(|r| r.0).collect();
            g.sort_by(f64::total_cmp);
            // Every point within one voxel edge of q lies in the 27 voxels searched, so the
            // nearest ones within that distance are found exactly.
            let within: Vec<f64> = d.iter().copied().filter(|&x| x <= size * size).take(5).collect();
            proptest::prop_assert_eq!(&g[..within.len()], &within[..]);
        }

        /// A memo carried over a run of queries (near each other, as a scan's points are,
        /// and far apart) gives each query the answer a fresh one does, in the same order.
        #[test]
        fn memo_never_changes_an_answer(
            pts in proptest::collection::vec((-2.0f64..2.0, -2.0f64..2.0, -1.0f64..1.0), 1..300),
            start in (-2.5f64..2.5, -2.5f64..2.5, -1.5f64..1.5),
            steps in proptest::collection::vec((-0.3f64..0.3, -0.3f64..0.3, -0.3f64..0.3), 1..60),
            k in 0usize..12,
        ) {
            let mut cloud = VoxelCloud::new(0.25);
            cloud.extend(pts.iter().map(|&(x, y, z)| Point3::new(x, y, z)));
            let mut memo = NearBlocks::default();
            let (mut with, mut fresh) = (Vec::new(), Vec::new());
            let mut q = Point3::new(start.0, start.1, start.2);
            for (i, (dx, dy, dz)) in steps.into_iter().enumerate() {
                // Every seventh query jumps across the cloud.
                q = if i % 7 == 6 { Point3::new(-q.x, -q.y, -q.z) } else { q + Vector3::new(dx, dy, dz) };
                cloud.nearest_with(&q, k, &mut with, &mut memo);
                cloud.nearest(&q, k, &mut fresh);
                proptest::prop_assert_eq!(&with, &fresh);
            }
        }
    }

    proptest::proptest! {
        /// `extend` keeps what point-by-point `insert` keeps, `points_within` lists what
        /// filtering `points` lists, and `retain_within` keeps
        /// exactly the points within the radius (whole blocks are decided by their boxes).
        #[test]
        fn extend_and_retain_match_point_by_point(
            pts in proptest::collection::vec((-3.0f64..3.0, -3.0f64..3.0, -1.0f64..1.0), 1..300),
            c in (-3.0f64..3.0, -3.0f64..3.0, -1.0f64..1.0),
            radius in 0.0f64..4.0,
            size in 0.05f64..0.6,
        ) {
            let pts: Vec<Point3<f64>> = pts.iter().map(|&(x, y, z)| Point3::new(x, y, z)).collect();
            let mut one = VoxelCloud::new(size);
            let mut kept = Vec::new();
            for p in &pts {
                if one.insert(*p) {
                    kept.push(*p);
                }
            }
            let mut all = VoxelCloud::new(size);
            let bad = [Point3::new(f64::NAN, 0.0, 0.0), Point3::new(0.0, f64::INFINITY, 0.0)];
            let added = all.extend(pts.iter().copied().chain(bad));
            proptest::prop_assert_eq!(added, kept.len());
            proptest::prop_assert_eq!(all.len(), kept.len());
            let sorted = |c: &VoxelCloud| {
                let mut v: Vec<[f64; 3]> = c.points().map(|p| [p.x, p.y, p.z]).collect();
                v.sort_by(|a, b| a.partial_cmp(b).unwrap());
                v
            };
            proptest::prop_assert_eq!(sorted(&all), sorted(&one));
            let centre = Point3::new(c.0, c.1, c.2);
            // `points_within` is `points` filtered, in the same order.
            let near: Vec<Point3<f64>> = all.points_within(&centre, radius).copied().collect();
            let filtered: Vec<Point3<f64>> = all
                .points()
                .filter(|p| (*p - centre).norm_squared() <= radius * radius)
                .copied()
                .collect();
            proptest::prop_assert_eq!(&near, &filtered);
            // `sample_within` steps through the same list.
            for max in [0, 1, 2, 7, 50, 1000] {
                let every = near.len().div_ceil(max.max(1)).max(1);
                let stepped: Vec<Point3<f64>> = near.iter().step_by(every).copied().collect();
                proptest::prop_assert_eq!(all.sample_within(&centre, radius, max), stepped);
            }
            all.retain_within(&centre, radius);
            let mut want: Vec<[f64; 3]> = kept
                .iter()
                .filter(|p| (*p - centre).norm_squared() <= radius * radius)
                .map(|p| [p.x, p.y, p.z])
                .collect();
            want.sort_by(|a, b| a.partial_cmp(b).unwrap());
            proptest::prop_assert_eq!(all.len(), want.len());
            proptest::prop_assert_eq!(sorted(&all), want);
        }

        /// `extend_transformed` adds what `extend` adds for the transformed points, in the
        /// same order (so the clouds list their points alike), onto a cloud that already
        /// holds some voxels, with repeats and non-finite points in the batch; the batch is
        /// large enough to be split between threads.
        #[test]
        fn extend_transformed_equals_extend(
            before in proptest::collection::vec((-3.0f64..3.0, -3.0f64..3.0, -1.0f64..1.0), 0..200),
            batch in proptest::collection::vec((-3.0f64..3.0, -3.0f64..3.0, -1.0f64..1.0), 0..12_000),
            t in (-1.0f64..1.0, -1.0f64..1.0, -1.0f64..1.0),
            r in (-1.0f64..1.0, -1.0f64..1.0, -1.0f64..1.0),
            size in 0.05f64..0.6,
        ) {
            let pose = Isometry3::new(Vector3::new(t.0, t.1, t.2), Vector3::new(r.0, r.1, r.2));
            let to_point = |&(x, y, z): &(f64, f64, f64)| Point3::new(x, y, z);
            let mut batch: Vec<Point3<f64>> = batch.iter().map(to_point).collect();
            let repeats: Vec<Point3<f64>> = batch.iter().step_by(7).copied().collect();
            batch.extend(repeats);
            batch.push(Point3::new(f64::NAN, 0.0, 0.0));
            batch.push(Point3::new(0.0, 0.0, f64::NEG_INFINITY));
            let mut serial = VoxelCloud::new(size);
            serial.extend(before.iter().map(to_point));
            let mut parallel = serial.clone();
            let a = serial.extend(batch.iter().map(|p| pose * p));
            let b = parallel.extend_transformed(&pose, &batch);
            proptest::prop_assert_eq!(a, b);
            proptest::prop_assert_eq!(serial.len(), parallel.len());
            let listed = |c: &VoxelCloud| c.points().map(|p| [p.x, p.y, p.z]).collect::<Vec<_>>();
            proptest::prop_assert_eq!(listed(&serial), listed(&parallel));
        }
    }

    #[test]
    fn a_negative_or_nan_radius_holds_no_point() {
        let mut cloud = VoxelCloud::new(0.1);
        let n = cloud.extend((0..50).map(|i| Point3::new(0.1 * f64::from(i) + 0.05, 0.0, 0.0)));
        assert_eq!(n, 50);
        let centre = Point3::new(1.0, 0.0, 0.0);
        for r in [-0.5, -f64::INFINITY, f64::NAN] {
            assert_eq!(cloud.points_within(&centre, r).count(), 0, "{r}");
            assert!(cloud.sample_within(&centre, r, 10).is_empty(), "{r}");
        }
        assert_eq!(cloud.points_within(&centre, f64::INFINITY).count(), 50);
        let mut dropped = cloud.clone();
        dropped.retain_within(&centre, f64::NAN);
        assert_eq!(dropped.len(), 0);
        cloud.retain_within(&centre, 0.5);
        assert!(!cloud.is_empty() && cloud.len() < 50);
    }

    #[test]
    fn a_long_corridor_leaves_its_axis_unconstrained() {
        // A 60 m corridor along x, 3 m wide and high, closed at both ends far away.
        let corridor = Scene {
            name: "corridor".into(),
            min: Point3::new(0.0, 0.0, 0.0),
            max: Point3::new(60.0, 3.0, 3.0),
            start: Point3::new(30.0, 1.5, 1.5),
            boxes: vec![
                (Point3::new(-1.0, -1.0, -1.0), Point3::new(61.0, 4.0, 0.0)),
                (Point3::new(-1.0, -1.0, 3.0), Point3::new(61.0, 4.0, 4.0)),
                (Point3::new(-1.0, -1.0, -1.0), Point3::new(61.0, 0.0, 4.0)),
                (Point3::new(-1.0, 3.0, -1.0), Point3::new(61.0, 4.0, 4.0)),
            ],
        };
        let pose = Isometry3::translation(30.0, 1.5, 1.5);
        let map_pts: Vec<_> = scan(&corridor, &pose, 12_000)
            .iter()
            .map(|q| pose * q)
            .collect();
        let map = PlaneMap::new(&map_pts);
        let r = map.register(
            &scan(&corridor, &pose, 3_000),
            &pose,
            &RegistrationConfig::default(),
        );
        // The weakest direction is a translation along the corridor; only the rays that reach
        // the far ends, 30 m away, constrain it.
        assert!(r.weakest[3].abs() > 0.99, "{:?}", r.weakest);
        assert!(
            r.information[0] < 1e-3 * r.information[5],
            "{:?}",
            r.information
        );
    }

    #[test]
    fn an_empty_map_changes_nothing() {
        let map = PlaneMap::new(&[]);
        assert!(map.is_empty());
        let p = Isometry3::translation(1.0, 2.0, 3.0);
        let r = map.register(&[Point3::origin()], &p, &RegistrationConfig::default());
        assert_eq!(r.pose, p);
        assert_eq!(r.matched, 0);
        // NaN scan points are skipped, not matched.
        let full = PlaneMap::new(&[
            Point3::new(0.0, 0.0, 0.0),
            Point3::new(1.0, 0.0, 0.0),
            Point3::new(0.0, 1.0, 0.0),
        ]);
        let r = full.register(
            &[Point3::new(f64::NAN, 0.0, 0.0)],
            &p,
            &RegistrationConfig::default(),
        );
        assert_eq!((r.pose, r.matched), (p, 0));
    }

    #[test]
    fn the_prior_keeps_a_weakly_constrained_direction_near_the_prediction() {
        // A corridor (walls y = 0 and y = 4, floor z = 0) constrains y, z and the attitude;
        // only a 1 m² patch across it constrains x, and the map has that patch 0.2 m farther
        // than the scan sees it: a wrong, weak constraint.
        let grid = |n: i32, step: f64| (0..n).map(move |i| f64::from(i) * step);
        let mut world = Vec::new();
        for x in grid(200, 0.1).map(|x| x - 10.0) {
            for h in grid(31, 0.1) {
                world.push(Point3::new(x, 0.0, h));
                world.push(Point3::new(x, 4.0, h));
            }
            for y in grid(41, 0.1) {
                world.push(Point3::new(x, y, 0.0));
            }
        }
        let patch = |x: f64, step: f64, n: i32| {
            grid(n, step)
                .flat_map(move |a| grid(n, step).map(move |b| Point3::new(x, 1.5 + a, 1.0 + b)))
        };
        let mut map_points = world.clone();
        map_points.extend(patch(5.2, 0.1, 11));
        let map = PlaneMap::new(&map_points);
        let pose = Isometry3::translation(0.0, 2.0, 1.5);
        let mut scan: Vec<Point3<f64>> = world
            .iter()
            .step_by(7)
            .filter(|p| p.x.abs() < 5.0)
            .map(|p| pose.inverse() * p)
            .collect();
        scan.extend(patch(5.0, 0.25, 5).map(|p| pose.inverse() * p));
        let cfg = RegistrationConfig::default();
        let shift = |prior: &Matrix6<f64>| {
            let r = register_with_prior(&map, &scan, &pose, prior, &cfg);
            (r.pose.translation.vector - pose.translation.vector, r)
        };
        let (free, r) = shift(&Matrix6::zeros());
        // A non-finite prior is ignored.
        assert_eq!(shift(&Matrix6::from_element(f64::NAN)).0, free);
        assert!(
            free.x > 0.15,
            "without the prior the patch drags x: {free:?} {r:?}"
        );
        // With it, x moves by about 0.2 · I / (I + w) for the patch's information I along x
        // (about 20 here) and the prior's weight w (30): less than half as far.
        let prior = Matrix6::from_diagonal(&Vector6::new(1e3, 1e3, 1e3, 30.0, 30.0, 30.0));
        let (d, r) = shift(&prior);
        assert!(
            d.x > 0.0 && d.x < 0.5 * free.x,
            "the prior holds x: {d:?} {r:?}"
        );
        // The same pose as the closed form of one linear step: with the planes fixed, x solves
        // (I + w) x = I · 0.2 along the axis.
        let along = r.hessian[(3, 3)];
        assert!(
            (d.x - 0.2 * along / (along + 30.0)).abs() < 0.02,
            "{} vs {}",
            d.x,
            0.2 * along / (along + 30.0)
        );
        assert!(d.y.abs() < 0.01 && d.z.abs() < 0.01, "{d:?}");
    }
}
