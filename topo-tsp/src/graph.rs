//! A topological graph of free space: nodes at positions, straight edges checked free by the caller.

use std::cmp::Ordering;
use std::collections::BinaryHeap;

use std::collections::HashMap;

use crate::error::{Result, TspError};

/// Index of a graph node.
pub type NodeId = usize;

/// The caller's free-space check: whether the straight segment from `a` to `b` is traversable.
///
/// Implemented for closures `Fn(&[f64; 3], &[f64; 3]) -> bool`.
pub trait FreeSpace {
    /// Whether the segment a → b is free.
    fn segment_free(&self, a: &[f64; 3], b: &[f64; 3]) -> bool;
}

impl<F: Fn(&[f64; 3], &[f64; 3]) -> bool> FreeSpace for F {
    fn segment_free(&self, a: &[f64; 3], b: &[f64; 3]) -> bool {
        self(a, b)
    }
}

fn dist(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

/// A graph of free space with permanent nodes and per-cycle temporary ones (the odometry node,
/// the viewpoints), with A* and Dijkstra shortest paths by edge length.
///
/// New nodes connect to every existing node within a radius whose segment the caller's
/// [`FreeSpace`] check accepts; neighbours are found with a spatial hash whose cell edge is the
/// first positive connection radius used.
///
/// # Example
/// ```
/// use topo_tsp::TopoGraph;
/// # fn main() -> Result<(), topo_tsp::TspError> {
/// let free = |_: &[f64; 3], _: &[f64; 3]| true;
/// let mut g = TopoGraph::new();
/// let a = g.add_node([0.0, 0.0, 1.0], 3.0, &free)?;
/// let b = g.add_node([2.0, 0.0, 1.0], 3.0, &free)?;
/// let c = g.add_node([4.0, 0.0, 1.0], 3.0, &free)?;
/// let path = g.shortest_path(a, c)?.expect("connected");
/// assert_eq!(path.nodes, vec![a, b, c]);
/// assert!((path.length - 4.0).abs() < 1e-12);
/// # Ok(()) }
/// ```
#[derive(Clone)]
pub struct TopoGraph {
    positions: Vec<[f64; 3]>,
    adjacency: Vec<Vec<(NodeId, f64)>>,
    index: SpatialHash,
    permanent: usize,
}

impl core::fmt::Debug for TopoGraph {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("TopoGraph")
            .field("nodes", &self.positions.len())
            .field("permanent", &self.permanent)
            .field(
                "edges",
                &(self.adjacency.iter().map(Vec::len).sum::<usize>() / 2),
            )
            .finish()
    }
}

impl Default for TopoGraph {
    fn default() -> Self {
        Self::new()
    }
}

/// A node path and its length \[m\].
#[derive(Debug, Clone, PartialEq)]
pub struct GraphPath {
    /// The nodes from start to goal.
    pub nodes: Vec<NodeId>,
    /// Sum of the edge lengths \[m\].
    pub length: f64,
}

#[derive(PartialEq)]
struct Entry {
    key: f64,
    node: NodeId,
}

impl Eq for Entry {}

impl PartialOrd for Entry {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}

impl Ord for Entry {
    // Min-heap on the key, ties by node index: deterministic.
    fn cmp(&self, other: &Self) -> Ordering {
        other
            .key
            .total_cmp(&self.key)
            .then_with(|| other.node.cmp(&self.node))
    }
}

/// Shortest distances and predecessors from one source (Dijkstra).
#[derive(Debug, Clone)]
pub struct ShortestPaths {
    source: NodeId,
    dist: Vec<f64>,
    pred: Vec<usize>,
}

impl ShortestPaths {
    /// Distance \[m\] from the source to `node` (+∞ if unreachable or out of range).
    pub fn distance(&self, node: NodeId) -> f64 {
        self.dist.get(node).copied().unwrap_or(f64::INFINITY)
    }

    /// The node path from the source to `node`, or `None` if unreachable.
    pub fn path_to(&self, node: NodeId) -> Option<Vec<NodeId>> {
        if !self.distance(node).is_finite() {
            return None;
        }
        let mut path = vec![node];
        let mut v = node;
        while v != self.source {
            v = self.pred[v];
            path.push(v);
        }
        path.reverse();
        Some(path)
    }
}

