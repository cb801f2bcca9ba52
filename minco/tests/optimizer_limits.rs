//! The optimiser respects v_max and a_max (within 2 %, by dense sampling) and lowers the cost
//! below the initial guess's, on 200 random paths; bad requests give typed errors.
#![allow(clippy::unwrap_used, clippy::print_stdout)]

use minco::{MincoError, Optimizer, OptimizerConfig};

struct Lcg(u64);

impl Lcg {
    fn next(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// Runs the optimiser of order S on `cases` random paths and checks limits, cost and goal.
fn random_paths_respect_the_limits<const S: usize>(cases: usize, seed: u64) {
    let mut rng = Lcg(seed);
    let mut worst_v: f64 = 0.0;
    let mut worst_a: f64 = 0.0;
    for case in 0..cases {
        let inner = 1 + (rng.next() * 6.0) as usize;
        let v_max = 1.0 + 3.0 * rng.next();
        let a_max = 1.0 + 4.0 * rng.next();
        let mut p = [0.0, 0.0, 1.0];
        let start = p;
        let mut path = Vec::new();
        for _ in 0..=inner {
            p = [
                p[0] + 0.5 + 3.0 * rng.next(),
                p[1] + 4.0 * (rng.next() - 0.5),
                p[2] + (rng.next() - 0.5),
            ];
            path.push(p);
        }
        let goal = path.pop().unwrap();
        let rest = |x: [f64; 3]| {
            let mut s = [[0.0; 3]; S];
            s[0] = x;
            s
        };
        let cfg = OptimizerConfig::default().with_limits(v_max, a_max);
        let mut opt = Optimizer::<S, 3>::new(cfg, rest(start), rest(goal), &path).unwrap();
        let sol = opt.optimize().unwrap();
        let v = sol.trajectory.max_speed(64) / v_max;
        let a = sol.trajectory.max_acceleration(64) / a_max;
        worst_v = worst_v.max(v);
        worst_a = worst_a.max(a);
        assert!(v <= 1.02, "case {case}: speed {v} × v_max ({sol:?})");
        assert!(a <= 1.02, "case {case}: acceleration {a} × a_max");
        assert!(
            sol.cost < sol.initial_cost,
            "case {case}: {} !< {}",
            sol.cost,
            sol.initial_cost
        );
        let pos = sol.trajectory.position(sol.trajectory.duration()).unwrap();
        assert!(
            (0..3).all(|d| (pos[d] - goal[d]).abs() < 1e-9),
            "case {case}: misses the goal"
        );
    }
    println!("S = {S}: worst speed ratio {worst_v:.4}, worst acceleration ratio {worst_a:.4}");
}

#[test]
fn two_hundred_random_paths_respect_the_limits() {
    random_paths_respect_the_limits::<3>(200, 2024);
}

#[test]
fn minimum_acceleration_and_snap_respect_the_limits() {
    random_paths_respect_the_limits::<2>(40, 7);
    random_paths_respect_the_limits::<4>(40, 11);
}

#[test]
fn bad_requests_are_typed_errors() {
    let rest = |x: [f64; 3]| [x, [0.0; 3], [0.0; 3]];
    let path = [[1.0, 0.0, 0.0]];
    let cfg = OptimizerConfig::default();
    assert!(matches!(
        Optimizer::<3, 3>::new(
            cfg.with_limits(0.0, 1.0),
            rest([0.0; 3]),
            rest([2.0, 0.0, 0.0]),
            &path
        ),
        Err(MincoError::InvalidConfig { .. })
    ));
    assert!(matches!(
        Optimizer::<3, 3>::new(
            cfg.with_limits(1.0, f64::NAN),
            rest([0.0; 3]),
            rest([2.0, 0.0, 0.0]),
            &path
        ),
        Err(MincoError::InvalidConfig { .. })
    ));
    assert!(matches!(
        Optimizer::<3, 3>::new(
            cfg,
            rest([0.0; 3]),
            rest([2.0, 0.0, 0.0]),
            &[[f64::NAN, 0.0, 0.0]]
        ),
        Err(MincoError::NonFinite { .. })
    ));
    // Starting faster than v_max cannot be made feasible.
    let fast = [[0.0; 3], [10.0, 0.0, 0.0], [0.0; 3]];
    assert!(matches!(
        Optimizer::<3, 3>::new(cfg, fast, rest([2.0, 0.0, 0.0]), &path),
        Err(MincoError::Infeasible(_))
    ));
    let mut opt =
        Optimizer::<3, 3>::new(cfg, rest([0.0; 3]), rest([2.0, 0.0, 0.0]), &path).unwrap();
    let mut g = vec![0.0; opt.dimension()];
    assert!(matches!(
        opt.cost_and_gradient(&[0.0], &mut g),
        Err(MincoError::LengthMismatch { .. })
    ));
    let x = vec![f64::INFINITY; opt.dimension()];
    assert!(matches!(
        opt.cost_and_gradient(&x, &mut g),
        Err(MincoError::NonFinite { .. })
    ));
    // Orders outside 2..=4 are refused before anything is indexed.
    assert!(matches!(
        Optimizer::<1, 3>::new(cfg, [[0.0; 3]], [[1.0; 3]], &[]),
        Err(MincoError::UnsupportedOrder(1))
    ));
    let mut huge = cfg;
    huge.memory = usize::MAX;
    assert!(matches!(
        huge.validate(),
        Err(MincoError::InvalidConfig { .. })
    ));
    // Zero inner points: a single piece still optimises.
    let mut single =
        Optimizer::<3, 3>::new(cfg, rest([0.0; 3]), rest([2.0, 0.0, 0.0]), &[]).unwrap();
    let sol = single.optimize().unwrap();
    assert!(sol.trajectory.max_speed(64) <= 3.0 * 1.02);
    assert_eq!(sol.max_speed, sol.trajectory.max_speed(64));
    assert!(matches!(
        sol.trajectory.sample(1e-300),
        Err(MincoError::InvalidConfig { .. })
    ));
    assert!(matches!(
        sol.trajectory.sample(f64::NAN),
        Err(MincoError::InvalidConfig { .. })
    ));
}
