//! L-BFGS with the weak-Wolfe bracketing line search of Lewis and Overton.
//!
//! The Lewis–Overton search only brackets: it doubles the step while the curvature
//! condition fails and bisects once the sufficient-decrease condition fails. Unlike
//! strong-Wolfe searches it needs no interpolation and copes with the kinks the
//! penalty terms introduce, which is why GCOPTER-style optimisers use it.

/// How a minimisation ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[non_exhaustive]
pub enum Status {
    /// The relative cost decrease or the gradient norm fell below its tolerance.
    Converged,
    /// The iteration budget ran out; the best point so far is returned.
    MaxIterations,
    /// The line search found no acceptable step (usually: converged to rounding level).
    LineSearchFailed,
}

/// Settings of the minimiser.
#[derive(Debug, Clone, Copy)]
pub(crate) struct LbfgsSettings {
    pub(crate) memory: usize,
    pub(crate) max_iterations: usize,
    pub(crate) rel_cost_tol: f64,
    /// The relative decrease is measured over this many iterations.
    pub(crate) past: usize,
    pub(crate) grad_tol: f64,
    pub(crate) c1: f64,
    pub(crate) c2: f64,
    pub(crate) max_line_search: usize,
}

/// Result of a minimisation.
#[derive(Debug, Clone)]
pub(crate) struct LbfgsResult {
    pub(crate) iterations: usize,
    pub(crate) status: Status,
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// Minimises `f` from `x` (overwritten with the result). `f(x, grad)` returns the cost and
/// writes the gradient; a non-finite cost is treated as +∞ (the step is shortened).
pub(crate) fn minimize(
    x: &mut [f64],
    settings: &LbfgsSettings,
    mut f: impl FnMut(&[f64], &mut [f64]) -> f64,
) -> LbfgsResult {
    let n = x.len();
    let m = settings.memory.max(1);
    let mut g = vec![0.0; n];
    let mut fx = f(x, &mut g);
    // History rows are allocated as pairs are stored, so a large `memory` costs only what
    // the run uses.
    let mut s_hist: Vec<Vec<f64>> = Vec::new();
    let mut y_hist: Vec<Vec<f64>> = Vec::new();
    let mut rho = vec![0.0; m];
    let mut alpha = vec![0.0; m];
    let (mut head, mut len) = (0usize, 0usize);
    let mut d = vec![0.0; n];
    let mut x_new = vec![0.0; n];
    let mut g_new = vec![0.0; n];
    let (mut s_new, mut y_new) = (vec![0.0; n], vec![0.0; n]);
    let mut status = Status::MaxIterations;
    let mut iterations = 0;
    let past = settings.past.max(1);
    let mut history = vec![fx; past];
    if !fx.is_finite() {
        return LbfgsResult {
            iterations,
            status: Status::LineSearchFailed,
        };
    }
    while iterations < settings.max_iterations {
        let gnorm = dot(&g, &g).sqrt();
        if gnorm <= settings.grad_tol * fx.abs().max(1.0) {
            status = Status::Converged;
            break;
        }
        // Two-loop recursion: d = −H g.
        d.copy_from_slice(&g);
        for k in 0..len {
            let i = (head + m - 1 - k) % m;
            alpha[i] = rho[i] * dot(&s_hist[i], &d);
            for (dj, yj) in d.iter_mut().zip(&y_hist[i]) {
                *dj -= alpha[i] * yj;
            }
        }
        if len > 0 {
            let i = (head + m - 1) % m;
            let gamma = dot(&s_hist[i], &y_hist[i]) / dot(&y_hist[i], &y_hist[i]);
            d.iter_mut().for_each(|v| *v *= gamma);
        } else {
            // First step: unit length.
            d.iter_mut().for_each(|v| *v /= gnorm);
        }
        for k in (0..len).rev() {
            let i = (head + m - 1 - k) % m;
            let beta = rho[i] * dot(&y_hist[i], &d);
            for (dj, sj) in d.iter_mut().zip(&s_hist[i]) {
                *dj += sj * (alpha[i] - beta);
            }
        }
        d.iter_mut().for_each(|v| *v = -*v);
        let mut dg0 = dot(&d, &g);
        if dg0.is_nan() || dg0 >= 0.0 {
            // Not a descent direction (numerical trouble): restart from steepest descent.
            for (dj, gj) in d.iter_mut().zip(&g) {
                *dj = -gj / gnorm;
            }
            dg0 = -gnorm;
            len = 0;
        }

        // Lewis–Overton weak-Wolfe bracketing.
        let (mut lo, mut hi, mut t) = (0.0f64, f64::INFINITY, 1.0f64);
        let mut accepted = None;
        for _ in 0..settings.max_line_search {
            for ((xn, xi), di) in x_new.iter_mut().zip(x.iter()).zip(&d) {
                *xn = xi + t * di;
            }
            let fn_ = f(&x_new, &mut g_new);
            if !fn_.is_finite() || fn_ > fx + settings.c1 * t * dg0 {
                hi = t;
            } else if dot(&g_new, &d) < settings.c2 * dg0 {
                lo = t;
            } else {
                accepted = Some(fn_);
                break;
            }
            t = if hi.is_finite() {
                0.5 * (lo + hi)
            } else {
                2.0 * lo.max(t)
            };
        }
        let Some(f_new) = accepted else {
            status = Status::LineSearchFailed;
            break;
        };
        iterations += 1;
        // History update (cautious: only with positive curvature). The pair is built in
        // scratch so a rejected one never overwrites the oldest stored pair.
        for k in 0..n {
            s_new[k] = x_new[k] - x[k];
            y_new[k] = g_new[k] - g[k];
        }
        let sy = dot(&s_new, &y_new);
        if sy > 1e-12 * dot(&s_new, &s_new).sqrt() * dot(&y_new, &y_new).sqrt() {
            // `head` walks 0, 1, … before wrapping, so a slot is new exactly at the end.
            if head == s_hist.len() {
                s_hist.push(s_new.clone());
                y_hist.push(y_new.clone());
            } else {
                s_hist[head].copy_from_slice(&s_new);
                y_hist[head].copy_from_slice(&y_new);
            }
            rho[head] = 1.0 / sy;
            head = (head + 1) % m;
            len = (len + 1).min(m);
        }
        x.copy_from_slice(&x_new);
        g.copy_from_slice(&g_new);
        // Relative decrease over the last `past` iterations.
        let before = history[iterations % past];
        history[iterations % past] = f_new;
        fx = f_new;
        let decrease = (before - f_new) / f_new.abs().max(1.0);
        if iterations >= past && decrease < settings.rel_cost_tol {
            status = Status::Converged;
            break;
        }
    }
    LbfgsResult { iterations, status }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn settings() -> LbfgsSettings {
        LbfgsSettings {
            memory: 8,
            max_iterations: 500,
            rel_cost_tol: 0.0,
            past: 3,
            grad_tol: 1e-10,
            c1: 1e-4,
            c2: 0.9,
            max_line_search: 60,
        }
    }

    #[test]
    fn minimises_rosenbrock() {
        let mut x = [-1.2, 1.0];
        let r = minimize(&mut x, &settings(), |x, g| {
            let (a, b) = (x[0], x[1]);
            g[0] = -2.0 * (1.0 - a) - 400.0 * a * (b - a * a);
            g[1] = 200.0 * (b - a * a);
            (1.0 - a).powi(2) + 100.0 * (b - a * a).powi(2)
        });
        assert!(
            (x[0] - 1.0).abs() < 1e-5 && (x[1] - 1.0).abs() < 1e-5,
            "{x:?} {r:?}"
        );
    }

    #[test]
    fn minimises_a_kinked_function() {
        // |x| + x² style kink: the bracketing search still makes progress.
        let f = |x: &[f64], g: &mut [f64]| {
            g[0] = x[0].signum() + 2.0 * x[0];
            g[1] = 2.0 * (x[1] - 1.0);
            x[0].abs() + x[0] * x[0] + (x[1] - 1.0).powi(2)
        };
        let mut x = [3.0, -2.0];
        let r = minimize(&mut x, &settings(), f);
        let cost = f(&x, &mut [0.0; 2]);
        assert!(cost < 1e-6, "{x:?} {r:?}");
    }

    #[test]
    fn non_finite_start_is_reported() {
        let mut x = [0.0];
        let r = minimize(&mut x, &settings(), |_, g| {
            g[0] = 0.0;
            f64::NAN
        });
        assert_eq!(r.status, Status::LineSearchFailed);
    }
}
