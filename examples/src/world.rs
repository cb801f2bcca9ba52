//! World queries for the simulator, behind one adapter over parry3d: ray casts for the LiDAR
//! and distances for collision checks.

use nalgebra::{Isometry3, Point3, Vector3};
use parry3d::query::{PointQuery, Ray, RayCast};
use parry3d::shape::{Compound, Cuboid, SharedShape, Voxels};

use crate::box_grid::{Aabb, BoxGrid, Lattice};

/// Errors building a world.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum WorldError {
    /// A box with a NaN or infinite corner, or min > max on some axis.
    #[error("box {0} is not a finite box with min <= max")]
    BadBox(usize),
    /// A voxel size that is not positive and finite.
    #[error("voxel size {0} m is not positive and finite")]
    BadVoxel(f64),
    /// A point cloud too large for the voxel grid (coordinates beyond ±2³¹ voxels).
    #[error("point {0} lies too far out for {1} m voxels")]
    TooFar(usize, f64),
    /// A point cloud whose bounding box holds more than 2³⁴ voxels.
    #[error("the cloud's bounding box holds more than 2^34 voxels of {0} m")]
    TooLarge(f64),
}

/// The solid geometry of a world.
#[derive(Clone)]
enum Geometry {
    /// parry3d's compound answers distances; a uniform grid of our own answers ray casts
    /// (faster for the LiDAR; see the simulator bench).
    Boxes(Compound, BoxGrid),
    /// A point cloud's voxels: parry3d's voxel shape answers distances, a dense bit grid
    /// walked by DDA answers ray casts (faster for the LiDAR; see the simulator bench).
    Voxels(Voxels, VoxelGrid),
}

/// Occupied voxels as a dense bit grid over their bounding box.
#[derive(Clone)]
struct VoxelGrid {
    lattice: Lattice,
    bits: Vec<u64>,
}

impl VoxelGrid {
    /// The grid of `cells` (voxel indices, non-empty); `None` above 2³⁴ cells.
    fn new(size: f64, cells: &[[i64; 3]]) -> Option<Self> {
        let mut min = [i64::MAX; 3];
        let mut max = [i64::MIN; 3];
        for c in cells {
            for k in 0..3 {
                min[k] = min[k].min(c[k]);
                max[k] = max[k].max(c[k]);
            }
        }
        let dims = [0, 1, 2].map(|k| usize::try_from(max[k] - min[k] + 1).unwrap_or(usize::MAX));
        let volume = dims
            .iter()
            .try_fold(1usize, |v, &d| v.checked_mul(d))
            .filter(|&v| v <= 1 << 34)?;
        // Voxel indices are far inside f64's exact integers.
        #[allow(clippy::cast_precision_loss)]
        let lo = min.map(|m| m as f64 * size);
        let mut g = Self {
            lattice: Lattice {
                lo,
                cell: size,
                dims,
            },
            bits: vec![0; volume.div_ceil(64)],
        };
        for c in cells {
            let i = g
                .lattice
                .index([0, 1, 2].map(|k| usize::try_from(c[k] - min[k]).unwrap_or(0)));
            g.bits[i >> 6] |= 1 << (i & 63);
        }
        Some(g)
    }

    /// Whether an occupied voxel meets the cube of half-edge `r` about `p` (every voxel within
    /// `r` of `p` does); also `true`, without looking, for a cube of more than 4096 voxels.
    fn any_within(&self, p: &Point3<f64>, r: f64) -> bool {
        let l = &self.lattice;
        let mut lo = [0usize; 3];
        let mut hi = [0usize; 3];
        for k in 0..3 {
            let a = ((p[k] - r - l.lo[k]) / l.cell).floor();
            let b = ((p[k] + r - l.lo[k]) / l.cell).floor();
            // Dimensions are below 2^34: exact in f64.
            #[allow(clippy::cast_precision_loss)]
            let top = (l.dims[k] - 1) as f64;
            if !(a <= top && b >= 0.0) {
                // Outside the grid on this axis, or NaN.
                return false;
            }
            // Clamped into [0, top]: the casts are exact.
            #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
            {
                lo[k] = a.max(0.0) as usize;
                hi[k] = b.min(top) as usize;
            }
        }
        let cells: usize = (0..3).map(|k| hi[k] - lo[k] + 1).product();
        if cells > 4096 {
            // A large cube: the distance query is the cheaper answer.
            return true;
        }
        (lo[2]..=hi[2]).any(|z| {
            (lo[1]..=hi[1]).any(|y| {
                (lo[0]..=hi[0]).any(|x| {
                    let i = l.index([x, y, z]);
                    self.bits[i >> 6] & (1 << (i & 63)) != 0
                })
            })
        })
    }

