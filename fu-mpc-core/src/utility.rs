//! The frontier utility of equations (17)–(18) and its per-step piecewise-linear surrogates.

use core::f64::consts::{PI, TAU};

use lidar_kinematics::KinematicChain;
use nalgebra::{Isometry3, Point3};

use crate::error::{invalid, too_large};
use crate::{CoreError, PeriodicPwl, Result};

/// A frontier target for the scan controller: a cluster centre and its intensity score.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrontierTarget {
    /// Cluster centre c_i in the world frame \[m\].
    pub center: Point3<f64>,
    /// Intensity score s_i ≥ 0 (e.g. the cluster's frontier cell count).
    pub score: f64,
}

/// Gates and decay of the frontier utility.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct UtilityConfig {
    /// σ of the distance decay exp(−d²/2σ²), eq. (17) \[m\]; default 5 m, the scale of the
    /// viewpoint distances a frontier is seen from.
    pub sigma: f64,
    /// Distance gate: targets farther than this are not visible \[m\]; default 15 m.
    pub max_distance: f64,
    /// Angular gate: largest angle between the scan direction d_k and the direction to a
    /// target \[rad\]; default 30°.
    pub half_angle: f64,
}

impl Default for UtilityConfig {
    fn default() -> Self {
        Self {
            sigma: 5.0,
            max_distance: 15.0,
            half_angle: 30f64.to_radians(),
        }
    }
}

impl UtilityConfig {
    /// Checks every setting.
    ///
    /// # Errors
    /// [`CoreError::InvalidConfig`] for σ or the distance gate not positive and finite, or an
    /// angular gate outside (0, π].
    pub fn validate(&self) -> Result<()> {
        if !(self.sigma.is_finite() && self.sigma > 0.0) {
            return invalid("sigma", self.sigma, "must be positive and finite [m]");
        }
        if !(self.max_distance.is_finite() && self.max_distance > 0.0) {
            return invalid(
                "max_distance",
                self.max_distance,
                "must be positive and finite [m]",
            );
        }
        if !(self.half_angle > 0.0 && self.half_angle <= PI) {
            return invalid("half_angle", self.half_angle, "must be in (0, pi] [rad]");
        }
        Ok(())
    }
}

