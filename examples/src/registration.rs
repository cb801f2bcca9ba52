//! Point-to-plane scan-to-map registration, the core of the simulator's LiDAR odometry.
//!
//! The map is a k-d tree (kiddo) over registered world points; each scan point is matched to
//! the plane fitted to its nearest map points, and the pose is refined by Gauss–Newton on
//! SE(3) with a Huber kernel.

use std::num::NonZeroUsize;

use kiddo::{ImmutableKdTree, SquaredEuclidean};
use nalgebra::{
    Isometry3, Matrix3, Matrix6, Point3, SymmetricEigen, Translation3, UnitQuaternion, Vector3,
    Vector6,
};

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
    /// Eigenvalues of JᵀJ in the last iteration, increasing: a small one flags a direction
    /// the geometry does not constrain (the corridor degeneracy).
    pub information: Vector6<f64>,
    /// The unit direction ξ = [ω; v] of the smallest eigenvalue: the motion the scan
    /// constrains least.
    pub weakest: Vector6<f64>,
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

    /// The plane (unit normal n, a point on it) fitted to the neighbours of `q`, if they are
    /// close enough and planar enough.
    fn plane(
        &self,
        q: &Point3<f64>,
        cfg: &RegistrationConfig,
    ) -> Option<(Vector3<f64>, Point3<f64>)> {
        let tree = self.tree.as_ref()?;
        let k = NonZeroUsize::new(cfg.neighbours.min(self.points.len()))?;
        let nn = tree
            .query(&[q.x, q.y, q.z])
            .nearest_n::<SquaredEuclidean<f64>>(k)
            .execute();
        if nn.len() < 3
            || nn
                .iter()
                .any(|r| r.distance > cfg.max_neighbour_distance.powi(2))
        {
            return None;
        }
        let pts: Vec<Vector3<f64>> = nn
            .iter()
            .filter_map(|r| self.points.get(usize::try_from(r.item).ok()?))
            .map(|p| Vector3::new(p[0], p[1], p[2]))
            .collect();
        #[allow(clippy::cast_precision_loss)]
        let mean = pts.iter().sum::<Vector3<f64>>() / pts.len() as f64;
        let cov = pts.iter().fold(Matrix3::zeros(), |m, p| {
            m + (p - mean) * (p - mean).transpose()
        });
        let eig = SymmetricEigen::new(cov);
        let mut idx = [0usize, 1, 2];
        idx.sort_by(|a, b| eig.eigenvalues[*a].total_cmp(&eig.eigenvalues[*b]));
        let (l0, l1) = (eig.eigenvalues[idx[0]].max(0.0), eig.eigenvalues[idx[1]]);
        if l1.is_nan() || l1 <= 0.0 || l0 > cfg.planarity * l1 {
            return None;
        }
        Some((
            eig.eigenvectors.column(idx[0]).into_owned(),
            Point3::from(mean),
        ))
    }

    /// Registers `scan` (points in the scan frame) to the map, starting from `initial`.
    /// Non-finite scan points are skipped; with no matches the initial pose is returned
    /// unchanged (`matched == 0`).
    pub fn register(
        &self,
        scan: &[Point3<f64>],
        initial: &Isometry3<f64>,
        cfg: &RegistrationConfig,
    ) -> Registration {
        let mut pose = *initial;
        let mut out = Registration {
            pose,
            matched: 0,
            iterations: 0,
            information: Vector6::zeros(),
            weakest: Vector6::zeros(),
        };
        for it in 0..cfg.iterations {
            let mut h = Matrix6::zeros();
            let mut g = Vector6::zeros();
            let mut matched = 0;
            for p in scan.iter().filter(|p| p.iter().all(|v| v.is_finite())) {
                let x = pose * p;
                let Some((n, c)) = self.plane(&x, cfg) else {
                    continue;
                };
                let r = n.dot(&(x - c));
                // Left perturbation ξ = [ω; v]: ∂r/∂ξ = [(x × n)ᵀ, nᵀ].
                let xn = x.coords.cross(&n);
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
            let eig = SymmetricEigen::new(h);
            let mut order = [0usize, 1, 2, 3, 4, 5];
            order.sort_by(|a, b| eig.eigenvalues[*a].total_cmp(&eig.eigenvalues[*b]));
            out.information = Vector6::from_fn(|i, _| eig.eigenvalues[order[i]]);
            out.weakest = eig.eigenvectors.column(order[0]).into_owned();
            if matched < 6 {
                break;
            }
            let Some(chol) = h.cholesky() else { break };
            let dx = -chol.solve(&g);
            let omega = Vector3::new(dx[0], dx[1], dx[2]);
            let v = Vector3::new(dx[3], dx[4], dx[5]);
            let delta = Isometry3::from_parts(
                Translation3::from(v),
                UnitQuaternion::from_scaled_axis(omega),
            );
            pose = delta * pose;
            if omega.norm() + v.norm() < cfg.tolerance {
                break;
            }
        }
        out.pose = pose;
        out
    }
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
        let map = PlaneMap::new(&map_pts);
        let s = scan(&scene, &truth, 3_000);
        let guess = Isometry3::from_parts(
            Translation3::new(0.15, -0.1, 0.05),
            UnitQuaternion::from_euler_angles(0.0, 0.02, 0.06),
        ) * truth;
        let cfg = RegistrationConfig {
            iterations: 30,
            ..Default::default()
        };
        let r = map.register(&s, &guess, &cfg);
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
        // The weakest direction is a translation along the corridor.
        assert!(r.weakest[3].abs() > 0.99, "{:?}", r.weakest);
        assert!(
            r.information[0] < 1e-4 * r.information[5],
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
}
