//! Which frontier clusters the explorer still asks for, kept up to date frame by frame.

use frontier::{Cluster, ClusterId, FrameUpdate, FrontierDelta, Frontiers, VoxelMap};
use fu_mpc_core::FrontierTarget;
use nalgebra::Point3;
use rustc_hash::{FxHashMap, FxHashSet};

/// The frontier clusters the mission asks for, judged from scratch: the reference the
/// cache's tests compare [`MissionCache`] with.
#[cfg(test)]
pub(crate) fn mission_clusters<'a>(
    frontiers: &'a Frontiers,
    map: &'a VoxelMap,
    hits: &'a HitCells,
    region: (Point3<f64>, Point3<f64>),
) -> impl Iterator<Item = &'a Cluster> {
    frontiers
        .clusters()
        .filter(move |c| keeps(c, map, hits, region))
}

/// Whether the mission asks for `cluster`: at least [`FrontierConfig::min_cluster_cells`]
/// cells (as [`Frontiers::clusters`] lists), more than a quarter of them inside the region,
/// not [`surface_bound`] and never hit.
///
/// A frontier cell a return has ended in holds a surface: its unknown neighbour lies behind
/// that surface, inside the solid, and no view resolves it. (The sinkhole's ledges lie at the
/// heights of cell centres: the cells they cut are hit from above and cleared by grazing rays,
/// so they end free with an unknown cell below and free cells beside, which
/// [`surface_bound`] does not catch; runs never finished for them.)
///
/// [`FrontierConfig::min_cluster_cells`]: frontier::FrontierConfig::min_cluster_cells
fn keeps(
    cluster: &Cluster,
    map: &VoxelMap,
    hits: &HitCells,
    region: (Point3<f64>, Point3<f64>),
) -> bool {
    let grid = *map.grid();
    let h = 0.5 * grid.resolution();
    let (lo, hi) = region;
    let inner = |p: Point3<f64>| (0..3).all(|k| p[k] > lo[k] + h && p[k] < hi[k] - h);
    let live = cluster
        .cells()
        .iter()
        .filter(|&&q| inner(grid.center(q)) && !surface_bound(map, q) && !hits.contains(q))
        .count();
    // A frontier onto a narrow passage has many cells beside its walls: a quarter of free
    // ones keeps it.
    4 * live > cluster.cells().len()
}

/// Whether a frontier cell lies on a surface: along an axis where it has an unknown face
/// neighbour, one of its four face neighbours across that axis is occupied.
///
/// A cell that a surface cuts in two can be free (rays cross its open half) while its
/// neighbour on the far side, inside the solid, is never observed: a frontier no view
/// resolves. Such cells sit in a layer of occupied ones; a frontier onto open unknown space
/// has free or unknown cells beside it. On the region's faces the same happens with the map's
/// padding and the scene's outer walls, so cells there are not counted either.
pub(crate) fn surface_bound(map: &VoxelMap, c: frontier::Cell) -> bool {
    use frontier::CellState::{Occupied, Unknown};
    let grid = map.grid();
    let state = |d: [i32; 3]| grid.offset(c, d).map(|n| map.cell_state(n));
    (0..3).any(|axis| {
        let mut d = [0; 3];
        d[axis] = 1;
        let up = state(d);
        d[axis] = -1;
        let down = state(d);
        if up != Some(Unknown) && down != Some(Unknown) {
            return false;
        }
        // The four sideways neighbours.
        (0..3).filter(|&k| k != axis).any(|k| {
            let mut e = [0; 3];
            e[k] = 1;
            let a = state(e);
            e[k] = -1;
            a == Some(Occupied) || state(e) == Some(Occupied)
        })
    })
}

/// Every map cell a return has ended in: a bit per cell of the map's grid, or a hash set
/// for a grid of more than 2^28 cells (32 MiB of bits).
#[derive(Debug, Clone)]
pub(crate) enum HitCells {
    Bits { dims: [usize; 2], bits: Vec<u64> },
    Hash(FxHashSet<frontier::Cell>),
}

impl HitCells {
    /// An empty set for the cells of `map`'s grid.
    pub(crate) fn new(map: &VoxelMap) -> Self {
        let [nx, ny, nz] = map.grid().dims().map(|d| d as usize);
        let cells = nx.saturating_mul(ny).saturating_mul(nz);
        if cells > 1 << 28 {
            return Self::Hash(FxHashSet::default());
        }
        Self::Bits {
            dims: [nx, ny],
            bits: vec![0; cells.div_ceil(64)],
        }
    }

