//! The filter's noise: what the spec declares, what the user gives, or what
//! the log itself says.
//!
//! Estimation maximises the likelihood of the sightings' innovations (the
//! prediction-error decomposition of a linear-Gaussian state space model,
//! with a robust tail beyond the gate) over the process-noise densities and a
//! scale of the observation sigmas. It needs no ground truth, so it works on
//! any log with sightings; ground truth only judges it afterwards (NEES).
use super::filter::{Filter, Pass};
use super::simplex;
use super::{EkfOptions, LocalizeError};

use crate::run::Run;

/// Where the filter's noise comes from when the user does not give all of it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NoiseSource {
    /// The spec's `[[noise]]` sigmas and observation sigmas as written.
    Spec,
    /// Estimated from the log (see the module documentation).
    Estimate,
}

/// The noise of one filter: one sigma per process-noise input (the spec's
/// `[[noise]]`, or the body twist's vx, vy, omega for a model without any),
/// and a factor on each of the observation's declared sigmas (range and
/// bearing: a camera's range is often ten times worse than its bearing
/// relative to what a spec guesses, so one common factor cannot fit both).
#[derive(Debug, Clone, PartialEq)]
pub struct NoiseModel {
    pub names: Vec<String>,
    pub sigma: Vec<f64>,
    /// Whether `sigma[i]` is a density (variance sigma^2 per second) rather
    /// than seed 001's per-row sigma.
    pub density: Vec<bool>,
    pub obs_scale: [f64; 2],
    /// The persistent part of each observation error (a camera's range and
    /// bearing errors stay alike for seconds when it sees one landmark from
    /// about one place), as a factor on the spec's sigmas; 0: white errors.
    /// The range's part grows with the range: it is this factor on the
    /// spec's range sigma per metre of range (a camera that ranges by a
    /// target's apparent size errs in proportion: on the MRCLAM robots the
    /// spread of the range error is about 4% of the range from 1 to 5 m).
    pub persistent: [f64; 2],
    /// How long (s) the persistent part lasts.
    pub memory_s: f64,
}

/// Nelder-Mead runs at most this many times, each from the last one's result.
const RESTARTS: usize = 4;

/// A difference in the cost (-2 log-likelihood of the sightings) under this
/// is no evidence for one noise over another (a likelihood ratio of 1.6).
pub(super) const SIGNIFICANT: f64 = 1.0;

/// Fewer sightings than this say too little about the noise: the spec's is kept.
pub const MIN_SIGHTINGS: usize = 20;

impl NoiseModel {
    /// White noise on the body twist, for a model that declares none: 0.05 m/s
    /// and 0.05 rad/s per sqrt(Hz), a start for estimation.
    pub fn twist_default() -> NoiseModel {
        NoiseModel {
            names: vec!["twist_vx".into(), "twist_vy".into(), "twist_omega".into()],
            sigma: vec![0.05; 3],
            density: vec![true; 3],
            obs_scale: [1.0; 2],
            persistent: [0.0; 2],
            memory_s: 10.0,
        }
    }

    /// The variance of noise input `i` held over `h` seconds of a row of
    /// `dt_row` seconds. A density q gives q/h (white noise averaged over h:
    /// the pose variance G q/h G^T grows as q h, whatever the log's rate). A
    /// per-row sigma is seed 001's variance per row: spread over the pieces a
    /// sighting cuts the row into, so the row adds the same as uncut.
    pub fn step_variance(&self, i: usize, h: f64, dt_row: f64) -> f64 {
        let s2 = self.sigma[i] * self.sigma[i];
        if self.density[i] {
            s2 / h
        } else {
            s2 * dt_row / h
        }
    }

