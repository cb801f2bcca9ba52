//! Viewpoint sampling, visibility ratios (4)–(5) and dynamic clusters (6).

use nalgebra::{Point3, Vector3};
use rayon::prelude::*;
use rustc_hash::FxHashMap;

use crate::frontier::{Cluster, ClusterId, Frontiers};
use crate::grid::Cell;
use crate::map::{CellState, VoxelMap};
use crate::{FrontierError, Result};

/// Which directions a sensor at a viewpoint can see.
///
/// The argument is the offset from the viewpoint to the target \[m\], in the world frame. A
/// LiDAR spinning on a motor sees nearly a full sphere ([`Omnidirectional`]); a fixed one sees a
/// band of elevations ([`ElevationBand`]) or less. Closures `Fn(&Vector3<f64>) -> bool` work too.
pub trait FieldOfView {
    /// Whether a target at `offset` from the sensor is inside the field of view.
    fn sees(&self, offset: &Vector3<f64>) -> bool;
}

impl<F: Fn(&Vector3<f64>) -> bool> FieldOfView for F {
    fn sees(&self, offset: &Vector3<f64>) -> bool {
        self(offset)
    }
}

/// Every direction: a rotating LiDAR's field of view over a revolution.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Omnidirectional;

impl FieldOfView for Omnidirectional {
    fn sees(&self, _offset: &Vector3<f64>) -> bool {
        true
    }
}

/// Directions whose elevation above the horizontal plane lies in `[min, max]` \[rad\]: a
/// horizontally mounted spinning LiDAR (e.g. ±15° for a 16-ring sensor).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ElevationBand {
    /// Lowest elevation \[rad\].
    pub min: f64,
    /// Highest elevation \[rad\].
    pub max: f64,
}

impl FieldOfView for ElevationBand {
    fn sees(&self, offset: &Vector3<f64>) -> bool {
        let e = offset.z.atan2(offset.xy().norm());
        e >= self.min && e <= self.max
    }
}

/// Largest number of candidate viewpoints per cluster, `radii.len() × elevations.len() ×
/// azimuths` (2^16; the default samples 90): [`ViewpointConfig::validate`] rejects more, and
/// [`sample_candidates`] returns none for more.
pub const MAX_CANDIDATES: usize = 1 << 16;

/// Settings of viewpoint sampling, visibility and dynamic clustering.
///
/// Candidates for a cluster with centre c and normal n are c + r·d for every radius r and
/// every direction d at an elevation e above the plane normal to n (e = π/2 is along n) and
/// one of `azimuths` equally spaced azimuths around n: `radii.len() × elevations.len() ×
/// azimuths` candidates in the hemisphere of n, at most [`MAX_CANDIDATES`].
#[derive(Debug, Clone, PartialEq)]
pub struct ViewpointConfig {
    /// Sampling distances from the cluster centre \[m\]; default 1.5, 2.5, 3.5.
    pub radii: Vec<f64>,
    /// Elevations above the plane normal to n \[rad\], each in [0, π/2]; default 15°, 40°, 65°.
    pub elevations: Vec<f64>,
    /// Azimuths around n, at most [`MAX_CANDIDATES`]; default 10.
    pub azimuths: usize,
    /// Smallest clearance to occupied cells \[m\]; default 0.5.
    pub safety_distance: f64,
    /// Largest distance at which a cell counts as seen \[m\]; default 5 (FUEL uses 4.5).
    pub sensor_range: f64,
    /// r0 of (5): the least share of a cluster's cells a viewpoint must see; default 0.5.
    pub min_visibility: f64,
    /// Cells per cluster over which r(v) is evaluated: at most this many, evenly spaced in the
    /// cluster's sorted cell list (0: every cell). Default 32, as FUEL also evaluates
    /// visibility on a down-sampled cluster.
    pub visibility_samples: usize,
    /// Whether unknown cells block the view (conservative) or only occupied ones do
    /// (optimistic, as FUEL); default `false`.
    pub unknown_occludes: bool,
    /// α of (6): cost per metre of extent a merge adds \[1/m\]; default 1.
    pub alpha: f64,
    /// β of (6): gain per shared viewpoint a merge keeps; default 0.1.
    pub beta: f64,
}

