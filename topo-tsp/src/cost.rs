//! The transition cost (7), the heading term (8), and the cost matrix of the open tour (9).

use crate::error::{Result, TspError};
use crate::graph::{NodeId, TopoGraph};
use crate::matrix::CostMatrix;

/// Settings of the global cost.
///
/// # Example
/// ```
/// use topo_tsp::CostConfig;
/// let cfg = CostConfig::default();
/// assert_eq!(cfg.v_max, 3.0);
/// assert!(cfg.validate().is_ok());
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
#[non_exhaustive]
pub struct CostConfig {
    /// Maximum flight speed v_max \[m/s\]. Default 3.0, the FU-MPC experiments' value.
    pub v_max: f64,
    /// Heading weight w_f of eq. (8) \[s/rad\]. The paper gives no value; default 1.0.
    pub heading_weight: f64,
    /// Below this speed \[m/s\] the heading term is left out (the direction of motion is
    /// undefined at rest). Default 0.1.
    pub min_heading_speed: f64,
    /// Cost \[s\] of an arc between nodes with no graph path. Default 10,000.
    pub unreachable_penalty: f64,
}

impl Default for CostConfig {
    fn default() -> Self {
        Self {
            v_max: 3.0,
            heading_weight: 1.0,
            min_heading_speed: 0.1,
            unreachable_penalty: 1e4,
        }
    }
}

impl CostConfig {
    /// Checks every setting.
    ///
    /// # Errors
    /// [`TspError::InvalidConfig`] naming the first bad one.
    pub fn validate(&self) -> Result<()> {
        let ok =
            |v: f64, positive: bool| v.is_finite() && if positive { v > 0.0 } else { v >= 0.0 };
        if !ok(self.v_max, true) {
            return Err(TspError::InvalidConfig {
                what: "v_max",
                reason: "must be positive and finite",
            });
        }
        if !ok(self.heading_weight, false)
            || !ok(self.min_heading_speed, false)
            || !ok(self.unreachable_penalty, false)
        {
            return Err(TspError::InvalidConfig {
                what: "heading_weight, min_heading_speed, unreachable_penalty",
                reason: "must be non-negative and finite",
            });
        }
        Ok(())
    }
}

/// The transition cost of eq. (7) along a path of points \[s\]:
/// d = Σ_l (‖x_{l+1} − x_l‖ + 0.5 |z_{l+1} − z_l|) / (v_max / 2); ∞ for a `v_max` that is not
/// positive (NaN included).
///
/// # Example
/// ```
/// use topo_tsp::transition_cost;
/// // 3 m level and 2 m of climb at v_max = 2 m/s: (3 + (2 + 1)) / 1 s.
/// let d = transition_cost(&[[0.0, 0.0, 0.0], [3.0, 0.0, 0.0], [3.0, 0.0, 2.0]], 2.0);
/// assert!((d - 6.0).abs() < 1e-12);
/// ```
pub fn transition_cost(path: &[[f64; 3]], v_max: f64) -> f64 {
    let sum: f64 = path
        .windows(2)
        .map(|w| {
            let (a, b) = (w[0], w[1]);
            let len =
                ((b[0] - a[0]).powi(2) + (b[1] - a[1]).powi(2) + (b[2] - a[2]).powi(2)).sqrt();
            // eq. (7): altitude change costs half a metre per metre on top of the length
            len + 0.5 * (b[2] - a[2]).abs()
        })
        .sum();
    if v_max.is_nan() || v_max <= 0.0 {
        // No speed covers any distance.
        return f64::INFINITY;
    }
    sum / (0.5 * v_max)
}

