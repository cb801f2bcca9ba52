//! FU-MPC properties on random problems and its behaviour on hand-made ones.
#![allow(clippy::unwrap_used)]

use std::f64::consts::{PI, TAU};

use fu_mpc_core::{
    FisherConfig, FisherTable, FrontierTarget, FuMpc, MpcConfig, ScanController, ScanInput,
    ScanStatus,
};
use lidar_kinematics::{FieldOfView, KinematicChain, LidarSensor, MotorModel, MotorState};
use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use proptest::prelude::*;

fn cases() -> u32 {
    std::env::var("PROPTEST_CASES")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(200)
}

fn reference(n: usize, v: Vector3<f64>, yaw_rate: f64, dt: f64) -> Vec<Isometry3<f64>> {
    (0..=n)
        .map(|i| {
            let t = i as f64 * dt;
            Isometry3::from_parts(
                Translation3::from(v * t),
                UnitQuaternion::from_axis_angle(&Vector3::z_axis(), yaw_rate * t),
            )
        })
        .collect()
}

/// A forward-looking sensor (±35° azimuth, ±15° elevation): what it sees depends on the
/// motor angle.
fn sector_sensor() -> LidarSensor {
    LidarSensor::ring16().with_field_of_view(FieldOfView::try_new(-0.6, 0.6, -0.26, 0.26).unwrap())
}

/// A room-like cloud: floor, two walls, for a non-trivial Fisher table.
fn room_cloud() -> Vec<Point3<f64>> {
    let mut c = Vec::new();
    for i in 0..30 {
        for j in 0..30 {
            let (a, b) = (f64::from(i) * 0.3 - 4.5, f64::from(j) * 0.3 - 4.5);
            c.push(Point3::new(a, b, -1.2));
            c.push(Point3::new(5.0, a, b * 0.4));
            c.push(Point3::new(a, -6.0, b * 0.4));
        }
    }
    c
}

/// The room's table, built once.
fn room_table() -> &'static FisherTable {
    static TABLE: std::sync::OnceLock<FisherTable> = std::sync::OnceLock::new();
    TABLE.get_or_init(|| {
        FisherTable::build(
            &room_cloud(),
            &Isometry3::identity(),
            &KinematicChain::default(),
            &sector_sensor(),
            &FisherConfig::default(),
        )
        .unwrap()
    })
}

