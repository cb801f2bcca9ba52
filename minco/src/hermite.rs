//! Hermite form of one piece on the unit interval, and the small dense algebra of its blocks.
//!
//! A polynomial of degree 2S − 1 on [0, T] is fixed by its states (derivatives 0..S−1) at both
//! ends, z = [a₀..a_{S−1}, b₀..b_{S−1}]. With τ = t/T, the scaled states z̃_j = T^{m_j} z_j
//! (m_j = j mod S, the order of slot j) and the scaled coefficients c̃_k = T^k c_k are related
//! by a constant matrix, c̃ = B₁ z̃, and the effort of the piece is
//! ∫₀^T ‖p^(S)‖² dt = T^{1−2S} z̃ᵀ W₁ z̃ with W₁ = B₁ᵀ Q₁ B₁. Every table here is a compile-time
//! constant, so a solve only scales them by powers of T.

use crate::poly::MAX_COEFFS;

/// A 2S × 2S table (S ≤ 4), indexed `[row][column]`.
pub(crate) type Table = [[f64; MAX_COEFFS]; MAX_COEFFS];

/// Largest size of a junction block: the S − 1 free derivatives 1..S−1 of a junction state.
pub(crate) const MAX_FREE: usize = MAX_COEFFS / 2 - 1;

/// A small square block of the junction system.
pub(crate) type Block = [[f64; MAX_FREE]; MAX_FREE];

/// The constant tables of order S.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Tables {
    /// B₁: scaled states to scaled coefficients.
    pub(crate) b: Table,
    /// (m_j − k) · B₁\[k\]\[j\]: with T^{−k−1}, the T-derivative of B(T) = T^{−k} B₁ T^{m_j}.
    pub(crate) b_dt: Table,
    /// W₁ = B₁ᵀ Q₁ B₁: the effort of a piece on [0, 1] as a quadratic form in its states.
    pub(crate) w: Table,
    /// (m_i + m_j + 1 − 2S) · W₁\[i\]\[j\]: with T^{−2S}, the T-derivative of W(T).
    pub(crate) w_dt: Table,
}

/// The tables of each order, `TABLES[s]` for s = 2, 3, 4.
pub(crate) const TABLES: [Tables; 5] = {
    let zero = Tables {
        b: [[0.0; MAX_COEFFS]; MAX_COEFFS],
        b_dt: [[0.0; MAX_COEFFS]; MAX_COEFFS],
        w: [[0.0; MAX_COEFFS]; MAX_COEFFS],
        w_dt: [[0.0; MAX_COEFFS]; MAX_COEFFS],
    };
    [zero, zero, tables(2), tables(3), tables(4)]
};

/// An exact fraction n/d (d > 0, lowest terms), for building the tables at compile time:
/// f64 elimination would leave errors of ~1e-14 relative in them, and every solve would
/// inherit those as systematic residuals in the high derivatives.
#[derive(Debug, Clone, Copy)]
struct Ratio {
    n: i128,
    d: i128,
}

const fn gcd(mut a: i128, mut b: i128) -> i128 {
    if a < 0 {
        a = -a;
    }
    if b < 0 {
        b = -b;
    }
    while b != 0 {
        let r = a % b;
        a = b;
        b = r;
    }
    a
}

impl Ratio {
    const ZERO: Ratio = Ratio { n: 0, d: 1 };

    const fn new(n: i128, d: i128) -> Ratio {
        let (n, d) = if d < 0 { (-n, -d) } else { (n, d) };
        let g = gcd(n, d);
        if g == 0 {
            Ratio::ZERO
        } else {
            Ratio { n: n / g, d: d / g }
        }
    }

    const fn int(n: i128) -> Ratio {
        Ratio { n, d: 1 }
    }

    const fn add(self, o: Ratio) -> Ratio {
        Ratio::new(self.n * o.d + o.n * self.d, self.d * o.d)
    }

    const fn sub(self, o: Ratio) -> Ratio {
        Ratio::new(self.n * o.d - o.n * self.d, self.d * o.d)
    }

    const fn mul(self, o: Ratio) -> Ratio {
        Ratio::new(self.n * o.n, self.d * o.d)
    }

    const fn div(self, o: Ratio) -> Ratio {
        Ratio::new(self.n * o.d, self.d * o.n)
    }

    /// Correctly rounded: numerators and denominators of these tables are far below 2^53.
    const fn to_f64(self) -> f64 {
        self.n as f64 / self.d as f64
    }
}

/// k!/(k − m)! as an integer.
const fn falling(m: usize, k: usize) -> i128 {
    let mut f = 1;
    let mut j = k + 1 - m;
    while j <= k {
        f *= j as i128;
        j += 1;
    }
    f
}

