//! Frontier surrogates against the gates evaluated directly.
#![allow(clippy::unwrap_used)]

use std::f64::consts::TAU;

use fu_mpc_core::{FrontierTarget, UtilityConfig, frontier_surrogates};
use lidar_kinematics::{Extrinsics, KinematicChain};
use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use proptest::prelude::*;

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    #[test]
    fn knots_match_the_hard_gates_away_from_their_edges(
        targets in proptest::collection::vec((-10.0f64..10.0, -10.0f64..10.0, -3.0f64..3.0, 0.1f64..50.0), 1..8),
        roll in -0.3f64..0.3, pitch in -0.3f64..0.3, yaw in -3.0f64..3.0,
        tilt in -0.5f64..0.5,
    ) {
        let mount = Isometry3::from_parts(Translation3::new(0.0, 0.0, 0.1), UnitQuaternion::from_euler_angles(tilt, 0.0, 0.0));
        let chain = KinematicChain::new(Extrinsics::try_new(Isometry3::identity(), mount).unwrap());
        let pose = Isometry3::from_parts(Translation3::new(0.5, -0.5, 1.0), UnitQuaternion::from_euler_angles(roll, pitch, yaw));
        let targets: Vec<_> = targets.iter().map(|&(x, y, z, s)| FrontierTarget { center: Point3::new(x, y, z), score: s }).collect();
        let cfg = UtilityConfig::default();
        let knots = 72;
        let mut out = Vec::new();
        frontier_surrogates(&chain, &[pose], &targets, &cfg, knots, &mut out).unwrap();
        prop_assert_eq!(out.len(), 1);
        let h = TAU / knots as f64;
        let p = Point3::from(pose.translation.vector);
        let total: f64 = targets.iter().map(|t| (-(t.center - p).norm_squared() / (2.0 * cfg.sigma * cfg.sigma)).exp() * t.score).sum();
        for c in 0..knots {
            let theta = c as f64 * h;
            let d = chain.scan_direction(&pose.rotation, theta).unwrap();
            let mut seen = 0.0;
            let mut ambiguous = false;
            for t in &targets {
                let v: Vector3<f64> = t.center - p;
                let r = (-v.norm_squared() / (2.0 * cfg.sigma * cfg.sigma)).exp() * t.score;
                if v.norm() > cfg.max_distance {
                    continue;
                }
                let angle = d.dot(&v.normalize()).clamp(-1.0, 1.0).acos();
                // Within one cell of the gate's edge the surrogate is smoothed.
                if (angle - cfg.half_angle).abs() < h {
                    ambiguous = true;
                }
                if angle <= cfg.half_angle {
                    seen += r;
                }
            }
            if !ambiguous {
                let want = (total - seen) / total;
                prop_assert!((out[0].values()[c] - want).abs() < 1e-9, "knot {}: {} vs {}", c, out[0].values()[c], want);
            }
            prop_assert!((0.0..=1.0 + 1e-12).contains(&out[0].values()[c]));
        }
    }
}

#[test]
fn bad_inputs() {
    let chain = KinematicChain::default();
    let pose = [Isometry3::identity()];
    let mut out = Vec::new();
    let ok = [FrontierTarget {
        center: Point3::new(1.0, 0.0, 0.0),
        score: 1.0,
    }];
    assert!(
        frontier_surrogates(&chain, &pose, &ok, &UtilityConfig::default(), 0, &mut out).is_err()
    );
    let bad_cfg = UtilityConfig {
        sigma: 0.0,
        ..UtilityConfig::default()
    };
    assert!(frontier_surrogates(&chain, &pose, &ok, &bad_cfg, 72, &mut out).is_err());
    let nan = [FrontierTarget {
        center: Point3::new(f64::NAN, 0.0, 0.0),
        score: 1.0,
    }];
    assert!(
        frontier_surrogates(&chain, &pose, &nan, &UtilityConfig::default(), 72, &mut out).is_err()
    );
    // No targets: J = 0 everywhere.
    frontier_surrogates(&chain, &pose, &[], &UtilityConfig::default(), 72, &mut out).unwrap();
    assert!(out[0].values().iter().all(|v| *v == 0.0));
}
