//! The command timing the sightings support: a velocity-commanded robot
//! executes its commands some tenths of a second after the log says
//! (`input_delay`, CONTRACT section 3) and follows them with a first-order
//! lag (`command_lag`). When the spec declares such a parameter and the
//! filter's noise is estimated from the log, the parameter is estimated with
//! it, by the same likelihood of the sightings' innovations: it needs no
//! ground truth either. A spec that declares both gets the delay first,
//! then the lag with the delay found.
//!
//! The likelihood is not smooth in the timing: a shift moves sightings across
//! the gate, and each one that flips changes the cost by a step. A scan over
//! the parameter's range in steps of [`STEP_S`] finds the basin; a golden
//! section inside the best step's neighbours refines it; a step of the cost
//! smaller than [`super::noise::SIGNIFICANT`] is no evidence for either side.
use super::filter::{Filter, Keep, Pass};
use super::noise;
use super::noise_model::NoiseModel;
use super::EkfOptions;
use crate::model_on_log::model::Runner;
use crate::model_on_log::run::Run;

/// The scan's step, s: a tenth of the delays seen on real velocity-commanded
/// robots (0.1-0.5 s), and finer than the 0.26-1.4 s between their rows.
pub const STEP_S: f64 = 0.05;

/// A command-timing parameter a spec may declare (see [`crate::model_on_log::timeline`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Timing {
    /// The command logged at t acts from t + delay (`input_delay = true`).
    Delay,
    /// The robot follows its commands with this time constant (`input_lag = true`).
    Lag,
}

impl Timing {
    /// Both, in the order they are estimated: the lag follows the delay.
    pub const ALL: [Timing; 2] = [Timing::Delay, Timing::Lag];

    /// The spec's parameter for it, if it declares one.
    pub fn parameter(self, r: &Runner) -> Option<usize> {
        match self {
            Timing::Delay => r.input_delay,
            Timing::Lag => r.input_lag,
        }
    }

    /// The widest range scanned, s, whatever the parameter's bounds: a
    /// delay beyond a second is a clock error, not a controller's lag; a
    /// delay may be negative (a log stamped late), a time constant may not.
    fn range(self) -> (f64, f64) {
        match self {
            Timing::Delay => (-0.5, 1.0),
            Timing::Lag => (0.0, 1.0),
        }
    }

    /// What it is, in words.
    pub fn what(self) -> &'static str {
        match self {
            Timing::Delay => "input delay",
            Timing::Lag => "command lag",
        }
    }
}

/// What the sightings say about one timing parameter.
#[derive(Debug, Clone, PartialEq)]
pub struct TimingEstimate {
    pub timing: Timing,
    /// The parameter's name.
    pub name: String,
    /// The spec's (or `--set`'s) value, s.
    pub spec_s: f64,
    /// The value the filter runs with, s.
    pub estimate_s: f64,
    /// -2 log-likelihood of the sightings with the spec's value minus with
    /// the estimate (with the estimate's noise): how much the data prefer it.
    pub gain: f64,
}

/// The runs as the robot executed their commands with parameter `i` at `value`.
fn executed(r: &Runner, runs: &[Run], i: usize, value: f64) -> (Runner, Vec<Run>) {
    let mut at = r.clone();
    at.p[i] = value;
    let runs = runs
        .iter()
        .map(|run| crate::model_on_log::timeline::executed(&at, &at.p, run).into_owned())
        .collect();
    (at, runs)
}

/// -2 log-likelihood of the sightings of `runs` with parameter `i` at `tau`
/// and `noise`.
fn cost(r: &Runner, runs: &[Run], o: &EkfOptions, noise: &NoiseModel, i: usize, tau: f64) -> f64 {
    let (at, runs) = executed(r, runs, i, tau);
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

/// The value of `timing`'s parameter `i` in its bounds (within
/// [`Timing::range`]) that maximises the sightings' likelihood with `noise`
/// held, and its cost.
fn best_value(
    r: &Runner,
    runs: &[Run],
    o: &EkfOptions,
    noise: &NoiseModel,
    (timing, i): (Timing, usize),
) -> (f64, f64) {
    use rayon::prelude::*;
    let param = &r.ir.runtime_params()[i];
    let range = timing.range();
    let lo = param.min.unwrap_or(range.0).max(range.0);
    let hi = param.max.unwrap_or(range.1).min(range.1);
    let steps = ((hi - lo) / STEP_S).floor() as usize;
    let scan: Vec<(f64, f64)> = (0..=steps)
        .into_par_iter()
        .map(|k| {
            let tau = lo + k as f64 * STEP_S;
            (tau, cost(r, runs, o, noise, i, tau))
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
    let (mut c1, mut c2) = (
        cost(r, runs, o, noise, i, x1),
        cost(r, runs, o, noise, i, x2),
    );
    for _ in 0..8 {
        if c1 <= c2 {
            (b, x2, c2) = (x2, x1, c1);
            x1 = b - g * (b - a);
            c1 = cost(r, runs, o, noise, i, x1);
        } else {
            (a, x1, c1) = (x1, x2, c2);
            x2 = a + g * (b - a);
            c2 = cost(r, runs, o, noise, i, x2);
        }
    }
    for (tau, c) in [(x1, c1), (x2, c2)] {
        if c < best_cost - noise::SIGNIFICANT {
            (best, best_cost) = (tau, c);
        }
    }
    (best, best_cost)
}

/// The noise and the command timing `runs` support, for the timing
/// parameters in `timings` that the model declares, starting from `noise`
/// (estimated with the spec's values). Each parameter in turn is found with
/// the noise held, then the noise is estimated again with the runs as the
/// robot executed them; the spec's value is kept unless the likelihood
/// prefers another by more than [`noise::SIGNIFICANT`]. Returns the runner
/// with the values set.
pub fn estimate(
    r: &Runner,
    runs: &[Run],
    o: &EkfOptions,
    mut noise: NoiseModel,
    (given, timings): (&[bool], &[Timing]),
) -> (Runner, NoiseModel, Vec<TimingEstimate>) {
    let mut at = r.clone();
    let mut found = Vec::new();
    for &timing in timings {
        let Some(i) = timing.parameter(&at) else {
            continue;
        };
        let (next, refined, estimate) = estimate_one(&at, runs, o, noise, given, (timing, i));
        (at, noise) = (next, refined);
        found.push(estimate);
    }
    (at, noise, found)
}

/// [`estimate`] for parameter `i` alone.
fn estimate_one(
    r: &Runner,
    runs: &[Run],
    o: &EkfOptions,
    noise: NoiseModel,
    given: &[bool],
    (timing, i): (Timing, usize),
) -> (Runner, NoiseModel, TimingEstimate) {
    let spec_s = r.p[i];
    let at_spec = cost(r, runs, o, &noise, i, spec_s);
    let (tau, c) = best_value(r, runs, o, &noise, (timing, i));
    let estimate = |estimate_s, gain| TimingEstimate {
        timing,
        name: r.names[i].clone(),
        spec_s,
        estimate_s,
        gain,
    };
    // (a NaN cost is no evidence either: the spec's value stays)
    let preferred = c < at_spec - noise::SIGNIFICANT;
    if !preferred {
        return (r.clone(), noise, estimate(spec_s, 0.0));
    }
    let (at, executed_runs) = executed(r, runs, i, tau);
    let refined = match Filter::new(&at, o) {
        Ok(f) => noise::estimate(&f, &executed_runs, &noise, given),
        Err(_) => noise,
    };
    let gain = cost(r, runs, o, &refined, i, spec_s) - cost(r, runs, o, &refined, i, tau);
    (at, refined, estimate(tau, gain))
}
