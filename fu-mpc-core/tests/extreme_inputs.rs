//! Finite inputs at the edges of the floats: typed errors or documented results, never NaN
//! passed on as a number.
#![allow(clippy::unwrap_used)]

use std::f64::consts::TAU;

use fu_mpc_core::{
    CoreError, FrontierTarget, FuMpc, MpcConfig, PeriodicPwl, PredictedStep, ScanController,
    ScanInput, UtilityConfig, frontier_surrogates, predict_into,
};
use lidar_kinematics::{KinematicChain, KinematicsError, MotorModel, MotorState};
use nalgebra::{Isometry3, Point3, Quaternion, Translation3, UnitQuaternion};

fn targets() -> [FrontierTarget; 2] {
    [
        FrontierTarget {
            center: Point3::new(0.0, 4.0, 0.0),
            score: 1.0,
        },
        FrontierTarget {
            center: Point3::new(3.0, -2.0, 0.5),
            score: 2.0,
        },
    ]
}

/// A pose whose quaternion is finite but not of unit norm is an error, as it is for the
/// kinematic chain, not tables of NaN.
#[test]
fn surrogates_reject_a_scaled_quaternion() {
    let chain = KinematicChain::default();
    for w in [2.0, 1e200] {
        let pose = Isometry3::from_parts(
            Translation3::identity(),
            UnitQuaternion::new_unchecked(Quaternion::new(w, 0.0, 0.0, 0.0)),
        );
        let mut out = Vec::new();
        let got = frontier_surrogates(
            &chain,
            &[pose; 3],
            &targets(),
            &UtilityConfig::default(),
            72,
            &mut out,
        );
        assert!(
            matches!(
                got,
                Err(CoreError::Kinematics(
                    KinematicsError::NotUnitRotation { .. }
                ))
            ),
            "{got:?}"
        );
        // FuMpc::evaluate builds the same surrogates.
        let cfg = MpcConfig {
            horizon: 2,
            ..MpcConfig::default()
        };
        let mut mpc = FuMpc::new(cfg, chain).unwrap();
        let input = ScanInput {
            motor: MotorState::new(0.0, 1.0),
            reference: &[pose; 3],
            targets: &targets(),
            fisher: None,
        };
        assert!(mpc.evaluate(&input, &[0.0, 0.0]).is_err());
    }
}

/// The prediction checks the initial state, Δt and the reference's translations itself,
/// even with no controls to step through.
#[test]
fn prediction_rejects_non_finite_states_and_steps() {
    let chain = KinematicChain::default();
    let motor = MotorModel::default();
    let mut out = [PredictedStep::default(); 2];
    let poses = [Isometry3::identity(); 2];
    let good = MotorState::new(0.0, 1.0);
    assert!(predict_into(&chain, &motor, good, &[0.0], 0.1, &poses, &mut out).is_ok());
    let mut one = [PredictedStep::default(); 1];
    for (state, dt) in [
        (MotorState::new(0.0, f64::NAN), 0.1),
        (MotorState::new(f64::INFINITY, 0.0), 0.1),
        (good, -1.0),
        (good, f64::NAN),
        (good, f64::INFINITY),
    ] {
        assert!(predict_into(&chain, &motor, state, &[], dt, &poses[..1], &mut one).is_err());
    }
    let mut far = poses;
    far[1].translation.vector.x = f64::NAN;
    let got = predict_into(&chain, &motor, good, &[0.0], 0.1, &far, &mut out);
    assert!(matches!(got, Err(CoreError::NonFinite { .. })), "{got:?}");
}

/// Angles so large that θ N_c / 2π overflows still land on the right knot, and values so far
/// apart that a slope overflows are refused.
#[test]
fn periodic_functions_at_the_edges_of_the_floats() {
    // 72 knots: θ · 72 / 2π overflows for |θ| above about 1.6e307.
    let f = PeriodicPwl::new((0..72).map(|i| f64::from(i % 7)).collect()).unwrap();
    for theta in [1e308, -1e308, f64::MAX, -f64::MAX, 3e307] {
        let (v, slope) = f.eval(theta);
        let (w, s) = f.eval(theta.rem_euclid(TAU));
        assert_eq!((v, slope), (w, s), "θ {theta}");
        assert!(v.is_finite() && slope.is_finite());
    }
    assert!(matches!(
        PeriodicPwl::new(vec![f64::MAX, -f64::MAX]),
        Err(CoreError::NonFinite { .. })
    ));
    // Far apart but with finite slopes: accepted.
    let wide = PeriodicPwl::new(vec![1e300, -1e300]).unwrap();
    assert!(wide.eval(1.0).1.is_finite());
}

/// Weights so large that every cost overflows are an error, not a silently idle optimiser,
/// and the controller works again with sane input afterwards.
#[test]
fn overflowing_weights_are_an_error() {
    let chain = KinematicChain::default();
    let cfg = MpcConfig {
        alpha: 1e308,
        ..MpcConfig::default()
    };
    let refs: Vec<Isometry3<f64>> = (0..=cfg.horizon)
        .map(|k| Isometry3::translation(0.1 * k as f64, 0.0, 0.0))
        .collect();
    let input = ScanInput {
        motor: MotorState::new(0.0, 1.0),
        reference: &refs,
        targets: &targets(),
        fisher: None,
    };
    let mut mpc = FuMpc::new(cfg, chain).unwrap();
    for _ in 0..2 {
        // Twice: the error leaves the controller's buffers in place.
        let got = mpc.command(&input);
        assert!(matches!(got, Err(CoreError::NonFinite { .. })), "{got:?}");
    }
    let mut sane = FuMpc::new(MpcConfig::default(), chain).unwrap();
    let cmd = sane.command(&input).unwrap();
    assert!(cmd.acceleration.abs() <= MpcConfig::default().limits.u_max());
}

/// A σ whose 2σ² underflows is a configuration error, not a NaN reward later.
#[test]
fn a_sigma_whose_square_underflows_is_refused() {
    for sigma in [1e-200, 1e-160, 1e200] {
        let cfg = UtilityConfig {
            sigma,
            ..UtilityConfig::default()
        };
        assert!(
            matches!(cfg.validate(), Err(CoreError::InvalidConfig { .. })),
            "σ {sigma}"
        );
    }
    let cfg = UtilityConfig {
        sigma: 1e-100,
        ..UtilityConfig::default()
    };
    assert!(cfg.validate().is_ok());
}

/// Priors at the edges of the floats: a symmetric covariance near f64::MAX is accepted, one
/// whose inverse overflows and an update whose sum overflows are errors, and a failed update
/// leaves the prior as it was.
#[test]
fn information_maps_at_the_edges_of_the_floats() {
    use fu_mpc_core::icr::InformationMap;
    let cell = vec![Point3::new(0.0, 0.0, 0.0)];
    let big = InformationMap::dense_covariance(cell.clone(), &[1e308]).unwrap();
    assert!(big.prior_diagonal()[0] > 0.0);
    let two = vec![Point3::origin(), Point3::new(1.0, 0.0, 0.0)];
    let tiny = InformationMap::dense_covariance(two, &[1e-310, 0.0, 0.0, 1e-310]);
    assert!(matches!(tiny, Err(CoreError::NonFinite { .. })), "{tiny:?}");
    let mut map = InformationMap::diagonal(cell, vec![1e308]).unwrap();
    assert!(matches!(
        map.add_information(&[1e308]),
        Err(CoreError::NonFinite { .. })
    ));
    assert_eq!(map.prior_diagonal(), vec![1e308]);
    assert!(map.log_det_prior().unwrap().is_finite());
}
