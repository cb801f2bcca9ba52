//! Ray insertion against a brute-force reference: every cell whose cube the segment crosses
//! for a positive length, found by clipping the segment to each cell of its bounding box.
#![allow(clippy::unwrap_used)]

mod common;

use std::collections::BTreeMap;

use frontier::{Bounds, Cell, CellState, MapConfig, VoxelMap};
use nalgebra::{Point3, Vector3};
use proptest::prelude::*;

/// The cell of `p`, clamped into the grid (a cut end may round a hair outside the bounds).
fn clamped(map: &VoxelMap, p: &Point3<f64>) -> Cell {
    let g = map.grid();
    let f = |k: usize| {
        ((p[k] - g.origin()[k]) / g.resolution())
            .floor()
            .clamp(0.0, f64::from(g.dims()[k] - 1)) as u32
    };
    Cell::new(f(0), f(1), f(2))
}

/// Cells the segment a → b crosses for a positive length, end cells always included.
fn brute_cells(map: &VoxelMap, a: &Point3<f64>, b: &Point3<f64>) -> Vec<Cell> {
    let g = map.grid();
    let (ca, cb) = (clamped(map, a), clamped(map, b));
    let mut out = vec![ca, cb];
    let res = g.resolution();
    for x in ca.x.min(cb.x)..=ca.x.max(cb.x) {
        for y in ca.y.min(cb.y)..=ca.y.max(cb.y) {
            for z in ca.z.min(cb.z)..=ca.z.max(cb.z) {
                let c = Cell::new(x, y, z);
                let lo = g.center(c) - Vector3::repeat(0.5 * res);
                let d = b - a;
                let (mut t0, mut t1) = (0.0f64, 1.0f64);
                for k in 0..3 {
                    if d[k] == 0.0 {
                        if a[k] < lo[k] || a[k] > lo[k] + res {
                            t1 = -1.0;
                        }
                    } else {
                        let (mut p, mut q) = ((lo[k] - a[k]) / d[k], (lo[k] + res - a[k]) / d[k]);
                        if p > q {
                            core::mem::swap(&mut p, &mut q);
                        }
                        t0 = t0.max(p);
                        t1 = t1.min(q);
                    }
                }
                if t1 - t0 > 1e-12 {
                    out.push(c);
                }
            }
        }
    }
    out.sort_unstable();
    out.dedup();
    out
}

fn q(p: f64) -> i32 {
    ((p / (1.0 - p)).ln() * 32.0).round() as i32
}

/// The reference map: quantised log-odds per observed cell, updated by the documented rules.
fn reference(map: &VoxelMap, frames: &[(Point3<f64>, Vec<Point3<f64>>)]) -> BTreeMap<Cell, i32> {
    let cfg = map.config();
    let (hit, miss, lo, hi) = (
        q(cfg.prob_hit),
        q(cfg.prob_miss),
        q(cfg.clamp_min),
        q(cfg.clamp_max),
    );
    let mut l: BTreeMap<Cell, i32> = BTreeMap::new();
    for (o, pts) in frames {
        let mut hits = std::collections::BTreeSet::new();
        let mut frees = std::collections::BTreeSet::new();
        let mut rays = Vec::new();
        for p in pts {
            let d = p - o;
            let (mut end, mut is_hit) = (*p, true);
            if d.norm() > cfg.max_range {
                end = o + d * (cfg.max_range / d.norm());
                is_hit = false;
            }
            if !map.bounds().contains(&end) {
                // Cut at the bounds.
                let (bl, bh) = (map.bounds().min(), map.bounds().max());
                let mut t1 = 1.0f64;
                for k in 0..3 {
                    let dk = end[k] - o[k];
                    if dk > 0.0 {
                        t1 = t1.min((bh[k] - o[k]) / dk);
                    } else if dk < 0.0 {
                        t1 = t1.min((bl[k] - o[k]) / dk);
                    }
                }
                end = o + (end - o) * t1;
                is_hit = false;
            }
            if is_hit {
                hits.insert(clamped(map, &end));
            }
            rays.push(end);
        }
        for end in &rays {
            for c in brute_cells(map, o, end) {
                if !hits.contains(&c) {
                    frees.insert(c);
                }
            }
        }
        for (set, delta) in [(&hits, hit), (&frees, miss)] {
            for c in set {
                let v = match l.get(c) {
                    None => delta,
                    Some(v) => v + delta,
                };
                l.insert(*c, v.clamp(lo, hi));
            }
        }
    }
    l
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]

    #[test]
    fn insertion_equals_the_reference(
        seed in 0u64..1000,
        boxes in proptest::collection::vec((0.5f64..7.5, 0.5f64..5.5, 0.2f64..2.8, 0.2f64..1.5), 1..5),
        origins in proptest::collection::vec((1.0f64..7.0, 1.0f64..5.0, 0.5f64..2.5), 1..4),
        range in 3.0f64..9.0,
    ) {
        let bounds = Bounds::new(Point3::new(0.0, 0.0, 0.0), Point3::new(8.0, 6.0, 3.0)).unwrap();
        let cfg = MapConfig { max_range: range, ..Default::default() };
        let mut map = VoxelMap::new(bounds, cfg).unwrap();
        let scene = common::Scene {
            boxes: boxes
                .iter()
                .map(|&(x, y, z, h)| (Point3::new(x, y, z), Point3::new(x + h, y + h, z + h)))
                .collect(),
        };
        let mut frames = Vec::new();
        for (k, &(x, y, z)) in origins.iter().enumerate() {
            let o = Point3::new(x, y, z);
            let mut pts = scene.scan(&o, 23 + (seed % 7) as u32, 9, 12.0);
            // Also rays that leave the bounds and rays longer than the range.
            pts.push(o + Vector3::new(11.0, 0.31 * k as f64, 0.2));
            frames.push((o, pts));
        }
        let states = |map: &VoxelMap| {
            let mut m = BTreeMap::new();
            map.for_each_known(|c, s| {
                m.insert(c, s);
            });
            m
        };
        for (o, pts) in &frames {
            // The reported changes are exactly the cells whose state differs, each once, and
            // the map's counts follow them.
            let before = states(&map);
            let update = map.insert_frame(o, pts).unwrap();
            let after = states(&map);
            let mut want_changes = Vec::new();
            for (c, s) in &after {
                let was = before.get(c).copied().unwrap_or(CellState::Unknown);
                if was != *s {
                    want_changes.push((*c, was, *s));
                }
            }
            let mut got_changes: Vec<_> =
                update.changed.iter().map(|x| (x.cell, x.before, x.after)).collect();
            got_changes.sort_unstable_by_key(|x| x.0);
            prop_assert_eq!(got_changes, want_changes);
            prop_assert_eq!(map.known_cells(), after.len());
            prop_assert_eq!(
                map.occupied_cells(),
                after.values().filter(|s| **s == CellState::Occupied).count()
            );
        }
        let want = reference(&map, &frames);
        let mut got = BTreeMap::new();
        map.for_each_known(|c, s| {
            got.insert(c, s);
        });
        prop_assert_eq!(got.len(), want.len());
        for (c, l) in &want {
            let s = if *l >= 0 { CellState::Occupied } else { CellState::Free };
            prop_assert_eq!(got.get(c), Some(&s), "cell {:?}", c);
            let p = 1.0 / (1.0 + (-f64::from(*l) / 32.0).exp());
            prop_assert!((map.probability(*c).unwrap() - p).abs() < 1e-12);
        }
    }
}
