//! The Fisher / A-optimality table of equations (15)–(16).

use core::f64::consts::TAU;

use lidar_kinematics::{KinematicChain, LidarSensor};
use nalgebra::{Isometry3, Matrix3, Point3, Vector3};
use rayon::prelude::*;

use crate::error::{invalid, too_large};
use crate::fov_gap::FovGap;
use crate::knn::map_neighbours;
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
    /// [`CoreError::InvalidConfig`](crate::CoreError::InvalidConfig) for no candidates or more
    /// than [`MAX_KNOTS`](crate::MAX_KNOTS), fewer than 3 neighbours, or ε that is not
    /// positive and finite.
    pub fn validate(&self) -> Result<()> {
        if self.candidates == 0 {
            return invalid("candidates", 0.0, "need at least one candidate angle");
        }
        if self.candidates > crate::MAX_KNOTS {
            return too_large("candidates", self.candidates, "at most MAX_KNOTS");
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
    /// Builds the table: normals by PCA of each point's K nearest neighbours (exact, from a grid
    /// over the cloud), then for each candidate angle θ_c the sum F(θ_c) = Σ n nᵀ over the points
    /// the sensor sees at θ_c (in range and in its field of view, with the chain at θ_c), eq. (15).
    ///
    /// Non-finite points are skipped (counted in [`FisherTable::skipped`]); an empty cloud gives
    /// F = 0 everywhere, so f = 3/ε at every angle (the documented fallback). Coplanar clouds
    /// give a rank-deficient F, which ε keeps invertible.
    ///
    /// # Errors
    /// An invalid `config`, kinematic errors for a non-finite body pose, and
    /// [`CoreError::NonFinite`](crate::CoreError::NonFinite) when ε is so small that some f(θ_c)
    /// overflows (3/ε for a direction that sees nothing: ε below about 1e-308).
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
        let walk = KnotWalk::new(chain, body_pose, sensor, nc)?;
        // Points outer, angles inner: each point's n nᵀ is formed once and the gates stay in
        // cache. Fixed chunks of points run in parallel and their sums are added in chunk
        // order, so the table does not depend on the number of threads.
        let partial: Vec<Vec<[f64; 6]>> = points
            .par_chunks(GATE_CHUNK)
            .zip(normals.par_chunks(GATE_CHUNK))
            .map(|(pts, nrm)| {
                let mut acc = vec![[0.0f64; 6]; nc];
                for (p, n) in pts.iter().zip(nrm) {
                    // eq. (15): the six distinct entries of n nᵀ.
                    let nn = [
                        n.x * n.x,
                        n.x * n.y,
                        n.x * n.z,
                        n.y * n.y,
                        n.y * n.z,
                        n.z * n.z,
                    ];
                    walk.for_each_seen(&Point3::new(p[0], p[1], p[2]), |c| {
                        for (ai, v) in acc[c].iter_mut().zip(nn) {
                            *ai += v;
                        }
                    });
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
            .map(|f| trace_inverse(&(f + Matrix3::identity() * eps), eps))
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

/// The candidate angles at which the sensor sees a point, found without testing most of the
/// angles it cannot see at.
///
/// As the motor turns, a point moves in the LiDAR frame on a circle about the motor axis, of
/// radius ρ its distance to the axis: between knots Δθ apart it moves at most ρΔθ. A point
/// whose circle never reaches the range shell or the elevation band is skipped whole; at a
/// knot that does not see it, the knots it cannot reach the seen region by
/// ([`FovGap::outside`] over ρΔθ) are skipped. Every knot tested uses the same test as
/// [`lidar_kinematics::VisibilityGate::contains`], so the result is that of testing every knot.
struct KnotWalk<'a> {
    sensor: &'a LidarSensor,
    /// World → LiDAR at each knot, as `LidarSensor::visibility_gate` prepares it.
    gates: Vec<(Matrix3<f64>, Vector3<f64>)>,
    /// World → motor base.
    to_base: Isometry3<f64>,
    /// Motor frame → LiDAR: its rotation's columns and its translation, so the LiDAR-frame
    /// point at φ = ψ − θ is c₀ + ρ (cos φ e₁ + sin φ e₂) with c₀ = z e₃ + t.
    e: [Vector3<f64>; 3],
    t: Vector3<f64>,
    gap: FovGap,
    /// Knot spacing Δθ \[rad\].
    spacing: f64,
}

impl<'a> KnotWalk<'a> {
    fn new(
        chain: &KinematicChain,
        body_pose: &Isometry3<f64>,
        sensor: &'a LidarSensor,
        knots: usize,
    ) -> Result<Self> {
        let gates = (0..knots)
            .map(|c| {
                // Knot counts are far below 2^53.
                #[allow(clippy::cast_precision_loss)]
                let theta = TAU * c as f64 / knots as f64;
                let to_lidar = chain.lidar_pose(body_pose, theta)?.inverse();
                Ok((
                    to_lidar.rotation.to_rotation_matrix().into_inner(),
                    to_lidar.translation.vector,
                ))
            })
            .collect::<Result<Vec<_>>>()?;
        let ex = chain.extrinsics();
        let to_base = (body_pose * ex.motor_base_in_body()).inverse();
        let from_motor = ex.lidar_in_motor().inverse();
        let m = from_motor.rotation.to_rotation_matrix().into_inner();
        // Knot counts are far below 2^53.
        #[allow(clippy::cast_precision_loss)]
        let spacing = TAU / knots as f64;
        Ok(Self {
            sensor,
            gates,
            to_base,
            e: [m.column(0).into(), m.column(1).into(), m.column(2).into()],
            t: from_motor.translation.vector,
            gap: FovGap::new(sensor),
            spacing,
        })
    }

    /// Calls `seen(c)` for each knot c (in increasing order) whose gate contains `p`.
    fn for_each_seen(&self, p: &Point3<f64>, mut seen: impl FnMut(usize)) {
        // A margin far above the rounding of the transforms.
        let margin = 1e-9 * (1.0 + p.coords.amax());
        let q = self.to_base * p;
        let rho = (q.x * q.x + q.y * q.y).sqrt();
        // The circle's range of heights z_L and of distances r_L from the LiDAR: each a
        // sinusoid in φ, c + a cos φ + b sin φ, so within c ± √(a² + b²).
        let c0 = self.e[2] * q.z + self.t;
        let [e1, e2, _] = &self.e;
        let z_amp = rho * e1.z.hypot(e2.z);
        let (z_lo, z_hi) = (c0.z - z_amp - margin, c0.z + z_amp + margin);
        let r2_mid = c0.norm_squared() + rho * rho;
        let r2_amp = 2.0 * rho * c0.dot(e1).hypot(c0.dot(e2));
        let r_lo = (r2_mid - r2_amp).max(0.0).sqrt() - margin;
        let r_hi = (r2_mid + r2_amp).max(0.0).sqrt() + margin;
        let g = &self.gap;
        // Seen needs r_min ≤ r ≤ r_max and r sin β_min ≤ z ≤ r sin β_max somewhere on the circle.
        let lowest = g.sin_el_min * if g.sin_el_min >= 0.0 { r_lo } else { r_hi };
        let highest = g.sin_el_max * if g.sin_el_max >= 0.0 { r_hi } else { r_lo };
        if r_hi < g.r_min || r_lo > g.r_max || z_hi < lowest || z_lo > highest {
            return;
        }
        let step = rho * self.spacing;
        let mut c = 0;
        while c < self.gates.len() {
            let (rot, tr) = &self.gates[c];
            let pl = rot * p.coords + tr;
            if self.sensor.sees_in_lidar_frame(&Point3::from(pl)) {
                seen(c);
                c += 1;
                continue;
            }
            let d = g.outside(&pl) - margin;
            if d <= 0.0 {
                c += 1;
            } else if step > 0.0 {
                // Knots c + 1..=c + j with j ρΔθ < d cannot see the point.
                // A finite count; far below usize::MAX for any sane ratio, saturating anyway.
                #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
                let j = ((d / step).ceil() as usize).saturating_sub(1);
                c = c.saturating_add(1 + j);
            } else {
                // On the axis: the point does not move.
                return;
            }
        }
    }
}

/// tr(A⁻¹) of A = F + εI, F symmetric positive semi-definite, via its adjugate; from its
/// eigenvalues (each at least ε) when A is so near singular for its size that the adjugate
/// cancels (det A below 1e-8 of its diagonal's product: a rank-deficient F with a small ε),
/// or its determinant under- or overflows.
fn trace_inverse(a: &Matrix3<f64>, eps: f64) -> f64 {
    let c00 = a[(1, 1)] * a[(2, 2)] - a[(1, 2)] * a[(2, 1)];
    let c11 = a[(0, 0)] * a[(2, 2)] - a[(0, 2)] * a[(2, 0)];
    let c22 = a[(0, 0)] * a[(1, 1)] - a[(0, 1)] * a[(1, 0)];
    let det = a.determinant();
    let adjugate = (c00 + c11 + c22) / det;
    let diagonal = a[(0, 0)] * a[(1, 1)] * a[(2, 2)];
    // Written so NaN and overflow take the eigenvalues too.
    if det >= 1e-8 * diagonal && det > 0.0 && adjugate.is_finite() {
        return adjugate;
    }
    let scale = a.amax();
    if !(scale.is_finite() && scale > 0.0) {
        return adjugate;
    }
    let eigen = nalgebra::SymmetricEigen::new(a / scale).eigenvalues;
    eigen.iter().map(|&l| 1.0 / (l * scale).max(eps)).sum()
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

/// Unit normals by PCA of each point's K nearest neighbours (K capped at the cloud size;
/// exact neighbours, ties by index, from [`crate::knn`]); a point with a degenerate
/// neighbourhood gets the z axis.
pub(crate) fn normals(points: &[[f64; 3]], k: usize) -> Vec<Vector3<f64>> {
    if points.len() < 3 {
        return vec![Vector3::z(); points.len()];
    }
    map_neighbours(points, k, |nn| {
        if nn.len() < 3 {
            return Vector3::z();
        }
        let mut mean = Vector3::zeros();
        for &j in nn {
            mean += Vector3::from(points[j]);
        }
        // Neighbour counts are small.
        #[allow(clippy::cast_precision_loss)]
        let count = nn.len() as f64;
        mean /= count;
        let mut cov = Matrix3::zeros();
        for &j in nn {
            let d = Vector3::from(points[j]) - mean;
            cov += d * d.transpose();
        }
        least_eigenvector(&cov)
    })
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
/// eigenvector), or a smallest eigenvalue of multiplicity two or more when the rounding lets
/// the closed form see it. Near a repeated eigenvalue the closed form keeps about half the
/// digits: the eigenvalues are then good to about 1e-8 of the largest (their order too, so
/// two nearly equal ones may come out swapped), and a double smallest eigenvalue may come
/// out as two close values with some unit vector of its eigenplane.
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

    fn pose(v: &[f64]) -> Isometry3<f64> {
        Isometry3::new(
            Vector3::new(v[0], v[1], v[2]),
            Vector3::new(v[3], v[4], v[5]),
        )
    }

    proptest! {
        /// The knot walk reports exactly the knots whose visibility gate contains the point,
        /// for tilted and offset mounts, narrow and full fields of view, and points near and
        /// far, on and off the motor axis.
        #[test]
        fn knot_walk_equals_testing_every_knot(
            mount in proptest::collection::vec(-1.5f64..1.5, 6),
            base in proptest::collection::vec(-1.0f64..1.0, 6),
            body in proptest::collection::vec(-3.0f64..3.0, 6),
            fov in (-3.2f64..3.2, 0.05f64..7.0, -1.5f64..1.5, 0.0f64..1.5),
            range in (0.0f64..3.0, 1.0f64..60.0),
            knots in 1usize..100,
            cloud in proptest::collection::vec((-30.0f64..30.0, -30.0f64..30.0, -30.0f64..30.0), 1..40),
        ) {
            use lidar_kinematics::{Extrinsics, FieldOfView, RangeLimits};
            let chain = KinematicChain::new(
                Extrinsics::try_new(pose(&mount), pose(&base)).unwrap(),
            );
            let el_max = (fov.2 + fov.3).min(core::f64::consts::FRAC_PI_2);
            let sensor = LidarSensor::new(
                lidar_kinematics::SpinningPattern::ring16(),
                RangeLimits::try_new(range.0, range.0 + range.1).unwrap(),
            )
            .with_field_of_view(FieldOfView::try_new(fov.0, fov.0 + fov.1, fov.2, el_max).unwrap());
            let body = pose(&body);
            let walk = KnotWalk::new(&chain, &body, &sensor, knots).unwrap();
            // Points of the cloud, and points on the motor axis.
            let axis = body * chain.extrinsics().motor_base_in_body();
            let mut points: Vec<Point3<f64>> =
                cloud.iter().map(|&(x, y, z)| Point3::new(x, y, z)).collect();
            points.extend(cloud.iter().take(3).map(|&(_, _, z)| axis * Point3::new(0.0, 0.0, z)));
            for p in &points {
                let mut got = Vec::new();
                walk.for_each_seen(p, |c| got.push(c));
                let want: Vec<usize> = (0..knots)
                    .filter(|&c| {
                        #[allow(clippy::cast_precision_loss)]
                        let theta = TAU * c as f64 / knots as f64;
                        sensor.visibility_gate(&chain, &body, theta).unwrap().contains(p)
                    })
                    .collect();
                prop_assert_eq!(got, want, "point {:?}", p);
            }
        }
    }

    #[test]
    fn trace_inverse_matches_nalgebra() {
        let a = Matrix3::new(4.0, 1.0, 0.5, 1.0, 3.0, 0.2, 0.5, 0.2, 2.0);
        let inv = a.try_inverse().unwrap();
        assert!((trace_inverse(&a, 1.0) - inv.trace()).abs() < 1e-12);
    }

    /// A rank-one F (a tilted plane seen by thousands of points) with a small ε, where the
    /// adjugate cancels to wrong and even negative values: tr((F + εI)⁻¹) stays close to the
    /// sum of its exact eigenvalues' reciprocals (2000 + ε, ε and ε), and
    /// ε at the extremes of the floats gives 3/ε.
    #[test]
    fn trace_inverse_of_a_nearly_singular_matrix() {
        let n = Vector3::new(1.0, -0.37, -0.21).normalize();
        let f = n * n.transpose() * 2000.0;
        // The eigenvalues are good to about 1e-13 of F's scale: relative to ε, 1e-7 at
        // ε = 1e-3, 1e-4 at 1e-9.
        for (eps, tol) in [(1e-3, 1e-6), (1e-6, 1e-6), (1e-9, 1e-3)] {
            let got = trace_inverse(&(f + Matrix3::identity() * eps), eps);
            let want = 1.0 / (2000.0 + eps) + 2.0 / eps;
            assert!((got - want).abs() <= tol * want, "ε {eps}: {got} vs {want}");
        }
        for eps in [1e-110, 1e-300, f64::MAX] {
            let got = trace_inverse(&(Matrix3::identity() * eps), eps);
            let want = 3.0 / eps;
            assert!(
                (got - want).abs() <= 1e-12 * want,
                "ε {eps}: {got} vs {want}"
            );
        }
    }
}