    /// The first occupied voxel along the ray, by 3-D DDA: the distance at which the ray
    /// enters it, within `max`.
    fn cast_ray(&self, o: &Point3<f64>, d: &Vector3<f64>, max: f64) -> Option<f64> {
        self.lattice.walk(o, d, max, |i, entry, _| {
            (self.bits[i >> 6] & (1 << (i & 63)) != 0).then_some(entry)
        })
    }
}

/// A static world of solid axis-aligned boxes, or of the occupied voxels of a point cloud.
///
/// Ray casts run in `f64` (a DDA through a grid of box lists, or through the voxels);
/// distances come from parry3d, which works in `f32`: exact to about 1e-6 relative (2 µm at
/// 20 m), far below the LiDAR's range noise.
///
/// # Example
/// ```
/// use fu_mpc_examples::world::World;
/// use nalgebra::{Point3, Vector3};
///
/// let w = World::from_boxes(&[(Point3::new(2.0, -1.0, -1.0), Point3::new(3.0, 1.0, 1.0))]).unwrap();
/// let t = w.cast_ray(&Point3::origin(), &Vector3::x(), 10.0).unwrap();
/// assert!((t - 2.0).abs() < 1e-5);
/// assert!((w.distance(&Point3::origin()) - 2.0).abs() < 1e-5);
/// ```
#[derive(Clone)]
pub struct World {
    geometry: Option<Geometry>,
}

impl std::fmt::Debug for World {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match &self.geometry {
            Some(Geometry::Boxes(c, _)) => f
                .debug_struct("World")
                .field("boxes", &c.shapes().len())
                .finish(),
            Some(Geometry::Voxels(_, g)) => f
                .debug_struct("World")
                .field("voxel_size", &g.lattice.cell)
                .field("grid", &g.lattice.dims)
                .finish(),
            None => f.debug_struct("World").field("boxes", &0).finish(),
        }
    }
}

impl World {
    /// A world from solid boxes given by their min and max corners \[m\]. No boxes is an
    /// empty world.
    ///
    /// # Errors
    /// [`WorldError::BadBox`] for a box that is not finite or has min > max.
    pub fn from_boxes(boxes: &[(Point3<f64>, Point3<f64>)]) -> Result<Self, WorldError> {
        let mut shapes = Vec::with_capacity(boxes.len());
        let mut aabbs = Vec::with_capacity(boxes.len());
        for (i, (lo, hi)) in boxes.iter().enumerate() {
            let ok = (0..3).all(|k| lo[k].is_finite() && hi[k].is_finite() && lo[k] <= hi[k]);
            if !ok {
                return Err(WorldError::BadBox(i));
            }
            aabbs.push(Aabb {
                lo: [lo.x, lo.y, lo.z],
                hi: [hi.x, hi.y, hi.z],
            });
            let c = (lo.coords + hi.coords) * 0.5;
            let h = (hi - lo) * 0.5;
            // parry3d is f32: the narrowing is intended.
            #[allow(clippy::cast_possible_truncation)]
            let (c, h) = (c.map(|v| v as f32), h.map(|v| v as f32));
            shapes.push((
                Isometry3::translation(c.x, c.y, c.z),
                SharedShape::new(Cuboid::new(h)),
            ));
        }
        Ok(Self {
            geometry: (!shapes.is_empty())
                .then(|| Geometry::Boxes(Compound::new(shapes), BoxGrid::new(&aabbs))),
        })
    }

