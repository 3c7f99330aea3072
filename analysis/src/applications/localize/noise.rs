//! The filter's noise: what the spec declares, what the user gives, or what
//! the log itself says.
//!
//! Estimation maximises the likelihood of the sightings' innovations (the
//! prediction-error decomposition of a linear-Gaussian state space model,
//! with a robust tail beyond the gate) over the process-noise densities and a
//! scale of the observation sigmas. It needs no ground truth, so it works on
//! any log with sightings; ground truth only judges it afterwards (NEES).
use super::filter::{Filter, Pass};
use super::noise_model::{Lingering, NoiseModel, NoiseSource, PERSISTENT_START_S, SHARED_START_S};
use super::reading::RangeReading;
use super::simplex;
use super::{EkfOptions, LocalizeError};

use crate::model_on_log::run::Run;

/// A lingering part from the search's log-space coordinates [range factor,
/// bearing factor, memory] (the memory relative to `start_s`).
fn lingering(v: &[f64], start_s: f64) -> Lingering {
    Lingering {
        factor: [v[0].exp(), v[1].exp()],
        memory_s: start_s * v[2].exp(),
    }
}

/// Nelder-Mead runs at most this many times, each from the last one's result.
const RESTARTS: usize = 4;

/// A difference in the cost (-2 log-likelihood of the sightings) under this
/// is no evidence for one noise over another (a likelihood ratio of 1.6).
pub(super) const SIGNIFICANT: f64 = 1.0;

/// Fewer sightings than this say too little about the noise: the spec's is kept.
pub const MIN_SIGHTINGS: usize = 20;

/// The noise the filter runs with on `runs`, and a sentence saying where it
/// came from.
pub fn choose(
    f: &Filter,
    runs: &[Run],
    o: &EkfOptions,
) -> Result<(NoiseModel, String), LocalizeError> {
    let (m, given) = with_given(f, o);
    // every process noise given: the user has chosen the filter, the
    // observation sigmas are the spec's (estimating them alone against a
    // fixed process noise would let them explain the motion's errors)
    if o.noise == NoiseSource::Spec || given.iter().all(|g| *g) {
        let from = if given.iter().any(|g| *g) {
            "given (--noise) and the spec's"
        } else {
            "the spec's"
        };
        return Ok((m, format!("noise: {from}")));
    }
    let sightings: usize = runs.iter().map(|r| r.landmarks.len()).sum();
    if sightings < MIN_SIGHTINGS {
        return Ok((
            m,
            format!("noise: the spec's ({sightings} sightings are too few to estimate it from; {MIN_SIGHTINGS} needed)"),
        ));
    }
    let est = estimate(f, runs, &m, &given);
    Ok((
        est,
        format!(
            "noise: estimated from the {sightings} sightings of the log(s) by the innovations' likelihood: the process-noise densities{} and the observation errors, white, per landmark and shared (--noise NAME=SIGMA fixes a process noise, all of them fix the filter; --spec-noise takes the spec's)",
            if given.iter().any(|g| *g) { " not given" } else { "" }
        ),
    ))
}

/// The spec's noise with the sigmas `o` gives, and which ones it gives.
pub fn with_given(f: &Filter, o: &EkfOptions) -> (NoiseModel, Vec<bool>) {
    let mut m = f.declared_noise();
    let mut given = vec![false; m.names.len()];
    for (name, s) in &o.noise_sigma {
        if let Some(i) = m.names.iter().position(|n| n == name) {
            m.sigma[i] = *s;
            given[i] = true;
        }
    }
    (m, given)
}

/// Whether [`choose`] estimates the noise of `runs` from their sightings
/// (rather than taking the spec's or the user's).
pub fn estimated(f: &Filter, runs: &[Run], o: &EkfOptions) -> bool {
    let (_, given) = with_given(f, o);
    let sightings: usize = runs.iter().map(|r| r.landmarks.len()).sum();
    o.noise == NoiseSource::Estimate && !given.iter().all(|g| *g) && sightings >= MIN_SIGHTINGS
}