    /// Adds `c`, a cell of the map's grid; whether it was new.
    pub(crate) fn insert(&mut self, c: frontier::Cell) -> bool {
        match self {
            Self::Bits { dims, bits } => {
                let i = c.x as usize + dims[0] * (c.y as usize + dims[1] * c.z as usize);
                let (w, bit) = (i >> 6, 1u64 << (i & 63));
                match bits.get_mut(w) {
                    Some(word) if *word & bit == 0 => {
                        *word |= bit;
                        true
                    }
                    _ => false,
                }
            }
            Self::Hash(h) => h.insert(c),
        }
    }

    /// Whether `c` has been hit.
    pub(crate) fn contains(&self, c: frontier::Cell) -> bool {
        match self {
            Self::Bits { dims, bits } => {
                let i = c.x as usize + dims[0] * (c.y as usize + dims[1] * c.z as usize);
                bits.get(i >> 6)
                    .is_some_and(|w| w & (1u64 << (i & 63)) != 0)
            }
            Self::Hash(h) => h.contains(&c),
        }
    }
}

/// The clusters the mission asks for (see [`keeps`]) kept frame by frame: a cluster's verdict
/// depends only on its cells (fixed for its id), their face neighbours' states and which of
/// them were hit, so only the clusters a frame touches are judged again.
#[derive(Debug, Clone)]
pub(crate) struct MissionCache {
    hits: HitCells,
    verdicts: FxHashMap<ClusterId, bool>,
    ids: Vec<ClusterId>,
    /// The scan controller's targets, one per id of `ids`: taken while the refresh visits
    /// the clusters, so the scan controller needs no lookup by id.
    targets: Vec<FrontierTarget>,
}

impl MissionCache {
    /// An empty cache for `map`'s grid.
    pub(crate) fn new(map: &VoxelMap) -> Self {
        Self {
            hits: HitCells::new(map),
            verdicts: FxHashMap::default(),
            ids: Vec::new(),
            targets: Vec::new(),
        }
    }

    /// The mission clusters' ids as of the last [`MissionCache::refresh`], in id order.
    pub(crate) fn ids(&self) -> &[ClusterId] {
        &self.ids
    }

    /// The mission clusters as the scan controller's targets, in the order of
    /// [`MissionCache::ids`]: each cluster's centre, scored by its cell count.
    pub(crate) fn targets(&self) -> &[FrontierTarget] {
        &self.targets
    }

    /// Takes in one frame: the map's and the frontier's changes and the cells its returns
    /// ended in (`hits`, cells of the map's grid), then re-judges the clusters they touch.
    pub(crate) fn refresh(
        &mut self,
        frontiers: &Frontiers,
        map: &VoxelMap,
        changes: Option<(&FrameUpdate, &FrontierDelta)>,
        hits: impl IntoIterator<Item = frontier::Cell>,
        region: (Point3<f64>, Point3<f64>),
    ) {
        let forget = |c: frontier::Cell, verdicts: &mut FxHashMap<ClusterId, bool>| {
            if let Some(id) = frontiers.owner(c) {
                verdicts.remove(&id);
            }
        };
        if let Some((update, delta)) = changes {
            for id in &delta.removed {
                self.verdicts.remove(id);
            }
            // A changed cell alters `surface_bound` of its face neighbours' clusters.
            let grid = map.grid();
            for ch in &update.changed {
                forget(ch.cell, &mut self.verdicts);
                for d in FACES {
                    if let Some(n) = grid.offset(ch.cell, d) {
                        forget(n, &mut self.verdicts);
                    }
                }
            }
        }
        for c in hits {
            if self.hits.insert(c) {
                forget(c, &mut self.verdicts);
            }
        }
        self.ids.clear();
        self.targets.clear();
        for c in frontiers.clusters() {
            let keep = *self
                .verdicts
                .entry(c.id())
                .or_insert_with(|| keeps(c, map, &self.hits, region));
            if keep {
                self.ids.push(c.id());
                self.targets.push(FrontierTarget {
                    center: c.center(),
                    // Cell counts are far below 2^53.
                    #[allow(clippy::cast_precision_loss)]
                    score: c.cells().len() as f64,
                });
            }
        }
    }
}

