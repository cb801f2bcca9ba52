//! Motion compensation ("deskew") of one LiDAR frame: see [`Deskewer`].

use nalgebra::{Isometry3, Matrix3, Point3, UnitQuaternion, Vector3};

use crate::angle::wrap_to_pi;
use crate::chain::{KinematicChain, check_len};
use crate::error::{KinematicsError, Result, check_finite, check_pose};
use crate::so3;
use crate::trig::sin_cos_reduced;

/// A body pose T_B^W at a time \[s\].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PoseSample {
    /// Time \[s\].
    pub time: f64,
    /// Body pose in the world.
    pub pose: Isometry3<f64>,
}

impl PoseSample {
    /// A pose sample.
    pub fn new(time: f64, pose: Isometry3<f64>) -> Self {
        Self { time, pose }
    }
}

/// A motor angle \[rad\] at a time \[s\], e.g. an encoder reading.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AngleSample {
    /// Time \[s\].
    pub time: f64,
    /// Motor angle \[rad\], wrapped or unwrapped.
    pub angle: f64,
}

impl AngleSample {
    /// An angle sample.
    pub fn new(time: f64, angle: f64) -> Self {
        Self { time, angle }
    }
}

/// A point in the LiDAR frame \[m\] with its measurement time \[s\].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TimedPoint {
    /// Measurement time \[s\].
    pub time: f64,
    /// The point in the LiDAR frame at that time \[m\].
    pub point: Point3<f64>,
}

impl TimedPoint {
    /// A timed point.
    pub fn new(time: f64, point: Point3<f64>) -> Self {
        Self { time, point }
    }
}

/// The frame the deskewed points are expressed in.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum DeskewTarget {
    /// The world frame.
    World,
    /// The body frame at the given time \[s\] (e.g. the frame end), interpolated like the points.
    BodyAt(f64),
}

/// One span between consecutive pose samples, prepared for interpolation.
#[derive(Debug, Clone, Copy)]
struct PoseSpan {
    t0: f64,
    t1: f64,
    inv_dt: f64,
    q0: UnitQuaternion<f64>,
    p0: Vector3<f64>,
    dp: Vector3<f64>,
    /// Rotation axis of R0ᵀR1 (unit, or zero when there is no rotation).
    axis: Vector3<f64>,
    /// Rotation angle of R0ᵀR1 \[rad\].
    angle: f64,
}

impl PoseSpan {
    fn new(a: &PoseSample, b: &PoseSample) -> Self {
        let phi = so3::log(&(a.pose.rotation.inverse() * b.pose.rotation));
        let angle = phi.norm();
        let dt = b.time - a.time;
        Self {
            t0: a.time,
            t1: b.time,
            inv_dt: if dt > 0.0 { 1.0 / dt } else { 0.0 },
            q0: a.pose.rotation,
            p0: a.pose.translation.vector,
            dp: b.pose.translation.vector - a.pose.translation.vector,
            axis: if angle > 0.0 {
                phi / angle
            } else {
                Vector3::zeros()
            },
            angle,
        }
    }

    /// The interpolated pose at time `t` in [t0, t1].
    fn pose_at(&self, t: f64) -> Isometry3<f64> {
        let s = (t - self.t0) * self.inv_dt;
        Isometry3::from_parts(
            (self.p0 + self.dp * s).into(),
            self.q0 * so3::exp(&(self.axis * (self.angle * s))),
        )
    }
}

/// A pose span with the motor-base extrinsic and the output transform folded in, for the
/// hot loop. For a point r in the rotated motor frame (r = R_z(θ) T_L^M p) at span fraction s:
///
/// out = G (p0 + s Δp + R0 Rod_k(sα) (R_MB r + t_MB)) + g
///     = base + s vel + Rod_{G R0 k}(sα) (A r + c),  A = G R0 R_MB,  c = G R0 t_MB,
///
/// using R Rod_k(α) = Rod_{Rk}(α) R for any rotation R.
#[derive(Debug, Clone, Copy)]
struct FoldedSpan {
    t0: f64,
    t1: f64,
    inv_dt: f64,
    angle: f64,
    a: Matrix3<f64>,
    c: Vector3<f64>,
    axis: Vector3<f64>,
    base: Vector3<f64>,
    vel: Vector3<f64>,
}