/// Maximise the innovations' likelihood over the sigmas not `given` (as
/// densities), the observation errors' white part and their lingering
/// parts, and the sensor's range reading, in log space: a coarse scan of
/// one common factor finds the basin (a filter far too confident rejects
/// everything and learns nothing), Nelder-Mead refines every coordinate.
///
/// The range reading is tried after a search without it, and kept (the
/// search done again with it) only where the sightings show it
/// (`search_with_reading_if_shown`).
///
/// The two lingering parts compete for the same errors, so the order they
/// enter in matters (the likelihood has a basin for each). The shared part
/// enters first: on the MRCLAM robots with the persistent part first, the
/// search settled 80-490 worse in -2 log-likelihood than with both at once,
/// landmark errors lasting 10-15 minutes standing in for the camera's. The
/// persistent part is then tried with the rest held, and kept (everything
/// refined with it) only where it makes the sightings
/// [`LINGERING_EVIDENCE`] more likely: a log whose sightings have no
/// lingering errors and straight ranges (the speed bench's) costs one
/// search of the process noise, the white part and the shared part, and
/// two short trials.
pub fn estimate(f: &Filter, runs: &[Run], start: &NoiseModel, given: &[bool]) -> NoiseModel {
    let space = Space::new(runs, start, given);
    let plans: Vec<_> = runs.iter().map(|run| f.plan(run)).collect();
    let cost = |v: &[f64]| -> f64 {
        let m = space.at(v);
        // beyond the reading's bounds or the shared part's longest memory:
        // not a noise the filter may take
        if !m.range_reading.is_physical() || m.shared.memory_s > space.shared_memory_max {
            return f64::INFINITY;
        }
        runs.iter()
            .zip(&plans)
            .map(
                |(run, plan)| match f.run_plan(plan, run, &m, super::Keep::Cost) {
                    Ok(Pass { cost, .. }) if cost.is_finite() => cost,
                    _ => f64::INFINITY,
                },
            )
            .sum()
    };
    let persistent = space.persistent();
    let (tried, first): (Vec<usize>, Vec<usize>) =
        (0..space.dims()).partition(|k| persistent.contains(k));
    let ((c, x), free) = search_with_reading_if_shown(&space, &cost, scan(&space, &cost), first);
    let mut trial = x.clone();
    trial[persistent.start] = 0.0;
    trial[persistent.start + 1] = 0.0;
    let with = search(&cost, (cost(&trial), trial), &tried);
    if c - with.0 < LINGERING_EVIDENCE {
        return space.at(&x);
    }
    let all: Vec<usize> = free.into_iter().chain(tried).collect();
    space.at(&search(&cost, with, &all).1)
}

/// The search over `dims` from the scan's point `start`, with the range
/// reading only where the sightings show it: searched without it, then the
/// reading tried with the rest held. Where that makes the sightings
/// [`READING_EVIDENCE`] more likely, everything is searched again from
/// `start` with the reading found: refined from the held point instead, the
/// search stayed where the lingering parts had paid for the reading's error
/// (on MRCLAM robot 3 a scale of -9% where fit finds +2%, beside a shared
/// part lasting 13 minutes; RMSE worse on four robots of five). A camera
/// that reads straight-line range costs the trial only (the speed bench's).
/// Returns the result and the coordinates left free.
fn search_with_reading_if_shown(
    space: &Space,
    cost: &simplex::Objective,
    start: (f64, Vec<f64>),
    dims: Vec<usize>,
) -> ((f64, Vec<f64>), Vec<usize>) {
    let reading = space.reading();
    let straight: Vec<usize> = dims
        .iter()
        .copied()
        .filter(|k| !reading.contains(k))
        .collect();
    let (c, x) = search(cost, start.clone(), &straight);
    let tried = search(cost, (c, x.clone()), &reading.clone().collect::<Vec<_>>());
    if c - tried.0 < READING_EVIDENCE {
        return ((c, x), straight);
    }
    let mut from = start.1;
    from[reading.clone()].copy_from_slice(&tried.1[reading]);
    let again = search(cost, (cost(&from), from), &dims);
    (if again.0 <= tried.0 { again } else { tried }, dims)
}