/// The heading term of eq. (8) \[s\]: w_f θ, θ the angle between the velocity and the direction
/// from `from` to `to`; 0 when the speed is below `min_speed` or the two points coincide.
///
/// # Example
/// ```
/// use topo_tsp::heading_cost;
/// let h = heading_cost([1.0, 0.0, 0.0], [0.0; 3], [0.0, 5.0, 0.0], 2.0, 0.1);
/// assert!((h - std::f64::consts::PI).abs() < 1e-12); // 90° × 2 s/rad
/// ```
pub fn heading_cost(
    velocity: [f64; 3],
    from: [f64; 3],
    to: [f64; 3],
    weight: f64,
    min_speed: f64,
) -> f64 {
    let d = [to[0] - from[0], to[1] - from[1], to[2] - from[2]];
    let speed = norm(velocity);
    let len = norm(d);
    if !(speed >= min_speed && speed > 0.0 && len > 0.0) {
        return 0.0;
    }
    let theta = if (1e-70..=1e70).contains(&speed) && (1e-70..=1e70).contains(&len) {
        angle(velocity, d)
    } else {
        // Products that may over- or underflow: the angle does not depend on the vectors'
        // lengths, so of both scaled to unit size.
        let unit = |v: [f64; 3]| {
            let m = largest(v);
            v.map(|x| x / m)
        };
        angle(unit(velocity), unit(d))
    };
    // eq. (8)
    weight * theta
}

/// The angle between `a` and `b`, atan2(‖a × b‖, a · b).
fn angle(a: [f64; 3], b: [f64; 3]) -> f64 {
    let cross = [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ];
    let dot = a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    (cross[0].powi(2) + cross[1].powi(2) + cross[2].powi(2))
        .sqrt()
        .atan2(dot)
}

/// The largest magnitude of a vector's components.
fn largest(v: [f64; 3]) -> f64 {
    v.iter().fold(0.0f64, |m, x| m.max(x.abs()))
}

/// ‖v‖, also where the squares over- or underflow (scaled to the largest component then).
pub(crate) fn norm(v: [f64; 3]) -> f64 {
    let n = (v[0].powi(2) + v[1].powi(2) + v[2].powi(2)).sqrt();
    if n > 0.0 && n.is_finite() {
        return n;
    }
    let m = largest(v);
    if !(m > 0.0 && m.is_finite()) {
        return n;
    }
    let u = v.map(|x| x / m);
    m * (u[0].powi(2) + u[1].powi(2) + u[2].powi(2)).sqrt()
}

/// The (M + 1) × (M + 1) cost matrix of the open tour (9): node 0 is the odometry node `odom`,
/// nodes 1..=M the `viewpoints`. Entry (i, j) is the cost (7) along the shortest graph path,
/// plus the heading term (8) on arcs out of node 0; pairs with no path cost
/// `unreachable_penalty`. Arcs into node 0 keep their cost: the solver makes them free.
///
/// # Errors
/// [`TspError::InvalidConfig`] for bad settings, [`TspError::NonFinite`] for a non-finite
/// velocity, [`TspError::NoSuchNode`] for unknown nodes, [`TspError::TooLarge`] for more than
/// [`CostMatrix::MAX_LEN`] nodes in all, and [`TspError::BadCost`] when settings that pass
/// [`CostConfig::validate`] still make a cost overflow (a heading weight near `f64::MAX`, a
/// `v_max` of a few subnormals).
///
/// # Example
/// ```
/// use topo_tsp::{CostConfig, TopoGraph, cost_matrix};
/// # fn main() -> Result<(), topo_tsp::TspError> {
/// let free = |_: &[f64; 3], _: &[f64; 3]| true;
/// let mut g = TopoGraph::new();
/// let a = g.add_node([0.0, 0.0, 1.0], 5.0, &free)?;
/// let b = g.add_node([3.0, 0.0, 1.0], 5.0, &free)?;
/// let m = cost_matrix(&g, a, &[b], [0.0; 3], &CostConfig::default())?;
/// assert!((m.cost(0, 1) - 2.0).abs() < 1e-12); // 3 m at v_max/2 = 1.5 m/s
/// # Ok(()) }
/// ```
pub fn cost_matrix(
    graph: &TopoGraph,
    odom: NodeId,
    viewpoints: &[NodeId],
    velocity: [f64; 3],
    cfg: &CostConfig,
) -> Result<CostMatrix> {
    cfg.validate()?;
    if !velocity.iter().all(|v| v.is_finite()) {
        return Err(TspError::NonFinite { what: "velocity" });
    }
    let nodes: Vec<NodeId> = std::iter::once(odom)
        .chain(viewpoints.iter().copied())
        .collect();
    let positions = nodes
        .iter()
        .map(|&n| graph.position(n))
        .collect::<Result<Vec<_>>>()?;
    let n = nodes.len();
    CostMatrix::check_len(n)?;
    let mut rows = vec![vec![0.0; n]; n];
    for i in 0..n {
        let sp = graph.shortest_paths_from(nodes[i])?;
        for j in 0..n {
            if i == j {
                continue;
            }
            rows[i][j] = match sp.path_to(nodes[j]) {
                Some(path) => {
                    let pts = path
                        .iter()
                        .map(|&v| graph.position(v))
                        .collect::<Result<Vec<_>>>()?;
                    transition_cost(&pts, cfg.v_max)
                }
                None => cfg.unreachable_penalty,
            };
            if i == 0 {
                rows[i][j] += heading_cost(
                    velocity,
                    positions[0],
                    positions[j],
                    cfg.heading_weight,
                    cfg.min_heading_speed,
                );
            }
        }
    }
    CostMatrix::from_rows(&rows)
}

