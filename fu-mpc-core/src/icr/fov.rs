//! The differentiable field of view of iCR: signed distance functions and the probit, eqs.
//! (18)–(21) and the appendix (Lemma 2, eqs. (29)–(31)).

use core::f64::consts::PI;

use nalgebra::{Vector2, Vector3};

use crate::Result;
use crate::error::invalid;

/// A field of view with a signed distance function in the body frame, eq. (18): negative
/// inside, positive outside, with its gradient.
pub trait FovSdf: Sync {
    /// The signed distance d(q) \[m\] of the body-frame point `q` and its gradient ∂d/∂q.
    ///
    /// Where d is not differentiable (on a ridge between two closest features) the gradient
    /// of one of them is returned; non-finite input gives a non-finite distance.
    fn sdf(&self, q: &Vector3<f64>) -> (f64, Vector3<f64>);
}

/// The 2-D field of view of the paper's experiment: the isosceles triangle with its apex at the
/// origin, its axis along +x, height `h` and legs at ±ψ (the cone of the appendix projected on
/// z = 0). Its SDF acts on (q_x, q_y); q_z is ignored.
///
/// # Example
/// ```
/// use fu_mpc_core::icr::{FovSdf, Triangle};
/// use nalgebra::Vector3;
///
/// let fov = Triangle::new(3.0, 30f64.to_radians()).unwrap(); // 3 m high, 60° opening
/// let (inside, _) = fov.sdf(&Vector3::new(2.0, 0.0, 0.0));
/// let (outside, grad) = fov.sdf(&Vector3::new(4.0, 0.0, 0.0));
/// assert!((inside + 1.0).abs() < 1e-12); // 1 m from the base
/// assert!((outside - 1.0).abs() < 1e-12 && (grad.x - 1.0).abs() < 1e-12);
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Triangle {
    height: f64,
    half_angle: f64,
    /// Unit outward normals and offsets of the two legs and the base: n·q + b ≤ 0 inside.
    normals: [Vector2<f64>; 3],
    offsets: [f64; 3],
    /// The corners: apex, upper base corner, lower base corner.
    corners: [Vector2<f64>; 3],
    /// The edges (start, direction, 1/length²): apex→upper, lower→apex, upper→lower.
    edges: [(Vector2<f64>, Vector2<f64>, f64); 3],
}

impl Triangle {
    /// The triangle of height `height` \[m\] and half opening angle `half_angle` \[rad\].
    ///
    /// # Errors
    /// [`CoreError::InvalidConfig`](crate::CoreError::InvalidConfig) unless the height is
    /// positive and finite and 0 < ψ < π/2.
    pub fn new(height: f64, half_angle: f64) -> Result<Self> {
        if !(height.is_finite() && height > 0.0) {
            return invalid("height", height, "must be positive and finite");
        }
        if !(half_angle > 0.0 && half_angle < 0.5 * PI) {
            return invalid("half_angle", half_angle, "must lie in (0, pi/2)");
        }
        let (s, c) = half_angle.sin_cos();
        // eq. (30)–(31), normalised: a₁ = (−1, 1/tan ψ), a₂ = (−1, −1/tan ψ), a₃ = (1, 0).
        let normals = [
            Vector2::new(-s, c),
            Vector2::new(-s, -c),
            Vector2::new(1.0, 0.0),
        ];
        let offsets = [0.0, 0.0, -height];
        let w = height * half_angle.tan();
        let corners = [
            Vector2::zeros(),
            Vector2::new(height, w),
            Vector2::new(height, -w),
        ];
        let edges = [(0, 1), (2, 0), (1, 2)].map(|(a, b): (usize, usize)| {
            let e = corners[b] - corners[a];
            (corners[a], e, 1.0 / e.norm_squared())
        });
        Ok(Self {
            height,
            half_angle,
            normals,
            offsets,
            corners,
            edges,
        })
    }

    /// Height h \[m\].
    pub fn height(&self) -> f64 {
        self.height
    }

