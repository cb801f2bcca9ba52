//! Trajectory metrics: absolute pose error after Umeyama alignment, trajectory length, and
//! the TUM trajectory format.
//!
//! # Example
//! ```
//! use fu_mpc_examples::metrics::{ape, Alignment};
//! use nalgebra::Point3;
//!
//! let truth: Vec<_> = (0..10).map(|i| Point3::new(f64::from(i), 0.0, 1.0)).collect();
//! let estimate: Vec<_> = truth.iter().map(|p| p + nalgebra::Vector3::new(0.0, 0.1, 0.0)).collect();
//! // A constant offset is an error without alignment and none after it.
//! assert!((ape(&truth, &estimate, Alignment::None).unwrap().rmse - 0.1).abs() < 1e-12);
//! assert!(ape(&truth, &estimate, Alignment::Se3).unwrap().rmse < 1e-9);
//! ```

use std::io::{self, Write};

use nalgebra::{Isometry3, Matrix3, Point3, Rotation3, Translation3, UnitQuaternion, Vector3};

/// Errors of the metrics.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum MetricsError {
    /// The two trajectories differ in length.
    #[error("trajectories differ in length: {0} vs {1}")]
    LengthMismatch(usize, usize),
    /// Too few poses for the requested computation.
    #[error("need at least {needed} poses, got {got}")]
    TooFew {
        /// Poses needed.
        needed: usize,
        /// Poses given.
        got: usize,
    },
    /// A NaN or infinite coordinate.
    #[error("a position is not finite")]
    NonFinite,
    /// Writing failed.
    #[error(transparent)]
    Io(#[from] io::Error),
}

/// How the estimate is aligned to the truth before the error is measured.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Alignment {
    /// Compare as given (both in the same world frame).
    None,
    /// Rigid SE(3) alignment by Umeyama's method (as `evo_ape --align`).
    Se3,
}

/// Translation error statistics \[m\].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ApeStats {
    /// Root mean square error.
    pub rmse: f64,
    /// Mean error.
    pub mean: f64,
    /// Largest error.
    pub max: f64,
}

/// The rigid transform T minimising Σ ‖T·src_i − dst_i‖² (Umeyama 1991, without scale).
///
/// # Errors
/// [`MetricsError::LengthMismatch`], [`MetricsError::TooFew`] for fewer than 3 points,
/// [`MetricsError::NonFinite`].
pub fn umeyama(src: &[Point3<f64>], dst: &[Point3<f64>]) -> Result<Isometry3<f64>, MetricsError> {
    check(src, dst, 3)?;
    #[allow(clippy::cast_precision_loss)]
    let n = src.len() as f64;
    let mu_s = src.iter().fold(Vector3::zeros(), |a, p| a + p.coords) / n;
    let mu_d = dst.iter().fold(Vector3::zeros(), |a, p| a + p.coords) / n;
    let mut cov = Matrix3::zeros();
    for (s, d) in src.iter().zip(dst) {
        cov += (d.coords - mu_d) * (s.coords - mu_s).transpose();
    }
    cov /= n;
    let svd = cov.svd(true, true);
    let (Some(u), Some(v_t)) = (svd.u, svd.v_t) else {
        return Ok(Isometry3::translation(
            mu_d.x - mu_s.x,
            mu_d.y - mu_s.y,
            mu_d.z - mu_s.z,
        ));
    };
    // Reflection guard: det(U Vᵀ) must be +1.
    let mut s = Matrix3::identity();
    if (u * v_t).determinant() < 0.0 {
        s[(2, 2)] = -1.0;
    }
    let r = u * s * v_t;
    let rotation = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(r));
    let t = mu_d - rotation * mu_s;
    Ok(Isometry3::from_parts(Translation3::from(t), rotation))
}

