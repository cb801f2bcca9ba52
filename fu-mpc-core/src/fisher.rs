//! The Fisher / A-optimality table of equations (15)–(16).

use core::f64::consts::TAU;
use std::num::NonZeroUsize;

use kiddo::{ImmutableKdTree, SquaredEuclidean};
use lidar_kinematics::{KinematicChain, LidarSensor};
use nalgebra::{Isometry3, Matrix3, Point3, Vector3};
use rayon::prelude::*;

use crate::error::invalid;
use crate::{PeriodicPwl, Result};

/// Settings of the Fisher table.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FisherConfig {
    /// Candidate motor angles N_c over one revolution; default 72 (5° apart).
    pub candidates: usize,
    /// Neighbours K for each point's PCA normal; default 10 (the issue's and the paper's K).
    pub neighbours: usize,
    /// Regularisation ε of tr((F + εI)⁻¹); default 1: the information of one point aligned
    /// with each axis, so a direction that sees nothing costs 3/ε = 3 while a direction that
    /// sees hundreds of well-spread normals costs a few hundredths.
    pub epsilon: f64,
}

impl Default for FisherConfig {
    fn default() -> Self {
        Self {
            candidates: 72,
            neighbours: 10,
            epsilon: 1.0,
        }
    }
}

impl FisherConfig {
    /// Checks every setting.
    ///
    /// # Errors
    /// [`CoreError::InvalidConfig`](crate::CoreError::InvalidConfig) for no candidates, fewer than 3 neighbours, or ε that is not
    /// positive and finite.
    pub fn validate(&self) -> Result<()> {
        if self.candidates == 0 {
            return invalid("candidates", 0.0, "need at least one candidate angle");
        }
        check_neighbours(self.neighbours)?;
        if !(self.epsilon.is_finite() && self.epsilon > 0.0) {
            return invalid("epsilon", self.epsilon, "must be positive and finite");
        }
        Ok(())
    }
}

/// The localisation cost f(θ) = tr((F(θ) + εI)⁻¹) over one motor revolution, eq. (16).
///
/// Built once per update from the local cloud and the sensor pose (on any thread: the table is
/// an immutable `Send + Sync` value), then read by the MPC at any angle by periodic linear
/// interpolation.
///
/// # Example
/// ```
/// use fu_mpc_core::{FisherConfig, FisherTable};
/// use lidar_kinematics::{FieldOfView, KinematicChain, LidarSensor};
/// use nalgebra::{Isometry3, Point3};
///
/// // A floor and one wall in front (+x): directions toward the wall see two constraints.
/// let mut cloud = Vec::new();
/// for i in 0..40 {
///     for j in 0..40 {
///         let (a, b) = (f64::from(i) * 0.25 - 5.0, f64::from(j) * 0.25 - 5.0);
///         cloud.push(Point3::new(a, b, -1.0));
///         cloud.push(Point3::new(4.0, a, b * 0.3));
///     }
/// }
/// // A forward-looking sensor (±35° azimuth), so the motor angle decides what it sees.
/// let sensor = LidarSensor::ring16()
///     .with_field_of_view(FieldOfView::try_new(-0.6, 0.6, -0.26, 0.26).unwrap());
/// let table = FisherTable::build(&cloud, &Isometry3::identity(), &KinematicChain::default(),
///                                &sensor, &FisherConfig::default()).unwrap();
/// assert_eq!(table.cost().len(), 72);
/// assert!(table.value(0.0) < table.value(std::f64::consts::PI));
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct FisherTable {
    cost: PeriodicPwl,
    information: Vec<Matrix3<f64>>,
    points_used: usize,
    skipped: usize,
}

