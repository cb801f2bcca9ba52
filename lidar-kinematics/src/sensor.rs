//! LiDAR beam patterns, range limits, field of view and the visibility gate.
//!
//! A [`BeamPattern`] is data: for frame `f` it yields the frame's beams, each a
//! time offset from the frame start and a unit direction in the LiDAR frame
//! (x forward, z up). Two families are provided:
//! - [`SpinningPattern`]: a multi-ring sensor whose head turns about its z axis once
//!   per frame, all rings firing together at each azimuth step;
//! - [`NonRepetitivePattern`]: a wide-field sensor in the style of the Livox Mid-360,
//!   whose lines sweep the full azimuth while their elevation oscillates at a rate
//!   incommensurate with the frame rate, so successive frames fill the field of view.
//!
//! A [`LidarSensor`] couples a pattern with [`RangeLimits`] and answers whether a
//! world point is visible at a given motor angle: the gate later crates use.
//!
//! # Example
//! ```
//! use lidar_kinematics::{KinematicChain, LidarSensor};
//! use nalgebra::{Isometry3, Point3};
//!
//! # fn main() -> Result<(), lidar_kinematics::KinematicsError> {
//! let sensor = LidarSensor::ring16();
//! assert_eq!(sensor.pattern().points_per_frame(), 16 * 1800);
//! let beams: Vec<_> = sensor.pattern().frame(0).collect();
//! assert!(beams.iter().all(|b| (b.direction.norm() - 1.0).abs() < 1e-12));
//!
//! let chain = KinematicChain::default();
//! let body = Isometry3::identity();
//! // 10 m ahead on the horizon: inside ±15°; straight up: outside.
//! assert!(sensor.can_see(&chain, &body, 0.0, &Point3::new(10.0, 0.0, 0.0))?);
//! assert!(!sensor.can_see(&chain, &body, 0.0, &Point3::new(0.0, 0.0, 10.0))?);
//! # Ok(()) }
//! ```

use core::f64::consts::{FRAC_PI_2, TAU};

use nalgebra::{Isometry3, Matrix3, Point3, Unit, Vector3};

use crate::chain::KinematicChain;
use crate::error::{KinematicsError, Result, check_finite};
use crate::motor::check_dt;

/// Most beams a frame may have (keeps every index computation far from overflow).
///
/// Generating beams one at a time ([`BeamPattern::frame`], [`BeamPattern::beam`]) needs no
/// memory per beam, but a collected frame ([`BeamPattern::fill_frame`]) holds
/// `size_of::<Beam>()` = 32 bytes per beam: 8 GiB at this limit.
pub const MAX_POINTS_PER_FRAME: usize = 1 << 28;

/// One beam of a frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Beam {
    /// Time of the beam after the frame start \[s\].
    pub time_offset: f64,
    /// Beam direction in the LiDAR frame.
    pub direction: Unit<Vector3<f64>>,
}

/// The beam direction at azimuth `az` and elevation `el` \[rad\] (x forward, z up).
#[inline]
fn direction(az: f64, el: f64) -> Unit<Vector3<f64>> {
    let (sa, ca) = az.sin_cos();
    let (se, ce) = el.sin_cos();
    Unit::new_unchecked(Vector3::new(ce * ca, ce * sa, se))
}

fn invalid(what: &'static str, reason: &'static str) -> KinematicsError {
    KinematicsError::InvalidParameter { what, reason }
}

/// Minimum and maximum measurable range \[m\].
///
/// # Example
/// ```
/// use lidar_kinematics::RangeLimits;
/// let r = RangeLimits::try_new(0.5, 100.0).unwrap();
/// assert!(r.contains(50.0) && !r.contains(0.1));
/// assert!(RangeLimits::try_new(5.0, 1.0).is_err());
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RangeLimits {
    min: f64,
    max: f64,
}

impl RangeLimits {
    /// Validates and builds limits: finite, 0 ≤ `min` < `max` \[m\].
    ///
    /// # Errors
    /// [`KinematicsError::InvalidRange`] otherwise.
    pub fn try_new(min: f64, max: f64) -> Result<Self> {
        if min.is_finite() && max.is_finite() && min >= 0.0 && min < max {
            Ok(Self { min, max })
        } else {
            Err(KinematicsError::InvalidRange { min, max })
        }
    }

    /// Minimum range \[m\].
    pub fn min(&self) -> f64 {
        self.min
    }

    /// Maximum range \[m\].
    pub fn max(&self) -> f64 {
        self.max
    }

    /// Whether a range \[m\] is measurable: `min ≤ r ≤ max`.
    #[inline]
    pub fn contains(&self, range: f64) -> bool {
        range >= self.min && range <= self.max
    }
}

/// An angular field of view in the LiDAR frame: an azimuth interval about z and an elevation band.
///
/// # Example
/// ```
/// use lidar_kinematics::FieldOfView;
/// use nalgebra::Vector3;
/// let fov = FieldOfView::try_new(-0.5, 0.5, -0.2, 0.9).unwrap();
/// assert!(fov.contains(&Vector3::new(1.0, 0.1, 0.5)));
/// assert!(!fov.contains(&Vector3::new(-1.0, 0.0, 0.0)));
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FieldOfView {
    azimuth_min: f64,
    azimuth_width: f64,
    elevation_min: f64,
    elevation_max: f64,
    sin_el_min: f64,
    sin_el_max: f64,
    /// Unit vector of the azimuth interval's centre and the cosine of its half width.
    center_cos: f64,
    center_sin: f64,
    cos_half_width: f64,
}