/// Absolute position error of `estimate` against `truth`, pose by pose.
///
/// # Errors
/// As [`umeyama`] for [`Alignment::Se3`]; otherwise length mismatch, no poses, NaN.
pub fn ape(
    truth: &[Point3<f64>],
    estimate: &[Point3<f64>],
    alignment: Alignment,
) -> Result<ApeStats, MetricsError> {
    check(truth, estimate, 1)?;
    let t = match alignment {
        Alignment::None => Isometry3::identity(),
        Alignment::Se3 => umeyama(estimate, truth)?,
    };
    let (mut sum2, mut sum, mut max) = (0.0, 0.0, 0.0f64);
    for (g, e) in truth.iter().zip(estimate) {
        let d = (t * e - g).norm();
        sum2 += d * d;
        sum += d;
        max = max.max(d);
    }
    #[allow(clippy::cast_precision_loss)]
    let n = truth.len() as f64;
    Ok(ApeStats {
        rmse: (sum2 / n).sqrt(),
        mean: sum / n,
        max,
    })
}

/// Length of a polyline \[m\].
pub fn trajectory_length(points: &[Point3<f64>]) -> f64 {
    points.windows(2).map(|w| (w[1] - w[0]).norm()).sum()
}

/// The first time a coverage series reaches `level` (same units as the series), or `None`
/// if it never does (a NaN `level` never is). Samples with a NaN time or coverage are passed
/// over.
///
/// A run's exploration time counts until its planner runs out of targets, which in a scene
/// with frontier no view clears (cells behind a surface, say) comes long after the scene is
/// seen; the time to 99 % compares how fast controllers see it.
///
/// # Example
/// ```
/// use fu_mpc_examples::metrics::time_to_coverage;
/// let series = [(0.0, 0.1), (1.0, 0.5), (2.0, 0.995), (3.0, 1.0)];
/// assert_eq!(time_to_coverage(&series, 0.99), Some(2.0));
/// assert_eq!(time_to_coverage(&series[..2], 0.99), None);
/// ```
pub fn time_to_coverage(series: &[(f64, f64)], level: f64) -> Option<f64> {
    series
        .iter()
        .find(|(t, c)| !t.is_nan() && *c >= level)
        .map(|&(t, _)| t)
}

/// Writes poses in the TUM format: `time tx ty tz qx qy qz qw`, one per line.
///
/// # Errors
/// [`MetricsError::LengthMismatch`] or an I/O error.
pub fn write_tum(
    out: &mut impl Write,
    times: &[f64],
    poses: &[Isometry3<f64>],
) -> Result<(), MetricsError> {
    if times.len() != poses.len() {
        return Err(MetricsError::LengthMismatch(times.len(), poses.len()));
    }
    for (t, p) in times.iter().zip(poses) {
        let v = p.translation.vector;
        let q = p.rotation.coords; // (x, y, z, w)
        writeln!(
            out,
            "{t:.6} {:.6} {:.6} {:.6} {:.9} {:.9} {:.9} {:.9}",
            v.x, v.y, v.z, q[0], q[1], q[2], q[3]
        )?;
    }
    Ok(())
}