    /// Half opening angle ψ \[rad\].
    pub fn half_angle(&self) -> f64 {
        self.half_angle
    }

    /// The 2-D signed distance and gradient, eq. (29).
    #[inline]
    pub fn sdf2(&self, q: &Vector2<f64>) -> (f64, Vector2<f64>) {
        let side: [f64; 3] = core::array::from_fn(|i| self.normals[i].dot(q) + self.offsets[i]);
        if side.iter().all(|s| *s <= 0.0) {
            // Inside (D_i of Lemma 2 with a non-positive sign): the nearest edge.
            let mut best = 0;
            for i in 1..3 {
                if side[i] > side[best] {
                    best = i;
                }
            }
            return (side[best], self.normals[best]);
        }
        // Outside. The distance is at least every positive side value (the triangle lies in
        // each half-plane), so an edge the point is outside of whose foot lies on it is the
        // nearest feature (D_i of Lemma 2): no square root needed.
        for (i, (p, e, inv_len2)) in self.edges.iter().enumerate() {
            if side[i] > 0.0 {
                let t = (q - p).dot(e) * inv_len2;
                if (0.0..=1.0).contains(&t) {
                    return (side[i], self.normals[i]);
                }
            }
        }
        // Otherwise the nearest corner (P_i).
        let mut best = (f64::INFINITY, Vector2::zeros());
        for c in &self.corners {
            let diff = q - c;
            let d2 = diff.norm_squared();
            if d2 < best.0 {
                best = (d2, diff);
            }
        }
        let (d, diff) = (best.0.sqrt(), best.1);
        if d > 0.0 {
            (d, diff / d)
        } else {
            (d, Vector2::zeros())
        }
    }
}

impl FovSdf for Triangle {
    #[inline]
    fn sdf(&self, q: &Vector3<f64>) -> (f64, Vector3<f64>) {
        let (d, g) = self.sdf2(&Vector2::new(q.x, q.y));
        (d, Vector3::new(g.x, g.y, 0.0))
    }
}

/// A 3-D field of view: the solid cone with its apex at the origin, its axis along +x, height
/// `h` and half angle ψ, closed by a flat base (the cone F_c of the appendix).
///
/// Its SDF is that of the triangle in the meridian half-plane (x, ρ = √(y² + z²)), since the
/// nearest boundary point lies in the plane through the axis and q. On the axis (ρ = 0) the
/// distance has a ridge; the gradient there is taken along x only.
///
/// # Example
/// ```
/// use fu_mpc_core::icr::{Cone, FovSdf};
/// use nalgebra::Vector3;
///
/// let fov = Cone::new(10.0, 35f64.to_radians()).unwrap();
/// assert!(fov.sdf(&Vector3::new(5.0, 1.0, 1.0)).0 < 0.0);
/// assert!(fov.sdf(&Vector3::new(-1.0, 0.0, 0.0)).0 > 0.0);
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Cone {
    section: Triangle,
}

impl Cone {
    /// The cone of height `height` \[m\] and half angle `half_angle` \[rad\].
    ///
    /// # Errors
    /// As [`Triangle::new`].
    pub fn new(height: f64, half_angle: f64) -> Result<Self> {
        Ok(Self {
            section: Triangle::new(height, half_angle)?,
        })
    }

    /// Height h \[m\].
    pub fn height(&self) -> f64 {
        self.section.height
    }

    /// Half angle ψ \[rad\].
    pub fn half_angle(&self) -> f64 {
        self.section.half_angle
    }
}

impl FovSdf for Cone {
    #[inline]
    fn sdf(&self, q: &Vector3<f64>) -> (f64, Vector3<f64>) {
        let rho = q.y.hypot(q.z);
        let (d, g) = self.section.sdf2(&Vector2::new(q.x, rho));
        let radial = if rho > 0.0 {
            Vector2::new(q.y, q.z) / rho * g.y
        } else {
            Vector2::zeros()
        };
        (d, Vector3::new(g.x, radial.x, radial.y))
    }
}