impl FoldedSpan {
    /// Folds the motor base (r_mb, t_mb) and the output transform (g_r, g_t) into `span`.
    fn new(
        span: &PoseSpan,
        r_mb: &Matrix3<f64>,
        t_mb: &Vector3<f64>,
        g_r: &Matrix3<f64>,
        g_t: &Vector3<f64>,
    ) -> Self {
        let r0 = span.q0.to_rotation_matrix().into_inner();
        let g_r0 = g_r * r0;
        Self {
            t0: span.t0,
            t1: span.t1,
            inv_dt: span.inv_dt,
            angle: span.angle,
            a: g_r0 * r_mb,
            c: g_r0 * t_mb,
            axis: g_r0 * span.axis,
            base: g_r * span.p0 + g_t,
            vel: g_r * span.dp,
        }
    }

    /// Fraction of the span at time `t`.
    #[inline(always)]
    fn fraction(&self, t: f64) -> f64 {
        (t - self.t0) * self.inv_dt
    }

    /// Maps a point of the rotated motor frame to the output frame at span fraction `s`,
    /// given (sin, cos) of the partial rotation angle s·angle.
    #[inline(always)]
    fn apply(&self, s: f64, (sn, cs): (f64, f64), r: &Vector3<f64>) -> Vector3<f64> {
        let x = self.a * r + self.c;
        let k = &self.axis;
        // Rodrigues' formula: slerp's partial rotation.
        let rot = x * cs + k.cross(&x) * sn + k * (k.dot(&x) * (1.0 - cs));
        rot + self.base + self.vel * s
    }
}

/// Points processed per pass of the deskew loop (its scratch lives on the stack: 16 KiB).
const CHUNK: usize = 256;

/// One span between consecutive angle samples.
#[derive(Debug, Clone, Copy)]
struct AngleSpan {
    t0: f64,
    t1: f64,
    theta0: f64,
    rate: f64,
}

/// Validates a time-stamped sequence: non-empty, finite, strictly increasing, and with
/// finite gaps of finite reciprocal (interpolation scales by 1 / gap; an infinite factor
/// times a zero offset would be NaN).
fn check_times(times: impl Iterator<Item = f64>, what: &'static str) -> Result<()> {
    let mut last = f64::NEG_INFINITY;
    let mut n = 0;
    for (i, t) in times.enumerate() {
        check_finite(t, "sample time")?;
        if t <= last {
            return Err(KinematicsError::Unsorted { what, index: i });
        }
        if i > 0 {
            let gap = t - last;
            check_finite(gap, "gap between sample times")?;
            check_finite(1.0 / gap, "reciprocal of a gap between sample times")?;
        }
        last = t;
        n += 1;
    }
    if n == 0 {
        return Err(KinematicsError::Empty { what });
    }
    Ok(())
}

/// Validates pose samples: finite unit poses whose consecutive position steps are finite
/// (a step that overflows would turn the interpolation into NaN).
fn check_poses(poses: &[PoseSample]) -> Result<()> {
    for p in poses {
        check_pose(&p.pose, "pose sample")?;
    }
    for w in poses.windows(2) {
        let step = w[1].pose.translation.vector - w[0].pose.translation.vector;
        if !step.iter().all(|v| v.is_finite()) {
            return Err(KinematicsError::NonFinite {
                what: "position step between pose samples",
            });
        }
    }
    Ok(())
}

/// Index of the first span ending at or after `t` (the last span for a later `t`), trying
/// `hint` first (points usually come in time order). The answer does not depend on the hint:
/// a time on the boundary of two contiguous spans goes to the earlier one whatever the
/// previous point was, so a point's deskew depends on that point alone and a frame may be
/// deskewed in chunks.
#[inline]
fn find_span<S>(spans: &[S], hint: usize, t: f64, bounds: impl Fn(&S) -> (f64, f64)) -> usize {
    if let Some(s) = spans.get(hint) {
        let (a, b) = bounds(s);
        let after_previous = match hint.checked_sub(1).and_then(|p| spans.get(p)) {
            Some(p) => bounds(p).1 < t,
            None => true,
        };
        if t >= a && t <= b && after_previous {
            return hint;
        }
    }
    let i = spans.partition_point(|s| bounds(s).1 < t);
    i.min(spans.len() - 1)
}