impl FieldOfView {
    /// Validates and builds a field of view \[rad\]. An azimuth interval of width ≥ 2π is the full circle.
    ///
    /// # Errors
    /// [`KinematicsError::NonFinite`] for non-finite bounds, [`KinematicsError::InvalidParameter`]
    /// unless `azimuth_min ≤ azimuth_max` and −π/2 ≤ `elevation_min` ≤ `elevation_max` ≤ π/2.
    pub fn try_new(
        azimuth_min: f64,
        azimuth_max: f64,
        elevation_min: f64,
        elevation_max: f64,
    ) -> Result<Self> {
        for (v, what) in [
            (azimuth_min, "azimuth_min"),
            (azimuth_max, "azimuth_max"),
            (elevation_min, "elevation_min"),
            (elevation_max, "elevation_max"),
        ] {
            check_finite(v, what)?;
        }
        if azimuth_min > azimuth_max {
            return Err(invalid("field of view", "azimuth_min > azimuth_max"));
        }
        if !(-FRAC_PI_2 <= elevation_min
            && elevation_min <= elevation_max
            && elevation_max <= FRAC_PI_2)
        {
            return Err(invalid(
                "field of view",
                "need -pi/2 <= elevation_min <= elevation_max <= pi/2",
            ));
        }
        let azimuth_width = (azimuth_max - azimuth_min).min(TAU);
        let center = azimuth_min + 0.5 * azimuth_width;
        Ok(Self {
            azimuth_min,
            azimuth_width,
            elevation_min,
            elevation_max,
            sin_el_min: elevation_min.sin(),
            sin_el_max: elevation_max.sin(),
            center_cos: center.cos(),
            center_sin: center.sin(),
            cos_half_width: (0.5 * azimuth_width).cos(),
        })
    }

    /// A full-azimuth band between two elevations \[rad\].
    ///
    /// # Errors
    /// As [`FieldOfView::try_new`].
    pub fn band(elevation_min: f64, elevation_max: f64) -> Result<Self> {
        Self::try_new(0.0, TAU, elevation_min, elevation_max)
    }

    /// Lower elevation bound \[rad\].
    pub fn elevation_min(&self) -> f64 {
        self.elevation_min
    }

    /// Upper elevation bound \[rad\].
    pub fn elevation_max(&self) -> f64 {
        self.elevation_max
    }

    /// Lower azimuth bound \[rad\].
    pub fn azimuth_min(&self) -> f64 {
        self.azimuth_min
    }

    /// Azimuth width \[rad\], at most 2π.
    pub fn azimuth_width(&self) -> f64 {
        self.azimuth_width
    }

    /// Whether the field covers all azimuths.
    pub fn is_full_azimuth(&self) -> bool {
        self.azimuth_width >= TAU
    }

    /// Whether a direction (any non-zero length) lies inside the field. The zero vector does not.
    #[inline]
    pub fn contains(&self, dir: &Vector3<f64>) -> bool {
        let n = dir.norm();
        if n > 0.0 && n.is_finite() {
            return self.contains_with_norm(dir, n);
        }
        // A length whose square under- or overflows: the field is a set of directions, so
        // the direction scaled to its largest component answers the same.
        rescaled(dir).is_some_and(|d| self.contains_with_norm(&d, d.norm()))
    }

    /// [`FieldOfView::contains`] for a direction whose norm `n` is known.
    #[inline]
    fn contains_with_norm(&self, dir: &Vector3<f64>, n: f64) -> bool {
        if !(n > 0.0 && n.is_finite()) {
            return false;
        }
        // Elevation is monotone in z/‖d‖ = sin(el): no trigonometry needed.
        if dir.z < self.sin_el_min * n || dir.z > self.sin_el_max * n {
            return false;
        }
        if self.is_full_azimuth() {
            return true;
        }
        // ‖d‖ is finite, so x² + y² cannot overflow: no need for the slower hypot.
        let r = (dir.x * dir.x + dir.y * dir.y).sqrt();
        if r == 0.0 {
            // Straight up or down: azimuth 0 by convention, as atan2(0, 0).
            return (-self.azimuth_min).rem_euclid(TAU) <= self.azimuth_width;
        }
        // The azimuth lies within half the width of the interval's centre: cos of the angle
        // to the centre at least cos(half width), with no trigonometry per call.
        dir.x * self.center_cos + dir.y * self.center_sin >= self.cos_half_width * r
    }
}

/// A multi-ring spinning LiDAR: `elevations.len()` rings fire together at each of
/// `azimuth_steps` equally spaced azimuths; the head turns once per `frame_period`.
///
/// # Example
/// ```
/// use lidar_kinematics::SpinningPattern;
/// let p = SpinningPattern::try_new(vec![-0.1, 0.0, 0.1], 360, 0.1).unwrap();
/// assert_eq!(p.points_per_frame(), 1080);
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct SpinningPattern {
    elevations: Vec<f64>,
    azimuth_steps: usize,
    frame_period: f64,
}

