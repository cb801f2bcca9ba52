//! The distance from a point to what a LiDAR sees, without trigonometry per point.

use lidar_kinematics::LidarSensor;
use nalgebra::Vector3;

/// A sensor's field of view and range, prepared for distance bounds: the sines and cosines of
/// its elevation bounds and of its azimuth wedge.
#[derive(Debug, Clone, Copy)]
pub(crate) struct FovGap {
    pub(crate) r_min: f64,
    pub(crate) r_max: f64,
    pub(crate) sin_el_min: f64,
    pub(crate) cos_el_min: f64,
    pub(crate) sin_el_max: f64,
    pub(crate) cos_el_max: f64,
    /// cos and sin of the azimuth centre and of the half width; `None` for all azimuths.
    pub(crate) azimuth: Option<(f64, f64, f64, f64)>,
}

impl FovGap {
    pub(crate) fn new(sensor: &LidarSensor) -> Self {
        let (fov, range) = (sensor.field_of_view(), sensor.range());
        let (sin_el_min, cos_el_min) = fov.elevation_min().sin_cos();
        let (sin_el_max, cos_el_max) = fov.elevation_max().sin_cos();
        let azimuth = (!fov.is_full_azimuth()).then(|| {
            let half = 0.5 * fov.azimuth_width();
            let (s, c) = (fov.azimuth_min() + half).sin_cos();
            let (sin_h, cos_h) = half.sin_cos();
            (c, s, cos_h, sin_h)
        });
        Self {
            r_min: range.min(),
            r_max: range.max(),
            sin_el_min,
            cos_el_min,
            sin_el_max,
            cos_el_max,
            azimuth,
        }
    }

    /// A lower bound on the distance \[m\] from a LiDAR-frame point to the region the sensor
    /// sees (≤ 0 inside): the largest of the distances to the range shells, r − r_max and
    /// r_min − r, to the elevation cones, r sin(β_min − β) and r sin(β − β_max), and to the
    /// azimuth wedge, ρ sin(|α − α_c| − w/2). Each is the exact distance to its own set while
    /// the angle beyond it is at most 90° and below it otherwise, and the seen region is their
    /// intersection.
    pub(crate) fn outside(&self, p: &Vector3<f64>) -> f64 {
        let r = p.norm();
        let mut d = (self.r_min - r).max(r - self.r_max);
        let rho = (p.x * p.x + p.y * p.y).sqrt();
        // r sin(β_min − β) = ρ sin β_min − z cos β_min, and the same for β_max.
        d = d
            .max(rho * self.sin_el_min - p.z * self.cos_el_min)
            .max(p.z * self.cos_el_max - rho * self.sin_el_max);
        if let Some((c, s, cos_h, sin_h)) = self.azimuth {
            // In the wedge's frame: x′ along its centre; ρ sin(|δ| − h) = |y′| cos h − x′ sin h.
            let x1 = p.x * c + p.y * s;
            let y1 = -p.x * s + p.y * c;
            d = d.max(y1.abs() * cos_h - x1 * sin_h);
        }
        d
    }
}