fn out_of_range(what: &'static str, time: f64, start: f64, end: f64) -> KinematicsError {
    KinematicsError::TimeOutOfRange {
        what,
        time,
        start,
        end,
    }
}

/// Motion compensation ("deskew") of LiDAR frames; owns scratch memory so repeated calls
/// do not allocate.
///
/// Each point of a frame is measured at its own time, while the body moves and
/// the motor turns. Deskewing maps every point through the kinematic chain (1)
/// with the body pose and motor angle *at its own timestamp*:
/// - body poses are interpolated between the given samples, rotation by slerp
///   (constant angular velocity in the body frame) and position linearly;
/// - motor angles are interpolated linearly between encoder samples along the
///   shorter arc, so wrapped encoder readings work as long as consecutive samples
///   are less than π apart.
///
/// The output is either in the world frame or in the body frame at a chosen time
/// (usually the frame end), see [`DeskewTarget`].
///
/// # Example
/// ```
/// use lidar_kinematics::{AngleSample, DeskewTarget, Deskewer, KinematicChain, PoseSample, TimedPoint};
/// use nalgebra::{Isometry3, Point3};
///
/// # fn main() -> Result<(), lidar_kinematics::KinematicsError> {
/// let poses = [
///     PoseSample::new(0.0, Isometry3::translation(0.0, 0.0, 0.0)),
///     PoseSample::new(0.1, Isometry3::translation(0.2, 0.0, 0.0)), // 2 m/s along x
/// ];
/// let angles = [AngleSample::new(0.0, 0.0), AngleSample::new(0.1, 0.0)];
/// // The same world point (5, 0, 0), seen at the start and at the end of the frame.
/// let points = [
///     TimedPoint::new(0.0, Point3::new(5.0, 0.0, 0.0)),
///     TimedPoint::new(0.1, Point3::new(4.8, 0.0, 0.0)),
/// ];
/// let mut deskewer = Deskewer::new(KinematicChain::default());
/// let world = deskewer.deskew_to_vec(&poses, &angles, &points, DeskewTarget::World)?;
/// assert!((world[0] - world[1]).norm() < 1e-12);
/// # Ok(()) }
/// ```
#[derive(Debug, Clone)]
pub struct Deskewer {
    chain: KinematicChain,
    pose_spans: Vec<PoseSpan>,
    folded: Vec<FoldedSpan>,
    angle_spans: Vec<AngleSpan>,
}

impl Deskewer {
    /// A deskewer for one kinematic chain.
    pub fn new(chain: KinematicChain) -> Self {
        Self {
            chain,
            pose_spans: Vec::new(),
            folded: Vec::new(),
            angle_spans: Vec::new(),
        }
    }

    /// The kinematic chain.
    pub fn chain(&self) -> &KinematicChain {
        &self.chain
    }

    fn prepare(&mut self, poses: &[PoseSample], angles: &[AngleSample]) -> Result<()> {
        check_times(poses.iter().map(|p| p.time), "pose samples")?;
        check_times(angles.iter().map(|a| a.time), "motor angle samples")?;
        check_poses(poses)?;
        for a in angles {
            check_finite(a.angle, "motor angle sample")?;
        }
        self.pose_spans.clear();
        if let [only] = poses {
            self.pose_spans.push(PoseSpan::new(only, only));
        }
        self.pose_spans
            .extend(poses.windows(2).map(|w| PoseSpan::new(&w[0], &w[1])));
        self.angle_spans.clear();
        if let [only] = angles {
            self.angle_spans.push(AngleSpan {
                t0: only.time,
                t1: only.time,
                theta0: wrap_to_pi(only.angle),
                rate: 0.0,
            });
        }
        for w in angles.windows(2) {
            // Finite angles can still differ by more than f64::MAX.
            let step = check_finite(w[1].angle - w[0].angle, "step between motor angle samples")?;
            // A tiny gap can overflow the rate even when 1 / gap is finite.
            let rate = check_finite(
                wrap_to_pi(step) / (w[1].time - w[0].time),
                "motor angle rate between samples",
            )?;
            self.angle_spans.push(AngleSpan {
                t0: w[0].time,
                t1: w[1].time,
                // Only sin θ and cos θ are used: wrapping keeps θ small for the fast sine.
                theta0: wrap_to_pi(w[0].angle),
                rate,
            });
        }
        Ok(())
    }