    /// A world of the voxels of edge `voxel` \[m\] (aligned with the origin) that hold at
    /// least one point of a cloud. Ray casts walk a dense bit grid over the voxels' bounding
    /// box by DDA; distances come from parry3d's voxel shape. Non-finite points are skipped;
    /// an empty cloud is an empty world.
    ///
    /// # Errors
    /// [`WorldError::BadVoxel`] for a voxel size that is not positive and finite,
    /// [`WorldError::TooFar`] for a point beyond ±2³¹ voxels, [`WorldError::TooLarge`] for a
    /// bounding box of more than 2³⁴ voxels.
    ///
    /// # Example
    /// ```
    /// use fu_mpc_examples::world::World;
    /// use nalgebra::{Point3, Vector3};
    ///
    /// // A wall of points at x = 2.
    /// let cloud: Vec<_> = (0..400)
    ///     .map(|i| Point3::new(2.05, f64::from(i % 20) * 0.1 - 1.0, f64::from(i / 20) * 0.1 - 1.0))
    ///     .collect();
    /// let w = World::from_points(&cloud, 0.1).unwrap();
    /// let t = w.cast_ray(&Point3::origin(), &Vector3::x(), 10.0).unwrap();
    /// assert!((t - 2.0).abs() < 1e-4);
    /// ```
    pub fn from_points(points: &[Point3<f64>], voxel: f64) -> Result<Self, WorldError> {
        if !(voxel.is_finite() && voxel > 0.0) {
            return Err(WorldError::BadVoxel(voxel));
        }
        let mut cells = Vec::with_capacity(points.len());
        let limit = f64::from(i32::MAX);
        for (i, p) in points.iter().enumerate() {
            if !p.iter().all(|v| v.is_finite()) {
                continue;
            }
            let g = p.coords.map(|v| (v / voxel).floor());
            if g.iter().any(|v| v.abs() >= limit) {
                return Err(WorldError::TooFar(i, voxel));
            }
            // Checked against the i32 range just above.
            #[allow(clippy::cast_possible_truncation)]
            cells.push(parry3d::math::Point::new(
                g.x as i32, g.y as i32, g.z as i32,
            ));
        }
        cells.sort_unstable_by_key(|c| (c.x, c.y, c.z));
        cells.dedup();
        if cells.is_empty() {
            return Ok(Self { geometry: None });
        }
        let idx: Vec<[i64; 3]> = cells
            .iter()
            .map(|c| [i64::from(c.x), i64::from(c.y), i64::from(c.z)])
            .collect();
        let grid = VoxelGrid::new(voxel, &idx).ok_or(WorldError::TooLarge(voxel))?;
        // parry3d is f32: the narrowing is intended.
        #[allow(clippy::cast_possible_truncation)]
        let size = voxel as f32;
        Ok(Self {
            geometry: Some(Geometry::Voxels(
                Voxels::new(parry3d::math::Vector::repeat(size), &cells),
                grid,
            )),
        })
    }

    /// Distance along the unit direction `dir` from `origin` to the first surface, if one is
    /// within `max` \[m\]. A ray starting inside a box or voxel hits at 0. `None` for NaN input.
    pub fn cast_ray(&self, origin: &Point3<f64>, dir: &Vector3<f64>, max: f64) -> Option<f64> {
        match self.geometry.as_ref()? {
            Geometry::Boxes(_, grid) => grid.cast_ray(origin, dir, max),
            Geometry::Voxels(_, grid) => grid.cast_ray(origin, dir, max),
        }
        .filter(|t| t.is_finite())
    }