#[cfg(test)]
mod tests {
    use super::*;
    use core::f64::consts::FRAC_PI_2;

    #[test]
    fn cost_matrix_on_a_hand_made_graph() {
        // A corridor 0 — 1 — 2 with a climb to 2, and an isolated node 3.
        let free = |_: &[f64; 3], _: &[f64; 3]| true;
        let mut g = TopoGraph::new();
        let n0 = g.add_node([0.0, 0.0, 0.0], 4.5, &free).unwrap();
        let n1 = g.add_node([4.0, 0.0, 0.0], 4.5, &free).unwrap();
        let n2 = g.add_node([4.0, 0.0, 3.0], 4.5, &free).unwrap();
        let n3 = g.add_node([50.0, 0.0, 0.0], 1.0, &free).unwrap();
        let cfg = CostConfig {
            v_max: 2.0,
            heading_weight: 2.0,
            min_heading_speed: 0.1,
            unreachable_penalty: 999.0,
        };
        // Moving along +y: node 1 (along +x) is 90° off.
        let m = cost_matrix(&g, n0, &[n1, n2, n3], [0.0, 1.0, 0.0], &cfg).unwrap();
        // 0 → 1: 4 m at 1 m/s plus 2 s/rad × π/2.
        assert!((m.cost(0, 1) - (4.0 + 2.0 * FRAC_PI_2)).abs() < 1e-12);
        // 1 → 2: 3 m of climb: (3 + 1.5) / 1.
        assert!((m.cost(1, 2) - 4.5).abs() < 1e-12);
        // 2 → 0: 5 m apart, beyond the 4.5 m radius, so via node 1: (3 + 1.5) + 4; no heading
        // term on arcs not out of node 0.
        assert!((m.cost(2, 0) - 8.5).abs() < 1e-12);
        assert_eq!(
            m.cost(0, 3) - heading_cost([0.0, 1.0, 0.0], [0.0; 3], [50.0, 0.0, 0.0], 2.0, 0.1),
            999.0
        );
        assert_eq!(m.cost(3, 1), 999.0);
        // At rest there is no heading term.
        let still = cost_matrix(&g, n0, &[n1], [0.0; 3], &cfg).unwrap();
        assert!((still.cost(0, 1) - 4.0).abs() < 1e-12);
    }

    #[test]
    fn bad_input_is_a_typed_error() {
        let free = |_: &[f64; 3], _: &[f64; 3]| true;
        let mut g = TopoGraph::new();
        let a = g.add_node([0.0; 3], 1.0, &free).unwrap();
        let cfg = CostConfig::default();
        assert!(matches!(
            cost_matrix(&g, a, &[7], [0.0; 3], &cfg),
            Err(TspError::NoSuchNode { .. })
        ));
        assert!(matches!(
            cost_matrix(&g, a, &[], [f64::NAN, 0.0, 0.0], &cfg),
            Err(TspError::NonFinite { .. })
        ));
        let bad = CostConfig { v_max: 0.0, ..cfg };
        assert!(matches!(
            cost_matrix(&g, a, &[], [0.0; 3], &bad),
            Err(TspError::InvalidConfig { .. })
        ));
        let bad = CostConfig {
            unreachable_penalty: -1.0,
            ..cfg
        };
        assert!(bad.validate().is_err());
        // n = 1: a single odometry node.
        assert_eq!(cost_matrix(&g, a, &[], [0.0; 3], &cfg).unwrap().len(), 1);
        assert_eq!(
            heading_cost([1.0, 0.0, 0.0], [0.0; 3], [0.0; 3], 1.0, 0.1),
            0.0
        );
    }
}
