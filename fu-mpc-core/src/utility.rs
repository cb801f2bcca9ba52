//! The frontier utility of equations (17)–(18) and its per-step piecewise-linear surrogates.

use core::f64::consts::{PI, TAU};

use lidar_kinematics::{KinematicChain, KinematicsError};
use nalgebra::{Isometry3, Point3, UnitQuaternion};

use crate::error::{invalid, too_large};
use crate::fastmath::{self, EXP_MIN};
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
    /// [`CoreError::InvalidConfig`] for σ or the distance gate not positive and finite (σ also
    /// with 2σ² a normal float: between about 1e-154 and 1e154 m), or an angular gate outside
    /// (0, π].
    pub fn validate(&self) -> Result<()> {
        // 2σ² must stay a positive finite number too: eq. (17) divides by it.
        let two_s2 = 2.0 * self.sigma * self.sigma;
        if !(self.sigma.is_finite() && self.sigma > 0.0 && two_s2.is_normal()) {
            return invalid(
                "sigma",
                self.sigma,
                "must be positive and finite, with 2 sigma^2 a normal float [m]",
            );
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
/// infinite target or pose (translation or rotation), a pose whose quaternion is not of unit
/// norm (to 1e-6, as the kinematic chain checks), a negative score, or scores so large
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
    let k = Constants::new(chain, config, knots);
    let (h, inv_h, cos_gate) = (k.h, k.inv_h, k.cos_gate);
    // Reuse the previous tables when their shape matches: no allocation per update.
    if out.len() != poses.len() || out.iter().any(|f| f.len() != knots) {
        out.clear();
        for _ in poses {
            out.push(PeriodicPwl::new(vec![0.0; knots])?);
        }
    }
    let mut block = Block::new();
    for (pose, table) in poses.iter().zip(out.iter_mut()) {
        let values = table.values_mut();
        if !(pose.translation.vector.iter().all(|v| v.is_finite())
            && pose.rotation.coords.iter().all(|v| v.is_finite()))
        {
            return Err(CoreError::NonFinite {
                what: "reference pose",
            });
        }
        // The same test as the kinematic chain's: a scaled quaternion is no rotation.
        let norm = pose.rotation.norm();
        if (norm - 1.0).abs() > 1e-6 {
            return Err(KinematicsError::NotUnitRotation {
                what: "reference pose",
                norm,
            }
            .into());
        }
        values.fill(0.0);
        let to_motor = (pose.rotation * k.motor_base)
            .inverse()
            .to_rotation_matrix();
        let m = to_motor.matrix();
        let frame = Frame {
            p: Point3::from(pose.translation.vector),
            rows: [
                [m[(0, 0)], m[(0, 1)], m[(0, 2)]],
                [m[(1, 0)], m[(1, 1)], m[(1, 2)]],
            ],
        };
        let mut total = 0.0;
        for chunk in targets.chunks(BLOCK) {
            let n = block.fill(chunk, &frame, &k, config.max_distance);
            for (j, t) in chunk.iter().enumerate().take(n) {
                let arg = block.arg[j];
                // Below EXP_MIN (or NaN) e^arg is subnormal, zero or NaN: libm's exp keeps
                // those exact.
                let r = if arg >= EXP_MIN {
                    block.r[j]
                } else {
                    arg.exp() * t.score // eq. (17)
                };
                total += r;
                let d = block.d[j];
                if d > config.max_distance || r == 0.0 {
                    continue;
                }
                if d == 0.0 {
                    // At the target: every direction sees it.
                    values.iter_mut().for_each(|x| *x += r);
                    continue;
                }
                // 0 < d ≤ max_distance here, so the angular quantities were computed.
                let s = block.slot[j];
                let rho = block.rho[s];
                if rho < cos_gate || rho == 0.0 {
                    continue;
                }
                let phi = block.phi[s];
                let delta = block.delta[s];
                // Knots within δ + h/2 of φ get a non-zero weight.
                let reach = delta + 0.5 * h;
                if reach >= PI {
                    add_everywhere(values, r, phi, delta, h);
                    continue;
                }
                add_arc(values, r, phi, delta, reach, inv_h);
            }
        }
        if !total.is_finite() {
            return Err(CoreError::NonFinite {
                what: "total frontier reward",
            });
        }
        let norm = if total > 0.0 { 1.0 / total } else { 0.0 };
        if norm.is_finite() {
            for x in values.iter_mut() {
                *x = (total - *x) * norm; // eq. (18)
            }
        } else {
            // A subnormal total has no finite reciprocal: divide, keeping J_k in [0, 1].
            for x in values.iter_mut() {
                *x = (total - *x) / total; // eq. (18)
            }
        }
    }
    Ok(())
}

/// The per-call constants of [`frontier_surrogates`].
struct Constants {
    /// Knot spacing h = 2π / N_c and its inverse.
    h: f64,
    inv_h: f64,
    /// Attitude of the motor base in the body frame.
    motor_base: UnitQuaternion<f64>,
    /// 2σ² of eq. (17).
    two_s2: f64,
    /// cos of the angular gate.
    cos_gate: f64,
}

impl Constants {
    fn new(chain: &KinematicChain, config: &UtilityConfig, knots: usize) -> Self {
        // Knot counts are far below 2^53.
        #[allow(clippy::cast_precision_loss)]
        let n = knots as f64;
        Self {
            h: TAU / n,
            inv_h: n / TAU,
            motor_base: chain.extrinsics().motor_base_in_body().rotation,
            two_s2: 2.0 * config.sigma * config.sigma,
            cos_gate: config.half_angle.cos(),
        }
    }
}

/// Targets per block of the per-target pass: its results live in stack arrays this long, so
/// a call allocates nothing for them.
const BLOCK: usize = 64;

/// One step's pose data for the per-target pass.
struct Frame {
    /// Position p_k.
    p: Point3<f64>,
    /// First two rows of the world-to-motor-base rotation: only u_x, u_y are needed.
    rows: [[f64; 3]; 2],
}

/// Per-target quantities of one step for a block of targets, structure-of-arrays so the
/// pass that fills them vectorises.
struct Block {
    /// Distance d to the target.
    d: [f64; BLOCK],
    /// Exponent −d²/2σ² of (17).
    arg: [f64; BLOCK],
    /// r = exp(arg) s, valid where arg ≥ [`EXP_MIN`].
    r: [f64; BLOCK],
    /// Length ρ of the in-plane part of the unit direction in the motor base frame (this and
    /// the next three are packed: target j's at `slot[j]`).
    rho: [f64; BLOCK],
    /// Azimuth φ of that direction (its x component u_x until the last loop).
    phi: [f64; BLOCK],
    /// Its y component u_y.
    uy: [f64; BLOCK],
    /// Half-width δ of the arc of motor angles that passes the angular gate (its cosine
    /// until the last loop).
    delta: [f64; BLOCK],
    /// Where target j's ρ, φ and δ are: the angular quantities are computed only for the
    /// targets within the distance gate, packed at the front of their arrays.
    slot: [usize; BLOCK],
}

impl Block {
    fn new() -> Self {
        Self {
            d: [0.0; BLOCK],
            arg: [0.0; BLOCK],
            r: [0.0; BLOCK],
            rho: [0.0; BLOCK],
            phi: [0.0; BLOCK],
            uy: [0.0; BLOCK],
            delta: [0.0; BLOCK],
            slot: [0; BLOCK],
        }
    }

    /// Fills the first `n = min(chunk.len(), BLOCK)` entries, returning `n`: d and r for
    /// every target, ρ, φ and δ (at `slot[j]`) for those with 0 < d ≤ `max_distance`, the
    /// only ones the gates can pass (in a large map most targets are beyond the distance gate
    /// and count only in R_total). Branch-free passes (NaN where ρ = 0; the caller's gates
    /// decide which values are used), each with shorter dependency chains than one loop
    /// would have, so more iterations overlap.
    fn fill(
        &mut self,
        chunk: &[FrontierTarget],
        f: &Frame,
        k: &Constants,
        max_distance: f64,
    ) -> usize {
        let n = chunk.len().min(BLOCK);
        let chunk = &chunk[..n];
        // The offset c − p goes into ρ, φ, u_y and d into δ until they are packed.
        for j in 0..n {
            let t = &chunk[j];
            let vx = t.center.x - f.p.x;
            let vy = t.center.y - f.p.y;
            let vz = t.center.z - f.p.z;
            // The operation order of nalgebra's `norm` and `Rotation3 * Vector3`: the gates
            // compare bit for bit the numbers they always have.
            let d = ((vx * vx + vy * vy) + vz * vz).sqrt();
            let arg = -d * d / k.two_s2;
            self.d[j] = d;
            self.arg[j] = arg;
            let arg_in = if arg >= EXP_MIN { arg } else { EXP_MIN };
            self.r[j] = fastmath::exp_in_range(arg_in) * t.score; // eq. (17)
            self.rho[j] = vx;
            self.phi[j] = vy;
            self.uy[j] = vz;
            self.delta[j] = d;
        }
        let gated = |d: f64| (d.is_nan() || d <= max_distance) && d != 0.0;
        let mut m = self.d[..n].iter().filter(|&&d| gated(d)).count();
        if 4 * m >= 3 * n {
            // Mostly within the gate: packing would cost more than it saves; every target
            // gets the angular quantities, in place.
            m = n;
            for (j, s) in self.slot[..n].iter_mut().enumerate() {
                *s = j;
            }
        } else {
            // Packing in place: slot[j] ≤ j, so no entry is overwritten before it is moved.
            m = 0;
            for j in 0..n {
                self.slot[j] = m;
                self.rho[m] = self.rho[j];
                self.phi[m] = self.phi[j];
                self.uy[m] = self.uy[j];
                self.delta[m] = self.delta[j];
                m += usize::from(gated(self.d[j]));
            }
        }
        let [a, b] = f.rows;
        let (rho, phi) = (&mut self.rho[..m], &mut self.phi[..m]);
        let (uy, delta) = (&mut self.uy[..m], &mut self.delta[..m]);
        for i in 0..m {
            let d = delta[i];
            // Direction in the motor base frame: d_k(θ) = (cos θ, sin θ, 0) there, so
            // cos∠ = ρ cos(θ − φ) with ρ the length of the in-plane part.
            let (wx, wy, wz) = (rho[i] / d, phi[i] / d, uy[i] / d);
            let ux = (a[0] * wx + a[1] * wy) + a[2] * wz;
            let vy = (b[0] * wx + b[1] * wy) + b[2] * wz;
            let r = (ux * ux + vy * vy).sqrt();
            rho[i] = r;
            phi[i] = ux;
            uy[i] = vy;
            delta[i] = (k.cos_gate / r).clamp(-1.0, 1.0);
        }
        for i in 0..m {
            phi[i] = fastmath::atan2(uy[i], phi[i]);
            delta[i] = fastmath::acos(delta[i]);
        }
        n
    }
}

/// Adds r · clamp(c0 − |k − φ/h|, 0, 1), c0 = ½ + δ/h, to the knots k h ∈ [φ − reach,
/// φ + reach] (indices wrapped into the table): the smoothed gate in units of the knot
/// spacing, no division per knot. Needs reach < π.
fn add_arc(values: &mut [f64], r: f64, phi: f64, delta: f64, reach: f64, inv_h: f64) {
    let knots = values.len();
    let centre = phi * inv_h;
    let c0 = 0.5 + delta * inv_h;
    let first = ceil_i32((phi - reach) * inv_h);
    let last = floor_i32((phi + reach) * inv_h);
    let Ok(n) = i32::try_from(knots) else {
        return;
    };
    // |φ ± reach| < 2π, so −N_c ≤ first and last ≤ N_c: the bounds never reject finite
    // φ, δ; they keep the index arithmetic below in range.
    if last < first || first < -n || last > n {
        return;
    }
    // Knot index of `first`, wrapped into [0, N_c) by a compare, not a division.
    let mut c = if first < 0 {
        first + n
    } else if first >= n {
        first - n
    } else {
        first
    }
    .unsigned_abs() as usize;
    let mut k = first;
    let mut left = (last - first).unsigned_abs() as usize + 1;
    // Contiguous runs up to the table's end, then from index 0: no wrap test per knot.
    while left > 0 && c < knots {
        let run = left.min(knots - c);
        for (i, x) in (0..).zip(values[c..c + run].iter_mut()) {
            // |k h − φ| ≤ δ + h/2 < π here, so the offset needs no wrapping.
            let kf = f64::from(k + i);
            *x += r * (c0 - (kf - centre).abs()).clamp(0.0, 1.0);
        }
        left -= run;
        // run ≤ N_c, which fits i32.
        #[allow(clippy::cast_possible_truncation, clippy::cast_possible_wrap)]
        let step = run as i32;
        k += step;
        c = 0;
    }
}

/// ⌈x⌉ for |x| < 2^31 without a library call (no SSE4.1 `roundsd` in the baseline target).
#[inline]
fn ceil_i32(x: f64) -> i32 {
    #[allow(clippy::cast_possible_truncation)]
    let t = x as i32;
    if f64::from(t) < x {
        t.saturating_add(1)
    } else {
        t
    }
}

/// ⌊x⌋ for |x| < 2^31 without a library call.
#[inline]
fn floor_i32(x: f64) -> i32 {
    #[allow(clippy::cast_possible_truncation)]
    let t = x as i32;
    if f64::from(t) > x {
        t.saturating_sub(1)
    } else {
        t
    }
}

/// Adds r times the smoothed gate at every knot: the arc δ + h/2 reaches all the way round.
fn add_everywhere(values: &mut [f64], r: f64, phi: f64, delta: f64, h: f64) {
    for (c, x) in values.iter_mut().enumerate() {
        // Knot counts are far below 2^53.
        #[allow(clippy::cast_precision_loss)]
        let th = c as f64 * h;
        *x += r * weight(th, phi, delta, h);
    }
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

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use lidar_kinematics::Extrinsics;
    use nalgebra::Translation3;
    use proptest::prelude::*;

    /// The libm-based implementation the inline kernels replaced, kept to compare against.
    fn reference_surrogates(
        chain: &KinematicChain,
        poses: &[Isometry3<f64>],
        targets: &[FrontierTarget],
        config: &UtilityConfig,
        knots: usize,
    ) -> Vec<Vec<f64>> {
        let k = Constants::new(chain, config, knots);
        let (h, inv_h, two_s2, cos_gate) = (k.h, k.inv_h, k.two_s2, k.cos_gate);
        let mut out = Vec::new();
        for pose in poses {
            let mut values = vec![0.0; knots];
            let to_motor = (pose.rotation * k.motor_base)
                .inverse()
                .to_rotation_matrix();
            let p = Point3::from(pose.translation.vector);
            let mut total = 0.0;
            for t in targets {
                let v = t.center - p;
                let d = v.norm();
                let r = (-d * d / two_s2).exp() * t.score;
                total += r;
                if d > config.max_distance || r == 0.0 {
                    continue;
                }
                if d == 0.0 {
                    values.iter_mut().for_each(|x| *x += r);
                    continue;
                }
                let u = to_motor * (v / d);
                let rho = (u.x * u.x + u.y * u.y).sqrt();
                if rho < cos_gate || rho == 0.0 {
                    continue;
                }
                let phi = u.y.atan2(u.x);
                let delta = (cos_gate / rho).clamp(-1.0, 1.0).acos();
                let reach = delta + 0.5 * h;
                if reach >= PI {
                    add_everywhere(&mut values, r, phi, delta, h);
                    continue;
                }
                arc_per_knot(&mut values, r, phi, delta, reach, inv_h);
            }
            let norm = if total > 0.0 { 1.0 / total } else { 0.0 };
            for x in &mut values {
                *x = (total - *x) * norm;
            }
            out.push(values);
        }
        out
    }

    fn pose_strategy() -> impl Strategy<Value = Isometry3<f64>> {
        (
            (-10.0f64..10.0, -10.0f64..10.0, -3.0f64..3.0),
            (-PI..PI, -PI..PI, -PI..PI),
        )
            .prop_map(|((x, y, z), (roll, pitch, yaw))| {
                Isometry3::from_parts(
                    Translation3::new(x, y, z),
                    UnitQuaternion::from_euler_angles(roll, pitch, yaw),
                )
            })
    }

    /// (x, y, z, score, placement): placement 0 puts the target on the first pose (d = 0),
    /// 1 gives it a zero score, anything else leaves it as drawn.
    type RawTarget = (f64, f64, f64, f64, u8);

    fn config_strategy() -> impl Strategy<Value = UtilityConfig> {
        (
            -3.0f64..2.0,
            0.1f64..40.0,
            prop_oneof![1e-4f64..=PI, Just(PI), Just(FRAC_PI_2)],
        )
            .prop_map(|(log_sigma, max_distance, half_angle)| UtilityConfig {
                sigma: 10f64.powf(log_sigma),
                max_distance,
                half_angle,
            })
    }

    use core::f64::consts::FRAC_PI_2;

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(512))]

        #[test]
        fn matches_the_libm_reference(
            poses in proptest::collection::vec(pose_strategy(), 1..4),
            raw in proptest::collection::vec(
                (-150.0f64..150.0, -60.0f64..60.0, -8.0f64..8.0, 0.0f64..100.0, 0u8..12),
                0..=200,
            ),
            config in config_strategy(),
            knots in 1usize..=100,
            mount_roll in -PI..PI,
            mount_pitch in -0.5f64..0.5,
        ) {
            let mount = Isometry3::from_parts(
                Translation3::new(0.05, 0.0, 0.1),
                UnitQuaternion::from_euler_angles(mount_roll, mount_pitch, 0.0),
            );
            let chain = KinematicChain::new(Extrinsics::try_new(Isometry3::identity(), mount).unwrap());
            let p0 = poses[0].translation.vector;
            let targets: Vec<FrontierTarget> = raw
                .iter()
                .map(|&(x, y, z, s, placement): &RawTarget| match placement {
                    0 => FrontierTarget { center: Point3::from(p0), score: s },
                    1 => FrontierTarget { center: Point3::new(x, y, z), score: 0.0 },
                    _ => FrontierTarget { center: Point3::new(x, y, z), score: s },
                })
                .collect();
            let mut out = Vec::new();
            frontier_surrogates(&chain, &poses, &targets, &config, knots, &mut out).unwrap();
            let want = reference_surrogates(&chain, &poses, &targets, &config, knots);
            prop_assert_eq!(out.len(), want.len());
            for (k, (got, want)) in out.iter().zip(&want).enumerate() {
                prop_assert_eq!(got.len(), knots);
                for (c, (g, w)) in got.values().iter().zip(want).enumerate() {
                    if w.is_finite() {
                        prop_assert!((g - w).abs() <= 1e-12, "step {} knot {}: {} vs {}", k, c, g, w);
                    } else {
                        // The reference overflows 1/R_total for a subnormal total.
                        prop_assert!((-1e-12..=1.0 + 1e-12).contains(g), "step {} knot {}: {}", k, c, g);
                    }
                }
            }
        }
    }

    /// The knot loop `add_arc` replaced: float `ceil`/`floor` and a division for the wrap.
    fn arc_per_knot(values: &mut [f64], r: f64, phi: f64, delta: f64, reach: f64, inv_h: f64) {
        let knots = values.len();
        let centre = phi * inv_h;
        let c0 = 0.5 + delta * inv_h;
        let first = ((phi - reach) * inv_h).ceil();
        let last = ((phi + reach) * inv_h).floor();
        #[allow(clippy::cast_possible_truncation)]
        let mut c = (first as i64).rem_euclid(knots as i64) as usize;
        let mut k = first;
        while k <= last {
            values[c] += r * (c0 - (k - centre).abs()).clamp(0.0, 1.0);
            k += 1.0;
            c += 1;
            if c == knots {
                c = 0;
            }
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(2048))]

        #[test]
        fn arc_matches_the_per_knot_loop_bit_for_bit(
            knots in prop_oneof![1usize..=100, 1usize..=crate::MAX_KNOTS],
            phi in -PI..=PI,
            frac in 0.0f64..=1.0,
            r in 1e-3f64..1e3,
        ) {
            #[allow(clippy::cast_precision_loss)]
            let h = TAU / knots as f64;
            #[allow(clippy::cast_precision_loss)]
            let inv_h = knots as f64 / TAU;
            let delta = frac * PI;
            let reach = delta + 0.5 * h;
            prop_assume!(reach < PI);
            let base: Vec<f64> = (0..knots).map(|c| (c % 7) as f64 * 0.25).collect();
            let mut got = base.clone();
            let mut want = base;
            add_arc(&mut got, r, phi, delta, reach, inv_h);
            arc_per_knot(&mut want, r, phi, delta, reach, inv_h);
            for (c, (g, w)) in got.iter().zip(&want).enumerate() {
                prop_assert_eq!(g.to_bits(), w.to_bits(), "knot {}: {} vs {}", c, g, w);
            }
        }
    }

    #[test]
    fn arc_edges() {
        // The arc ends exactly on knots, on both sides of θ = 0, and at φ = ±π.
        for knots in [2usize, 3, 4, 5, 8, 72, 100] {
            #[allow(clippy::cast_precision_loss)]
            let h = TAU / knots as f64;
            #[allow(clippy::cast_precision_loss)]
            let inv_h = knots as f64 / TAU;
            for phi in [-PI, -PI + 1e-15, -0.5 * h, 0.0, 0.5 * h, h, PI - 1e-15, PI] {
                for delta in [0.0, 0.5 * h, h, 2.0 * h, 2.5 * h, PI - h] {
                    let reach = delta + 0.5 * h;
                    if reach >= PI {
                        continue;
                    }
                    let mut got = vec![0.0; knots];
                    let mut want = vec![0.0; knots];
                    add_arc(&mut got, 1.5, phi, delta, reach, inv_h);
                    arc_per_knot(&mut want, 1.5, phi, delta, reach, inv_h);
                    assert_eq!(got, want, "{knots} {phi} {delta}");
                }
            }
        }
    }

    #[test]
    fn exponents_outside_the_fast_range() {
        let chain = KinematicChain::default();
        let pose = [Isometry3::identity()];
        let at = |x: f64| FrontierTarget {
            center: Point3::new(x, 0.0, 0.0),
            score: 1.0,
        };
        let mut out = Vec::new();
        // A σ whose 2σ² underflows is refused up front (−0/0 at a target would be NaN).
        let tiny = UtilityConfig {
            sigma: 1e-200,
            ..UtilityConfig::default()
        };
        for x in [1.0, 0.0] {
            let got = frontier_surrogates(&chain, &pose, &[at(x)], &tiny, 8, &mut out);
            assert!(matches!(got, Err(CoreError::InvalidConfig { .. })));
        }
        // The smallest σ accepted: r = 0 away from the target (−d²/2σ² = −∞ or far below
        // the exponent's range), the whole reward at it.
        let least = UtilityConfig {
            sigma: 1e-150,
            ..UtilityConfig::default()
        };
        frontier_surrogates(&chain, &pose, &[at(1.0)], &least, 8, &mut out).unwrap();
        assert!(out[0].values().iter().all(|v| *v == 0.0));
        // Subnormal r only (d²/2σ² ≈ 730): exact through libm, and J stays in [0, 1].
        let small = UtilityConfig {
            sigma: 0.1,
            ..UtilityConfig::default()
        };
        let far = [at(3.82), at(-3.83)];
        frontier_surrogates(&chain, &pose, &far, &small, 8, &mut out).unwrap();
        assert!(out[0].values().iter().all(|v| (0.0..=1.0).contains(v)));
        let want = reference_surrogates(&chain, &pose, &far, &small, 8);
        for (g, w) in out[0].values().iter().zip(&want[0]) {
            assert!(!w.is_finite() || (g - w).abs() <= 1e-12);
        }
    }

    #[test]
    fn integer_rounding() {
        for x in [
            -3.5, -3.0, -2.9, -0.5, -0.0, 0.0, 0.5, 2.0, 2.1, 16384.0, -16384.0,
        ] {
            assert!((f64::from(ceil_i32(x)) - x.ceil()).abs() < 0.5, "{x}");
            assert!((f64::from(floor_i32(x)) - x.floor()).abs() < 0.5, "{x}");
        }
        // Out of range or NaN: saturated or zero, no overflow.
        assert_eq!(ceil_i32(1e300), i32::MAX);
        assert_eq!(floor_i32(-1e300), i32::MIN);
        assert_eq!(ceil_i32(f64::NAN), 0);
    }
}