impl Default for ViewpointConfig {
    fn default() -> Self {
        Self {
            radii: vec![1.5, 2.5, 3.5],
            elevations: [15.0f64, 40.0, 65.0].map(f64::to_radians).to_vec(),
            azimuths: 10,
            safety_distance: 0.5,
            sensor_range: 5.0,
            visibility_samples: 32,
            min_visibility: 0.5,
            unknown_occludes: false,
            alpha: 1.0,
            beta: 0.1,
        }
    }
}

impl ViewpointConfig {
    /// Checks every setting.
    ///
    /// # Errors
    /// [`FrontierError::InvalidConfig`] naming the first setting out of range: empty sampling
    /// sets, more than [`MAX_CANDIDATES`] azimuths or candidates, radii or ranges that are not
    /// positive and finite, elevations outside [0, π/2], r0 outside (0, 1], or negative or
    /// NaN weights.
    pub fn validate(&self) -> Result<()> {
        let bad = |what, value, reason| {
            Err(FrontierError::InvalidConfig {
                what,
                value,
                reason,
            })
        };
        let pos = |v: f64| v.is_finite() && v > 0.0;
        if self.radii.is_empty() || self.elevations.is_empty() || self.azimuths == 0 {
            return bad(
                "radii/elevations/azimuths",
                0.0,
                "need at least one of each",
            );
        }
        // Only in the messages: exact below 2^53.
        #[allow(clippy::cast_precision_loss)]
        let count = |n: usize| n as f64;
        if self.azimuths > MAX_CANDIDATES {
            return bad(
                "azimuths",
                count(self.azimuths),
                "must be at most MAX_CANDIDATES (65536)",
            );
        }
        if self.candidates().is_none() {
            return bad(
                "radii.len() x elevations.len() x azimuths",
                count(self.radii.len()) * count(self.elevations.len()) * count(self.azimuths),
                "must be at most MAX_CANDIDATES (65536)",
            );
        }
        if let Some(r) = self.radii.iter().find(|r| !pos(**r)) {
            return bad("radii", *r, "must be positive and finite [m]");
        }
        if let Some(e) = self
            .elevations
            .iter()
            .find(|e| !(0.0..=core::f64::consts::FRAC_PI_2).contains(*e))
        {
            return bad("elevations", *e, "must be in [0, pi/2] [rad]");
        }
        if !(self.safety_distance.is_finite() && self.safety_distance >= 0.0) {
            return bad(
                "safety_distance",
                self.safety_distance,
                "must be >= 0 and finite [m]",
            );
        }
        if !pos(self.sensor_range) {
            return bad(
                "sensor_range",
                self.sensor_range,
                "must be positive and finite [m]",
            );
        }
        if !(self.min_visibility > 0.0 && self.min_visibility <= 1.0) {
            return bad("min_visibility", self.min_visibility, "must be in (0, 1]");
        }
        for (what, v) in [("alpha", self.alpha), ("beta", self.beta)] {
            if !(v.is_finite() && v >= 0.0) {
                return bad(what, v, "must be >= 0 and finite");
            }
        }
        Ok(())
    }

    /// Candidates per cluster, `None` above [`MAX_CANDIDATES`].
    fn candidates(&self) -> Option<usize> {
        self.radii
            .len()
            .checked_mul(self.elevations.len())?
            .checked_mul(self.azimuths)
            .filter(|&n| n <= MAX_CANDIDATES)
    }
}

/// One observation target for the tour planner: a dynamic cluster of frontier clusters that
/// can be seen together, and its representative viewpoint.
#[derive(Debug, Clone, PartialEq)]
pub struct Target {
    /// The representative viewpoint \[m\].
    pub viewpoint: Point3<f64>,
    /// The member frontier clusters, in the order they joined.
    pub members: Vec<ClusterId>,
    /// Mean of the members' cell centres \[m\].
    pub center: Point3<f64>,
    /// Total frontier cells of the members (the intensity score).
    pub score: f64,
    /// Frontier cells of the members the viewpoint sees.
    pub seen_cells: usize,
    /// Viewpoints in the shared visible region.
    pub shared_viewpoints: usize,
}

/// The result of [`plan_targets`].
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Plan {
    /// Targets, in the order their dynamic clusters were created.
    pub targets: Vec<Target>,
    /// Clusters with no valid viewpoint that sees at least r0 of their cells.
    pub unviewable: Vec<ClusterId>,
    /// Candidate viewpoints sampled.
    pub sampled: usize,
    /// Valid candidates (inside the bounds, free, with clearance, supported).
    pub valid: usize,
}