/// Builds the per-step surrogates J_k(θ), k = 0..poses.len(), on `knots` uniformly spaced
/// motor angles, into `out` (refilled in place when its shape already fits, so a controller
/// that calls this every cycle does not allocate).
///
/// At step k a target is visible when d_{k,i} = ‖p_k − c_i‖ passes the distance gate and the
/// angle between the scan direction d_k(θ) of (14) and c_i − p_k passes the angular gate;
/// then it contributes r_{k,i} = exp(−d²/2σ²) s_i, eq. (17). J_k(θ) = R_total − Σ_visible r,
/// eq. (18), with R_total = Σ_i r_{k,i} over all targets. The gate's edge is smoothed over one
/// grid cell h = 2π/N_c: a target counts with weight clamp(½ + (δ − |θ − φ|)/h, 0, 1), where
/// [φ − δ, φ + δ] is the arc of motor angles that passes the angular gate. The knot values are
/// divided by R_total when it is positive, so J_k ∈ [0, 1] and the weights α, β of (19) do
/// not depend on the scale of the scores.
///
/// # Errors
/// An invalid `config`, no knots or more than [`MAX_KNOTS`](crate::MAX_KNOTS), a NaN or
/// infinite target or pose (translation or rotation), a negative score, or scores so large
/// that their sum overflows. On error `out` may hold partial tables.
pub fn frontier_surrogates(
    chain: &KinematicChain,
    poses: &[Isometry3<f64>],
    targets: &[FrontierTarget],
    config: &UtilityConfig,
    knots: usize,
    out: &mut Vec<PeriodicPwl>,
) -> Result<()> {
    config.validate()?;
    if knots == 0 {
        return Err(CoreError::Empty {
            what: "surrogate knots",
        });
    }
    if knots > crate::MAX_KNOTS {
        return too_large("surrogate knots", knots, "at most MAX_KNOTS");
    }
    for t in targets {
        if !(t.center.iter().all(|v| v.is_finite()) && t.score.is_finite()) {
            return Err(CoreError::NonFinite {
                what: "frontier target",
            });
        }
        if t.score < 0.0 {
            return invalid("target score", t.score, "must be >= 0");
        }
    }
    // Knot counts are far below 2^53.
    #[allow(clippy::cast_precision_loss)]
    let h = TAU / knots as f64;
    #[allow(clippy::cast_precision_loss)]
    let inv_h = knots as f64 / TAU;
    let motor_base = chain.extrinsics().motor_base_in_body().rotation;
    let two_s2 = 2.0 * config.sigma * config.sigma;
    let cos_gate = config.half_angle.cos();
    // Reuse the previous tables when their shape matches: no allocation per update.
    if out.len() != poses.len() || out.iter().any(|f| f.len() != knots) {
        out.clear();
        for _ in poses {
            out.push(PeriodicPwl::new(vec![0.0; knots])?);
        }
    }
    for (pose, table) in poses.iter().zip(out.iter_mut()) {
        let values = table.values_mut();
        if !(pose.translation.vector.iter().all(|v| v.is_finite())
            && pose.rotation.coords.iter().all(|v| v.is_finite()))
        {
            return Err(CoreError::NonFinite {
                what: "reference pose",
            });
        }
        values.fill(0.0);
        let to_motor = (pose.rotation * motor_base).inverse().to_rotation_matrix();
        let p = Point3::from(pose.translation.vector);
        let mut total = 0.0;
        for t in targets {
            let v = t.center - p;
            let d = v.norm();
            let r = (-d * d / two_s2).exp() * t.score; // eq. (17)
            total += r;
            if d > config.max_distance || r == 0.0 {
                continue;
            }
            if d == 0.0 {
                // At the target: every direction sees it.
                values.iter_mut().for_each(|x| *x += r);
                continue;
            }
            // Direction in the motor base frame: d_k(θ) = (cos θ, sin θ, 0) there, so
            // cos∠ = ρ cos(θ − φ) with ρ the length of the in-plane part.
            let u = to_motor * (v / d);
            let rho = (u.x * u.x + u.y * u.y).sqrt();
            if rho < cos_gate || rho == 0.0 {
                continue;
            }
            let phi = u.y.atan2(u.x);
            let delta = (cos_gate / rho).clamp(-1.0, 1.0).acos();
            // Knots within δ + h/2 of φ get a non-zero weight.
            let reach = delta + 0.5 * h;
            if reach >= PI {
                for (c, x) in values.iter_mut().enumerate() {
                    #[allow(clippy::cast_precision_loss)]
                    let th = c as f64 * h;
                    *x += r * weight(th, phi, delta, h);
                }
                continue;
            }
            // In units of the knot spacing the smoothed gate is clamp(c0 − |c − φ/h|, 0, 1):
            // no division per knot.
            let centre = phi * inv_h;
            let c0 = 0.5 + delta * inv_h;
            let first = ((phi - reach) * inv_h).ceil();
            let last = ((phi + reach) * inv_h).floor();
            // Knot index of `first`, wrapped into [0, knots) once; the loop then steps it with
            // a compare instead of a division per knot. |first| ≤ knots, so the cast is exact.
            #[allow(clippy::cast_possible_truncation)]
            let mut c = (first as i64).rem_euclid(knots as i64) as usize;
            let mut k = first;
            while k <= last {
                // |k h − φ| ≤ δ + h/2 < π here, so the offset needs no wrapping.
                values[c] += r * (c0 - (k - centre).abs()).clamp(0.0, 1.0);
                k += 1.0;
                c += 1;
                if c == knots {
                    c = 0;
                }
            }
        }
        if !total.is_finite() {
            return Err(CoreError::NonFinite {
                what: "total frontier reward",
            });
        }
        let norm = if total > 0.0 { 1.0 / total } else { 0.0 };
        for x in values.iter_mut() {
            *x = (total - *x) * norm; // eq. (18)
        }
    }
    Ok(())
}

/// The smoothed angular gate: 1 inside the arc, 0 beyond it, linear over one cell at its edge.
#[inline]
fn weight(theta: f64, phi: f64, delta: f64, h: f64) -> f64 {
    let off = (theta - phi + PI).rem_euclid(TAU) - PI;
    gate(off.abs(), delta, h)
}

/// The smoothed gate at angular offset `off` ∈ [0, π] from the arc's centre.
#[inline]
fn gate(off: f64, delta: f64, h: f64) -> f64 {
    (0.5 + (delta - off) / h).clamp(0.0, 1.0)
}