    /// [`World::cast_ray`] through parry3d's own ray casts (its compound shape, or its voxel
    /// shape) instead of our box grid or voxel grid: kept so the simulator bench can compare
    /// the two in one run, and the tests can check one against the other.
    pub fn cast_ray_parry(
        &self,
        origin: &Point3<f64>,
        dir: &Vector3<f64>,
        max: f64,
    ) -> Option<f64> {
        #[allow(clippy::cast_possible_truncation)]
        let ray = Ray::new(origin.map(|x| x as f32), dir.map(|x| x as f32));
        #[allow(clippy::cast_possible_truncation)]
        let max = max as f32;
        let id = Isometry3::identity();
        match self.geometry.as_ref()? {
            Geometry::Boxes(c, _) => c.cast_ray(&id, &ray, max, true),
            Geometry::Voxels(v, _) => v.cast_ray(&id, &ray, max, true),
        }
        .map(f64::from)
        .filter(|t| t.is_finite())
    }

    /// Whether a box or voxel lies closer than `d` \[m\] to `p`: exactly
    /// `self.distance(p) < d`, but in a voxel world a point with no voxel near it is answered
    /// from the voxels' bit grid without a distance query (building a point cloud's
    /// explorable space asks this of every cell).
    pub fn closer_than(&self, p: &Point3<f64>, d: f64) -> bool {
        if let Some(Geometry::Voxels(_, grid)) = &self.geometry
            && d.is_finite()
            && p.iter().all(|v| v.is_finite())
            // The margin covers parry3d's f32 rounding (micrometres at scene coordinates).
            && !grid.any_within(p, d.max(0.0) + 1e-3)
        {
            return false;
        }
        self.distance(p) < d
    }