/// Whether the centre of `cell` is seen from `from`: within range, inside the field of view
/// and not occluded (voxel ray cast). `false` for a viewpoint outside the map bounds or not
/// finite, and for a `config` that fails [`ViewpointConfig::validate`].
pub fn cell_visible(
    map: &VoxelMap,
    from: &Point3<f64>,
    cell: Cell,
    fov: &impl FieldOfView,
    config: &ViewpointConfig,
) -> bool {
    map.bounds().contains(from)
        && config.validate().is_ok()
        && in_view(map, from, cell, fov, config)
}

/// [`cell_visible`] for a viewpoint inside the bounds and a valid `config`.
fn in_view(
    map: &VoxelMap,
    from: &Point3<f64>,
    cell: Cell,
    fov: &impl FieldOfView,
    config: &ViewpointConfig,
) -> bool {
    let off = map.grid().center(cell) - from;
    off.norm() <= config.sensor_range
        && fov.sees(&off)
        && !map.occluded(from, cell, config.unknown_occludes)
}

/// The visibility ratio (4): the share of `cluster`'s cells seen from `from`; 0 for a viewpoint
/// outside the map or not finite, and for a `config` that fails [`ViewpointConfig::validate`].
pub fn visibility_ratio(
    map: &VoxelMap,
    cluster: &Cluster,
    from: &Point3<f64>,
    fov: &impl FieldOfView,
    config: &ViewpointConfig,
) -> f64 {
    if !map.bounds().contains(from) || cluster.cells().is_empty() || config.validate().is_err() {
        return 0.0;
    }
    let seen = cluster
        .cells()
        .iter()
        .filter(|c| in_view(map, from, **c, fov, config))
        .count();
    ratio(seen, cluster.cells().len())
}

fn ratio(a: usize, b: usize) -> f64 {
    // Cell counts are far below 2^53.
    #[allow(clippy::cast_precision_loss)]
    let r = a as f64 / b.max(1) as f64;
    r
}

/// The candidate viewpoints of a cluster, before validation, in the hemisphere of its normal;
/// none when `config` asks for more than [`MAX_CANDIDATES`].
pub fn sample_candidates(cluster: &Cluster, config: &ViewpointConfig) -> Vec<Point3<f64>> {
    let Some(count) = config.candidates() else {
        return Vec::new();
    };
    let n = cluster.normal();
    let helper = if n.z.abs() < 0.9 {
        Vector3::z()
    } else {
        Vector3::x()
    };
    let u = n.cross(&helper).normalize();
    let w = n.cross(&u);
    let mut out = Vec::with_capacity(count);
    for &r in &config.radii {
        for &e in &config.elevations {
            for k in 0..config.azimuths {
                // Azimuth counts are small.
                #[allow(clippy::cast_precision_loss)]
                let a = core::f64::consts::TAU * k as f64 / config.azimuths as f64;
                let d = e.cos() * (a.cos() * u + a.sin() * w) + e.sin() * n;
                out.push(cluster.center() + r * d);
            }
        }
    }
    out
}

/// Whether a viewpoint is valid: inside the bounds, in a known-free cell, with clearance at
/// least the safety distance, and supported by the caller's predicate.
pub fn viewpoint_valid(
    map: &VoxelMap,
    p: &Point3<f64>,
    config: &ViewpointConfig,
    supported: &impl Fn(&Point3<f64>) -> bool,
) -> bool {
    map_allows(map, p, config) && supported(p)
}

/// The map's part of [`viewpoint_valid`]: inside the bounds, in a known-free cell, with
/// clearance at least the safety distance.
fn map_allows(map: &VoxelMap, p: &Point3<f64>, config: &ViewpointConfig) -> bool {
    map.state(p) == CellState::Free && map.is_clear(p, config.safety_distance)
}

/// At most `k` evenly spaced cells of `cells` (all of them for `k = 0`).
fn subsample(cells: &[Cell], k: usize) -> Vec<Cell> {
    if k == 0 || cells.len() <= k {
        return cells.to_vec();
    }
    (0..k).map(|j| cells[j * cells.len() / k]).collect()
}

/// Which of the first 64 samples of a cluster were evaluated from a candidate, and which of
/// those are seen: the r0 test and the choice of representatives ask for the same cells.
#[derive(Debug, Clone, Copy, Default)]
struct Bits {
    asked: u64,
    seen: u64,
}