    /// Deskews `points` into `out` (same length).
    ///
    /// Pose and angle samples must be non-empty, finite and strictly increasing in time; every
    /// point time must lie within both spans, and a `BodyAt` time within the pose span (it
    /// needs no motor angle): nothing is extrapolated.
    /// A point with non-finite coordinates maps to non-finite coordinates.
    ///
    /// # Errors
    /// - [`KinematicsError::Empty`] for no pose or no angle samples;
    /// - [`KinematicsError::Unsorted`] for sample times that do not strictly increase;
    /// - [`KinematicsError::NonFinite`] for a non-finite sample, point time or `BodyAt` time,
    ///   and for finite samples whose interpolation would not be finite: a gap between
    ///   consecutive sample times that is infinite or whose reciprocal is (below about
    ///   5.6e-309 s), a position step between poses or an angle step between motor angles
    ///   that overflows, a motor angle rate (wrapped step / gap) that overflows, or poses
    ///   whose composition with the target frame overflows (translations near `f64::MAX`);
    /// - [`KinematicsError::NotUnitRotation`] for a pose whose rotation is not of unit norm;
    /// - [`KinematicsError::LengthMismatch`] unless `out` is as long as `points`;
    /// - [`KinematicsError::TimeOutOfRange`] for a point or `BodyAt` time outside the samples.
    ///
    /// On error `out` may be partly written.
    pub fn deskew(
        &mut self,
        poses: &[PoseSample],
        angles: &[AngleSample],
        points: &[TimedPoint],
        target: DeskewTarget,
        out: &mut [Point3<f64>],
    ) -> Result<()> {
        check_len("deskew output", points.len(), out.len())?;
        self.prepare(poses, angles)?;
        let (pose_start, pose_end) = (
            self.pose_spans[0].t0,
            self.pose_spans[self.pose_spans.len() - 1].t1,
        );
        let (angle_start, angle_end) = (
            self.angle_spans[0].t0,
            self.angle_spans[self.angle_spans.len() - 1].t1,
        );
        let start = pose_start.max(angle_start);
        let end = pose_end.min(angle_end);

        // World → output frame, x ↦ G x + g.
        let (g_r, g_t) = match target {
            DeskewTarget::World => (Matrix3::identity(), Vector3::zeros()),
            DeskewTarget::BodyAt(t) => {
                check_finite(t, "deskew target time")?;
                if t < pose_start || t > pose_end {
                    return Err(out_of_range("pose samples", t, pose_start, pose_end));
                }
                let i = find_span(&self.pose_spans, 0, t, |s| (s.t0, s.t1));
                let inv = self.pose_spans[i].pose_at(t).inverse();
                (
                    inv.rotation.to_rotation_matrix().into_inner(),
                    inv.translation.vector,
                )
            }
        };
        let mb = self.chain.extrinsics().motor_base_in_body();
        let (r_mb, t_mb) = (
            mb.rotation.to_rotation_matrix().into_inner(),
            mb.translation.vector,
        );
        self.folded.clear();
        self.folded.extend(
            self.pose_spans
                .iter()
                .map(|span| FoldedSpan::new(span, &r_mb, &t_mb, &g_r, &g_t)),
        );
        // Finite poses whose composition with the target frame overflows (translations near
        // f64::MAX): an error, not NaN points.
        let finite = |v: &Vector3<f64>| v.iter().all(|x| x.is_finite());
        if !(finite(&g_t)
            && self
                .folded
                .iter()
                .all(|f| finite(&f.base) && finite(&f.vel) && finite(&f.c)))
        {
            return Err(KinematicsError::NonFinite {
                what: "pose composed with the deskew target frame",
            });
        }

        // Three passes per chunk: locate each point's spans (branchy), evaluate all sines and
        // cosines (a branch-free loop that vectorises), then compose the transforms.
        let (mut pi, mut ai) = (0, 0);
        let mut span = [0usize; CHUNK];
        let mut frac = [0.0f64; CHUNK];
        let mut args = [0.0f64; 2 * CHUNK];
        let mut sc = [(0.0f64, 0.0f64); 2 * CHUNK];
        for (pts, outs) in points.chunks(CHUNK).zip(out.chunks_mut(CHUNK)) {
            let n = pts.len();
            for (k, p) in pts.iter().enumerate() {
                let t = p.time;
                if !(t >= start && t <= end) {
                    check_finite(t, "point time")?;
                    let (what, s, e) = if t < pose_start || t > pose_end {
                        ("pose samples", pose_start, pose_end)
                    } else {
                        ("motor angle samples", angle_start, angle_end)
                    };
                    return Err(out_of_range(what, t, s, e));
                }
                ai = find_span(&self.angle_spans, ai, t, |s| (s.t0, s.t1));
                let a = &self.angle_spans[ai];
                pi = find_span(&self.folded, pi, t, |s| (s.t0, s.t1));
                let ps = &self.folded[pi];
                span[k] = pi;
                frac[k] = ps.fraction(t);
                // s·angle ∈ [0, π]; |θ| ≤ 2π as θ0 is wrapped and a span adds at most π:
                // both inside the fast sine's range.
                args[2 * k] = frac[k] * ps.angle;
                args[2 * k + 1] = a.theta0 + a.rate * (t - a.t0);
            }
            for (out, &x) in sc[..2 * n].iter_mut().zip(&args[..2 * n]) {
                *out = sin_cos_reduced(x);
            }
            for (k, (o, p)) in outs.iter_mut().zip(pts).enumerate() {
                let r = self
                    .chain
                    .lidar_to_motor_unchecked(sc[2 * k + 1], &p.point.coords);
                o.coords = self.folded[span[k]].apply(frac[k], sc[2 * k], &r);
            }
        }
        Ok(())
    }