/// The cost of holding a constant target speed from `omega0`, clipped to the limits.
fn constant_speed(cfg: &MpcConfig, omega0: f64, target: f64) -> Vec<f64> {
    let l = cfg.limits;
    let mut w = omega0.clamp(l.omega_min(), l.omega_max());
    (0..cfg.horizon)
        .map(|_| {
            let u = l.saturate_acceleration((target - w) / cfg.dt);
            w += u * cfg.dt;
            u
        })
        .collect()
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(cases()))]

    #[test]
    fn solutions_are_feasible_and_no_worse_than_the_warm_starts(
        theta0 in -10.0f64..10.0,
        omega0 in -PI..PI,
        vx in -2.0f64..2.0, vy in -2.0f64..2.0,
        yaw_rate in -0.5f64..0.5,
        targets in proptest::collection::vec((-8.0f64..8.0, -8.0f64..8.0, -1.0f64..2.0, 0.0f64..100.0), 0..6),
        alpha in 0.0f64..3.0, beta in 0.0f64..3.0, gamma in 0.0f64..0.1,
        with_table in proptest::bool::ANY,
        // 72 knots share the Fisher table's grid (the solver's combined tables); 36 do not.
        knots in proptest::sample::select(vec![72usize, 36]),
    ) {
        let cfg = MpcConfig { alpha, beta, gamma, knots, ..MpcConfig::default() };
        let chain = KinematicChain::default();
        let table = with_table.then(room_table);
        let targets: Vec<_> = targets
            .iter()
            .map(|&(x, y, z, s)| FrontierTarget { center: Point3::new(x, y, z), score: s })
            .collect();
        let refs = reference(cfg.horizon, Vector3::new(vx, vy, 0.0), yaw_rate, cfg.dt);
        let input = ScanInput { motor: MotorState::new(theta0, omega0), reference: &refs, targets: &targets, fisher: table };
        let mut mpc = FuMpc::new(cfg, chain).unwrap();
        let cmd = mpc.command(&input).unwrap();
        let sol = mpc.solution().clone();
        // (21) and (20), and the prediction is the model's own rollout, (11)–(12).
        let l = cfg.limits;
        prop_assert!(sol.controls.iter().all(|u| u.abs() <= l.u_max() + 1e-12));
        prop_assert_eq!(cmd.acceleration, sol.controls[0]);
        let model = MotorModel::new(l);
        let mut x = MotorState::new(theta0, omega0);
        for (k, u) in sol.controls.iter().enumerate() {
            let w_unsat = x.omega + u * cfg.dt;
            x = model.step(x, *u, cfg.dt).unwrap();
            prop_assert!(x.omega >= l.omega_min() - 1e-12 && x.omega <= l.omega_max() + 1e-12);
            // Saturation inactive: the speed is the unsaturated one.
            prop_assert!((x.omega - w_unsat).abs() < 1e-9);
            prop_assert!((sol.predicted[k + 1].theta - x.theta).abs() < 1e-12);
            prop_assert!((sol.predicted[k + 1].omega - x.omega).abs() < 1e-12);
        }
        // Never worse than the warm start or any constant-speed candidate.
        let total = sol.cost.total();
        prop_assert!(total <= sol.warm_start_cost + 1e-9 * (1.0 + total.abs()));
        for target in [l.omega_min(), l.omega_max(), 0.5 * (l.omega_min() + l.omega_max()), omega0] {
            let cand = constant_speed(&cfg, omega0, target);
            let c = mpc.evaluate(&input, &cand).unwrap().total();
            prop_assert!(total <= c + 1e-9 * (1.0 + c.abs()), "{} > {}", total, c);
        }
        prop_assert!(cmd.status != ScanStatus::Direct);
    }
}

/// Runs a controller in closed loop for `cycles` and returns the motor angles.
fn closed_loop(
    mpc: &mut FuMpc,
    targets: &[FrontierTarget],
    table: Option<&FisherTable>,
    cycles: usize,
) -> Vec<f64> {
    let cfg = *mpc.config();
    let model = MotorModel::new(cfg.limits);
    let refs = reference(cfg.horizon, Vector3::zeros(), 0.0, cfg.dt);
    let mut x = MotorState::new(0.0, PI);
    let mut angles = Vec::new();
    for _ in 0..cycles {
        let input = ScanInput {
            motor: x,
            reference: &refs,
            targets,
            fisher: table,
        };
        let cmd = mpc.command(&input).unwrap();
        x = model.step(x, cmd.acceleration, cfg.dt).unwrap();
        angles.push(x.theta);
    }
    angles
}

fn share_within(angles: &[f64], center: f64, half: f64) -> f64 {
    let n = angles
        .iter()
        .filter(|a| ((*a - center + PI).rem_euclid(TAU) - PI).abs() <= half)
        .count();
    n as f64 / angles.len() as f64
}

#[test]
fn frontier_only_dwells_on_the_target() {
    let cfg = MpcConfig {
        beta: 0.0,
        ..MpcConfig::default()
    };
    let mut mpc = FuMpc::new(cfg, KinematicChain::default()).unwrap();
    // One target at +y: motor angle π/2 looks at it.
    let targets = [FrontierTarget {
        center: Point3::new(0.0, 4.0, 0.0),
        score: 40.0,
    }];
    let angles = closed_loop(&mut mpc, &targets, None, 60);
    let share = share_within(&angles[20..], PI / 2.0, 30f64.to_radians());
    // A constant spin would spend 1/6 of the time there.
    assert!(share > 0.6, "share {share}");
}