/// Pooled candidates and lazily evaluated visibility. The config is valid and every
/// candidate lies in a free cell, inside the bounds, so visibility skips those checks.
struct Pool<'a, F> {
    map: &'a VoxelMap,
    clusters: Vec<&'a Cluster>,
    /// The cells r(v) is evaluated over, per cluster.
    samples: Vec<Vec<Cell>>,
    /// How far from a cluster's centre its visible region is looked for \[m\].
    reach: Vec<f64>,
    points: Vec<Point3<f64>>,
    fov: &'a F,
    config: &'a ViewpointConfig,
    /// The samples' visibility found so far, per (cluster, candidate) pair judged.
    memo: FxHashMap<(u32, u32), Bits>,
}

/// The key of a (cluster, candidate) pair; both counts fit `u32`.
#[allow(clippy::cast_possible_truncation)]
fn key(i: usize, v: usize) -> (u32, u32) {
    (i as u32, v as u32)
}

impl<F: FieldOfView> Pool<'_, F> {
    /// Judges r(v) ≥ r0 for every (cluster, candidate) pair of `pairs`, in parallel (pairs
    /// are independent), remembers the samples' visibility, and returns the verdicts in order.
    fn judge_all(&mut self, pairs: &[(usize, usize)]) -> Vec<bool>
    where
        F: Sync,
    {
        let this = &*self;
        let judged: Vec<(bool, Bits)> = pairs
            .par_iter()
            .map(|&(i, v)| {
                let mut bits = Bits::default();
                (this.judge(i, v, &mut bits), bits)
            })
            .collect();
        let verdicts = judged.iter().map(|(ok, _)| *ok).collect();
        self.memo.extend(
            pairs
                .iter()
                .zip(judged)
                .map(|(&(i, v), (_, bits))| (key(i, v), bits)),
        );
        verdicts
    }

    /// Whether r(v) ≥ r0 for cluster `i` from candidate `v`, counting the samples only until
    /// the answer is known.
    fn judge(&self, i: usize, v: usize, bits: &mut Bits) -> bool {
        let n = self.samples[i].len();
        // Cell counts are far below 2^53.
        #[allow(
            clippy::cast_precision_loss,
            clippy::cast_possible_truncation,
            clippy::cast_sign_loss
        )]
        let need = ((self.config.min_visibility * n as f64) - 1e-9)
            .ceil()
            .max(0.0) as usize;
        let (mut seen, mut left) = (0usize, n);
        for j in 0..n {
            if seen >= need || seen + left < need {
                break;
            }
            left -= 1;
            if self.visible(i, v, j, bits) {
                seen += 1;
            }
        }
        seen >= need
    }

    /// Whether sample `j` of cluster `i` is seen from candidate `v`, remembered in `bits` for
    /// the first 64 samples.
    fn visible(&self, i: usize, v: usize, j: usize, bits: &mut Bits) -> bool {
        let c = self.samples[i][j];
        let p = self.points[v];
        if j >= 64 {
            return in_view(self.map, &p, c, self.fov, self.config);
        }
        let bit = 1u64 << j;
        if bits.asked & bit != 0 {
            return bits.seen & bit != 0;
        }
        let seen = in_view(self.map, &p, c, self.fov, self.config);
        bits.asked |= bit;
        if seen {
            bits.seen |= bit;
        }
        seen
    }

    /// Whether candidate `v` is close enough to cluster `i` to be in its visible region.
    fn near(&self, i: usize, v: usize) -> bool {
        (self.points[v] - self.clusters[i].center()).norm() <= self.reach[i]
    }

    /// Cells of cluster `i` seen from `v`, estimated from the samples.
    fn estimate(&self, i: usize, v: usize) -> f64 {
        let mut bits = self.memo.get(&key(i, v)).copied().unwrap_or_default();
        let n = self.samples[i].len();
        let k = (0..n).filter(|&j| self.visible(i, v, j, &mut bits)).count();
        ratio(k, n) * self.clusters[i].score()
    }

    /// Cells of cluster `i` seen from `v`, counted on every cell.
    fn count(&self, i: usize, v: usize) -> usize {
        let p = self.points[v];
        self.clusters[i]
            .cells()
            .iter()
            .filter(|c| in_view(self.map, &p, **c, self.fov, self.config))
            .count()
    }
}

struct Dynamic {
    members: Vec<usize>,
    region: Vec<usize>,
    min: Point3<f64>,
    max: Point3<f64>,
}

fn extent(min: &Point3<f64>, max: &Point3<f64>) -> f64 {
    (max - min).norm()
}