    /// [`Deskewer::deskew`] into a new vector.
    ///
    /// # Errors
    /// As [`Deskewer::deskew`].
    pub fn deskew_to_vec(
        &mut self,
        poses: &[PoseSample],
        angles: &[AngleSample],
        points: &[TimedPoint],
        target: DeskewTarget,
    ) -> Result<Vec<Point3<f64>>> {
        let mut out = vec![Point3::origin(); points.len()];
        self.deskew(poses, angles, points, target, &mut out)?;
        Ok(out)
    }
}

/// The body pose at time `t` \[s\], interpolated between samples (slerp and linear).
///
/// Validates the samples on every call (O(n)); for many queries use [`Deskewer`].
///
/// # Errors
/// As [`Deskewer::deskew`] for the pose samples and the time: [`KinematicsError::Empty`],
/// [`KinematicsError::Unsorted`], [`KinematicsError::NonFinite`] (also for a sample time gap
/// that is infinite or has an infinite reciprocal, or a position step that overflows),
/// [`KinematicsError::NotUnitRotation`] or [`KinematicsError::TimeOutOfRange`].
///
/// # Example
/// ```
/// use lidar_kinematics::{interpolate_pose, PoseSample};
/// use nalgebra::{Isometry3, Vector3};
/// # fn main() -> Result<(), lidar_kinematics::KinematicsError> {
/// let s = [
///     PoseSample::new(0.0, Isometry3::identity()),
///     PoseSample::new(1.0, Isometry3::new(Vector3::new(2.0, 0.0, 0.0), Vector3::new(0.0, 0.0, 1.0))),
/// ];
/// let mid = interpolate_pose(&s, 0.5)?;
/// assert!((mid.translation.vector.x - 1.0).abs() < 1e-12);
/// assert!((mid.rotation.angle() - 0.5).abs() < 1e-12);
/// # Ok(()) }
/// ```
pub fn interpolate_pose(samples: &[PoseSample], t: f64) -> Result<Isometry3<f64>> {
    check_times(samples.iter().map(|p| p.time), "pose samples")?;
    check_poses(samples)?;
    check_finite(t, "query time")?;
    let (start, end) = (samples[0].time, samples[samples.len() - 1].time);
    if t < start || t > end {
        return Err(out_of_range("pose samples", t, start, end));
    }
    let i = samples.partition_point(|s| s.time <= t);
    if i >= samples.len() {
        return Ok(samples[samples.len() - 1].pose);
    }
    Ok(PoseSpan::new(&samples[i - 1], &samples[i]).pose_at(t))
}