impl SpinningPattern {
    /// Validates and builds a pattern: ring elevations \[rad\] strictly increasing within
    /// [−π/2, π/2], at least one azimuth step, frame period > 0 \[s\], at most
    /// [`MAX_POINTS_PER_FRAME`] beams per frame (a collected frame costs 32 bytes a beam).
    ///
    /// # Errors
    /// [`KinematicsError::Empty`], [`KinematicsError::NonFinite`],
    /// [`KinematicsError::InvalidParameter`] or [`KinematicsError::NonPositiveDt`] for bad values.
    pub fn try_new(elevations: Vec<f64>, azimuth_steps: usize, frame_period: f64) -> Result<Self> {
        if elevations.is_empty() {
            return Err(KinematicsError::Empty {
                what: "ring elevations",
            });
        }
        for &e in &elevations {
            check_finite(e, "ring elevation")?;
            if e.abs() > FRAC_PI_2 {
                return Err(invalid("ring elevation", "must lie in [-pi/2, pi/2]"));
            }
        }
        if elevations.windows(2).any(|w| w[0] >= w[1]) {
            return Err(invalid("ring elevations", "must be strictly increasing"));
        }
        if azimuth_steps == 0 {
            return Err(invalid("azimuth steps", "must be at least 1"));
        }
        if elevations
            .len()
            .checked_mul(azimuth_steps)
            .is_none_or(|p| p > MAX_POINTS_PER_FRAME)
        {
            return Err(invalid(
                "spinning pattern",
                "more than 2^28 beams per frame",
            ));
        }
        check_dt(frame_period)?;
        Ok(Self {
            elevations,
            azimuth_steps,
            frame_period,
        })
    }

    /// `rings` equally spaced rings from `lowest` to `highest` elevation \[rad\].
    fn uniform(rings: usize, lowest: f64, highest: f64, azimuth_steps: usize, period: f64) -> Self {
        let step = (highest - lowest) / (rings as f64 - 1.0);
        Self {
            elevations: (0..rings).map(|i| lowest + step * i as f64).collect(),
            azimuth_steps,
            frame_period: period,
        }
    }

    /// 16 rings over ±15° (2° apart), 1800 azimuth steps (0.2°), 10 Hz: a VLP-16-like sensor.
    pub fn ring16() -> Self {
        Self::uniform(16, -15f64.to_radians(), 15f64.to_radians(), 1800, 0.1)
    }

    /// 32 rings over −16°..+15° (1° apart), 1800 azimuth steps, 10 Hz.
    pub fn ring32() -> Self {
        Self::uniform(32, -16f64.to_radians(), 15f64.to_radians(), 1800, 0.1)
    }

    /// Ring elevations \[rad\], lowest first.
    pub fn elevations(&self) -> &[f64] {
        &self.elevations
    }

    /// Azimuth steps per revolution.
    pub fn azimuth_steps(&self) -> usize {
        self.azimuth_steps
    }

    /// Beams per frame: rings × azimuth steps.
    pub fn points_per_frame(&self) -> usize {
        self.elevations.len() * self.azimuth_steps
    }

    /// Duration of one frame (one head revolution) \[s\].
    pub fn frame_period(&self) -> f64 {
        self.frame_period
    }

    fn beam(&self, k: usize) -> Beam {
        let rings = self.elevations.len();
        let (a, r) = (k / rings, k % rings);
        let frac = a as f64 / self.azimuth_steps as f64;
        Beam {
            time_offset: frac * self.frame_period,
            direction: direction(TAU * frac, self.elevations[r]),
        }
    }
}

/// A wide-field non-repetitive pattern in the style of the Livox Mid-360.
///
/// `lines` emitters share the point stream round-robin. Each sweeps the full azimuth
/// `azimuth_turns_per_frame` times per frame, evenly offset from the others, while
/// its elevation follows a triangle wave between `elevation_min` and `elevation_max`
/// with `elevation_cycles_per_frame` cycles per frame. A non-integer cycle count makes
/// every frame different, so coverage of the field grows with integration time.
/// The pattern is a deterministic function of the global point index: frame `f` is the
/// same every time it is generated.
///
/// This models the sensor's coverage, not the vendor's exact scan curves.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NonRepetitivePattern {
    points_per_frame: usize,
    frame_period: f64,
    lines: usize,
    elevation_min: f64,
    elevation_max: f64,
    azimuth_turns_per_frame: f64,
    elevation_cycles_per_frame: f64,
}