/// Turns the frontier's clusters into observation targets: samples and validates viewpoints
/// for each cluster, keeps the visible region R = {v : r(v) ≥ r0} of (5), merges clusters into
/// dynamic clusters by the cost J = α Δd − β q of (6), and picks a representative viewpoint per
/// dynamic cluster.
///
/// - A dynamic cluster D keeps its shared visible region R_D: viewpoints sampled for its
///   members that see at least r0 of every member's cells. A cluster X may merge into D only
///   if R_X ∩ R_D ≠ ∅, i.e. some viewpoint of R_D within X's sampling reach (largest radius plus
///   half X's box diagonal from its centre) sees at least r0 of X; q = |R_X ∩ R_D| and Δd is
///   the growth of the diagonal of D's bounding box. r(v) is evaluated over
///   [`ViewpointConfig::visibility_samples`] cells of each cluster.
/// - Clusters are taken in id order and merged greedily into the dynamic cluster of least J;
///   with no valid merge they start a new one.
/// - The representative viewpoint sees the most member cells (estimated on the samples;
///   [`Target::seen_cells`] is then counted on every cell); ties go to the one nearest to
///   `uav`.
/// - `supported` is the caller's test that a point is in a region the planner can reach (for
///   example near a node of its topological graph); it is called on this thread, in order.
///
/// Deterministic: the same map, frontier and inputs give the same plan, for any number of
/// threads. Visibility is evaluated on rayon's thread pool (clusters, and dynamic clusters,
/// are independent), so `fov` must be `Sync`.
///
/// # Errors
/// An invalid `config` (see [`ViewpointConfig::validate`]) or a `uav` position that is not
/// finite.
pub fn plan_targets(
    map: &VoxelMap,
    frontiers: &Frontiers,
    uav: &Point3<f64>,
    fov: &(impl FieldOfView + Sync),
    supported: impl Fn(&Point3<f64>) -> bool,
    config: &ViewpointConfig,
) -> Result<Plan> {
    let clusters: Vec<&Cluster> = frontiers.clusters().collect();
    plan_targets_among(map, &clusters, uav, fov, supported, config)
}