impl FisherTable {
    /// Builds the table: normals by PCA of each point's K nearest neighbours (a k-d tree), then
    /// for each candidate angle θ_c the sum F(θ_c) = Σ n nᵀ over the points the sensor sees at
    /// θ_c (in range and in its field of view, with the chain at θ_c), eq. (15).
    ///
    /// Non-finite points are skipped (counted in [`FisherTable::skipped`]); an empty cloud gives
    /// F = 0 everywhere, so f = 3/ε at every angle (the documented fallback). Coplanar clouds
    /// give a rank-deficient F, which ε keeps invertible.
    ///
    /// # Errors
    /// An invalid `config`, or kinematic errors for a non-finite body pose.
    pub fn build(
        cloud: &[Point3<f64>],
        body_pose: &Isometry3<f64>,
        chain: &KinematicChain,
        sensor: &LidarSensor,
        config: &FisherConfig,
    ) -> Result<Self> {
        config.validate()?;
        let points: Vec<[f64; 3]> = cloud
            .iter()
            .filter(|p| p.iter().all(|v| v.is_finite()))
            .map(|p| [p.x, p.y, p.z])
            .collect();
        let skipped = cloud.len() - points.len();
        let normals = normals(&points, config.neighbours);
        let nc = config.candidates;
        let gates = (0..nc)
            .map(|c| {
                // Knot counts are far below 2^53.
                #[allow(clippy::cast_precision_loss)]
                let theta = TAU * c as f64 / nc as f64;
                sensor.visibility_gate(chain, body_pose, theta)
            })
            .collect::<core::result::Result<Vec<_>, _>>()?;
        // Points outer, angles inner: each point's n nᵀ is formed once and the gates stay in
        // cache. Fixed chunks of points run in parallel and their sums are added in chunk
        // order, so the table does not depend on the number of threads.
        let partial: Vec<Vec<[f64; 6]>> = points
            .par_chunks(GATE_CHUNK)
            .zip(normals.par_chunks(GATE_CHUNK))
            .map(|(pts, nrm)| {
                let mut acc = vec![[0.0f64; 6]; nc];
                for (p, n) in pts.iter().zip(nrm) {
                    let p = Point3::new(p[0], p[1], p[2]);
                    // eq. (15): the six distinct entries of n nᵀ.
                    let nn = [
                        n.x * n.x,
                        n.x * n.y,
                        n.x * n.z,
                        n.y * n.y,
                        n.y * n.z,
                        n.z * n.z,
                    ];
                    for (gate, a) in gates.iter().zip(acc.iter_mut()) {
                        if gate.contains(&p) {
                            for (ai, v) in a.iter_mut().zip(nn) {
                                *ai += v;
                            }
                        }
                    }
                }
                acc
            })
            .collect();
        let mut acc = vec![[0.0f64; 6]; nc];
        for part in &partial {
            for (a, b) in acc.iter_mut().zip(part) {
                for (ai, bi) in a.iter_mut().zip(b) {
                    *ai += bi;
                }
            }
        }
        let information: Vec<Matrix3<f64>> = acc
            .iter()
            .map(|a| Matrix3::new(a[0], a[1], a[2], a[1], a[3], a[4], a[2], a[4], a[5]))
            .collect();
        let eps = config.epsilon;
        let values = information
            .iter()
            .map(|f| trace_inverse(&(f + Matrix3::identity() * eps)))
            .collect();
        Ok(Self {
            cost: PeriodicPwl::new(values)?,
            information,
            points_used: points.len(),
            skipped,
        })
    }

    /// f(θ) as a periodic piecewise-linear function.
    pub fn cost(&self) -> &PeriodicPwl {
        &self.cost
    }

    /// f(θ) \[1\] at any angle.
    pub fn value(&self, theta: f64) -> f64 {
        self.cost.value(theta)
    }

    /// F(θ_c) at each candidate angle (without ε).
    pub fn information(&self) -> &[Matrix3<f64>] {
        &self.information
    }

    /// Points that entered the table.
    pub fn points_used(&self) -> usize {
        self.points_used
    }

    /// Non-finite points skipped.
    pub fn skipped(&self) -> usize {
        self.skipped
    }
}

/// tr(A⁻¹) of a symmetric positive definite 3 × 3 matrix via its adjugate.
fn trace_inverse(a: &Matrix3<f64>) -> f64 {
    let c00 = a[(1, 1)] * a[(2, 2)] - a[(1, 2)] * a[(2, 1)];
    let c11 = a[(0, 0)] * a[(2, 2)] - a[(0, 2)] * a[(2, 0)];
    let c22 = a[(0, 0)] * a[(1, 1)] - a[(0, 1)] * a[(1, 0)];
    let det = a.determinant();
    (c00 + c11 + c22) / det
}

/// The neighbour count K of a PCA normal: at least 3 points span a plane.
pub(crate) fn check_neighbours(k: usize) -> Result<()> {
    if k < 3 {
        // Counts are small.
        #[allow(clippy::cast_precision_loss)]
        return invalid("neighbours", k as f64, "need at least 3 for a plane");
    }
    Ok(())
}

/// Points per parallel task of the visibility sums in [`FisherTable::build`].
const GATE_CHUNK: usize = 2048;

/// Points per parallel task of [`normals`].
const NORMAL_CHUNK: usize = 512;