impl TopoGraph {
    /// An empty graph.
    pub fn new() -> Self {
        Self {
            positions: Vec::new(),
            adjacency: Vec::new(),
            index: SpatialHash::default(),
            permanent: 0,
        }
    }

    /// Number of nodes (permanent and temporary).
    pub fn len(&self) -> usize {
        self.positions.len()
    }

    /// Whether the graph has no nodes.
    pub fn is_empty(&self) -> bool {
        self.positions.is_empty()
    }

    /// Position of a node.
    ///
    /// # Errors
    /// [`TspError::NoSuchNode`] for an unknown id.
    pub fn position(&self, node: NodeId) -> Result<[f64; 3]> {
        self.positions
            .get(node)
            .copied()
            .ok_or(TspError::NoSuchNode {
                node,
                size: self.len(),
            })
    }

    /// Neighbours of a node with the edge lengths \[m\].
    ///
    /// # Errors
    /// [`TspError::NoSuchNode`] for an unknown id.
    pub fn neighbors(&self, node: NodeId) -> Result<&[(NodeId, f64)]> {
        self.adjacency
            .get(node)
            .map(Vec::as_slice)
            .ok_or(TspError::NoSuchNode {
                node,
                size: self.len(),
            })
    }

    fn insert(&mut self, p: [f64; 3], radius: f64, free: &impl FreeSpace) -> Result<NodeId> {
        if !p.iter().all(|v| v.is_finite()) {
            return Err(TspError::NonFinite {
                what: "node position",
            });
        }
        if !(radius >= 0.0 && radius.is_finite()) {
            return Err(TspError::InvalidConfig {
                what: "connection radius",
                reason: "must be finite and non-negative",
            });
        }
        let id = self.positions.len();
        let item = u32::try_from(id).map_err(|_| TspError::InvalidConfig {
            what: "graph size",
            reason: "at most 2^32 nodes",
        })?;
        let near = self.index.within(&self.positions, &p, radius);
        self.positions.push(p);
        self.adjacency.push(Vec::new());
        // A radius whose square overflows (above about 1.3e154) lets the squared-distance
        // test pass any pair: such pairs are checked by their distance itself.
        let huge = (radius * radius).is_infinite();
        for other in near {
            let q = self.positions[other];
            let mut len = dist(&p, &q);
            if len.is_infinite() {
                // The squares overflowed, perhaps not the distance itself.
                len = crate::cost::norm([p[0] - q[0], p[1] - q[1], p[2] - q[2]]);
            }
            if !len.is_finite() || huge && len > radius {
                continue;
            }
            if free.segment_free(&p, &q) {
                self.adjacency[id].push((other, len));
                self.adjacency[other].push((id, len));
            }
        }
        self.index.insert(&p, item, radius);
        Ok(id)
    }

    /// Adds a permanent node, connected to the nodes within `radius` \[m\] whose segment is free.
    ///
    /// # Errors
    /// [`TspError::NonFinite`] for a bad position, [`TspError::InvalidConfig`] for a bad radius
    /// or while temporary nodes exist (clear them first).
    pub fn add_node(&mut self, p: [f64; 3], radius: f64, free: &impl FreeSpace) -> Result<NodeId> {
        if self.permanent != self.len() {
            return Err(TspError::InvalidConfig {
                what: "add_node",
                reason: "permanent nodes cannot be added while temporary nodes exist",
            });
        }
        let id = self.insert(p, radius, free)?;
        self.permanent += 1;
        Ok(id)
    }

    /// Adds a temporary node (removed by [`TopoGraph::clear_temporary`]).
    ///
    /// # Errors
    /// As [`TopoGraph::add_node`] for bad input.
    pub fn add_temporary_node(
        &mut self,
        p: [f64; 3],
        radius: f64,
        free: &impl FreeSpace,
    ) -> Result<NodeId> {
        self.insert(p, radius, free)
    }

    /// Removes every temporary node and its edges.
    pub fn clear_temporary(&mut self) {
        let keep = self.permanent;
        for id in keep..self.positions.len() {
            let p = self.positions[id];
            // Ids of temporary nodes were checked to fit u32 when they were added.
            #[allow(clippy::cast_possible_truncation)]
            self.index.remove(&p, id as u32);
        }
        self.positions.truncate(keep);
        self.adjacency.truncate(keep);
        for adj in &mut self.adjacency {
            adj.retain(|&(n, _)| n < keep);
        }
    }