    /// Distance from `p` to the nearest box or voxel \[m\]; 0 inside one, infinite in an empty
    /// world.
    pub fn distance(&self, p: &Point3<f64>) -> f64 {
        let Some(g) = self.geometry.as_ref() else {
            return f64::INFINITY;
        };
        #[allow(clippy::cast_possible_truncation)]
        let q = p.map(|v| v as f32);
        let id = Isometry3::identity();
        f64::from(match g {
            Geometry::Boxes(c, _) => c.distance_to_point(&id, &q, true),
            Geometry::Voxels(v, _) => v.distance_to_point(&id, &q, true),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// Distance from `p` to the nearest of `boxes` (0 inside one).
    fn nearest_box(boxes: &[(Point3<f64>, Point3<f64>)], p: &Point3<f64>) -> f64 {
        boxes
            .iter()
            .map(|(lo, hi)| {
                Vector3::from_fn(|k, _| (lo[k] - p[k]).max(p[k] - hi[k]).max(0.0)).norm()
            })
            .fold(f64::INFINITY, f64::min)
    }

    fn inside(boxes: &[(Point3<f64>, Point3<f64>)], p: &Point3<f64>) -> bool {
        boxes
            .iter()
            .any(|(lo, hi)| (0..3).all(|k| p[k] >= lo[k] && p[k] <= hi[k]))
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(128))]

        /// The first hit equals a fine march along the ray (to the march step plus f32 error).
        #[test]
        fn ray_casts_equal_a_march(
            boxes in proptest::collection::vec((-5.0f64..5.0, -5.0f64..5.0, -5.0f64..5.0, 0.1f64..3.0, 0.1f64..3.0, 0.1f64..3.0), 1..8),
            o in (-8.0f64..8.0, -8.0f64..8.0, -8.0f64..8.0),
            d in (-1.0f64..1.0, -1.0f64..1.0, -1.0f64..1.0),
        ) {
            let boxes: Vec<_> = boxes
                .iter()
                .map(|&(x, y, z, a, b, c)| (Point3::new(x, y, z), Point3::new(x + a, y + b, z + c)))
                .collect();
            let dir = Vector3::new(d.0, d.1, d.2);
            prop_assume!(dir.norm() > 0.1);
            let dir = dir.normalize();
            let origin = Point3::new(o.0, o.1, o.2);
            let w = World::from_boxes(&boxes).unwrap();
            let max = 20.0;
            let step = 1e-3;
            let marched = (0..=(max / step) as usize)
                .map(|i| i as f64 * step)
                .find(|t| inside(&boxes, &(origin + dir * *t)));
            match (w.cast_ray(&origin, &dir, max), marched) {
                (Some(t), Some(m)) => prop_assert!((t - m).abs() <= step + 1e-4, "{} vs {}", t, m),
                (None, None) => {}
                // Only a graze shorter than the march step may be seen by one and not the
                // other: some box is crossed for less than two steps.
                (got, want) => {
                    let grazed = boxes.iter().any(|(lo, hi)| {
                        let (mut t0, mut t1) = (0.0f64, max);
                        for k in 0..3 {
                            if dir[k].abs() < 1e-12 {
                                if origin[k] < lo[k] || origin[k] > hi[k] {
                                    return false;
                                }
                            } else {
                                let (a, b) = ((lo[k] - origin[k]) / dir[k], (hi[k] - origin[k]) / dir[k]);
                                t0 = t0.max(a.min(b));
                                t1 = t1.min(a.max(b));
                            }
                        }
                        t0 <= t1 && t1 - t0 < 2.0 * step
                    });
                    prop_assert!(grazed, "{:?} vs {:?}", got, want);
                }
            }
            // Distances: zero inside, otherwise the distance to the nearest box.
            let truth = nearest_box(&boxes, &origin);
            prop_assert!((w.distance(&origin) - truth).abs() < 1e-4 * (1.0 + truth));
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]

        /// A point cloud's voxel world: the first hit equals a march through the occupied
        /// voxels, and distances equal the nearest occupied voxel's.
        #[test]
        fn voxel_worlds_equal_a_march(
            pts in proptest::collection::vec((-3.0f64..3.0, -3.0f64..3.0, -3.0f64..3.0), 1..60),
            o in (-4.0f64..4.0, -4.0f64..4.0, -4.0f64..4.0),
            d in (-1.0f64..1.0, -1.0f64..1.0, -1.0f64..1.0),
        ) {
            let size = 0.5;
            let cloud: Vec<Point3<f64>> = pts.iter().map(|&(x, y, z)| Point3::new(x, y, z)).collect();
            let w = World::from_points(&cloud, size).unwrap();
            // The occupied voxels as boxes.
            let boxes: Vec<(Point3<f64>, Point3<f64>)> = cloud
                .iter()
                .map(|p| {
                    let lo = p.map(|v| (v / size).floor() * size);
                    (lo, lo + Vector3::repeat(size))
                })
                .collect();
            let dir = Vector3::new(d.0, d.1, d.2);
            prop_assume!(dir.norm() > 0.1);
            let dir = dir.normalize();
            let origin = Point3::new(o.0, o.1, o.2);
            let step = 1e-3;
            let marched = (0..=(12.0 / step) as usize)
                .map(|i| i as f64 * step)
                .find(|t| inside(&boxes, &(origin + dir * *t)));
            match (w.cast_ray(&origin, &dir, 12.0), marched) {
                (Some(t), Some(m)) => prop_assert!((t - m).abs() <= step + 1e-4, "{} vs {}", t, m),
                (None, None) => {}
                // A graze shorter than the march step: allowed either way.
                (Some(t), None) => {
                    let p = origin + dir * t;
                    let on_a_voxel = boxes
                        .iter()
                        .any(|(lo, hi)| (0..3).all(|k| p[k] >= lo[k] - 1e-4 && p[k] <= hi[k] + 1e-4));
                    prop_assert!(on_a_voxel, "a hit at {} off every voxel", t);
                }
                (None, Some(m)) => prop_assert!(false, "missed a hit at {}", m),
            }
            let truth = nearest_box(&boxes, &origin);
            prop_assert!((w.distance(&origin) - truth).abs() < 1e-4 * (1.0 + truth), "{} vs {}", w.distance(&origin), truth);
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(256))]

        /// `closer_than` answers exactly as a distance query does, near voxels, far from
        /// them, outside the voxels' box and for non-finite input.
        #[test]
        fn closer_than_equals_the_distance_test(
            pts in proptest::collection::vec((-3.0f64..3.0, -3.0f64..3.0, -3.0f64..3.0), 1..40),
            qs in proptest::collection::vec((-5.0f64..5.0, -5.0f64..5.0, -5.0f64..5.0), 40),
            d in 0.0f64..1.5,
            size in 0.1f64..0.6,
        ) {
            let cloud: Vec<Point3<f64>> = pts.iter().map(|&(x, y, z)| Point3::new(x, y, z)).collect();
            let w = World::from_points(&cloud, size).unwrap();
            // Points near the cloud's points, where the answer turns.
            let near = cloud.iter().map(|p| p + Vector3::new(d * 0.7, -d * 0.4, size * 0.5));
            let queries = qs.iter().map(|&(x, y, z)| Point3::new(x, y, z)).chain(near);
            for q in queries {
                prop_assert_eq!(w.closer_than(&q, d), w.distance(&q) < d, "{} at {}", q, d);
            }
            let nan = Point3::new(f64::NAN, 0.0, 0.0);
            prop_assert_eq!(w.closer_than(&nan, d), w.distance(&nan) < d);
            prop_assert_eq!(w.closer_than(&cloud[0], f64::INFINITY), w.distance(&cloud[0]) < f64::INFINITY);
        }
    }

