//! A motor encoder model for simulation: quantisation and latency.
//!
//! The encoder reports the motor angle wrapped to [0, 2π), floored to one of
//! `counts_per_revolution` steps, and as it was `latency` seconds before the
//! read. The true angle between recorded samples is interpolated linearly.
//!
//! # Example
//! ```
//! use lidar_kinematics::{Encoder, EncoderConfig};
//!
//! # fn main() -> Result<(), lidar_kinematics::KinematicsError> {
//! let mut enc = Encoder::new(EncoderConfig::try_new(4096, 0.002)?);
//! enc.record(0.0, 0.0)?;
//! enc.record(0.01, 0.1)?; // 10 rad/s
//! let reading = enc.read(0.01)?; // sees the angle at t = 0.008
//! assert_eq!(reading.count, (0.08 / (std::f64::consts::TAU / 4096.0)).floor() as u32);
//! # Ok(()) }
//! ```

use std::collections::VecDeque;

use core::f64::consts::TAU;

use crate::angle::wrap_to_two_pi;
use crate::error::{KinematicsError, Result, check_finite};

/// Encoder settings.
///
/// # Example
/// ```
/// use lidar_kinematics::EncoderConfig;
/// let cfg = EncoderConfig::default();
/// assert_eq!(cfg.counts_per_revolution(), 4096);
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EncoderConfig {
    counts_per_revolution: u32,
    latency: f64,
}

impl EncoderConfig {
    /// Validates and builds a configuration: `counts_per_revolution ≥ 1`, latency \[s\] finite and ≥ 0.
    ///
    /// # Errors
    /// [`KinematicsError::InvalidParameter`] for zero counts or a negative latency,
    /// [`KinematicsError::NonFinite`] for a non-finite latency.
    pub fn try_new(counts_per_revolution: u32, latency: f64) -> Result<Self> {
        if counts_per_revolution == 0 {
            return Err(KinematicsError::InvalidParameter {
                what: "encoder counts per revolution",
                reason: "must be at least 1",
            });
        }
        check_finite(latency, "encoder latency")?;
        if latency < 0.0 {
            return Err(KinematicsError::InvalidParameter {
                what: "encoder latency",
                reason: "must be non-negative",
            });
        }
        Ok(Self {
            counts_per_revolution,
            latency,
        })
    }

    /// Counts per revolution (a 12-bit encoder has 4096).
    pub fn counts_per_revolution(&self) -> u32 {
        self.counts_per_revolution
    }

    /// Latency between the angle and its report \[s\].
    pub fn latency(&self) -> f64 {
        self.latency
    }

    /// Angle of one count \[rad\].
    pub fn resolution(&self) -> f64 {
        TAU / f64::from(self.counts_per_revolution)
    }

    /// The count of an angle \[rad\]: ⌊wrap(θ) / resolution⌋, in 0..counts_per_revolution.
    ///
    /// # Errors
    /// [`KinematicsError::NonFinite`] for a non-finite angle.
    pub fn count(&self, theta: f64) -> Result<u32> {
        check_finite(theta, "motor angle")?;
        let c = (wrap_to_two_pi(theta) / self.resolution()).floor();
        // `c` lies in [0, counts] and is an integer; the clamp guards the
        // rounding edge where wrap(θ)/resolution rounds up to `counts`.
        Ok((c as u32).min(self.counts_per_revolution - 1))
    }

    /// The angle an encoder reports for a true angle \[rad\]: count × resolution, in [0, 2π).
    ///
    /// # Errors
    /// [`KinematicsError::NonFinite`] for a non-finite angle.
    pub fn quantise(&self, theta: f64) -> Result<f64> {
        Ok(f64::from(self.count(theta)?) * self.resolution())
    }
}

impl Default for EncoderConfig {
    /// A 12-bit magnetic encoder (4096 counts) with 1 ms latency.
    fn default() -> Self {
        Self {
            counts_per_revolution: 4096,
            latency: 1e-3,
        }
    }
}

/// One encoder report.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EncoderReading {
    /// Time of the read \[s\].
    pub time: f64,
    /// Raw count, in 0..counts_per_revolution.
    pub count: u32,
    /// The reported angle, count × resolution, in [0, 2π) \[rad\].
    pub angle: f64,
}

/// A stateful encoder: record true angles as the simulation runs, read delayed, quantised reports.
///
/// It keeps only the history the latency needs.
#[derive(Debug, Clone)]
pub struct Encoder {
    config: EncoderConfig,
    history: VecDeque<(f64, f64)>,
}

impl Encoder {
    /// An encoder with no history.
    pub fn new(config: EncoderConfig) -> Self {
        Self {
            config,
            history: VecDeque::new(),
        }
    }

    /// The encoder's settings.
    pub fn config(&self) -> &EncoderConfig {
        &self.config
    }