/// The coarse scan: one factor on every free process sigma, 1e-2 .. 1e3 (in
/// parallel: the passes are independent and call no symbolica), the
/// observation errors' white and shared parts at the spec's sigmas, no
/// persistent part.
fn scan(space: &Space, cost: &simplex::Objective) -> (f64, Vec<f64>) {
    use rayon::prelude::*;
    let o = space.free.len();
    let persistent = space.persistent();
    (-4..=6)
        .into_par_iter()
        .map(|step| {
            let mut v = vec![0.0; space.dims()];
            for x in &mut v[..o] {
                *x = step as f64 * 0.5 * std::f64::consts::LN_10;
            }
            v[persistent.start] = NONE;
            v[persistent.start + 1] = NONE;
            (cost(&v), v)
        })
        .collect::<Vec<_>>()
        .into_iter()
        .min_by(|a, b| a.0.total_cmp(&b.0))
        .expect("the scan has eleven points")
}

/// The noise models the estimate searches, in log-space coordinates: a
/// factor on each free process sigma, the white part's two factors, then
/// the persistent and shared parts' [range, bearing, memory], then the range
/// reading's share of depth and scale (in [`READING_STEP`] units, not logs:
/// both are 0 for the spec's straight-line range).
struct Space {
    base: NoiseModel,
    free: Vec<usize>,
    /// The longest the shared part may last (s): see [`SHARED_MEMORY_SHARE`].
    shared_memory_max: f64,
}

impl Space {
    /// The space around `start`, its process sigmas not `given` as densities
    /// (a per-row sigma as the density that adds the same variance per
    /// median row of `runs`).
    fn new(runs: &[Run], start: &NoiseModel, given: &[bool]) -> Space {
        let median_dt = {
            let mut d: Vec<f64> = runs.iter().flat_map(|r| r.dt.iter().copied()).collect();
            d.sort_by(f64::total_cmp);
            d[d.len() / 2]
        };
        let mut base = start.clone();
        let free: Vec<usize> = (0..base.sigma.len()).filter(|&i| !given[i]).collect();
        for &i in &free {
            if !base.density[i] {
                base.sigma[i] *= median_dt.sqrt();
                base.density[i] = true;
            }
            if base.sigma[i] <= 0.0 {
                base.sigma[i] = 0.01;
            }
        }
        let longest = runs
            .iter()
            .map(|r| r.dt.iter().sum::<f64>())
            .fold(0.0, f64::max);
        Space {
            base,
            free,
            // never below where the search starts it (a log of seconds)
            shared_memory_max: (longest / SHARED_MEMORY_SHARE).max(SHARED_START_S),
        }
    }

    /// The persistent part's coordinates.
    fn persistent(&self) -> std::ops::Range<usize> {
        let o = self.free.len() + 2;
        o..o + 3
    }

    /// The range reading's coordinates.
    fn reading(&self) -> std::ops::Range<usize> {
        let o = self.free.len() + 8;
        o..o + 2
    }

    fn dims(&self) -> usize {
        self.free.len() + 10
    }

    fn at(&self, v: &[f64]) -> NoiseModel {
        let mut m = self.base.clone();
        for (k, &i) in self.free.iter().enumerate() {
            m.sigma[i] = self.base.sigma[i] * v[k].exp();
        }
        let o = self.free.len();
        m.obs_scale = [v[o].exp(), v[o + 1].exp()];
        m.persistent = lingering(&v[o + 2..o + 5], PERSISTENT_START_S);
        m.shared = lingering(&v[o + 5..o + 8], SHARED_START_S);
        m.range_reading = RangeReading {
            depth_share: READING_STEP[0] * v[o + 8],
            scale: READING_STEP[1] * v[o + 9],
        };
        m
    }
}

