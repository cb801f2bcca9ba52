//! Costs and coordinates at the edges of the floats: valid tours, true angles and edges
//! within the radius, never a partial answer.
#![allow(clippy::unwrap_used)]

use core::f64::consts::{FRAC_PI_4, PI};

use topo_tsp::{
    CostMatrix, TopoGraph, brute_force, heading_cost, held_karp, held_karp_open, transition_cost,
};

fn is_permutation_from_zero(order: &[usize], n: usize) -> bool {
    let mut seen = vec![false; n];
    order.len() == n
        && order.first() == Some(&0)
        && order
            .iter()
            .all(|&i| i < n && !std::mem::replace(&mut seen[i], true))
}

/// When every tour's length overflows the exact solver still returns a whole tour, as the
/// brute force does.
#[test]
fn exact_tours_of_costs_that_overflow_are_whole() {
    for n in 3..=6 {
        let m = CostMatrix::from_fn(n, |i, j| if i == j { 0.0 } else { 1e308 }).unwrap();
        let hk = held_karp(&m).unwrap();
        assert!(
            is_permutation_from_zero(&hk.order, n),
            "{n}: {:?}",
            hk.order
        );
        assert_eq!(hk.length, f64::INFINITY);
        assert_eq!(hk.length, brute_force(&m).unwrap().length);
        let open = held_karp_open(&m).unwrap();
        assert!(is_permutation_from_zero(&open.order, n));
        assert_eq!(open.length, m.open_length(&open.order));
    }
}

/// The heading angle does not depend on the vectors' lengths, even where their products over-
/// or underflow.
#[test]
fn heading_angles_of_huge_and_tiny_vectors() {
    for s in [1.0, 1e200, 1e300, 1e-200] {
        let h = heading_cost([s, s, 0.0], [0.0; 3], [1.0, 0.0, 0.0], 1.0, 0.0);
        assert!((h - FRAC_PI_4).abs() < 1e-12, "velocity scale {s}: {h}");
        let h = heading_cost([1.0, 0.0, 0.0], [0.0; 3], [s, s, 0.0], 1.0, 0.0);
        assert!((h - FRAC_PI_4).abs() < 1e-12, "offset scale {s}: {h}");
    }
    let back = heading_cost([-1e300, 0.0, 0.0], [0.0; 3], [1e300, 0.0, 0.0], 1.0, 0.0);
    assert!((back - PI).abs() < 1e-12);
}

/// A v_max that is not positive covers no distance.
#[test]
fn transition_cost_without_speed_is_infinite() {
    let path = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]];
    for v in [0.0, -1.0, f64::NAN] {
        assert_eq!(transition_cost(&path, v), f64::INFINITY);
        assert_eq!(transition_cost(&[], v), f64::INFINITY);
    }
    assert_eq!(transition_cost(&path, 2.0), 1.0);
}

/// With a radius whose square overflows, nodes join only the nodes within it, by finite
/// edges.
#[test]
fn huge_radii_link_only_nodes_within_them() {
    let free = |_: &[f64; 3], _: &[f64; 3]| true;
    let mut g = TopoGraph::new();
    let a = g.add_node([0.0; 3], 1e200, &free).unwrap();
    let b = g.add_node([1e180, 0.0, 0.0], 1e200, &free).unwrap();
    let c = g.add_node([-f64::MAX, 0.0, 0.0], 1e200, &free).unwrap();
    let d = g.add_node([1e250, 0.0, 0.0], 1e200, &free).unwrap();
    let neighbours = |n| g.neighbors(n).unwrap().to_vec();
    assert_eq!(neighbours(a), vec![(b, 1e180)]);
    assert!(neighbours(c).is_empty());
    assert!(neighbours(d).is_empty());
    assert!(neighbours(b).iter().all(|&(_, len)| len.is_finite()));
}