impl NonRepetitivePattern {
    /// Validates and builds a pattern.
    ///
    /// `points_per_frame` in 1..=[`MAX_POINTS_PER_FRAME`] (a collected frame costs 32 bytes a
    /// beam), `lines` ≥ 1, `frame_period` > 0 \[s\] with `frame_period × points_per_frame`
    /// finite (so every beam's time offset is), −π/2 ≤ `elevation_min` < `elevation_max` ≤
    /// π/2 \[rad\], `azimuth_turns_per_frame` and `elevation_cycles_per_frame` in (0, 1e6]
    /// (so their phases stay finite over any number of frames).
    ///
    /// # Errors
    /// [`KinematicsError::InvalidParameter`], [`KinematicsError::NonFinite`] or
    /// [`KinematicsError::NonPositiveDt`] for bad values.
    pub fn try_new(
        points_per_frame: usize,
        frame_period: f64,
        lines: usize,
        elevation_min: f64,
        elevation_max: f64,
        azimuth_turns_per_frame: f64,
        elevation_cycles_per_frame: f64,
    ) -> Result<Self> {
        if points_per_frame > MAX_POINTS_PER_FRAME {
            return Err(invalid(
                "non-repetitive pattern",
                "more than 2^28 beams per frame",
            ));
        }
        if points_per_frame == 0 || lines == 0 {
            return Err(invalid(
                "non-repetitive pattern",
                "needs at least one point and one line",
            ));
        }
        check_dt(frame_period)?;
        // At most 2^28 beams, so the count is exact.
        #[allow(clippy::cast_precision_loss)]
        if !(frame_period * points_per_frame as f64).is_finite() {
            return Err(invalid(
                "non-repetitive pattern",
                "frame period times beams per frame overflows",
            ));
        }
        FieldOfView::band(elevation_min, elevation_max)?;
        if elevation_min == elevation_max {
            return Err(invalid("non-repetitive pattern", "elevation band is empty"));
        }
        for (v, what) in [
            (azimuth_turns_per_frame, "azimuth turns per frame"),
            (elevation_cycles_per_frame, "elevation cycles per frame"),
        ] {
            check_finite(v, what)?;
            if v <= 0.0 {
                return Err(invalid(what, "must be positive"));
            }
            if v > 1e6 {
                return Err(invalid(what, "must be at most 1e6"));
            }
        }
        Ok(Self {
            points_per_frame,
            frame_period,
            lines,
            elevation_min,
            elevation_max,
            azimuth_turns_per_frame,
            elevation_cycles_per_frame,
        })
    }

    /// Mid-360-like: 360° × −7°..+52°, 4 lines, 20,000 points per frame at 10 Hz (200 kHz).
    ///
    /// The elevation cycle count, 100/φ ≈ 61.8 (φ the golden ratio), is far from any
    /// ratio of small integers, so frames do not repeat.
    pub fn mid360() -> Self {
        Self {
            points_per_frame: 20_000,
            frame_period: 0.1,
            lines: 4,
            elevation_min: (-7f64).to_radians(),
            elevation_max: 52f64.to_radians(),
            azimuth_turns_per_frame: 1.0,
            elevation_cycles_per_frame: 50.0 * (5f64.sqrt() - 1.0),
        }
    }

    /// Beams per frame.
    pub fn points_per_frame(&self) -> usize {
        self.points_per_frame
    }

    /// Duration of one frame \[s\].
    pub fn frame_period(&self) -> f64 {
        self.frame_period
    }

    /// Number of emitter lines.
    pub fn lines(&self) -> usize {
        self.lines
    }

    /// Elevation band \[rad\] as (lowest, highest).
    pub fn elevation_band(&self) -> (f64, f64) {
        (self.elevation_min, self.elevation_max)
    }

    fn beam(&self, frame: u64, k: usize) -> Beam {
        let lines = self.lines as f64;
        // The beam's index n over all frames, its line n mod L and ⌊n / L⌋: in integers
        // while n < 2^53, where they equal the float expressions below exactly (and cost no
        // fmod call).
        let exact = u128::from(frame) * (self.points_per_frame as u128) + k as u128;
        let (rem, quot) = if exact < 1 << 53 {
            let l = self.lines as u128;
            ((exact % l) as f64, (exact / l) as f64)
        } else {
            let n = frame as f64 * self.points_per_frame as f64 + k as f64;
            (n % lines, (n / lines).floor())
        };
        let line = rem / lines;
        // Frames measured in units of this line's own samples.
        let f = quot * lines / self.points_per_frame as f64;
        let az = TAU * (self.azimuth_turns_per_frame * f + line).fract();
        let phase = (self.elevation_cycles_per_frame * f + 0.5 * line).fract();
        let tri = 1.0 - (2.0 * phase - 1.0).abs();
        let el = self.elevation_min + (self.elevation_max - self.elevation_min) * tri;
        Beam {
            time_offset: k as f64 * self.frame_period / self.points_per_frame as f64,
            direction: direction(az, el),
        }
    }
}

/// A beam pattern: one of the supported sensor families.
///
/// A pattern is data: for frame `f` it yields the frame's beams, each a time offset from the
/// frame start and a unit direction in the LiDAR frame (x forward, z up).
#[derive(Debug, Clone, PartialEq)]
pub enum BeamPattern {
    /// A multi-ring spinning sensor.
    Spinning(SpinningPattern),
    /// A wide-field non-repetitive sensor.
    NonRepetitive(NonRepetitivePattern),
}

impl BeamPattern {
    /// Duration of one frame \[s\].
    pub fn frame_period(&self) -> f64 {
        match self {
            Self::Spinning(p) => p.frame_period(),
            Self::NonRepetitive(p) => p.frame_period(),
        }
    }

