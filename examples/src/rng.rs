//! The simulator's one seeded random source: scenes, sensor noise and IMU noise all draw
//! from it, so a seed fixes a whole run.

/// A 64-bit linear congruential generator with uniform and normal samples.
#[derive(Debug, Clone)]
pub struct Rng {
    state: u64,
    spare: Option<f64>,
}

impl Rng {
    /// A generator from a seed.
    pub fn new(seed: u64) -> Self {
        Self {
            state: seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ 0xD1B5_4A32_D192_ED03,
            spare: None,
        }
    }

    /// Uniform in [0, 1).
    pub fn unit(&mut self) -> f64 {
        self.state = self
            .state
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        // The top 53 bits form an exact f64 mantissa.
        #[allow(clippy::cast_precision_loss)]
        let v = (self.state >> 11) as f64 / (1u64 << 53) as f64;
        v
    }

    /// Uniform in [lo, hi).
    pub fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.unit()
    }

    /// One standard normal sample (Box–Muller).
    pub fn normal(&mut self) -> f64 {
        if let Some(s) = self.spare.take() {
            return s;
        }
        // 1 − unit ∈ (0, 1]: the logarithm stays finite.
        let (u, v) = (1.0 - self.unit(), self.unit());
        let r = (-2.0 * u.ln()).sqrt();
        let a = core::f64::consts::TAU * v;
        self.spare = Some(r * a.sin());
        r * a.cos()
    }
}