/// Builds the tables of order `s` by exact Gauss–Jordan elimination of the Hermite conditions.
const fn tables(s: usize) -> Tables {
    let n = 2 * s;
    // Hermite conditions: row m is p^(m)(0) = m! c̃_m, row s + m is p^(m)(1) = Σ_k k!/(k−m)! c̃_k.
    let mut h = [[Ratio::ZERO; MAX_COEFFS]; MAX_COEFFS];
    let mut inv = [[Ratio::ZERO; MAX_COEFFS]; MAX_COEFFS];
    let mut m = 0;
    while m < s {
        h[m][m] = Ratio::int(falling(m, m));
        let mut k = m;
        while k < n {
            h[s + m][k] = Ratio::int(falling(m, k));
            k += 1;
        }
        m += 1;
    }
    let mut i = 0;
    while i < n {
        inv[i][i] = Ratio::int(1);
        i += 1;
    }
    // Gauss–Jordan: inv = H⁻¹ = B₁ (exact, so any non-zero pivot will do).
    let mut col = 0;
    while col < n {
        let mut piv = col;
        while h[piv][col].n == 0 {
            piv += 1;
        }
        let (hr, ir) = (h[piv], inv[piv]);
        h[piv] = h[col];
        inv[piv] = inv[col];
        h[col] = hr;
        inv[col] = ir;
        let p = h[col][col];
        let mut j = 0;
        while j < n {
            h[col][j] = h[col][j].div(p);
            inv[col][j] = inv[col][j].div(p);
            j += 1;
        }
        let mut r = 0;
        while r < n {
            if r != col && h[r][col].n != 0 {
                let f = h[r][col];
                let mut j = 0;
                while j < n {
                    h[r][j] = h[r][j].sub(f.mul(h[col][j]));
                    inv[r][j] = inv[r][j].sub(f.mul(inv[col][j]));
                    j += 1;
                }
            }
            r += 1;
        }
        col += 1;
    }
    // W₁ = B₁ᵀ Q₁ B₁ with Q₁[k][l] = k!/(k−s)! · l!/(l−s)! / (k + l − 2s + 1) for k, l ≥ s.
    let mut qb = [[Ratio::ZERO; MAX_COEFFS]; MAX_COEFFS];
    let mut k = s;
    while k < n {
        let mut j = 0;
        while j < n {
            let mut acc = Ratio::ZERO;
            let mut l = s;
            while l < n {
                let q = Ratio::new(falling(s, k) * falling(s, l), (k + l - 2 * s + 1) as i128);
                acc = acc.add(q.mul(inv[l][j]));
                l += 1;
            }
            qb[k][j] = acc;
            j += 1;
        }
        k += 1;
    }
    let mut out = Tables {
        b: [[0.0; MAX_COEFFS]; MAX_COEFFS],
        b_dt: [[0.0; MAX_COEFFS]; MAX_COEFFS],
        w: [[0.0; MAX_COEFFS]; MAX_COEFFS],
        w_dt: [[0.0; MAX_COEFFS]; MAX_COEFFS],
    };
    let mut i = 0;
    while i < n {
        let mut j = 0;
        while j < n {
            let mut acc = Ratio::ZERO;
            let mut k = s;
            while k < n {
                acc = acc.add(inv[k][i].mul(qb[k][j]));
                k += 1;
            }
            let e = (i % s + j % s + 1) as i128 - (2 * s) as i128;
            out.w[i][j] = acc.to_f64();
            out.w_dt[i][j] = acc.mul(Ratio::int(e)).to_f64();
            out.b[i][j] = inv[i][j].to_f64();
            out.b_dt[i][j] = inv[i][j]
                .mul(Ratio::int((j % s) as i128 - i as i128))
                .to_f64();
            j += 1;
        }
        i += 1;
    }
    out
}