/// [`plan_targets`] over a chosen subset of clusters, taken in the given order (for example
/// the clusters nearest to the UAV, in id order, to bound the work in a large map). Clusters
/// of another map's frontier give meaningless targets.
///
/// # Errors
/// As [`plan_targets`].
pub fn plan_targets_among(
    map: &VoxelMap,
    clusters: &[&Cluster],
    uav: &Point3<f64>,
    fov: &(impl FieldOfView + Sync),
    supported: impl Fn(&Point3<f64>) -> bool,
    config: &ViewpointConfig,
) -> Result<Plan> {
    config.validate()?;
    if !uav.iter().all(|v| v.is_finite()) {
        return Err(FrontierError::NonFinite {
            what: "UAV position",
        });
    }
    let clusters: Vec<&Cluster> = clusters.to_vec();
    let samples = clusters
        .iter()
        .map(|c| subsample(c.cells(), config.visibility_samples))
        .collect();
    let far = config.radii.iter().copied().fold(0.0, f64::max);
    let reach = clusters
        .iter()
        .map(|c| far + 0.5 * (c.bbox_max() - c.bbox_min()).norm())
        .collect();
    let mut pool = Pool {
        map,
        clusters,
        samples,
        reach,
        points: Vec::new(),
        fov,
        config,
        memo: FxHashMap::default(),
    };
    let mut plan = Plan::default();
    // Each cluster's own candidates, pooled; the map's tests run in parallel, the caller's
    // predicate in order on this thread.
    let free: Vec<(usize, Vec<Point3<f64>>)> = pool
        .clusters
        .par_iter()
        .map(|c| {
            let all = sample_candidates(c, config);
            let n = all.len();
            let kept = all
                .into_iter()
                .filter(|p| map_allows(map, p, config))
                .collect();
            (n, kept)
        })
        .collect();
    // Each cluster's own visible region: the pairs of a cluster and its own candidates.
    let mut pairs: Vec<(usize, usize)> = Vec::new();
    for (i, (n, kept)) in free.into_iter().enumerate() {
        plan.sampled += n;
        let start = pool.points.len();
        pool.points
            .extend(kept.into_iter().filter(|p| supported(p)));
        pairs.extend((start..pool.points.len()).map(|v| (i, v)));
    }
    plan.valid = pool.points.len();
    let verdicts = pool.judge_all(&pairs);
    let mut regions: Vec<Vec<usize>> = vec![Vec::new(); pool.clusters.len()];
    for (&(i, v), ok) in pairs.iter().zip(verdicts) {
        if ok {
            regions[i].push(v);
        }
    }
    let mut dynamic: Vec<Dynamic> = Vec::new();
    for i in 0..pool.clusters.len() {
        let region = core::mem::take(&mut regions[i]);
        if region.is_empty() {
            plan.unviewable.push(pool.clusters[i].id());
            continue;
        }
        let (cmin, cmax) = (pool.clusters[i].bbox_min(), pool.clusters[i].bbox_max());
        let reach = 2.0 * config.sensor_range;
        // The viewpoints of every dynamic cluster near enough to share some with this one.
        let near: Vec<(usize, Vec<usize>)> = dynamic
            .iter()
            .enumerate()
            .filter(|(_, d)| {
                // Quick reject: boxes too far apart to be seen from one point.
                let gap = (0..3)
                    .map(|a| (d.min[a] - cmax[a]).max(cmin[a] - d.max[a]).max(0.0))
                    .fold(0.0f64, |s, g| s + g * g)
                    .sqrt();
                gap <= reach
            })
            .map(|(k, d)| {
                let vs = d.region.iter().copied().filter(|&v| pool.near(i, v));
                (k, vs.collect())
            })
            .collect();
        let pairs: Vec<(usize, usize)> = near
            .iter()
            .flat_map(|(_, vs)| vs.iter().map(|&v| (i, v)))
            .collect();
        let verdicts = pool.judge_all(&pairs);
        let mut best: Option<(f64, usize, Vec<usize>)> = None;
        let mut at = 0;
        for (k, vs) in near {
            let d = &dynamic[k];
            let shared: Vec<usize> = vs
                .iter()
                .zip(&verdicts[at..])
                .filter(|(_, ok)| **ok)
                .map(|(v, _)| *v)
                .collect();
            at += vs.len();
            if shared.is_empty() {
                continue;
            }
            let (nmin, nmax) = (d.min.inf(&cmin), d.max.sup(&cmax));
            let dd = extent(&nmin, &nmax) - extent(&d.min, &d.max);
            // Counts are small.
            #[allow(clippy::cast_precision_loss)]
            let j = config.alpha * dd - config.beta * shared.len() as f64; // eq. (6)
            if best.as_ref().is_none_or(|b| j < b.0) {
                best = Some((j, k, shared));
            }
        }
        match best {
            Some((_, k, shared)) => {
                let d = &mut dynamic[k];
                d.members.push(i);
                d.region = shared;
                d.min = d.min.inf(&cmin);
                d.max = d.max.sup(&cmax);
            }
            None => dynamic.push(Dynamic {
                members: vec![i],
                region,
                min: cmin,
                max: cmax,
            }),
        }
    }
    // Representatives: the most member cells seen (estimated on the samples), ties to the
    // nearest; then the exact count. Dynamic clusters are independent.
    let pool = &pool;
    let targets: Vec<Option<Target>> = dynamic
        .par_iter()
        .map(|d| {
            let mut best: Option<(f64, f64, usize)> = None;
            for &v in &d.region {
                let seen: f64 = d.members.iter().map(|&m| pool.estimate(m, v)).sum();
                let dist = (pool.points[v] - uav).norm();
                let better = best.is_none_or(|(s, bd, _)| seen > s || (seen == s && dist < bd));
                if better {
                    best = Some((seen, dist, v));
                }
            }
            let (_, _, v) = best?;
            let seen: usize = d.members.iter().map(|&m| pool.count(m, v)).sum();
            let cells: usize = d
                .members
                .iter()
                .map(|&m| pool.clusters[m].cells().len())
                .sum();
            let center = d.members.iter().fold(Vector3::zeros(), |s, &m| {
                s + pool.clusters[m].center().coords * pool.clusters[m].score()
            }) / ratio(cells, 1);
            Some(Target {
                viewpoint: pool.points[v],
                members: d.members.iter().map(|&m| pool.clusters[m].id()).collect(),
                center: Point3::from(center),
                score: ratio(cells, 1),
                seen_cells: seen,
                shared_viewpoints: d.region.len(),
            })
        })
        .collect();
    plan.targets = targets.into_iter().flatten().collect();
    Ok(plan)
}