/// Unit normals by PCA of each point's K nearest neighbours (K capped at the cloud size); a
/// point with a degenerate neighbourhood gets the z axis.
pub(crate) fn normals(points: &[[f64; 3]], k: usize) -> Vec<Vector3<f64>> {
    if points.len() < 3 {
        return vec![Vector3::z(); points.len()];
    }
    let Ok(tree) = ImmutableKdTree::<f64, 3>::new_from_slice(points) else {
        return vec![Vector3::z(); points.len()];
    };
    let Some(k) = NonZeroUsize::new(k.min(points.len())) else {
        return vec![Vector3::z(); points.len()];
    };
    // Queries in Morton order of their cells visit the tree's nodes in nearly the order it
    // stores them, so consecutive queries find their nodes in cache.
    let order = morton_order(points);
    // Each point's normal is independent of the others: the queries run on rayon's threads,
    // in fixed chunks, and the result is the same on any number of threads.
    let sorted: Vec<Vector3<f64>> = order
        .par_iter()
        .with_min_len(NORMAL_CHUNK)
        .map(|&i| {
            let p = &points[i];
            let nn = tree
                .query(p)
                .nearest_n::<SquaredEuclidean<f64>>(k)
                .unsorted()
                .execute();
            let mut mean = Vector3::zeros();
            let mut count = 0.0;
            for r in &nn {
                let q = points.get(usize::try_from(r.item).unwrap_or(usize::MAX));
                if let Some(q) = q {
                    mean += Vector3::from(*q);
                    count += 1.0;
                }
            }
            if count < 3.0 {
                return Vector3::z();
            }
            mean /= count;
            let mut cov = Matrix3::zeros();
            for r in &nn {
                if let Some(q) = points.get(usize::try_from(r.item).unwrap_or(usize::MAX)) {
                    let d = Vector3::from(*q) - mean;
                    cov += d * d.transpose();
                }
            }
            least_eigenvector(&cov)
        })
        .collect();
    let mut out = vec![Vector3::z(); points.len()];
    for (&i, n) in order.iter().zip(sorted) {
        out[i] = n;
    }
    out
}

/// Indices of `points` sorted by the Morton code of their cells on a 2^21 grid over the
/// points' bounding box (ties by index, so the order is deterministic).
fn morton_order(points: &[[f64; 3]]) -> Vec<usize> {
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for p in points {
        for d in 0..3 {
            lo[d] = lo[d].min(p[d]);
            hi[d] = hi[d].max(p[d]);
        }
    }
    let extent = (0..3).map(|d| hi[d] - lo[d]).fold(0.0, f64::max);
    let scale = if extent > 0.0 {
        f64::from((1u32 << 21) - 1) / extent
    } else {
        0.0
    };
    let mut keyed: Vec<(u64, usize)> = points
        .iter()
        .enumerate()
        .map(|(i, p)| {
            let mut key = 0u64;
            for d in 0..3 {
                // In [0, 2^21) by the scale; the float-to-int cast saturates anyway.
                #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
                let c = ((p[d] - lo[d]) * scale) as u64;
                key |= spread3(c) << d;
            }
            (key, i)
        })
        .collect();
    keyed.sort_unstable();
    keyed.into_iter().map(|(_, i)| i).collect()
}

/// The low 21 bits of `x` spread to every third bit.
fn spread3(x: u64) -> u64 {
    let mut x = x & 0x1f_ffff;
    x = (x | x << 32) & 0x1f_0000_0000_ffff;
    x = (x | x << 16) & 0x1f_0000_ff00_00ff;
    x = (x | x << 8) & 0x100f_00f0_0f00_f00f;
    x = (x | x << 4) & 0x10c3_0c30_c30c_30c3;
    x = (x | x << 2) & 0x1249_2492_4924_9249;
    x
}

/// The unit eigenvector of the smallest eigenvalue of a symmetric 3 × 3 matrix (see
/// [`least_eigen`]); the z axis when it is not defined.
pub(crate) fn least_eigenvector(a: &Matrix3<f64>) -> Vector3<f64> {
    least_eigen(a).map_or_else(Vector3::z, |(_, v)| v)
}

