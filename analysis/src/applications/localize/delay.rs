//! The input delay the sightings support: a velocity-commanded robot
//! executes its commands some tenths of a second after the log says
//! (`input_delay`, CONTRACT section 3). When the spec declares such a delay
//! and the filter's noise is estimated from the log, the delay is estimated
//! with it, by the same likelihood of the sightings' innovations: it needs
//! no ground truth either.
//!
//! The likelihood is not smooth in the delay: a shift moves sightings across
//! the gate, and each one that flips changes the cost by a step. A scan over
//! the parameter's range in steps of [`STEP_S`] finds the basin; a golden
//! section inside the best step's neighbours refines it; a step of the cost
//! smaller than [`super::noise::SIGNIFICANT`] is no evidence for either side.
use super::filter::{Filter, Keep, Pass};
use super::noise::{self, NoiseModel};
use super::EkfOptions;
use crate::model::Runner;
use crate::run::Run;

/// The scan's step, s: a tenth of the delays seen on real velocity-commanded
/// robots (0.1-0.5 s), and finer than the 0.26-1.4 s between their rows.
pub const STEP_S: f64 = 0.05;

/// The widest range scanned, s, whatever the parameter's bounds: delays
/// beyond a second are a clock error, not a controller's lag.
const RANGE_S: (f64, f64) = (-0.5, 1.0);

/// What the sightings say about the input delay.
#[derive(Debug, Clone, PartialEq)]
pub struct DelayEstimate {
    /// The parameter's name.
    pub name: String,
    /// The spec's (or `--set`'s) value, s.
    pub spec_s: f64,
    /// The delay the filter runs with, s.
    pub estimate_s: f64,
    /// -2 log-likelihood of the sightings with the spec's delay minus with
    /// the estimate (with the estimate's noise): how much the data prefer it.
    pub gain: f64,
}

/// The runs as the robot executed their commands with delay `tau`.
fn executed(r: &Runner, runs: &[Run], tau: f64) -> (Runner, Vec<Run>) {
    let mut at = r.clone();
    if let Some(i) = r.input_delay {
        at.p[i] = tau;
    }
    let runs = runs
        .iter()
        .map(|run| crate::timeline::executed(&at, &at.p, run).into_owned())
        .collect();
    (at, runs)
}

/// -2 log-likelihood of the sightings of `runs` with delay `tau` and `noise`.
fn cost(r: &Runner, runs: &[Run], o: &EkfOptions, noise: &NoiseModel, tau: f64) -> f64 {
    let (at, runs) = executed(r, runs, tau);
    let Ok(f) = Filter::new(&at, o) else {
        return f64::INFINITY;
    };
    runs.iter()
        .map(|run| match f.run(run, noise, Keep::Cost) {
            Ok(Pass { cost, .. }) if cost.is_finite() => cost,
            _ => f64::INFINITY,
        })
        .sum()
}

/// The delay in the parameter's bounds (within [`RANGE_S`]) that maximises the
/// sightings' likelihood with `noise` held, and its cost.
fn best_delay(
    r: &Runner,
    runs: &[Run],
    o: &EkfOptions,
    noise: &NoiseModel,
    i: usize,
) -> (f64, f64) {
    use rayon::prelude::*;
    let param = &r.ir.runtime_params()[i];
    let lo = param.min.unwrap_or(RANGE_S.0).max(RANGE_S.0);
    let hi = param.max.unwrap_or(RANGE_S.1).min(RANGE_S.1);
    let steps = ((hi - lo) / STEP_S).floor() as usize;
    let scan: Vec<(f64, f64)> = (0..=steps)
        .into_par_iter()
        .map(|k| {
            let tau = lo + k as f64 * STEP_S;
            (tau, cost(r, runs, o, noise, tau))
        })
        .collect();
    let (mut a, mut b) = (lo, hi);
    let (mut best, mut best_cost) = (r.p[i].clamp(lo, hi), f64::INFINITY);
    for &(tau, c) in &scan {
        if c < best_cost {
            (best, best_cost) = (tau, c);
            (a, b) = ((tau - STEP_S).max(lo), (tau + STEP_S).min(hi));
        }
    }
    // golden section within the best step's neighbours
    let g = (5f64.sqrt() - 1.0) / 2.0;
    let (mut x1, mut x2) = (b - g * (b - a), a + g * (b - a));
    let (mut c1, mut c2) = (cost(r, runs, o, noise, x1), cost(r, runs, o, noise, x2));
    for _ in 0..8 {
        if c1 <= c2 {
            (b, x2, c2) = (x2, x1, c1);
            x1 = b - g * (b - a);
            c1 = cost(r, runs, o, noise, x1);
        } else {
            (a, x1, c1) = (x1, x2, c2);
            x2 = a + g * (b - a);
            c2 = cost(r, runs, o, noise, x2);
        }
    }
    for (tau, c) in [(x1, c1), (x2, c2)] {
        if c < best_cost - noise::SIGNIFICANT {
            (best, best_cost) = (tau, c);
        }
    }
    (best, best_cost)
}

/// The noise and the input delay `runs` support, for a model that declares
/// an input delay (`r.input_delay`), starting from `noise` (estimated with
/// the spec's delay). The delay is found with that noise held, then the
/// noise is estimated again with the runs as the robot executed them; the
/// spec's delay is kept unless the likelihood prefers another by more than
/// [`noise::SIGNIFICANT`]. Returns the runner with the delay set.
pub fn estimate(
    r: &Runner,
    runs: &[Run],
    o: &EkfOptions,
    noise: NoiseModel,
    given: &[bool],
) -> (Runner, NoiseModel, Option<DelayEstimate>) {
    let Some(i) = r.input_delay else {
        return (r.clone(), noise, None);
    };
    let spec_s = r.p[i];
    let at_spec = cost(r, runs, o, &noise, spec_s);
    let (tau, c) = best_delay(r, runs, o, &noise, i);
    // (a NaN cost is no evidence either: the spec's delay stays)
    let preferred = c < at_spec - noise::SIGNIFICANT;
    if !preferred {
        let kept = DelayEstimate {
            name: r.names[i].clone(),
            spec_s,
            estimate_s: spec_s,
            gain: 0.0,
        };
        return (r.clone(), noise, Some(kept));
    }
    let (at, executed_runs) = executed(r, runs, tau);
    let refined = match Filter::new(&at, o) {
        Ok(f) => noise::estimate(&f, &executed_runs, &noise, given),
        Err(_) => noise,
    };
    let gain = cost(r, runs, o, &refined, spec_s) - cost(r, runs, o, &refined, tau);
    let found = DelayEstimate {
        name: r.names[i].clone(),
        spec_s,
        estimate_s: tau,
        gain,
    };
    (at, refined, Some(found))
}