    /// Removes the edge between `a` and `b` (both directions), for an edge the caller's
    /// free-space check no longer accepts (an obstacle seen after the edge was made). Returns
    /// whether there was such an edge. Nodes stay, so ids do not change.
    ///
    /// # Example
    /// ```
    /// use topo_tsp::TopoGraph;
    /// # fn main() -> Result<(), topo_tsp::TspError> {
    /// let free = |_: &[f64; 3], _: &[f64; 3]| true;
    /// let mut g = TopoGraph::new();
    /// let a = g.add_node([0.0, 0.0, 0.0], 3.0, &free)?;
    /// let b = g.add_node([2.0, 0.0, 0.0], 3.0, &free)?;
    /// assert!(g.remove_edge(a, b)?);
    /// assert!(g.shortest_path(a, b)?.is_none());
    /// assert!(!g.remove_edge(b, a)?);
    /// # Ok(()) }
    /// ```
    ///
    /// # Errors
    /// [`TspError::NoSuchNode`] for an unknown id.
    pub fn remove_edge(&mut self, a: NodeId, b: NodeId) -> Result<bool> {
        self.check(a)?;
        self.check(b)?;
        let before = self.adjacency[a].len();
        self.adjacency[a].retain(|&(n, _)| n != b);
        self.adjacency[b].retain(|&(n, _)| n != a);
        Ok(self.adjacency[a].len() != before)
    }

    fn check(&self, node: NodeId) -> Result<()> {
        if node < self.len() {
            Ok(())
        } else {
            Err(TspError::NoSuchNode {
                node,
                size: self.len(),
            })
        }
    }

    /// Dijkstra from `source` over the whole graph.
    ///
    /// # Errors
    /// [`TspError::NoSuchNode`] for an unknown id.
    pub fn shortest_paths_from(&self, source: NodeId) -> Result<ShortestPaths> {
        self.check(source)?;
        let n = self.len();
        let mut dist = vec![f64::INFINITY; n];
        let mut pred = vec![usize::MAX; n];
        let mut heap = BinaryHeap::new();
        dist[source] = 0.0;
        heap.push(Entry {
            key: 0.0,
            node: source,
        });
        while let Some(Entry { key, node }) = heap.pop() {
            if key > dist[node] {
                continue;
            }
            for &(nb, w) in &self.adjacency[node] {
                let cand = key + w;
                if cand < dist[nb] {
                    dist[nb] = cand;
                    pred[nb] = node;
                    heap.push(Entry {
                        key: cand,
                        node: nb,
                    });
                }
            }
        }
        Ok(ShortestPaths { source, dist, pred })
    }

    /// The shortest path from `from` to `to` by A* with the straight-line heuristic, or `None`
    /// if `to` is unreachable.
    ///
    /// # Errors
    /// [`TspError::NoSuchNode`] for an unknown id.
    pub fn shortest_path(&self, from: NodeId, to: NodeId) -> Result<Option<GraphPath>> {
        self.check(from)?;
        self.check(to)?;
        let n = self.len();
        let goal = self.positions[to];
        let h = |v: NodeId| dist(&self.positions[v], &goal);
        let mut g = vec![f64::INFINITY; n];
        let mut pred = vec![usize::MAX; n];
        let mut closed = vec![false; n];
        let mut heap = BinaryHeap::new();
        g[from] = 0.0;
        heap.push(Entry {
            key: h(from),
            node: from,
        });
        while let Some(Entry { node, .. }) = heap.pop() {
            if closed[node] {
                continue;
            }
            if node == to {
                let mut nodes = vec![to];
                let mut v = to;
                while v != from {
                    v = pred[v];
                    nodes.push(v);
                }
                nodes.reverse();
                return Ok(Some(GraphPath {
                    nodes,
                    length: g[to],
                }));
            }
            closed[node] = true;
            for &(nb, w) in &self.adjacency[node] {
                let cand = g[node] + w;
                if cand < g[nb] {
                    g[nb] = cand;
                    pred[nb] = node;
                    heap.push(Entry {
                        key: cand + h(nb),
                        node: nb,
                    });
                }
            }
        }
        Ok(None)
    }
}