    /// Number of beams in one frame.
    pub fn points_per_frame(&self) -> usize {
        match self {
            Self::Spinning(p) => p.points_per_frame(),
            Self::NonRepetitive(p) => p.points_per_frame(),
        }
    }

    /// The angular field the pattern's beams cover (full azimuth for both families).
    pub fn field_of_view(&self) -> FieldOfView {
        let (lo, hi) = match self {
            Self::Spinning(p) => (p.elevations[0], p.elevations[p.elevations.len() - 1]),
            Self::NonRepetitive(p) => (p.elevation_min, p.elevation_max),
        };
        // Both bounds were validated to lie in [−π/2, π/2] in order.
        FieldOfView {
            azimuth_min: 0.0,
            azimuth_width: TAU,
            elevation_min: lo,
            elevation_max: hi,
            sin_el_min: lo.sin(),
            sin_el_max: hi.sin(),
            center_cos: -1.0,
            center_sin: 0.0,
            cos_half_width: -1.0,
        }
    }

    /// The beams of frame `frame_index`, in time order.
    pub fn frame(&self, frame_index: u64) -> Frame<'_> {
        Frame {
            pattern: self,
            frame_index,
            next: 0,
            len: self.points_per_frame(),
        }
    }

    /// Beam `k` of frame `frame_index`, or `None` when `k` is not below
    /// [`BeamPattern::points_per_frame`]: the same beam [`BeamPattern::frame`] yields `k`-th,
    /// computed on its own, so a caller can generate a frame's beams in any order or in
    /// parallel.
    ///
    /// # Example
    /// ```
    /// use lidar_kinematics::LidarSensor;
    /// let pattern = LidarSensor::mid360().pattern().clone();
    /// assert_eq!(pattern.beam(3, 17), pattern.frame(3).nth(17));
    /// assert_eq!(pattern.beam(3, pattern.points_per_frame()), None);
    /// ```
    pub fn beam(&self, frame_index: u64, k: usize) -> Option<Beam> {
        (k < self.points_per_frame()).then(|| match self {
            Self::Spinning(p) => p.beam(k),
            Self::NonRepetitive(p) => p.beam(frame_index, k),
        })
    }

    /// Appends the beams of frame `frame_index` to `out` (reuses its capacity).
    ///
    /// `out` grows to [`BeamPattern::points_per_frame`] beams of 32 bytes each (up to 8 GiB
    /// at [`MAX_POINTS_PER_FRAME`]); iterate [`BeamPattern::frame`] instead to hold none.
    pub fn fill_frame(&self, frame_index: u64, out: &mut Vec<Beam>) {
        out.clear();
        out.extend(self.frame(frame_index));
    }
}

impl From<SpinningPattern> for BeamPattern {
    fn from(p: SpinningPattern) -> Self {
        Self::Spinning(p)
    }
}

impl From<NonRepetitivePattern> for BeamPattern {
    fn from(p: NonRepetitivePattern) -> Self {
        Self::NonRepetitive(p)
    }
}

/// Iterator over the beams of one frame, from [`BeamPattern::frame`].
#[derive(Debug, Clone)]
pub struct Frame<'a> {
    pattern: &'a BeamPattern,
    frame_index: u64,
    next: usize,
    len: usize,
}

impl Iterator for Frame<'_> {
    type Item = Beam;

    fn next(&mut self) -> Option<Beam> {
        if self.next >= self.len {
            return None;
        }
        let k = self.next;
        self.next += 1;
        self.pattern.beam(self.frame_index, k)
    }

    fn nth(&mut self, n: usize) -> Option<Beam> {
        self.next = self.next.saturating_add(n).min(self.len);
        self.next()
    }

    fn size_hint(&self) -> (usize, Option<usize>) {
        let n = self.len - self.next;
        (n, Some(n))
    }
}

impl ExactSizeIterator for Frame<'_> {}

/// A LiDAR: beam pattern, field of view and range limits.
///
/// # Example
/// ```
/// use lidar_kinematics::LidarSensor;
/// let s = LidarSensor::mid360();
/// assert_eq!(s.pattern().points_per_frame(), 20_000);
/// assert_eq!(s.range().max(), 40.0);
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct LidarSensor {
    pattern: BeamPattern,
    fov: FieldOfView,
    range: RangeLimits,
}

impl LidarSensor {
    /// A sensor with the pattern's own field of view.
    pub fn new(pattern: impl Into<BeamPattern>, range: RangeLimits) -> Self {
        let pattern = pattern.into();
        Self {
            fov: pattern.field_of_view(),
            pattern,
            range,
        }
    }

    /// Replaces the field of view used by the visibility gate (e.g. to model occlusion by the airframe).
    pub fn with_field_of_view(mut self, fov: FieldOfView) -> Self {
        self.fov = fov;
        self
    }

    /// [`SpinningPattern::ring16`] with a 0.3–100 m range.
    pub fn ring16() -> Self {
        Self::new(
            SpinningPattern::ring16(),
            RangeLimits {
                min: 0.3,
                max: 100.0,
            },
        )
    }