/// The range reading's units in the search's coordinates: the simplex's
/// first side (0.7) is then a share of depth of 0.35 and a scale of 7%.
const READING_STEP: [f64; 2] = [0.5, 0.1];

/// The coordinate of a factor of 0: no such part (not carried at all).
const NONE: f64 = f64::NEG_INFINITY;

/// How much more likely (-2 log-likelihood) the sightings must be with a
/// persistent part than without for the filter to carry one: chi-square's
/// 99.9% point for its three parameters, the level of diagnose's tests.
const LINGERING_EVIDENCE: f64 = 16.27;

/// The shared part lasts at most the longest run over this: an error that
/// lasts a tenth of the log is seen in at most ten independent stretches of
/// it, so its memory cannot be told from a constant's, and constants are
/// what the range reading's scale and the persistent part carry. Unbounded,
/// the shared part settled at 45 minutes on MRCLAM robot 2 (a range scale
/// estimated online, taking the motion's own speed error for it): mean NEES
/// 7.6 against 4.1.
const SHARED_MEMORY_SHARE: f64 = 10.0;

/// The same for a range reading other than straight-line range:
/// chi-square's 99.9% point for its two parameters.
const READING_EVIDENCE: f64 = 13.82;

/// Nelder-Mead over the coordinates `dims` of `from` (the others held),
/// restarted from its own result until a restart gains nothing: a simplex
/// can collapse on a flat valley before its floor. The cost is -2
/// log-likelihood: differences under SIGNIFICANT say nothing about the
/// noise, so both the simplex and the restarts stop there.
fn search(cost: &simplex::Objective, from: (f64, Vec<f64>), dims: &[usize]) -> (f64, Vec<f64>) {
    let (mut c, mut x) = from;
    let full = |sub: &[f64], x: &[f64]| {
        let mut v = x.to_vec();
        for (k, &d) in dims.iter().enumerate() {
            v[d] = sub[k];
        }
        v
    };
    for _ in 0..RESTARTS {
        let held = x.clone();
        let sub_cost = |sub: &[f64]| cost(&full(sub, &held));
        let start: Vec<f64> = dims.iter().map(|&d| x[d]).collect();
        let tol = SIGNIFICANT / (1.0 + c.abs());
        let (cn, next) = simplex::minimise(&sub_cost, start, 0.7, tol, 300);
        let gained = c - cn;
        if cn < c {
            (x, c) = (full(&next, &held), cn);
        }
        if gained < SIGNIFICANT {
            break;
        }
    }
    (c, x)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_density_adds_the_same_variance_however_a_row_is_cut() {
        let m = NoiseModel {
            names: vec!["a".into(), "b".into()],
            sigma: vec![0.3, 0.3],
            density: vec![true, false],
            obs_scale: [1.0; 2],
            persistent: Lingering::none(PERSISTENT_START_S),
            shared: Lingering::none(SHARED_START_S),
            range_reading: RangeReading::STRAIGHT,
        };
        // pose variance of one noise input over h: G ~ h, so h^2 * var
        let over = |i: usize, pieces: &[f64], row: f64| -> f64 {
            pieces
                .iter()
                .map(|h| h * h * m.step_variance(i, *h, row))
                .sum()
        };
        for i in 0..2 {
            let whole = over(i, &[0.1], 0.1);
            let cut = over(i, &[0.03, 0.07], 0.1);
            assert!((whole - cut).abs() < 1e-15, "{i}: {whole} vs {cut}");
        }
        // and a density grows with time, not rows: two rows of 0.05 = one of 0.1
        assert!((over(0, &[0.05, 0.05], 0.05) - over(0, &[0.1], 0.1)).abs() < 1e-15);
    }
}