/// Node ids bucketed in a grid of cubic cells, for radius queries.
///
/// A k-d tree that splits buckets by depth cannot split one whose points share the coordinate
/// of the split axis (viewpoints sampled at one height do); a hash grid has no such case.
#[derive(Debug, Clone, Default)]
struct SpatialHash {
    /// Cell edge \[m\]: the first positive radius of an insertion; 0 until then.
    cell: f64,
    buckets: HashMap<[i64; 3], Vec<u32>>,
}

impl SpatialHash {
    fn key(&self, p: &[f64; 3]) -> [i64; 3] {
        // Saturating float-to-int casts: far-away points share the border buckets, and
        // queries check distances exactly, so that stays correct.
        #[allow(clippy::cast_possible_truncation)]
        p.map(|v| (v / self.cell).floor() as i64)
    }

    fn insert(&mut self, p: &[f64; 3], item: u32, radius: f64) {
        if self.cell == 0.0 {
            if radius > 0.0 {
                self.cell = radius;
            } else {
                // Radius-0 insertions find no neighbours: any cell edge works until a real
                // radius comes.
                self.cell = 1.0;
            }
        }
        let key = self.key(p);
        self.buckets.entry(key).or_default().push(item);
    }

    fn remove(&mut self, p: &[f64; 3], item: u32) {
        if self.cell == 0.0 {
            return;
        }
        let key = self.key(p);
        if let Some(b) = self.buckets.get_mut(&key) {
            b.retain(|&i| i != item);
            if b.is_empty() {
                self.buckets.remove(&key);
            }
        }
    }