/// The shifted probit of eq. (20): Φ(x) = ½ [1 + erf(x / √(2κ) − 2)], a smooth step with
/// Φ(0) ≈ 0.002 that tends to the unit step as κ → 0.
///
/// # Example
/// ```
/// use fu_mpc_core::icr::Probit;
///
/// let phi = Probit::new(0.5).unwrap();
/// assert!((phi.value(0.0) - 0.00234).abs() < 1e-5);
/// assert!(phi.value(10.0) > 0.999_999);
/// ```
#[derive(Clone, Copy)]
pub struct Probit {
    kappa: f64,
    inv_scale: f64,
    /// The shared table of ½ erfc, fetched once here rather than per evaluation.
    table: &'static [(f64, f64)],
}

impl core::fmt::Debug for Probit {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("Probit")
            .field("kappa", &self.kappa)
            .finish()
    }
}

impl PartialEq for Probit {
    fn eq(&self, other: &Self) -> bool {
        self.kappa == other.kappa
    }
}

impl Probit {
    /// The probit with smoothing κ > 0 \[m²\].
    ///
    /// # Errors
    /// [`CoreError::InvalidConfig`](crate::CoreError::InvalidConfig) unless κ is positive and
    /// finite.
    pub fn new(kappa: f64) -> Result<Self> {
        if !(kappa.is_finite() && kappa > 0.0) {
            return invalid("kappa", kappa, "must be positive and finite");
        }
        Ok(Self {
            kappa,
            inv_scale: 1.0 / (2.0 * kappa).sqrt(),
            table: erfc_table(),
        })
    }

    /// κ \[m²\].
    pub fn kappa(&self) -> f64 {
        self.kappa
    }

    /// Φ(x), eq. (20).
    pub fn value(&self, x: f64) -> f64 {
        0.5 * (1.0 + libm::erf(x * self.inv_scale - 2.0))
    }

    /// Φ(x) and Φ′(x) = exp(−(x/√(2κ) − 2)²) / √(2πκ).
    pub fn value_and_slope(&self, x: f64) -> (f64, f64) {
        let y = x * self.inv_scale - 2.0;
        let slope = self.inv_scale / PI.sqrt() * (-y * y).exp();
        (0.5 * (1.0 + libm::erf(y)), slope)
    }

    /// V⁻¹_jj of eq. (21) for noise σ: (1 − Φ(d)) / σ², and its slope in d.
    ///
    /// 1 − Φ = ½ erfc(y) with y = d/√(2κ) − 2 is read from a cubic Hermite table of ½ erfc
    /// and its derivative (step 1/128 on y ∈ [−6, 6], exact beyond to double precision), so
    /// the value is within 3e-11 of the closed form and the slope is the interpolant's own:
    /// value and slope stay consistent for gradient methods, at a fraction of the cost of
    /// erf and exp per cell.
    #[inline]
    pub fn inverse_noise(&self, d: f64, sigma: f64) -> (f64, f64) {
        let w = 1.0 / (sigma * sigma);
        let (v, s) = half_erfc(self.table, d * self.inv_scale - 2.0);
        (v * w, s * self.inv_scale * w)
    }
}

/// Table range and resolution of [`half_erfc`].
const ERFC_LIMIT: f64 = 6.0;
const ERFC_STEPS_PER_UNIT: f64 = 128.0;

/// ½ erfc(y) and its derivative −exp(−y²)/√π at the knots y_i = −6 + i/128.
fn erfc_table() -> &'static [(f64, f64)] {
    static TABLE: std::sync::OnceLock<Vec<(f64, f64)>> = std::sync::OnceLock::new();
    TABLE.get_or_init(|| {
        // 1536 intervals: exact in f64.
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        let n = (2.0 * ERFC_LIMIT * ERFC_STEPS_PER_UNIT) as usize;
        (0..=n)
            .map(|i| {
                // Knot indices are small.
                #[allow(clippy::cast_precision_loss)]
                let y = -ERFC_LIMIT + i as f64 / ERFC_STEPS_PER_UNIT;
                (0.5 * libm::erfc(y), -(-y * y).exp() / PI.sqrt())
            })
            .collect()
    })
}