/// The inverse of the symmetric positive-definite leading `n × n` part of `a`, by an LDLᵀ
/// factorisation (no square roots).
///
/// `None` if a pivot is not positive and finite: the junction system is singular in floating
/// point (extreme durations).
#[inline(always)]
pub(crate) fn spd_inverse(a: &Block, n: usize) -> Option<Block> {
    // Unit lower L and pivots d with A = L diag(d) Lᵀ.
    let mut l = [[0.0; MAX_FREE]; MAX_FREE];
    let (mut piv, mut inv_d) = ([0.0; MAX_FREE], [0.0; MAX_FREE]);
    for j in 0..n {
        let mut d = a[j][j];
        for k in 0..j {
            d -= l[j][k] * l[j][k] * piv[k];
        }
        if !(d > 0.0 && d.is_finite()) {
            return None;
        }
        piv[j] = d;
        inv_d[j] = 1.0 / d;
        l[j][j] = 1.0;
        for i in j + 1..n {
            let mut v = a[i][j];
            for k in 0..j {
                v -= l[i][k] * l[j][k] * piv[k];
            }
            l[i][j] = v * inv_d[j];
        }
    }
    // L⁻¹ (unit lower) by forward substitution, then A⁻¹ = L⁻ᵀ diag(1/d) L⁻¹.
    let mut li = [[0.0; MAX_FREE]; MAX_FREE];
    for j in 0..n {
        li[j][j] = 1.0;
        for i in j + 1..n {
            let mut v = 0.0;
            for k in j..i {
                v -= l[i][k] * li[k][j];
            }
            li[i][j] = v;
        }
    }
    let mut inv = [[0.0; MAX_FREE]; MAX_FREE];
    for i in 0..n {
        for j in 0..=i {
            let mut v = 0.0;
            for k in i..n {
                v += li[k][i] * inv_d[k] * li[k][j];
            }
            inv[i][j] = v;
            inv[j][i] = v;
        }
    }
    Some(inv)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::poly::eval;

    /// B₁ reproduces the states it was built from, for every order.
    #[test]
    fn hermite_interpolates_its_states() {
        for s in 2..=4 {
            let t = &TABLES[s];
            for j in 0..2 * s {
                // Coefficients of the basis polynomial of state slot j.
                let c: Vec<[f64; 1]> = (0..2 * s).map(|k| [t.b[k][j]]).collect();
                for m in 0..s {
                    let want = |slot: usize| if slot == j { 1.0 } else { 0.0 };
                    let at0 = eval(&c, m, 0.0)[0];
                    let at1 = eval(&c, m, 1.0)[0];
                    assert!((at0 - want(m)).abs() < 1e-12, "s={s} j={j} m={m}");
                    assert!((at1 - want(s + m)).abs() < 1e-12, "s={s} j={j} m={m}");
                }
            }
        }
    }

    /// The tables are exact: W₁ of S = 4 has integer entries, and W₁ annihilates constants.
    #[test]
    fn tables_are_exact() {
        let t = &TABLES[4];
        assert_eq!(t.w[0][0], 100_800.0);
        assert_eq!(t.w[1][5], 24_480.0);
        assert_eq!(t.b[4][3], -2.0 / 3.0);
        for s in 2..=4 {
            let t = &TABLES[s];
            for i in 0..2 * s {
                assert_eq!(t.w[i][0], -t.w[i][s], "s={s} i={i}");
            }
        }
    }

    /// W₁ is the effort: compare with a fine midpoint quadrature of ‖p^(s)‖².
    #[test]
    fn effort_table_matches_quadrature() {
        for s in 2..=4 {
            let t = &TABLES[s];
            let z: Vec<f64> = (0..2 * s).map(|j| (j as f64 * 0.7).sin() + 0.3).collect();
            let c: Vec<[f64; 1]> = (0..2 * s)
                .map(|k| [(0..2 * s).map(|j| t.b[k][j] * z[j]).sum()])
                .collect();
            let steps = 20_000_u32;
            let quad: f64 = (0..steps)
                .map(|i| {
                    let x = (f64::from(i) + 0.5) / f64::from(steps);
                    eval(&c, s, x)[0].powi(2)
                })
                .sum::<f64>()
                / f64::from(steps);
            let form: f64 = (0..2 * s)
                .flat_map(|i| (0..2 * s).map(move |j| (i, j)))
                .map(|(i, j)| z[i] * t.w[i][j] * z[j])
                .sum();
            assert!((quad - form).abs() < 1e-6 * form.abs().max(1.0), "s={s}");
        }
    }

    #[test]
    fn spd_inverse_inverts_and_rejects() {
        let a: Block = [[4.0, 1.0, 0.5], [1.0, 3.0, 0.2], [0.5, 0.2, 2.0]];
        for n in 1..=3 {
            let inv = spd_inverse(&a, n).unwrap();
            for i in 0..n {
                for j in 0..n {
                    let v: f64 = (0..n).map(|k| a[i][k] * inv[k][j]).sum();
                    let want = if i == j { 1.0 } else { 0.0 };
                    assert!((v - want).abs() < 1e-14);
                }
            }
        }
        let indefinite: Block = [[1.0, 2.0, 0.0], [2.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
        assert!(spd_inverse(&indefinite, 2).is_none());
        let nan: Block = [[f64::NAN, 0.0, 0.0]; 3];
        assert!(spd_inverse(&nan, 1).is_none());
    }
}