    /// [`SpinningPattern::ring32`] with a 0.3–100 m range.
    pub fn ring32() -> Self {
        Self::new(
            SpinningPattern::ring32(),
            RangeLimits {
                min: 0.3,
                max: 100.0,
            },
        )
    }

    /// [`NonRepetitivePattern::mid360`] with a 0.1–40 m range.
    pub fn mid360() -> Self {
        Self::new(
            NonRepetitivePattern::mid360(),
            RangeLimits {
                min: 0.1,
                max: 40.0,
            },
        )
    }

    /// The beam pattern.
    pub fn pattern(&self) -> &BeamPattern {
        &self.pattern
    }

    /// The field of view used by the visibility gate.
    pub fn field_of_view(&self) -> &FieldOfView {
        &self.fov
    }

    /// The range limits.
    pub fn range(&self) -> &RangeLimits {
        &self.range
    }

    /// Whether a point given in the LiDAR frame is within range and inside the field of view.
    #[inline]
    pub fn sees_in_lidar_frame(&self, p: &Point3<f64>) -> bool {
        let n = p.coords.norm();
        if n > 0.0 && n.is_finite() {
            return self.range.contains(n) && self.fov.contains_with_norm(&p.coords, n);
        }
        // A distance whose square under- or overflows (or the origin, or a non-finite point).
        rescaled(&p.coords).is_some_and(|d| {
            let m = d.norm();
            self.range.contains(p.coords.amax() * m) && self.fov.contains_with_norm(&d, m)
        })
    }

    /// Whether the LiDAR, at motor angle θ \[rad\] on a body at `body_pose`, can see a world point
    /// (range and field of view; occlusion is the caller's business).
    ///
    /// # Errors
    /// [`KinematicsError::NonFinite`] or [`KinematicsError::NotUnitRotation`] for a bad pose or angle.
    pub fn can_see(
        &self,
        chain: &KinematicChain,
        body_pose: &Isometry3<f64>,
        theta: f64,
        world_point: &Point3<f64>,
    ) -> Result<bool> {
        Ok(self
            .visibility_gate(chain, body_pose, theta)?
            .contains(world_point))
    }

    /// The visibility test for one pose and motor angle, set up once for many points.
    ///
    /// # Errors
    /// As [`LidarSensor::can_see`].
    pub fn visibility_gate(
        &self,
        chain: &KinematicChain,
        body_pose: &Isometry3<f64>,
        theta: f64,
    ) -> Result<VisibilityGate<'_>> {
        let world_to_lidar = chain.lidar_pose(body_pose, theta)?.inverse();
        Ok(VisibilityGate {
            sensor: self,
            rotation: world_to_lidar.rotation.to_rotation_matrix().into_inner(),
            translation: world_to_lidar.translation.vector,
        })
    }
}

/// [`LidarSensor::can_see`] prepared for one pose and motor angle.
///
/// # Example
/// ```
/// use lidar_kinematics::{KinematicChain, LidarSensor};
/// use nalgebra::{Isometry3, Point3};
/// # fn main() -> Result<(), lidar_kinematics::KinematicsError> {
/// let sensor = LidarSensor::mid360();
/// let gate = sensor.visibility_gate(&KinematicChain::default(), &Isometry3::identity(), 0.0)?;
/// assert!(gate.contains(&Point3::new(5.0, 0.0, 2.0)));   // 22° up
/// assert!(!gate.contains(&Point3::new(5.0, 0.0, -2.0))); // 22° down
/// # Ok(()) }
/// ```
#[derive(Debug, Clone, Copy)]
pub struct VisibilityGate<'a> {
    sensor: &'a LidarSensor,
    rotation: Matrix3<f64>,
    translation: Vector3<f64>,
}

impl VisibilityGate<'_> {
    /// Whether the world point is within range and inside the field of view.
    #[inline]
    pub fn contains(&self, world_point: &Point3<f64>) -> bool {
        let p = self.rotation * world_point.coords + self.translation;
        self.sensor.sees_in_lidar_frame(&Point3::from(p))
    }
}