    /// Records the true (unwrapped) motor angle \[rad\] at time `t` \[s\].
    ///
    /// # Errors
    /// [`KinematicsError::NonFinite`] for non-finite input,
    /// [`KinematicsError::Unsorted`] if `t` is not after the last recorded time.
    pub fn record(&mut self, t: f64, theta: f64) -> Result<()> {
        check_finite(t, "encoder time")?;
        check_finite(theta, "motor angle")?;
        if let Some(&(last, _)) = self.history.back()
            && t <= last
        {
            return Err(KinematicsError::Unsorted {
                what: "encoder samples",
                index: self.history.len(),
            });
        }
        self.history.push_back((t, theta));
        // Drop samples older than any future read can need: a read at time ≥ t
        // looks at ≥ t − latency, which needs only the last sample before that.
        let horizon = t - self.config.latency;
        while self.history.len() > 2 && self.history[1].0 <= horizon {
            self.history.pop_front();
        }
        Ok(())
    }

    /// The report of a read at time `t` \[s\]: the angle at `t − latency`, quantised.
    ///
    /// # Errors
    /// [`KinematicsError::NonFinite`] for a non-finite time,
    /// [`KinematicsError::Empty`] before any sample was recorded,
    /// [`KinematicsError::TimeOutOfRange`] if `t − latency` lies outside the recorded span.
    pub fn read(&self, t: f64) -> Result<EncoderReading> {
        check_finite(t, "encoder read time")?;
        let (Some(&(t0, _)), Some(&(t1, _))) = (self.history.front(), self.history.back()) else {
            return Err(KinematicsError::Empty {
                what: "encoder history",
            });
        };
        let ts = t - self.config.latency;
        if ts < t0 || ts > t1 {
            return Err(KinematicsError::TimeOutOfRange {
                what: "encoder history",
                time: ts,
                start: t0,
                end: t1,
            });
        }
        let i = self.history.partition_point(|&(ti, _)| ti <= ts);
        let theta = if i >= self.history.len() {
            self.history[self.history.len() - 1].1
        } else {
            let (ta, a) = self.history[i - 1];
            let (tb, b) = self.history[i];
            a + (b - a) * (ts - ta) / (tb - ta)
        };
        let count = self.config.count(theta)?;
        Ok(EncoderReading {
            time: t,
            count,
            angle: f64::from(count) * self.config.resolution(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        #[test]
        fn quantisation_error_is_below_one_count(theta in -1e3f64..1e3, counts in 1u32..100_000) {
            let cfg = EncoderConfig::try_new(counts, 0.0).unwrap();
            let q = cfg.quantise(theta).unwrap();
            prop_assert!((0.0..TAU).contains(&q));
            // How far the true angle lies past its count, measured forward around the circle
            // (a signed difference would wrap for coarse encoders with a count of over π).
            let err = crate::angle::wrap_to_two_pi(theta - q);
            let err = if err > TAU - 1e-9 { err - TAU } else { err };
            prop_assert!(err >= -1e-9 && err < cfg.resolution() + 1e-9, "err {err}");
        }

        /// A motor at constant speed is read as it was `latency` ago.
        #[test]
        fn latency_delays_the_reading(omega in -20.0f64..20.0, latency in 0.0f64..0.02, t_read in 0.05f64..0.9) {
            let cfg = EncoderConfig::try_new(1 << 20, latency).unwrap();
            let mut enc = Encoder::new(cfg);
            // Record at 1 kHz up to the read time, then read, as a simulator does.
            let mut k = 0;
            while f64::from(k) * 1e-3 <= t_read {
                let t = f64::from(k) * 1e-3;
                enc.record(t, omega * t).unwrap();
                k += 1;
            }
            enc.record(t_read, omega * t_read).ok();
            let r = enc.read(t_read).unwrap();
            let expected = cfg.quantise(omega * (t_read - latency)).unwrap();
            let diff = crate::angle::difference(expected, r.angle).abs();
            prop_assert!(diff <= cfg.resolution() + 1e-9);
        }
    }

    #[test]
    fn errors() {
        assert!(EncoderConfig::try_new(0, 0.0).is_err());
        assert!(EncoderConfig::try_new(10, -1.0).is_err());
        assert!(EncoderConfig::try_new(10, f64::NAN).is_err());
        let mut enc = Encoder::new(EncoderConfig::default());
        assert!(matches!(enc.read(0.0), Err(KinematicsError::Empty { .. })));
        enc.record(1.0, 0.0).unwrap();
        assert!(matches!(
            enc.record(1.0, 0.0),
            Err(KinematicsError::Unsorted { .. })
        ));
        assert!(matches!(
            enc.record(f64::NAN, 0.0),
            Err(KinematicsError::NonFinite { .. })
        ));
        assert!(matches!(
            enc.read(0.5),
            Err(KinematicsError::TimeOutOfRange { .. })
        ));
        assert!(matches!(
            enc.read(f64::INFINITY),
            Err(KinematicsError::NonFinite { .. })
        ));
    }

    #[test]
    fn history_stays_bounded() {
        let mut enc = Encoder::new(EncoderConfig::try_new(4096, 0.01).unwrap());
        for k in 0..10_000 {
            enc.record(f64::from(k) * 1e-3, 0.0).unwrap();
        }
        assert!(enc.history.len() <= 13);
        assert!(enc.read(9.999).is_ok());
    }
}
