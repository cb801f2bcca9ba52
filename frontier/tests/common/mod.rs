//! A tiny analytic scene of boxes and a spherical scanner, for the integration tests.
#![allow(dead_code, unreachable_pub, clippy::unwrap_used)]

use nalgebra::{Point3, Vector3};

/// Axis-aligned solid boxes.
#[derive(Debug, Clone)]
pub struct Scene {
    pub boxes: Vec<(Point3<f64>, Point3<f64>)>,
}

impl Scene {
    /// The first hit of the ray `o + t d`, t ∈ (0, t_max].
    pub fn cast(&self, o: &Point3<f64>, d: &Vector3<f64>, t_max: f64) -> Option<f64> {
        let mut best: Option<f64> = None;
        for (lo, hi) in &self.boxes {
            let (mut t0, mut t1) = (0.0f64, t_max);
            let mut hit = true;
            for k in 0..3 {
                if d[k].abs() < 1e-15 {
                    if o[k] < lo[k] || o[k] > hi[k] {
                        hit = false;
                        break;
                    }
                } else {
                    let (mut a, mut b) = ((lo[k] - o[k]) / d[k], (hi[k] - o[k]) / d[k]);
                    if a > b {
                        core::mem::swap(&mut a, &mut b);
                    }
                    t0 = t0.max(a);
                    t1 = t1.min(b);
                }
            }
            if hit && t0 <= t1 && t0 > 0.0 {
                best = Some(best.map_or(t0, |b: f64| b.min(t0)));
            }
        }
        best
    }

    /// A frame: hits on the scene, or points at `range` where nothing is hit.
    pub fn scan(
        &self,
        o: &Point3<f64>,
        azimuths: u32,
        elevations: u32,
        range: f64,
    ) -> Vec<Point3<f64>> {
        let mut pts = Vec::new();
        for i in 0..azimuths {
            let a = std::f64::consts::TAU * (f64::from(i) + 0.37) / f64::from(azimuths);
            for j in 0..elevations {
                let e = -1.2 + 2.4 * (f64::from(j) + 0.5) / f64::from(elevations);
                let d = Vector3::new(e.cos() * a.cos(), e.cos() * a.sin(), e.sin());
                let t = self.cast(o, &d, range).unwrap_or(range);
                pts.push(o + d * t);
            }
        }
        pts
    }
}

/// A 12 × 8 × 3 m room with walls, floor, ceiling and a dividing wall with a door at x = 6.
pub fn room() -> Scene {
    let p = Point3::new;
    Scene {
        boxes: vec![
            (p(-1.0, -1.0, -1.0), p(13.0, 9.0, 0.05)),
            (p(-1.0, -1.0, 2.95), p(13.0, 9.0, 4.0)),
            (p(-1.0, -1.0, -1.0), p(0.05, 9.0, 4.0)),
            (p(11.95, -1.0, -1.0), p(13.0, 9.0, 4.0)),
            (p(-1.0, -1.0, -1.0), p(13.0, 0.05, 4.0)),
            (p(-1.0, 7.95, -1.0), p(13.0, 9.0, 4.0)),
            (p(5.9, -1.0, -1.0), p(6.1, 3.5, 4.0)),
            (p(5.9, 4.5, -1.0), p(6.1, 9.0, 4.0)),
        ],
    }
}