/// `v` divided by its largest component's magnitude, for a finite non-zero `v`.
fn rescaled(v: &Vector3<f64>) -> Option<Vector3<f64>> {
    let s = v.amax();
    (s > 0.0 && s.is_finite()).then(|| v / s)
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn presets_have_the_documented_shape() {
        let p = SpinningPattern::ring32();
        assert_eq!(p.elevations().len(), 32);
        assert!((p.elevations()[0] - (-16f64).to_radians()).abs() < 1e-12);
        assert!((p.elevations()[31] - 15f64.to_radians()).abs() < 1e-12);
        let p = SpinningPattern::ring16();
        assert!((p.elevations()[1] - p.elevations()[0] - 2f64.to_radians()).abs() < 1e-12);
        assert_eq!(
            BeamPattern::from(NonRepetitivePattern::mid360()).points_per_frame(),
            20_000
        );
    }

    #[test]
    fn frames_are_time_ordered_unit_and_inside_fov() {
        for sensor in [
            LidarSensor::ring16(),
            LidarSensor::ring32(),
            LidarSensor::mid360(),
        ] {
            let pattern = sensor.pattern();
            let fov = pattern.field_of_view();
            let beams: Vec<Beam> = pattern.frame(3).collect();
            assert_eq!(beams.len(), pattern.points_per_frame());
            assert!(
                beams
                    .windows(2)
                    .all(|w| w[0].time_offset <= w[1].time_offset)
            );
            assert!(
                beams
                    .iter()
                    .all(|b| b.time_offset >= 0.0 && b.time_offset < pattern.frame_period())
            );
            for b in &beams {
                assert!((b.direction.norm() - 1.0).abs() < 1e-12);
                // Shrink toward the band's centre so boundary beams count as inside.
                let el = b.direction.z.asin();
                assert!(el >= fov.elevation_min() - 1e-12 && el <= fov.elevation_max() + 1e-12);
            }
        }
    }

    /// The Mid-360-like pattern covers its field: every 5° × 5° cell of the band is hit in one frame,
    /// and two frames differ.
    #[test]
    fn non_repetitive_pattern_covers_and_does_not_repeat() {
        let pattern = BeamPattern::from(NonRepetitivePattern::mid360());
        let (el_lo, el_hi) = (-7.0, 52.0);
        let cells_el = ((el_hi - el_lo) / 5.0f64).floor() as usize;
        let mut hit = vec![false; 72 * cells_el];
        for b in pattern.frame(0) {
            let az = b
                .direction
                .y
                .atan2(b.direction.x)
                .to_degrees()
                .rem_euclid(360.0);
            let el = b.direction.z.asin().to_degrees();
            let i = (az / 5.0) as usize;
            let j = ((el - el_lo) / 5.0) as usize;
            if j < cells_el {
                hit[j * 72 + i.min(71)] = true;
            }
        }
        let missing = hit.iter().filter(|h| !**h).count();
        assert_eq!(missing, 0, "{missing} cells not hit");
        let f0: Vec<Beam> = pattern.frame(0).take(100).collect();
        let f1: Vec<Beam> = pattern.frame(1).take(100).collect();
        assert!(
            f0.iter()
                .zip(&f1)
                .any(|(a, b)| (a.direction.into_inner() - b.direction.into_inner()).norm() > 1e-3)
        );
        // Deterministic: the same frame twice is identical.
        let again: Vec<Beam> = pattern.frame(0).take(100).collect();
        assert_eq!(f0, again);
    }

    #[test]
    fn fov_with_limited_azimuth() {
        let fov = FieldOfView::try_new(3.0, 3.5, -0.1, 0.1).unwrap(); // wraps through ±π
        assert!(fov.contains(&Vector3::new(-1.0, 0.0, 0.0)));
        assert!(fov.contains(&Vector3::new(-1.0, -0.2, 0.0)));
        assert!(!fov.contains(&Vector3::new(-1.0, 0.5, 0.0)));
        assert!(!fov.contains(&Vector3::zeros()));
        assert!(!fov.contains(&Vector3::new(f64::NAN, 0.0, 0.0)));
    }

    proptest! {
        /// The beam's line and sample count in integers equal the float formula they replace,
        /// bit for bit, for any frame and line count.
        #[test]
        fn integer_beam_indices_equal_the_float_formula(
            frame in prop_oneof![0u64..100_000, (1u64 << 40)..(1u64 << 40) + 1000],
            k in 0usize..20_000,
            lines in 1usize..7,
        ) {
            let p = NonRepetitivePattern { lines, ..NonRepetitivePattern::mid360() };
            let n = frame as f64 * p.points_per_frame as f64 + k as f64;
            let l = lines as f64;
            let f = (n / l).floor() * l / p.points_per_frame as f64;
            let az = TAU * (p.azimuth_turns_per_frame * f + (n % l) / l).fract();
            let phase = (p.elevation_cycles_per_frame * f + 0.5 * ((n % l) / l)).fract();
            let el = p.elevation_min + (p.elevation_max - p.elevation_min) * (1.0 - (2.0 * phase - 1.0).abs());
            let b = p.beam(frame, k);
            prop_assert_eq!(b.direction.into_inner(), direction(az, el).into_inner());
        }
    }

    proptest! {
        /// Random access gives the iterator's beams, for both families; `nth` skips to the
        /// same beam and ends the frame where the iterator does.
        #[test]
        fn random_access_beams_equal_the_frame_iterator(
            frame in 0u64..1000,
            k in 0usize..20_100,
            spinning in any::<bool>(),
        ) {
            let pattern = if spinning {
                LidarSensor::ring16().pattern().clone()
            } else {
                LidarSensor::mid360().pattern().clone()
            };
            let n = pattern.points_per_frame();
            // Walked one by one (`skip` would call `nth` itself).
            let mut walked = None;
            for (i, b) in pattern.frame(frame).enumerate() {
                if i == k {
                    walked = Some(b);
                }
            }
            prop_assert_eq!(pattern.beam(frame, k), walked);
            prop_assert_eq!(pattern.frame(frame).nth(k), walked);
            prop_assert_eq!(walked.is_some(), k < n);
            let mut it = pattern.frame(frame);
            let _ = it.nth(k);
            prop_assert_eq!(it.len(), n.saturating_sub(k + 1));
        }
    }

    proptest! {
        #[test]
        fn azimuth_test_matches_atan2(
            az_min in -7.0f64..7.0, width in 0.0f64..6.3,
            a in -4.0f64..4.0, r in 0.1f64..1.0, z in -0.04f64..0.04,
        ) {
            let fov = FieldOfView::try_new(az_min, az_min + width, -0.5, 0.5).unwrap();
            let (x, y) = (r * a.cos(), r * a.sin());
            let d = Vector3::new(x, y, z);
            let off = (y.atan2(x) - az_min).rem_euclid(TAU);
            // Away from the interval's edges (rounding decides exactly on them).
            // The cosine test resolves angles to about 1e-8 rad near a half width of 0 or π.
            prop_assume!((off - width).abs() > 1e-6 && off > 1e-6 && (TAU - off) > 1e-6);
            prop_assert_eq!(fov.contains(&d), width >= TAU || off <= width);
        }

        /// The gate agrees with transforming the point by the chain and testing range and angles.
        #[test]
        fn gate_matches_definition(
            theta in -10.0f64..10.0,
            p in nalgebra::proptest::vector(-60.0f64..60.0, nalgebra::Const::<3>),
            t in nalgebra::proptest::vector(-5.0f64..5.0, nalgebra::Const::<3>),
            r in nalgebra::proptest::vector(-1.0f64..1.0, nalgebra::Const::<3>),
        ) {
            let chain = KinematicChain::new(crate::Extrinsics::try_new(
                Isometry3::new(Vector3::new(0.0, 0.05, 0.0), Vector3::new(FRAC_PI_2, 0.0, 0.0)),
                Isometry3::translation(0.1, 0.0, -0.05),
            ).unwrap());
            let body = Isometry3::new(t, r);
            let sensor = LidarSensor::mid360();
            let world = Point3::from(p);
            let local = chain.world_to_lidar(&body, theta, &world).unwrap();
            let range = local.coords.norm();
            let el = (local.z / range).asin();
            let expected = (0.1..=40.0).contains(&range)
                && el >= (-7f64).to_radians() - 1e-12 && el <= 52f64.to_radians() + 1e-12;
            // Skip points within 1e-9 of a boundary, where rounding may go either way.
            let near_edge = (range - 40.0).abs() < 1e-9 || (range - 0.1).abs() < 1e-9
                || (el - (-7f64).to_radians()).abs() < 1e-9 || (el - 52f64.to_radians()).abs() < 1e-9;
            if !near_edge {
                prop_assert_eq!(sensor.can_see(&chain, &body, theta, &world).unwrap(), expected);
            }
        }
    }

    #[test]
    fn bad_parameters_are_typed_errors() {
        assert!(matches!(
            SpinningPattern::try_new(vec![], 10, 0.1),
            Err(KinematicsError::Empty { .. })
        ));
        assert!(SpinningPattern::try_new(vec![0.1, 0.0], 10, 0.1).is_err());
        assert!(SpinningPattern::try_new(vec![0.0], 0, 0.1).is_err());
        assert!(matches!(
            SpinningPattern::try_new(vec![0.0], 10, 0.0),
            Err(KinematicsError::NonPositiveDt(_))
        ));
        assert!(matches!(
            SpinningPattern::try_new(vec![f64::NAN], 10, 0.1),
            Err(KinematicsError::NonFinite { .. })
        ));
        assert!(SpinningPattern::try_new(vec![2.0], 10, 0.1).is_err());
        assert!(SpinningPattern::try_new(vec![0.0, 0.1], usize::MAX, 0.1).is_err());
        assert!(NonRepetitivePattern::try_new(usize::MAX, 0.1, 4, 0.0, 1.0, 1.0, 1.5).is_err());
        assert!(NonRepetitivePattern::try_new(0, 0.1, 4, 0.0, 1.0, 1.0, 1.5).is_err());
        assert!(NonRepetitivePattern::try_new(10, 0.1, 4, 1.0, 0.0, 1.0, 1.5).is_err());
        assert!(NonRepetitivePattern::try_new(10, 0.1, 4, 0.0, 1.0, f64::NAN, 1.5).is_err());
        assert!(NonRepetitivePattern::try_new(10, 0.1, 4, 0.0, 1.0, 1.0, -1.5).is_err());
        assert!(NonRepetitivePattern::try_new(10, 0.1, 4, 0.0, 1.0, 1.0, 1.5).is_ok());
        assert!(RangeLimits::try_new(-1.0, 1.0).is_err());
        assert!(RangeLimits::try_new(0.0, f64::INFINITY).is_err());
        assert!(FieldOfView::try_new(1.0, 0.0, 0.0, 0.1).is_err());
        assert!(FieldOfView::try_new(0.0, 1.0, 0.0, 2.0).is_err());
        let sensor = LidarSensor::ring16();
        assert!(matches!(
            sensor.can_see(
                &KinematicChain::default(),
                &Isometry3::identity(),
                f64::NAN,
                &Point3::origin()
            ),
            Err(KinematicsError::NonFinite { .. })
        ));
    }

    /// The memory figures in the docs of `MAX_POINTS_PER_FRAME` and `fill_frame` assume this.
    #[test]
    fn a_beam_is_32_bytes() {
        assert_eq!(core::mem::size_of::<Beam>(), 32);
    }
}