#[test]
fn uncertainty_only_dwells_near_the_best_direction() {
    let chain = KinematicChain::default();
    let table = FisherTable::build(
        &room_cloud(),
        &Isometry3::identity(),
        &chain,
        &sector_sensor(),
        &FisherConfig::default(),
    )
    .unwrap();
    let (best_c, _) = table
        .cost()
        .values()
        .iter()
        .enumerate()
        .min_by(|a, b| a.1.total_cmp(b.1))
        .unwrap();
    let best = table.cost().knot(best_c);
    let cfg = MpcConfig {
        alpha: 0.0,
        ..MpcConfig::default()
    };
    let mut mpc = FuMpc::new(cfg, chain).unwrap();
    let angles = closed_loop(&mut mpc, &[], Some(&table), 60);
    let tail: Vec<f64> = angles[20..].to_vec();
    let mean_cost: f64 = tail.iter().map(|a| table.value(*a)).sum::<f64>() / tail.len() as f64;
    let spin_cost: f64 = (0..360)
        .map(|d| table.value(f64::from(d).to_radians()))
        .sum::<f64>()
        / 360.0;
    assert!(
        mean_cost < 0.8 * spin_cost,
        "{mean_cost} vs spinning {spin_cost}"
    );
    let share = share_within(&tail, best, 45f64.to_radians());
    assert!(share > 0.5, "share {share} near {best}");
}

#[test]
fn a_huge_smoothness_weight_keeps_the_acceleration_constant() {
    let cfg = MpcConfig {
        gamma: 1e6,
        ..MpcConfig::default()
    };
    let mut mpc = FuMpc::new(cfg, KinematicChain::default()).unwrap();
    let refs = reference(cfg.horizon, Vector3::new(1.0, 0.0, 0.0), 0.1, cfg.dt);
    let targets = [FrontierTarget {
        center: Point3::new(3.0, 1.0, 0.0),
        score: 10.0,
    }];
    let input = ScanInput {
        motor: MotorState::new(0.3, 1.0),
        reference: &refs,
        targets: &targets,
        fisher: None,
    };
    mpc.command(&input).unwrap();
    let u = &mpc.solution().controls;
    let spread = u
        .windows(2)
        .map(|w| (w[1] - w[0]).abs())
        .fold(0.0, f64::max);
    assert!(spread < 1e-3, "{u:?}");
}

#[test]
fn bad_inputs_are_errors() {
    let chain = KinematicChain::default();
    assert!(
        FuMpc::new(
            MpcConfig {
                horizon: 0,
                ..MpcConfig::default()
            },
            chain
        )
        .is_err()
    );
    assert!(
        FuMpc::new(
            MpcConfig {
                dt: 0.0,
                ..MpcConfig::default()
            },
            chain
        )
        .is_err()
    );
    assert!(
        FuMpc::new(
            MpcConfig {
                dt: f64::NAN,
                ..MpcConfig::default()
            },
            chain
        )
        .is_err()
    );
    assert!(
        FuMpc::new(
            MpcConfig {
                alpha: -1.0,
                ..MpcConfig::default()
            },
            chain
        )
        .is_err()
    );
    assert!(lidar_kinematics::MotorLimits::try_new(2.0, 1.0, 1.0).is_err());
    let cfg = MpcConfig::default();
    let mut mpc = FuMpc::new(cfg, chain).unwrap();
    let refs = reference(cfg.horizon, Vector3::zeros(), 0.0, cfg.dt);
    let short = &refs[..3];
    let ok = ScanInput {
        motor: MotorState::new(0.0, 1.0),
        reference: &refs,
        targets: &[],
        fisher: None,
    };
    assert!(
        mpc.command(&ScanInput {
            reference: short,
            ..ok
        })
        .is_err()
    );
    assert!(
        mpc.command(&ScanInput {
            motor: MotorState::new(f64::NAN, 1.0),
            ..ok
        })
        .is_err()
    );
    let nan_target = [FrontierTarget {
        center: Point3::new(f64::NAN, 0.0, 0.0),
        score: 1.0,
    }];
    assert!(
        mpc.command(&ScanInput {
            targets: &nan_target,
            ..ok
        })
        .is_err()
    );
    let neg = [FrontierTarget {
        center: Point3::new(1.0, 0.0, 0.0),
        score: -1.0,
    }];
    assert!(
        mpc.command(&ScanInput {
            targets: &neg,
            ..ok
        })
        .is_err()
    );
    // A motor faster than its limit: the command is still within the limits.
    let fast = ScanInput {
        motor: MotorState::new(0.0, 10.0),
        ..ok
    };
    let cmd = mpc.command(&fast).unwrap();
    assert!(cmd.acceleration.abs() <= cfg.limits.u_max());
    // Nothing to look at and no table: any feasible command, cost zero.
    let cmd = mpc.command(&ok).unwrap();
    assert!(cmd.acceleration.is_finite());
    assert_eq!(
        mpc.solution().cost.frontier + mpc.solution().cost.localisation,
        0.0
    );
}