/// The eigenvalues (increasing) of a symmetric 3 × 3 matrix and the unit eigenvector of the
/// smallest, in closed form: the trigonometric solution of the characteristic cubic, and the
/// largest cross product of two rows of A − λ₀I. For PCA normals of point neighbourhoods.
///
/// `None` for a zero or non-finite matrix, a multiple of the identity (every direction is an
/// eigenvector), or a smallest eigenvalue of multiplicity two or more.
///
/// # Example
/// ```
/// use fu_mpc_core::least_eigen;
/// use nalgebra::{Matrix3, Vector3};
/// let a = Matrix3::from_diagonal(&Vector3::new(4.0, 1.0, 9.0));
/// let (l, n) = least_eigen(&a).unwrap();
/// assert!((l[0] - 1.0).abs() < 1e-12 && (l[2] - 9.0).abs() < 1e-12);
/// assert!((n.y.abs() - 1.0).abs() < 1e-12);
/// ```
pub fn least_eigen(a: &Matrix3<f64>) -> Option<([f64; 3], Vector3<f64>)> {
    let scale = a.abs().max();
    if !(scale.is_finite() && scale > 0.0) {
        return None;
    }
    let m = a / scale;
    let q = m.trace() / 3.0;
    let p1 = m[(0, 1)].powi(2) + m[(0, 2)].powi(2) + m[(1, 2)].powi(2);
    let p2 = (m[(0, 0)] - q).powi(2) + (m[(1, 1)] - q).powi(2) + (m[(2, 2)] - q).powi(2) + 2.0 * p1;
    let p = (p2 / 6.0).sqrt();
    if p < 1e-12 {
        return None;
    }
    let b = (m - Matrix3::identity() * q) / p;
    let r = (b.determinant() / 2.0).clamp(-1.0, 1.0);
    let phi = r.acos() / 3.0;
    let hi = q + 2.0 * p * phi.cos();
    let lo = q + 2.0 * p * (phi + TAU / 3.0).cos();
    let mid = 3.0 * q - hi - lo;
    let s = m - Matrix3::identity() * lo;
    let (r0, r1, r2) = (
        s.row(0).transpose(),
        s.row(1).transpose(),
        s.row(2).transpose(),
    );
    let best = [r0.cross(&r1), r0.cross(&r2), r1.cross(&r2)]
        .into_iter()
        .max_by(|x, y| x.norm_squared().total_cmp(&y.norm_squared()))?;
    let n = best.norm();
    (n > 1e-300).then(|| ([lo * scale, mid * scale, hi * scale], best / n))
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::SymmetricEigen;
    use proptest::prelude::*;

    proptest! {
        #[test]
        fn closed_form_eigen_matches_nalgebra(
            v in proptest::collection::vec(-3.0f64..3.0, 9),
        ) {
            // A positive semi-definite matrix BᵀB.
            let b = Matrix3::from_iterator(v);
            let a = b.transpose() * b;
            let eig = SymmetricEigen::new(a);
            let mut l: Vec<f64> = eig.eigenvalues.iter().copied().collect();
            l.sort_by(f64::total_cmp);
            let gap = (l[1] - l[0]) / l[2].max(1e-12);
            prop_assume!(l[2] > 1e-6 && gap > 1e-3);
            let (got, n) = least_eigen(&a).unwrap();
            for k in 0..3 {
                prop_assert!((got[k] - l[k]).abs() <= 1e-8 * l[2], "{:?} vs {:?}", got, l);
            }
            // A unit vector with A n = λ₀ n.
            prop_assert!((n.norm() - 1.0).abs() < 1e-9);
            prop_assert!((a * n - n * l[0]).norm() <= 1e-6 * l[2].max(1.0) / gap.min(1.0));
        }

        #[test]
        fn least_eigenvector_matches_a_reference(
            v in proptest::collection::vec(-3.0f64..3.0, 6),
        ) {
            let a = Matrix3::new(v[0], v[1], v[2], v[1], v[3], v[4], v[2], v[4], v[5]);
            let eig = SymmetricEigen::new(a);
            let mut idx = [0usize, 1, 2];
            idx.sort_by(|i, j| eig.eigenvalues[*i].total_cmp(&eig.eigenvalues[*j]));
            let (l0, l1) = (eig.eigenvalues[idx[0]], eig.eigenvalues[idx[1]]);
            // Only a well-separated smallest eigenvalue has a unique direction.
            prop_assume!(l1 - l0 > 1e-3 * (1.0 + a.abs().max()));
            let want = eig.eigenvectors.column(idx[0]).into_owned();
            let got = least_eigenvector(&a);
            prop_assert!((got.dot(&want).abs() - 1.0).abs() < 1e-6, "{:?} vs {:?}", got, want);
        }
    }

    proptest! {
        #[test]
        fn morton_order_is_a_permutation_along_the_curve(
            v in proptest::collection::vec(-50.0f64..50.0, 0..120),
        ) {
            let points: Vec<[f64; 3]> = v.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();
            let order = morton_order(&points);
            let mut seen = order;
            seen.sort_unstable();
            prop_assert_eq!(seen, (0..points.len()).collect::<Vec<_>>());
        }
    }

    #[test]
    fn spread_bits_interleave() {
        assert_eq!(spread3(0b111), 0b1001001);
        assert_eq!(spread3((1 << 21) - 1).count_ones(), 21);
        assert_eq!(spread3(1 << 20), 1 << 60);
        // Cells of the unit cube in Morton order: x first, then y, then z.
        let pts = [
            [1.0, 1.0, 1.0],
            [0.0, 0.0, 1.0],
            [0.0, 1.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0; 3],
        ];
        assert_eq!(morton_order(&pts), vec![4, 3, 2, 1, 0]);
    }

    #[test]
    fn trace_inverse_matches_nalgebra() {
        let a = Matrix3::new(4.0, 1.0, 0.5, 1.0, 3.0, 0.2, 0.5, 0.2, 2.0);
        let inv = a.try_inverse().unwrap();
        assert!((trace_inverse(&a) - inv.trace()).abs() < 1e-12);
    }
}
