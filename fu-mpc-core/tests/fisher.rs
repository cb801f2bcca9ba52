//! The Fisher table against a brute-force computation, and its fallbacks.
#![allow(clippy::unwrap_used)]

use fu_mpc_core::{FisherConfig, FisherTable};
use lidar_kinematics::{FieldOfView, KinematicChain, LidarSensor};
use nalgebra::{Isometry3, Matrix3, Point3, SymmetricEigen, Translation3, UnitQuaternion, Vector3};

fn sensor() -> LidarSensor {
    LidarSensor::ring16().with_field_of_view(FieldOfView::try_new(-0.6, 0.6, -0.4, 0.4).unwrap())
}

fn cloud() -> Vec<Point3<f64>> {
    // A box room with a slanted wall, with a little deterministic jitter.
    let mut c = Vec::new();
    let mut s = 1u64;
    let mut jitter = || {
        s = s
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((s >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * 0.02
    };
    for i in 0..25 {
        for j in 0..25 {
            let (a, b) = (f64::from(i) * 0.4 - 5.0, f64::from(j) * 0.4 - 5.0);
            c.push(Point3::new(a, b, -1.5 + jitter()));
            c.push(Point3::new(4.0 + jitter(), a, b * 0.3));
            c.push(Point3::new(a, -4.0 + 0.3 * a + jitter(), b * 0.3));
        }
    }
    c
}

/// Normals by brute-force K nearest neighbours (full sort) and a library eigen-solver.
fn brute_normals(points: &[Point3<f64>], k: usize) -> Vec<Vector3<f64>> {
    points
        .iter()
        .map(|p| {
            let mut d: Vec<(f64, usize)> = points
                .iter()
                .enumerate()
                .map(|(i, q)| ((q - p).norm_squared(), i))
                .collect();
            d.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
            let nn: Vec<Vector3<f64>> = d[..k].iter().map(|(_, i)| points[*i].coords).collect();
            let mean = nn.iter().sum::<Vector3<f64>>() / k as f64;
            let cov = nn.iter().fold(Matrix3::zeros(), |m, q| {
                m + (q - mean) * (q - mean).transpose()
            });
            let e = SymmetricEigen::new(cov);
            let i = (0..3)
                .min_by(|a, b| e.eigenvalues[*a].total_cmp(&e.eigenvalues[*b]))
                .unwrap();
            e.eigenvectors.column(i).into_owned()
        })
        .collect()
}

#[test]
fn table_equals_brute_force() {
    let points = cloud();
    let chain = KinematicChain::default();
    let pose = Isometry3::from_parts(
        Translation3::new(0.3, -0.2, 0.1),
        UnitQuaternion::from_euler_angles(0.05, -0.03, 0.4),
    );
    let cfg = FisherConfig {
        candidates: 36,
        ..FisherConfig::default()
    };
    let table = FisherTable::build(&points, &pose, &chain, &sensor(), &cfg).unwrap();
    let normals = brute_normals(&points, cfg.neighbours);
    let sensor = sensor();
    for c in 0..cfg.candidates {
        let theta = table.cost().knot(c);
        let gate = sensor.visibility_gate(&chain, &pose, theta).unwrap();
        let mut f = Matrix3::zeros();
        for (p, n) in points.iter().zip(&normals) {
            if gate.contains(p) {
                f += n * n.transpose();
            }
        }
        let got = table.information()[c];
        assert!(
            (got - f).abs().max() < 1e-6 * (1.0 + f.abs().max()),
            "knot {c}: {got} vs {f}"
        );
        let want = (f + Matrix3::identity() * cfg.epsilon)
            .try_inverse()
            .unwrap()
            .trace();
        assert!((table.cost().values()[c] - want).abs() < 1e-9 * (1.0 + want));
    }
    // Different directions see different geometry.
    let v = table.cost().values();
    let (lo, hi) = (
        v.iter().cloned().fold(f64::MAX, f64::min),
        v.iter().cloned().fold(0.0, f64::max),
    );
    assert!(hi > 2.0 * lo);
}

#[test]
fn fallbacks_and_errors() {
    let chain = KinematicChain::default();
    let id = Isometry3::identity();
    let cfg = FisherConfig::default();
    // Empty cloud: every direction costs 3/ε.
    let t = FisherTable::build(&[], &id, &chain, &sensor(), &cfg).unwrap();
    assert!(
        t.cost()
            .values()
            .iter()
            .all(|v| (v - 3.0 / cfg.epsilon).abs() < 1e-12)
    );
    // An ε so small that 3/ε overflows is the documented error, not an infinite table.
    let tiny_eps = FisherConfig {
        epsilon: 1e-310,
        ..cfg
    };
    assert!(matches!(
        FisherTable::build(&[], &id, &chain, &sensor(), &tiny_eps),
        Err(fu_mpc_core::CoreError::NonFinite { .. })
    ));
    // A single plane: F has rank one, the cost stays finite.
    let plane: Vec<_> = (0..400)
        .map(|i| {
            Point3::new(
                3.0,
                f64::from(i % 20) * 0.2 - 2.0,
                f64::from(i / 20) * 0.1 - 1.0,
            )
        })
        .collect();
    let t = FisherTable::build(&plane, &id, &chain, &sensor(), &cfg).unwrap();
    assert!(t.cost().values().iter().all(|v| v.is_finite() && *v > 0.0));
    assert!(t.value(0.0) < 3.0);
    // NaN points are skipped and counted.
    let mut bad = plane.clone();
    bad.push(Point3::new(f64::NAN, 0.0, 0.0));
    bad.push(Point3::new(0.0, f64::INFINITY, 0.0));
    let t2 = FisherTable::build(&bad, &id, &chain, &sensor(), &cfg).unwrap();
    assert_eq!(t2.skipped(), 2);
    assert_eq!(t2.points_used(), plane.len());
    assert_eq!(t2.cost(), t.cost());
    // More candidate angles than the documented limit is a configuration error.
    let too_many = FisherConfig {
        candidates: fu_mpc_core::MAX_KNOTS + 1,
        ..cfg
    };
    assert!(FisherTable::build(&plane, &id, &chain, &sensor(), &too_many).is_err());
    // A cloud whose box volume underflows still gets its table (its normals' search ends).
    let tiny = [
        Point3::new(3.0, 0.0, 0.0),
        Point3::new(3.0 + 1e-200, 0.0, 0.0),
        Point3::new(3.0, 1e-200, 0.0),
        Point3::new(3.0, 0.0, 1e-200),
    ];
    let t3 = FisherTable::build(&tiny, &id, &chain, &sensor(), &cfg).unwrap();
    assert_eq!(t3.points_used(), 4);
    // Bad settings.
    for c in [
        FisherConfig {
            candidates: 0,
            ..cfg
        },
        FisherConfig {
            neighbours: 2,
            ..cfg
        },
        FisherConfig {
            epsilon: 0.0,
            ..cfg
        },
        FisherConfig {
            epsilon: f64::NAN,
            ..cfg
        },
    ] {
        assert!(FisherTable::build(&plane, &id, &chain, &sensor(), &c).is_err());
    }
    // A non-finite pose.
    let nan_pose = Isometry3::from_parts(
        Translation3::new(f64::NAN, 0.0, 0.0),
        UnitQuaternion::identity(),
    );
    assert!(FisherTable::build(&plane, &nan_pose, &chain, &sensor(), &cfg).is_err());
}

#[test]
fn the_table_is_send_and_sync() {
    fn check<T: Send + Sync>() {}
    check::<FisherTable>();
}

/// The parallel normals and visibility sums give the same bits on 1 and 3 threads.
#[test]
fn the_table_does_not_depend_on_the_thread_count() {
    // Three shifted copies of the room: more points than one parallel chunk.
    let base = cloud();
    let big: Vec<Point3<f64>> = (0..3)
        .flat_map(|k| {
            let dx = 0.13 * f64::from(k);
            base.iter().map(move |p| Point3::new(p.x + dx, p.y, p.z))
        })
        .collect();
    let build = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| {
            FisherTable::build(
                &big,
                &Isometry3::identity(),
                &KinematicChain::default(),
                &sensor(),
                &FisherConfig::default(),
            )
            .unwrap()
        })
    };
    let (one, three) = (build(1), build(3));
    assert!(one.information().iter().any(|f| f.norm() > 0.0));
    assert_eq!(one, three);
}