/// ½ erfc(y) and its derivative by cubic Hermite interpolation of [`erfc_table`]; 1 and 0
/// below −6, 0 and 0 above 6 (erfc(6) ≈ 2e-17). NaN propagates.
#[inline]
fn half_erfc(table: &[(f64, f64)], y: f64) -> (f64, f64) {
    if y.is_nan() {
        return (f64::NAN, f64::NAN);
    }
    if y <= -ERFC_LIMIT {
        return (1.0, 0.0);
    }
    if y >= ERFC_LIMIT {
        return (0.0, 0.0);
    }
    let x = (y + ERFC_LIMIT) * ERFC_STEPS_PER_UNIT;
    // 0 ≤ x < 1536.
    #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
    let i = (x as usize).min(table.len() - 2);
    #[allow(clippy::cast_precision_loss)]
    let t = x - i as f64;
    let h = 1.0 / ERFC_STEPS_PER_UNIT;
    let ((f0, d0), (f1, d1)) = (table[i], table[i + 1]);
    let (m0, m1) = (d0 * h, d1 * h);
    // Cubic Hermite basis on t ∈ [0, 1].
    let t2 = t * t;
    let t3 = t2 * t;
    let v = (2.0 * t3 - 3.0 * t2 + 1.0) * f0
        + (t3 - 2.0 * t2 + t) * m0
        + (-2.0 * t3 + 3.0 * t2) * f1
        + (t3 - t2) * m1;
    let dv = (6.0 * t2 - 6.0 * t) * f0
        + (3.0 * t2 - 4.0 * t + 1.0) * m0
        + (-6.0 * t2 + 6.0 * t) * f1
        + (3.0 * t2 - 2.0 * t) * m1;
    (v, dv / h)
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// Brute force: the boundary sampled densely, the sign from the half-plane test.
    fn brute_triangle(t: &Triangle, q: &Vector2<f64>) -> f64 {
        let c = t.corners;
        let mut best = f64::INFINITY;
        for (a, b) in [(0, 1), (1, 2), (2, 0)] {
            for k in 0..=5_000 {
                let s = f64::from(k) / 5_000.0;
                let p = c[a] + (c[b] - c[a]) * s;
                best = best.min((q - p).norm());
            }
        }
        let inside = (0..3).all(|i| t.normals[i].dot(q) + t.offsets[i] <= 0.0);
        if inside { -best } else { best }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(100))]

        #[test]
        fn triangle_matches_brute_force(x in -2.0..6.0f64, y in -4.0..4.0f64) {
            let t = Triangle::new(3.0, 30f64.to_radians()).unwrap();
            let q = Vector2::new(x, y);
            let (d, g) = t.sdf2(&q);
            let b = brute_triangle(&t, &q);
            // The sampling step is 3.5 m / 5000 at most.
            prop_assert!((d - b).abs() < 1e-3, "{d} vs {b}");
            // The gradient has unit length and matches central differences away from ridges.
            prop_assert!((g.norm() - 1.0).abs() < 1e-12);
            let h = 1e-6;
            let fd = Vector2::new(
                (t.sdf2(&(q + Vector2::x() * h)).0 - t.sdf2(&(q - Vector2::x() * h)).0) / (2.0 * h),
                (t.sdf2(&(q + Vector2::y() * h)).0 - t.sdf2(&(q - Vector2::y() * h)).0) / (2.0 * h),
            );
            if (fd.norm() - 1.0).abs() < 1e-6 {
                prop_assert!((fd - g).norm() < 1e-5, "{fd} vs {g}");
            }
        }

        #[test]
        fn cone_matches_its_section(x in -2.0..12.0f64, y in -8.0..8.0f64, z in -8.0..8.0f64) {
            let c = Cone::new(10.0, 35f64.to_radians()).unwrap();
            let q = Vector3::new(x, y, z);
            let (d, g) = c.sdf(&q);
            // The meridian section, sampled by brute force.
            let b = brute_triangle(&c.section, &Vector2::new(x, y.hypot(z)));
            prop_assert!((d - b).abs() < 2e-3, "{d} vs {b}");
            let h = 1e-6;
            let fd: Vector3<f64> = Vector3::from_fn(|i, _| {
                let e = Vector3::ith(i, h);
                (c.sdf(&(q + e)).0 - c.sdf(&(q - e)).0) / (2.0 * h)
            });
            if (fd.norm() - 1.0).abs() < 1e-6 {
                prop_assert!((fd - g).norm() < 1e-5, "{fd} vs {g}");
            }
        }

        #[test]
        fn probit_slope_matches_differences(x in -5.0..5.0f64, kappa in 0.05..3.0f64) {
            let p = Probit::new(kappa).unwrap();
            let h = 1e-6;
            let fd = (p.value(x + h) - p.value(x - h)) / (2.0 * h);
            let (v, s) = p.value_and_slope(x);
            prop_assert!((v - p.value(x)).abs() < 1e-15);
            prop_assert!((fd - s).abs() < 1e-6 * s.abs().max(1e-3), "{fd} vs {s}");
            let (w, ws) = p.inverse_noise(x, 2.0);
            prop_assert!((w - (1.0 - v) / 4.0).abs() < 1e-11 && (ws + s / 4.0).abs() < 1e-7);
        }
    }

    /// The tabulated V⁻¹ is within 3e-11 of the closed form, and its slope matches its own
    /// central differences.
    #[test]
    fn tabulated_inverse_noise_matches_the_closed_form() {
        let p = Probit::new(0.5).unwrap();
        let mut worst: f64 = 0.0;
        for i in -20_000..20_000 {
            let d = f64::from(i) * 7e-4 + 1e-5;
            let (v, s) = p.inverse_noise(d, 1.0);
            worst = worst.max((v - (1.0 - p.value(d))).abs());
            let h = 1e-6;
            let fd = (p.inverse_noise(d + h, 1.0).0 - p.inverse_noise(d - h, 1.0).0) / (2.0 * h);
            assert!(
                (fd - s).abs() < 1e-6 * s.abs().max(1e-3),
                "d={d}: {fd} vs {s}"
            );
            let exact = p.value_and_slope(d).1;
            assert!((s + exact).abs() < 1e-7, "d={d}: {s} vs {}", -exact);
        }
        assert!(worst < 3e-11, "{worst}");
        assert!(p.inverse_noise(f64::NAN, 1.0).0.is_nan());
        assert_eq!(p.inverse_noise(100.0, 1.0), (0.0, 0.0));
        assert_eq!(p.inverse_noise(-100.0, 2.0), (0.25, 0.0));
    }

    #[test]
    fn probit_limits_and_shift() {
        let p = Probit::new(0.5).unwrap();
        // Φ(0) = ½ (1 + erf(−2)) ≈ 0.00234, the paper's shift.
        assert!((p.value(0.0) - 0.5 * (1.0 + libm::erf(-2.0))).abs() < 1e-15);
        assert!(p.value(-50.0) < 1e-300 + 1e-12 && p.value(50.0) > 1.0 - 1e-15);
        // Smaller κ gives a sharper step.
        let sharp = Probit::new(0.01).unwrap();
        assert!(sharp.value(0.5) > p.value(0.5));
    }

    #[test]
    fn bad_settings_are_errors() {
        assert!(Probit::new(0.0).is_err());
        assert!(Probit::new(-1.0).is_err());
        assert!(Probit::new(f64::NAN).is_err());
        assert!(Triangle::new(0.0, 0.5).is_err());
        assert!(Triangle::new(3.0, 0.0).is_err());
        assert!(Triangle::new(3.0, 2.0).is_err());
        assert!(Cone::new(f64::INFINITY, 0.5).is_err());
    }
}