    /// The ids of `positions` within `radius` of `p` (distance ≤ radius), sorted.
    fn within(&self, positions: &[[f64; 3]], p: &[f64; 3], radius: f64) -> Vec<usize> {
        let r2 = radius * radius;
        let close = |q: &[f64; 3]| {
            (q[0] - p[0]).powi(2) + (q[1] - p[1]).powi(2) + (q[2] - p[2]).powi(2) <= r2
        };
        let mut out: Vec<usize> = Vec::new();
        if self.cell > 0.0 {
            let lo = self.key(&p.map(|v| v - radius));
            let hi = self.key(&p.map(|v| v + radius));
            let span = |k: usize| u128::from(hi[k].abs_diff(lo[k])) + 1;
            let cells = span(0).saturating_mul(span(1)).saturating_mul(span(2));
            // Fewer cells than nodes: visit the buckets; otherwise a plain scan is cheaper.
            if cells <= positions.len() as u128 {
                for x in lo[0]..=hi[0] {
                    for y in lo[1]..=hi[1] {
                        for z in lo[2]..=hi[2] {
                            for &i in self.buckets.get(&[x, y, z]).into_iter().flatten() {
                                let i = i as usize;
                                if close(&positions[i]) {
                                    out.push(i);
                                }
                            }
                        }
                    }
                }
                out.sort_unstable();
                return out;
            }
        }
        out.extend((0..positions.len()).filter(|&i| close(&positions[i])));
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// Random points in a 10 m cube and a random (seeded) free-space predicate.
    fn random_graph(n: usize, seed: u64, radius: f64) -> TopoGraph {
        let mut s = seed;
        let mut next = move || {
            s = s
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            (s >> 11) as f64 / (1u64 << 53) as f64
        };
        let pts: Vec<[f64; 3]> = (0..n)
            .map(|_| [10.0 * next(), 10.0 * next(), 3.0 * next()])
            .collect();
        // Blocks segments that cross the plane x = 5 above z = 1.5 (a wall with a gap below).
        let free = |a: &[f64; 3], b: &[f64; 3]| {
            !((a[0] - 5.0) * (b[0] - 5.0) < 0.0 && a[2].min(b[2]) > 1.5)
        };
        let mut g = TopoGraph::new();
        for p in pts {
            g.add_node(p, radius, &free).unwrap();
        }
        g
    }

    proptest! {
        /// Dijkstra and A* agree with Floyd–Warshall.
        #[test]
        fn shortest_paths_match_floyd_warshall(n in 1usize..40, seed in any::<u64>(), radius in 1.0f64..6.0) {
            let g = random_graph(n, seed, radius);
            let mut fw = vec![vec![f64::INFINITY; n]; n];
            for i in 0..n {
                fw[i][i] = 0.0;
                for &(j, w) in g.neighbors(i).unwrap() {
                    fw[i][j] = fw[i][j].min(w);
                }
            }
            for k in 0..n {
                for i in 0..n {
                    for j in 0..n {
                        if fw[i][k] + fw[k][j] < fw[i][j] {
                            fw[i][j] = fw[i][k] + fw[k][j];
                        }
                    }
                }
            }
            for i in 0..n.min(5) {
                let sp = g.shortest_paths_from(i).unwrap();
                for j in 0..n {
                    let d = sp.distance(j);
                    prop_assert!((d - fw[i][j]).abs() < 1e-9 || (d.is_infinite() && fw[i][j].is_infinite()));
                    let astar = g.shortest_path(i, j).unwrap();
                    match astar {
                        Some(p) => {
                            prop_assert!((p.length - fw[i][j]).abs() < 1e-9);
                            // The node path is a real path of that length.
                            let len: f64 = p.nodes.windows(2).map(|w| {
                                g.neighbors(w[0]).unwrap().iter().find(|e| e.0 == w[1]).map(|e| e.1).unwrap()
                            }).sum();
                            prop_assert!((len - p.length).abs() < 1e-9);
                            prop_assert_eq!(sp.path_to(j).map(|v| v.len()).is_some(), true);
                        }
                        None => prop_assert!(fw[i][j].is_infinite()),
                    }
                }
            }
        }
    }

    #[test]
    fn temporary_nodes_come_and_go() {
        let free = |_: &[f64; 3], _: &[f64; 3]| true;
        let mut g = TopoGraph::new();
        let a = g.add_node([0.0; 3], 2.0, &free).unwrap();
        let t = g.add_temporary_node([1.0, 0.0, 0.0], 2.0, &free).unwrap();
        assert_eq!(g.neighbors(a).unwrap().len(), 1);
        assert!(g.add_node([5.0; 3], 1.0, &free).is_err());
        g.clear_temporary();
        assert_eq!(g.len(), 1);
        assert!(g.neighbors(a).unwrap().is_empty());
        assert!(g.position(t).is_err());
        // The removed node is gone from the neighbour search too.
        let b = g.add_node([1.5, 0.0, 0.0], 2.0, &free).unwrap();
        assert_eq!(g.neighbors(b).unwrap(), &[(a, 1.5)]);
    }

    #[test]
    fn removed_edges_reroute_paths_and_keep_the_nodes() {
        let free = |_: &[f64; 3], _: &[f64; 3]| true;
        let mut g = TopoGraph::new();
        // A square a-b-c-d with the short way a → c through b and the long one through d.
        let a = g.add_node([0.0, 0.0, 0.0], 2.5, &free).unwrap();
        let b = g.add_node([2.0, 0.0, 0.0], 2.5, &free).unwrap();
        let c = g.add_node([2.0, 2.0, 0.0], 2.5, &free).unwrap();
        let d = g.add_node([0.0, 2.1, 0.0], 2.5, &free).unwrap();
        assert_eq!(g.shortest_path(a, c).unwrap().unwrap().nodes, vec![a, b, c]);
        assert!(g.remove_edge(c, b).unwrap());
        assert!(!g.remove_edge(b, c).unwrap());
        assert!(!g.remove_edge(a, a).unwrap());
        assert!(g.neighbors(b).unwrap().iter().all(|e| e.0 != c));
        assert!(g.neighbors(c).unwrap().iter().all(|e| e.0 != b));
        let p = g.shortest_path(a, c).unwrap().unwrap();
        assert_eq!(p.nodes, vec![a, d, c]);
        assert!((p.length - (2.1 + 0.1f64.hypot(2.0))).abs() < 1e-12);
        assert_eq!(g.len(), 4);
        assert!(matches!(
            g.remove_edge(a, 9),
            Err(TspError::NoSuchNode { node: 9, .. })
        ));
        assert_eq!(g.neighbors(a).unwrap().len(), 2);
    }

    #[test]
    fn bad_input_is_a_typed_error() {
        let free = |_: &[f64; 3], _: &[f64; 3]| true;
        let mut g = TopoGraph::new();
        assert!(matches!(
            g.add_node([f64::NAN, 0.0, 0.0], 1.0, &free),
            Err(TspError::NonFinite { .. })
        ));
        assert!(matches!(
            g.add_node([0.0; 3], -1.0, &free),
            Err(TspError::InvalidConfig { .. })
        ));
        assert!(matches!(
            g.shortest_path(0, 1),
            Err(TspError::NoSuchNode { .. })
        ));
        assert!(matches!(
            g.shortest_paths_from(3),
            Err(TspError::NoSuchNode { .. })
        ));
        let a = g.add_node([0.0; 3], 1.0, &free).unwrap();
        let b = g.add_node([10.0, 0.0, 0.0], 1.0, &free).unwrap();
        assert_eq!(g.shortest_path(a, b).unwrap(), None);
        assert_eq!(g.shortest_paths_from(a).unwrap().path_to(b), None);
    }

    /// The neighbours of every node by brute force: every other node within `radius`.
    fn brute_neighbours(g: &TopoGraph, radius: f64) -> Vec<Vec<NodeId>> {
        (0..g.len())
            .map(|i| {
                let p = g.position(i).unwrap();
                (0..g.len())
                    .filter(|&j| j != i && dist(&p, &g.position(j).unwrap()) <= radius)
                    .collect()
            })
            .collect()
    }

    fn neighbour_ids(g: &TopoGraph, i: NodeId) -> Vec<NodeId> {
        let mut v: Vec<NodeId> = g.neighbors(i).unwrap().iter().map(|e| e.0).collect();
        v.sort_unstable();
        v
    }

    #[test]
    fn nodes_sharing_coordinates_and_positions_are_accepted() {
        // Hundreds of nodes on one height and one x, and forty at one point: a k-d tree that
        // splits buckets by depth cannot take these.
        let free = |_: &[f64; 3], _: &[f64; 3]| true;
        let mut g = TopoGraph::new();
        for k in 0..300 {
            g.add_node([1.0, 0.1 * f64::from(k % 60), 10.3], 2.0, &free)
                .unwrap();
        }
        for _ in 0..40 {
            g.add_temporary_node([1.0, 1.0, 10.3], 2.0, &free).unwrap();
        }
        let brute = brute_neighbours(&g, 2.0);
        for (i, want) in brute.iter().enumerate() {
            assert_eq!(&neighbour_ids(&g, i), want, "node {i}");
        }
        g.clear_temporary();
        assert_eq!(g.len(), 300);
        let c = g.add_temporary_node([1.0, 1.0, 10.3], 2.0, &free).unwrap();
        assert_eq!(neighbour_ids(&g, c), brute_neighbours(&g, 2.0)[c]);
    }

    proptest! {
        /// Edges join exactly the node pairs within the radius (the free-space check passing
        /// all), whatever the radii, and with coordinates snapped to a coarse lattice so many
        /// nodes share them.
        #[test]
        fn edges_are_the_pairs_within_the_radius(
            pts in proptest::collection::vec((0u8..8, 0u8..8, 0u8..3), 1..80),
            first_radius in 0.0f64..4.0,
            radius in 0.0f64..4.0,
            scale in prop_oneof![Just(0.5f64), Just(1e3), Just(1e-3)],
        ) {
            let free = |_: &[f64; 3], _: &[f64; 3]| true;
            let mut g = TopoGraph::new();
            for (k, (x, y, z)) in pts.iter().enumerate() {
                let p = [f64::from(*x) * scale, f64::from(*y) * scale, f64::from(*z) * scale];
                // The first insertion fixes the hash cell; later ones use another radius.
                let r = if k == 0 { first_radius } else { radius };
                g.add_node(p, r, &free).unwrap();
            }
            let brute = brute_neighbours(&g, radius);
            for i in 1..g.len() {
                // Node i connected to the earlier nodes within `radius` when it came.
                let earlier: Vec<NodeId> = neighbour_ids(&g, i).into_iter().filter(|&j| j < i).collect();
                let want: Vec<NodeId> = brute[i].iter().copied().filter(|&j| j < i).collect();
                prop_assert_eq!(earlier, want);
            }
        }
    }
}