    /// In the generated scenes, our ray casts agree with parry3d's (to its `f32` precision)
    /// on rays from random free points in random directions.
    #[test]
    fn scene_ray_casts_agree_with_parry() {
        use crate::rng::Rng;
        use crate::scene::Scene;
        for scene in [Scene::small(1), Scene::maze(1), Scene::sinkhole(1)] {
            let w = scene.world().unwrap();
            let mut rng = Rng::new(5);
            let (lo, hi) = (scene.min, scene.max);
            let mut hits = 0;
            for _ in 0..2000 {
                let o = Point3::from(Vector3::from_fn(|k, _| rng.range(lo[k], hi[k])));
                let d = Vector3::from_fn(|_, _| rng.normal()).normalize();
                let (ours, parry) = (w.cast_ray(&o, &d, 40.0), w.cast_ray_parry(&o, &d, 40.0));
                match (ours, parry) {
                    (Some(a), Some(b)) => {
                        assert!((a - b).abs() < 1e-4 * (1.0 + b), "{o} {d}: {a} vs {b}");
                        hits += 1;
                    }
                    (None, None) => {}
                    _ => panic!("{o} {d}: {ours:?} vs {parry:?}"),
                }
            }
            assert!(hits > 1000, "{hits}");
        }
    }

    #[test]
    fn point_cloud_worlds_reject_bad_sizes_and_skip_bad_points() {
        let p = [Point3::new(1.0, 0.0, 0.0)];
        assert_eq!(
            World::from_points(&p, 0.0).unwrap_err(),
            WorldError::BadVoxel(0.0)
        );
        assert!(World::from_points(&p, f64::NAN).is_err());
        assert!(World::from_points(&[Point3::new(1e12, 0.0, 0.0)], 0.1).is_err());
        let empty = World::from_points(&[Point3::new(f64::NAN, 0.0, 0.0)], 0.1).unwrap();
        assert_eq!(empty.cast_ray(&Point3::origin(), &Vector3::x(), 10.0), None);
        assert_eq!(empty.distance(&Point3::origin()), f64::INFINITY);
    }

    #[test]
    fn empty_world_and_bad_boxes() {
        let w = World::from_boxes(&[]).unwrap();
        assert_eq!(w.cast_ray(&Point3::origin(), &Vector3::x(), 10.0), None);
        assert_eq!(w.distance(&Point3::origin()), f64::INFINITY);
        let bad = [(Point3::new(1.0, 0.0, 0.0), Point3::new(0.0, 1.0, 1.0))];
        assert_eq!(World::from_boxes(&bad).unwrap_err(), WorldError::BadBox(0));
        let nan = [(Point3::new(f64::NAN, 0.0, 0.0), Point3::new(1.0, 1.0, 1.0))];
        assert!(World::from_boxes(&nan).is_err());
    }
}