fn check(a: &[Point3<f64>], b: &[Point3<f64>], needed: usize) -> Result<(), MetricsError> {
    if a.len() != b.len() {
        return Err(MetricsError::LengthMismatch(a.len(), b.len()));
    }
    if a.len() < needed {
        return Err(MetricsError::TooFew {
            needed,
            got: a.len(),
        });
    }
    if a.iter().chain(b).any(|p| !p.iter().all(|v| v.is_finite())) {
        return Err(MetricsError::NonFinite);
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn time_to_coverage_takes_the_first_sample_at_the_level() {
        let series = [
            (0.0, 0.2),
            (1.0, f64::NAN),
            (f64::NAN, 0.99),
            (2.0, 0.989),
            (3.0, 0.99),
            (4.0, 0.98),
            (5.0, 1.0),
        ];
        assert_eq!(time_to_coverage(&series, 0.99), Some(3.0));
        assert_eq!(time_to_coverage(&series, 1.0), Some(5.0));
        assert_eq!(time_to_coverage(&series, 0.1), Some(0.0));
        assert_eq!(time_to_coverage(&series, 1.5), None);
        assert_eq!(time_to_coverage(&[], 0.5), None);
        assert_eq!(time_to_coverage(&series, f64::NAN), None);
    }

    proptest! {
        #[test]
        fn umeyama_recovers_a_rigid_transform(
            pts in proptest::collection::vec((-10.0f64..10.0, -10.0f64..10.0, -10.0f64..10.0), 4..40),
            r in (-3.0f64..3.0, -1.5f64..1.5, -3.0f64..3.0),
            t in (-20.0f64..20.0, -20.0f64..20.0, -20.0f64..20.0),
        ) {
            let src: Vec<_> = pts.iter().map(|&(x, y, z)| Point3::new(x, y, z)).collect();
            // Points must span 3-D for a unique rotation.
            let c = src.iter().fold(Vector3::zeros(), |a, p| a + p.coords) / src.len() as f64;
            let cov = src.iter().fold(Matrix3::zeros(), |m, p| m + (p.coords - c) * (p.coords - c).transpose());
            let ev = cov.symmetric_eigenvalues();
            prop_assume!(ev.min() > 1e-3 * ev.max());
            let truth = Isometry3::from_parts(
                Translation3::new(t.0, t.1, t.2),
                UnitQuaternion::from_euler_angles(r.0, r.1, r.2),
            );
            let dst: Vec<_> = src.iter().map(|p| truth * p).collect();
            let est = umeyama(&src, &dst).unwrap();
            prop_assert!((est.translation.vector - truth.translation.vector).norm() < 1e-8);
            prop_assert!(est.rotation.angle_to(&truth.rotation) < 1e-8);
            // After alignment the error vanishes; against itself it is zero.
            prop_assert!(ape(&dst, &src, Alignment::Se3).unwrap().max < 1e-8);
            prop_assert_eq!(ape(&dst, &dst, Alignment::None).unwrap().max, 0.0);
        }
    }

    #[test]
    fn stats_and_errors() {
        let a = [Point3::origin(), Point3::new(1.0, 0.0, 0.0)];
        let b = [Point3::new(0.0, 0.3, 0.0), Point3::new(1.0, 0.0, 0.4)];
        let s = ape(&a, &b, Alignment::None).unwrap();
        assert!((s.max - 0.4).abs() < 1e-12);
        assert!((s.mean - 0.35).abs() < 1e-12);
        assert!((s.rmse - (0.125f64).sqrt()).abs() < 1e-12);
        assert!(matches!(
            ape(&a, &b[..1], Alignment::None),
            Err(MetricsError::LengthMismatch(2, 1))
        ));
        assert!(matches!(
            ape(&a, &b, Alignment::Se3),
            Err(MetricsError::TooFew { .. })
        ));
        assert!(matches!(
            ape(&[], &[], Alignment::None),
            Err(MetricsError::TooFew { .. })
        ));
        let nan = [Point3::new(f64::NAN, 0.0, 0.0), Point3::origin()];
        assert!(matches!(
            ape(&a, &nan, Alignment::None),
            Err(MetricsError::NonFinite)
        ));
        assert!((trajectory_length(&a) - 1.0).abs() < 1e-12);
    }

    #[test]
    fn tum_lines() {
        let mut out = Vec::new();
        let p = Isometry3::from_parts(Translation3::new(1.0, 2.0, 3.0), UnitQuaternion::identity());
        write_tum(&mut out, &[0.5], &[p]).unwrap();
        let s = String::from_utf8(out).unwrap();
        assert_eq!(
            s,
            "0.500000 1.000000 2.000000 3.000000 0.000000000 0.000000000 0.000000000 1.000000000\n"
        );
        assert!(write_tum(&mut Vec::new(), &[0.5, 1.0], &[p]).is_err());
    }
}