/// Counts above the documented limits are configuration errors, not allocations.
#[test]
fn counts_above_the_limits_are_errors() {
    let chain = KinematicChain::default();
    for bad in [
        MpcConfig {
            horizon: fu_mpc_core::MAX_HORIZON + 1,
            ..MpcConfig::default()
        },
        MpcConfig {
            horizon: usize::MAX,
            ..MpcConfig::default()
        },
        MpcConfig {
            knots: fu_mpc_core::MAX_KNOTS + 1,
            ..MpcConfig::default()
        },
        MpcConfig {
            iterations: usize::MAX,
            ..MpcConfig::default()
        },
    ] {
        assert!(FuMpc::new(bad, chain).is_err(), "{bad:?}");
    }
    assert!(
        FuMpc::new(
            MpcConfig {
                horizon: fu_mpc_core::MAX_HORIZON,
                knots: fu_mpc_core::MAX_KNOTS,
                ..MpcConfig::default()
            },
            chain
        )
        .is_ok()
    );
    let refs = reference(20, Vector3::zeros(), 0.0, 0.1);
    let mut out = Vec::new();
    assert!(
        fu_mpc_core::frontier_surrogates(
            &chain,
            &refs,
            &[],
            &fu_mpc_core::UtilityConfig::default(),
            usize::MAX,
            &mut out
        )
        .is_err()
    );
    // A rotation that is not finite is an error like a translation that is not.
    let mut bad_rotation = refs.clone();
    bad_rotation[3].rotation =
        UnitQuaternion::new_unchecked(nalgebra::Quaternion::new(f64::NAN, 0.0, 0.0, 0.0));
    assert!(
        fu_mpc_core::frontier_surrogates(
            &chain,
            &bad_rotation,
            &[],
            &fu_mpc_core::UtilityConfig::default(),
            72,
            &mut out
        )
        .is_err()
    );
}

/// Extreme but finite settings with no acceleration allowed (every bound active at once):
/// the dedicated solver's tables overflow, and the update still returns a feasible command.
#[test]
fn extreme_settings_still_give_a_feasible_command() {
    let chain = KinematicChain::default();
    let limits = lidar_kinematics::MotorLimits::try_new(-PI, PI, 0.0).unwrap();
    for (gamma, dt) in [(1e308, 0.1), (0.01, 1e155), (1e308, 1e155)] {
        let cfg = MpcConfig {
            gamma,
            dt,
            limits,
            ..MpcConfig::default()
        };
        let mut mpc = FuMpc::new(cfg, chain).unwrap();
        let refs = reference(cfg.horizon, Vector3::zeros(), 0.0, 0.1);
        let input = ScanInput {
            motor: MotorState::new(0.0, 4.0),
            reference: &refs,
            targets: &[FrontierTarget {
                center: Point3::new(3.0, 1.0, 0.0),
                score: 5.0,
            }],
            fisher: None,
        };
        let cmd = mpc.command(&input).unwrap();
        assert_eq!(cmd.acceleration, 0.0, "γ = {gamma}, Δt = {dt}");
    }
}