    /// A line per sigma, for people.
    pub fn describe(&self) -> Vec<String> {
        let mut out: Vec<String> = self
            .names
            .iter()
            .zip(&self.sigma)
            .zip(&self.density)
            .map(|((n, s), d)| {
                if *d {
                    format!(
                        "{n} = {s:.4e} per sqrt(s) (density: variance {:.3e} per second)",
                        s * s
                    )
                } else {
                    format!("{n} = {s:.4e} per row (seed 001 eq. 5)")
                }
            })
            .collect();
        out.push(format!(
            "observation sigmas, white part: the spec's times {:.3} (range) and {:.3} (bearing)",
            self.obs_scale[0], self.obs_scale[1]
        ));
        if self.persistent.iter().any(|p| *p > 0.0) {
            out.push(format!(
                "observation errors, persistent part (per landmark, lasting about {:.0} s): the spec's range sigma times {:.3} per metre of range, its bearing sigma times {:.3}",
                self.memory_s, self.persistent[0], self.persistent[1]
            ));
        }
        out
    }
}

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
            "noise: estimated from the {sightings} sightings of the log(s) by the innovations' likelihood: the process-noise densities{} and the observation errors, white and persistent (--noise NAME=SIGMA fixes a process noise, all of them fix the filter; --spec-noise takes the spec's)",
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
/// densities) and the observation scale, in log space: a coarse scan of one
/// common factor finds the basin (a filter far too confident rejects
/// everything and learns nothing), Nelder-Mead refines every sigma.
pub fn estimate(f: &Filter, runs: &[Run], start: &NoiseModel, given: &[bool]) -> NoiseModel {
    use rayon::prelude::*;
    let median_dt = {
        let mut d: Vec<f64> = runs.iter().flat_map(|r| r.dt.iter().copied()).collect();
        d.sort_by(f64::total_cmp);
        d[d.len() / 2]
    };
    // a per-row sigma as the density that adds the same variance per median row
    let mut base = start.clone();
    for ((sigma, density), _) in base
        .sigma
        .iter_mut()
        .zip(base.density.iter_mut())
        .zip(given)
        .filter(|(_, g)| !**g)
    {
        if !*density {
            *sigma *= median_dt.sqrt();
            *density = true;
        }
        if *sigma <= 0.0 {
            *sigma = 0.01;
        }
    }
    let free: Vec<usize> = (0..base.sigma.len()).filter(|&i| !given[i]).collect();
    let at = |v: &[f64]| -> NoiseModel {
        let mut m = base.clone();
        for (k, &i) in free.iter().enumerate() {
            m.sigma[i] = base.sigma[i] * v[k].exp();
        }
        let o = free.len();
        m.obs_scale = [v[o].exp(), v[o + 1].exp()];
        m.persistent = [v[o + 2].exp(), v[o + 3].exp()];
        m.memory_s = 10.0 * v[o + 4].exp();
        m
    };
    let plans: Vec<_> = runs.iter().map(|run| f.plan(run)).collect();
    let cost = |v: &[f64]| -> f64 {
        let m = at(v);
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
    // coarse: one factor on every free sigma, 1e-2 .. 1e3 (in parallel: the
    // passes are independent and call no symbolica)
    let n = free.len() + 5;
    let scan: Vec<(f64, Vec<f64>)> = (-4..=6)
        .into_par_iter()
        .map(|step| {
            let mut v = vec![step as f64 * 0.5 * std::f64::consts::LN_10; n];
            for x in &mut v[free.len()..] {
                *x = 0.0;
            }
            (cost(&v), v)
        })
        .collect();
    let (mut c, mut x) = scan
        .into_iter()
        .min_by(|a, b| a.0.total_cmp(&b.0))
        .expect("the scan has eleven points");
    // Nelder-Mead restarted from its own result until a restart gains
    // nothing: a simplex can collapse on a flat valley before its floor.
    // The cost is -2 log-likelihood: differences under SIGNIFICANT say
    // nothing about the noise, so both the simplex and the restarts stop there.
    for _ in 0..RESTARTS {
        let tol = SIGNIFICANT / (1.0 + c.abs());
        let (cn, next) = simplex::minimise(&cost, x.clone(), 0.7, tol, 300);
        let gained = c - cn;
        if cn < c {
            (x, c) = (next, cn);
        }
        if gained < SIGNIFICANT {
            break;
        }
    }
    at(&x)
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
            persistent: [0.0; 2],
            memory_s: 10.0,
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