/// The six face offsets.
const FACES: [[i32; 3]; 6] = [
    [1, 0, 0],
    [-1, 0, 0],
    [0, 1, 0],
    [0, -1, 0],
    [0, 0, 1],
    [0, 0, -1],
];

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;
    use frontier::{Bounds, MapConfig};
    use nalgebra::Vector3;

    /// The scan controller's targets of the clusters `ids`, looked up one by one.
    fn targets_of(frontiers: &Frontiers, ids: &[ClusterId]) -> Vec<FrontierTarget> {
        ids.iter()
            .filter_map(|id| frontiers.cluster(*id))
            .map(|c| FrontierTarget {
                center: c.center(),
                score: c.cells().len() as f64,
            })
            .collect()
    }

    /// A sheet of free cells onto open unknown space is a mission cluster until returns are
    /// found to end in most of its cells: then its unknown side lies behind a surface.
    #[test]
    fn clusters_of_hit_cells_leave_the_mission() {
        let bounds = Bounds::new(Point3::new(0.0, 0.0, 0.0), Point3::new(8.0, 8.0, 4.0)).unwrap();
        let mut map = VoxelMap::new(bounds, MapConfig::default()).unwrap();
        // A fan of rays in the plane z = 2.1: free cells with unknown ones above and below.
        let o = Point3::new(4.1, 4.1, 2.1);
        let ends: Vec<Point3<f64>> = (0..360)
            .map(|i| {
                let a = f64::from(i).to_radians();
                o + Vector3::new(a.cos(), a.sin(), 0.0) * 3.0
            })
            .collect();
        map.insert_frame(&o, &ends).unwrap();
        let mut frontiers = Frontiers::new(frontier::FrontierConfig::default()).unwrap();
        frontiers.rebuild(&map);
        let region = (Point3::new(0.0, 0.0, 0.0), Point3::new(8.0, 8.0, 4.0));
        let mut hits = HitCells::new(&map);
        let kept = |hits: &HitCells| mission_clusters(&frontiers, &map, hits, region).count();
        let all = kept(&hits);
        assert!(all > 0);
        // A few stray returns change nothing.
        let cells: Vec<frontier::Cell> = frontiers
            .clusters()
            .flat_map(|c| c.cells().iter().copied())
            .collect();
        for c in cells.iter().step_by(10) {
            hits.insert(*c);
        }
        assert_eq!(kept(&hits), all);
        // Returns in every cell: no cluster is left.
        for c in &cells {
            hits.insert(*c);
        }
        assert_eq!(kept(&hits), 0);
    }

    #[test]
    fn frontier_cells_beside_occupied_ones_are_surface_bound() {
        let bounds = Bounds::new(Point3::new(0.0, 0.0, 0.0), Point3::new(4.0, 4.0, 4.0)).unwrap();
        let o = Point3::new(0.5, 2.1, 2.1);
        let f = Point3::new(1.1, 2.1, 2.1);
        // One ray along x: the cell of f is free, unknown above and below.
        let ray = |end: Point3<f64>| {
            let mut map = VoxelMap::new(bounds, MapConfig::default()).unwrap();
            map.insert_frame(&o, &[end]).unwrap();
            map
        };
        // It ends in the next cell: f is free with an occupied neighbour beside its unknown
        // ones, as on a surface.
        let on_surface = ray(Point3::new(1.3, 2.1, 2.1));
        let c = on_surface.grid().cell_of(&f).unwrap();
        assert!(Frontiers::is_frontier_in(&on_surface, c));
        assert!(surface_bound(&on_surface, c));
        // It goes on: f's neighbours are free or unknown, a frontier onto open space.
        let open = ray(Point3::new(2.5, 2.1, 2.1));
        assert!(Frontiers::is_frontier_in(&open, c));
        assert!(!surface_bound(&open, c));
    }

    /// A cell turning occupied beside a frontier cell can make it surface bound while its
    /// cluster lives on (it is still a frontier cell): the cache judges that cluster again.
    #[test]
    fn a_neighbour_turning_occupied_is_judged_again() {
        let bounds = Bounds::new(Point3::new(0.0, 0.0, 0.0), Point3::new(6.0, 4.0, 4.0)).unwrap();
        let mut map = VoxelMap::new(bounds, MapConfig::default()).unwrap();
        let config = frontier::FrontierConfig {
            min_cluster_cells: 5,
            ..frontier::FrontierConfig::default()
        };
        let mut frontiers = Frontiers::new(config).unwrap();
        let region = (Point3::new(0.0, 0.0, 0.0), Point3::new(6.0, 4.0, 4.0));
        let mut cache = MissionCache::new(&map);
        let mut reference = HitCells::new(&map);
        let mut frame = |map: &mut VoxelMap,
                         frontiers: &mut Frontiers,
                         cache: &mut MissionCache,
                         o: Point3<f64>,
                         end: Point3<f64>| {
            let update = map.insert_frame(&o, &[end]).unwrap();
            let delta = frontiers.update(map, &update);
            let hit = map.grid().cell_of(&end).unwrap();
            reference.insert(hit);
            cache.refresh(frontiers, map, Some((&update, &delta)), [hit], region);
            let want: Vec<ClusterId> = mission_clusters(frontiers, map, &reference, region)
                .map(Cluster::id)
                .collect();
            assert_eq!(cache.ids(), &want[..]);
            // The targets are the same clusters' centres and cell counts, in id order.
            assert_eq!(cache.targets(), &targets_of(frontiers, &want)[..]);
        };
        // A line of free cells along x, unknown all round: one frontier cluster.
        frame(
            &mut map,
            &mut frontiers,
            &mut cache,
            Point3::new(0.5, 2.1, 2.1),
            Point3::new(3.7, 2.1, 2.1),
        );
        let line = frontiers.clusters().map(Cluster::id).collect::<Vec<_>>();
        assert_eq!(line.len(), 1);
        assert_eq!(cache.ids(), &line[..]);
        // Vertical rays ending just above the line: its cells get an occupied neighbour
        // beside their unknown ones, and the line's cluster stays the same.
        for i in 0..16 {
            let x = 0.5 + 0.2 * f64::from(i);
            frame(
                &mut map,
                &mut frontiers,
                &mut cache,
                Point3::new(x, 2.1, 3.7),
                Point3::new(x, 2.1, 2.3),
            );
            assert!(frontiers.cluster(line[0]).is_some());
        }
        assert!(!cache.ids().contains(&line[0]));
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(24))]
        /// After any sequence of frames in a furnished room (surfaces, so hit cells and
        /// surface-bound frontier cells), and of bare hits, the cache keeps exactly the
        /// clusters a from-scratch evaluation keeps.
        #[test]
        fn the_cache_equals_a_fresh_evaluation(
            frames in proptest::collection::vec(
                (proptest::array::uniform3(0.0f64..1.0), 0u64..1000, 50usize..600, 0u8..4),
                1..10,
            ),
        ) {
            let p = Point3::new;
            let world = crate::world::World::from_boxes(&[
                (p(-1.0, -1.0, -1.0), p(7.0, 7.0, 0.2)),
                (p(-1.0, -1.0, 2.8), p(7.0, 7.0, 4.0)),
                (p(-1.0, -1.0, -1.0), p(0.2, 7.0, 4.0)),
                (p(5.8, -1.0, -1.0), p(7.0, 7.0, 4.0)),
                (p(-1.0, -1.0, -1.0), p(7.0, 0.2, 4.0)),
                (p(-1.0, 5.8, -1.0), p(7.0, 7.0, 4.0)),
                (p(2.0, 2.5, 0.0), p(3.1, 3.3, 1.3)),
                (p(4.0, 0.0, 0.0), p(4.3, 3.5, 2.8)),
            ])
            .unwrap();
            let bounds = Bounds::new(Point3::new(0.0, 0.0, 0.0), Point3::new(6.0, 6.0, 3.0)).unwrap();
            let range = 3.0;
            let mut map = VoxelMap::new(bounds, MapConfig { max_range: range, ..MapConfig::default() }).unwrap();
            let mut frontiers = Frontiers::new(frontier::FrontierConfig::default()).unwrap();
            let region = (Point3::new(0.2, 0.2, 0.2), Point3::new(5.8, 5.8, 2.8));
            let mut cache = MissionCache::new(&map);
            let mut reference = HitCells::new(&map);
            for (o, seed, rays, kind) in frames {
                let mut r = crate::rng::Rng::new(seed);
                if kind == 0 {
                    // Bare hits in frontier cells, the map unchanged.
                    let hits: Vec<frontier::Cell> = frontiers
                        .clusters()
                        .flat_map(|c| c.cells().iter().copied())
                        .filter(|_| r.unit() < 0.3)
                        .collect();
                    for c in &hits {
                        reference.insert(*c);
                    }
                    cache.refresh(&frontiers, &map, None, hits, region);
                } else {
                    let o = p(0.4 + 3.4 * o[0], 0.4 + 5.2 * o[1], 0.4 + 2.2 * o[2]);
                    // Where a box stands the origin steps aside: rays start in free space.
                    let o = if world.distance(&o) > 0.05 { o } else { p(1.0, 1.0, 1.5) };
                    let ends: Vec<Point3<f64>> = (0..rays)
                        .map(|_| {
                            let d = Vector3::new(r.normal(), r.normal(), r.normal()).normalize();
                            // No return within range: the ray ends beyond it, no hit.
                            o + d * world.cast_ray(&o, &d, range).unwrap_or(range + 1.0)
                        })
                        .collect();
                    let update = map.insert_frame(&o, &ends).unwrap();
                    let delta = frontiers.update(&map, &update);
                    let grid = *map.grid();
                    let hits: Vec<frontier::Cell> = ends
                        .iter()
                        .filter(|e| (*e - o).norm() <= range)
                        .filter_map(|e| grid.cell_of(e))
                        .collect();
                    for c in &hits {
                        reference.insert(*c);
                    }
                    cache.refresh(&frontiers, &map, Some((&update, &delta)), hits, region);
                }
                let want: Vec<ClusterId> = mission_clusters(&frontiers, &map, &reference, region)
                    .map(Cluster::id)
                    .collect();
                proptest::prop_assert_eq!(cache.ids(), &want[..]);
                proptest::prop_assert_eq!(cache.targets(), &targets_of(&frontiers, &want)[..]);
            }
        }
    }
}
