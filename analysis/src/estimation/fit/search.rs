//! The global search of a calibration ([`super::fit`]): from the nominal
//! values a misspecified or roughly specified model's track can lie far
//! outside the right optimum's basin, so the fit from the starting values is
//! joined by other starts: the end of a continuation ladder of short
//! re-anchored segments, a gyro-only fit, and starts with each positive
//! parameter scaled (gains off by 5x, lengths off by 10x), screened on a
//! thinned log before any is fitted whole. The increments likelihood starts
//! from the best track fit. What the search finds is refined by the stages in
//! [`super`].
use super::covariance::{sandwich, variance_components};
use super::{cost_at_start, fit_from, fit_stage, fit_stage_from, segmented, Start};
use super::{FitError, FitOptions, FitResult, BASIN_TOLERANCE};
use crate::model_on_log::model::Runner;
use crate::model_on_log::run::Run;
use kinegen_model::decl::ObservationRole::YawRate;
use rayon::prelude::*;

/// Continuation ladder (segment lengths in seconds, shortest first): from rough
/// nominal values a long track is far outside the basin of the right optimum (a
/// steering gain 5x off turns a square into a spiral, and the nearest minimum is a
/// robot that does not move at all). Short re-anchored segments keep every
/// residual small and nearly linear in the parameters, so the short-segment fit
/// lands near the optimum; each longer stage refines from there.
const LADDER_S: [f64; 2] = [4.0, 15.0];

/// Rows a continuation stage reads at most (evenly spaced segments beyond this):
/// it only has to find the basin, so a million-row log need not be read in full.
const LADDER_ROWS: usize = 20_000;

/// Rows on which other starting points are screened before a whole long log is
/// fitted from them (see [`fit`]).
const SCREEN_ROWS: usize = 50_000;

/// Weighted residual RMS at which a fit is taken to have reached the noise, so no
/// further starting point is tried.
const AT_NOISE: f64 = 1.5;

/// [`fit`] without its final check of the undetermined directions.
pub(super) fn fit_unheld(r: &Runner, runs: &[Run], o: &FitOptions) -> Result<FitResult, FitError> {
    // Dead reckoning over hours drifts beyond any basin of attraction: runs longer
    // than 2 min are calibrated as 60 s segments, each re-anchored on its measured
    // start pose (relative rather than absolute error).
    let all_measured = runs.iter().all(|x| x.gt.is_some());
    if let Some(w) = o.increments.filter(|_| all_measured && o.use_pose) {
        // the estimate and its uncertainty from independent window increments,
        // started from the best absolute-track fit (which finds the basin)
        let track = fit_unheld(
            r,
            runs,
            &FitOptions {
                increments: None,
                ..o.clone()
            },
        )?;
        let mut from = r.clone();
        from.p = track.p.clone();
        let windows: Vec<Run> = runs.iter().flat_map(|x| x.segments(w)).collect();
        let mut inc = FitOptions {
            estimate_start: false,
            endpoints_only: true,
            ..o.clone()
        };
        let mut res = fit_stage(&from, &windows, &inc)?;
        // The sigmas are guesses (the spec's or the defaults): re-estimate each
        // residual kind's from its own residuals (variance components), so that
        // a kind whose noise was overstated does not dilute the information of
        // another, and refit with them.
        for _ in 0..3 {
            from.p = res.p.clone();
            inc = variance_components(&from, &windows, &inc);
            res = fit_stage(&from, &windows, &inc)?;
        }
        from.p = res.p.clone();
        sandwich(&from, &windows, &inc, &mut res);
        res.cost_before = track.cost_before;
        res.iterations += track.iterations;
        res.search_notes = track.search_notes;
        return Ok(res);
    }
    let split = segmented(runs);
    let direct = coarse_to_fine(r, &split, o)?;
    let at_noise = (2.0 * direct.cost_after / direct.n_residuals.max(1) as f64).sqrt() < AT_NOISE;
    if r.free.is_empty() || at_noise {
        return Ok(direct);
    }
    // On a long log the other starting points are screened on evenly spaced
    // segments (SCREEN_ROWS rows): a candidate is refined on the whole log only
    // when, refined on those segments, it ends below the direct fit refined on
    // the same segments. A short log is its own screen (nothing changes), and a
    // million-row log is not fitted in full three times over.
    let screen = thinned(split.clone(), SCREEN_ROWS);
    let whole = screen.len() == split.len();
    let direct_cost = direct.cost_after;
    let mut best = direct;
    let mut best_on_screen: Option<f64> = None;
    let mut starts: Vec<LabelledStart> = [continuation(r, runs, o), gyro_start(r, &screen, o)]
        .into_iter()
        .flatten()
        .map(|p| (None, p))
        .collect();
    if o.multi_start {
        starts.extend(screened_starts(r, &screen, o, &best));
    }
    let mut won: Option<String> = None;
    for (label, start) in starts {
        let mut from = r.clone();
        from.p = start;
        if !whole {
            let Ok(c) = fit_from(&from, &screen, o) else {
                continue;
            };
            let reference = *best_on_screen.get_or_insert_with(|| {
                let mut at = r.clone();
                at.p = best.p.clone();
                fit_from(&at, &screen, o).map_or(f64::INFINITY, |b| b.cost_after)
            });
            if c.cost_after >= reference * (1.0 - 1e-9) {
                continue;
            }
            from.p = c.p;
        }
        if let Ok(cand) = fit_from(&from, &split, o) {
            // a scaled start that ends with directions the data do not
            // determine holds them at its own, arbitrary, starting values
            let arbitrary = label.is_some() && !cand.undetermined.is_empty();
            if cand.cost_after < best.cost_after && !arbitrary {
                best_on_screen = None;
                best = cand.continuing(&best);
                won = label;
            }
        }
    }
    if let Some(label) = won.filter(|_| best.cost_after < LOCAL_MINIMUM * direct_cost) {
        best.search_notes.push(format!(
            "the fit from the starting values stopped in a local minimum: starting from {label} it reached a residual RMS {:.2}x smaller, and that result is reported. It depends on where the search starts: check the spec's nominal values",
            (direct_cost / best.cost_after).sqrt()
        ));
    }
    Ok(best)
}

/// Factors on one positive parameter's starting value that [`scaled_starts`]
/// tries: a length or gain within 10x of its nominal value is then within
/// about 1.8x of one of them, inside the basin a local fit finds (from
/// starting values 5-10x off, a real front-drive tricycle's fit stopped with
/// its wheelbase at a tenth of the truth and 2.5x the error).
const START_FACTORS: [f64; 4] = [0.1, 0.3, 3.0, 10.0];

/// A candidate's cost below this fraction of the direct fit's is a local
/// minimum avoided, and said (see [`FitOptions::multi_start`]).
const LOCAL_MINIMUM: f64 = 0.9;

/// The [`scaled_starts`] worth a full fit: each is run through one short
/// stage on `screen` (measured start headings, at most [`SCREEN_ITERATIONS`]
/// passes, stopping once in a basin), and only the one that ends lowest, and
/// below `direct`'s parameters put through the same stage, is returned. A
/// full fit from each of the 24 starts of a six-parameter robot took a
/// minute on a 35,000-row session.
fn screened_starts(
    r: &Runner,
    screen: &[Run],
    o: &FitOptions,
    direct: &FitResult,
) -> Option<LabelledStart> {
    let screen = thinned(screen.to_vec(), START_SCREEN_ROWS);
    let screen = &screen[..];
    let stage = FitOptions {
        estimate_start: false,
        max_iter: SCREEN_ITERATIONS,
        cost_tolerance: o.cost_tolerance.max(BASIN_TOLERANCE),
        ..o.clone()
    };
    let end_cost = |p: Vec<f64>| {
        let mut from = r.clone();
        from.p = p;
        fit_stage(&from, screen, &stage).map_or(f64::INFINITY, |f| f.cost_after)
    };
    let reference = end_cost(direct.p.clone());
    let scored: Vec<(f64, LabelledStart)> = scaled_starts(r)
        .into_par_iter()
        .map(|start| (end_cost(start.1.clone()), start))
        .collect();
    scored
        .into_iter()
        .filter(|(c, _)| c.is_finite() && *c < LOCAL_MINIMUM * reference)
        .min_by(|a, b| a.0.total_cmp(&b.0))
        .map(|x| x.1)
}

/// Passes of the screening stage of [`screened_starts`].
const SCREEN_ITERATIONS: usize = 15;

/// Rows (evenly spaced pieces) the screening stage of [`screened_starts`]
/// reads: a basin shows on a few thousand rows (the 40 starts of a
/// six-parameter robot took 10 s on its 35,000-row session read whole).
const START_SCREEN_ROWS: usize = 8_000;

/// Starting points with one positive free parameter (a length, a radius, a
/// gain: lower bound >= 0, positive nominal value) scaled by each of
/// [`START_FACTORS`], labelled for the user.
///
/// Several parameters can be off at once (a wheel radius 5x too large and a
/// wheelbase 10x too small: no single scaling leaves that tricycle's local
/// minimum), so [`JOINT_STARTS`] more scale all of them together, by factors
/// spread evenly over 0.1-10 in log space (a Halton sequence: deterministic,
/// and even in any number of dimensions).
fn scaled_starts(r: &Runner) -> Vec<LabelledStart> {
    let params = r.ir.runtime_params();
    let positive: Vec<usize> = r
        .free
        .iter()
        .copied()
        .filter(|&i| params[i].min.is_some_and(|m| m >= 0.0) && r.p[i] > 0.0)
        .collect();
    let scaled = |i: usize, f: f64| (r.p[i] * f).min(params[i].max.unwrap_or(f64::INFINITY));
    let mut out = Vec::new();
    for &i in &positive {
        for f in START_FACTORS {
            let mut p = r.p.clone();
            p[i] = scaled(i, f);
            let label = format!("{} = {:.6} ({f}x its starting value)", r.names[i], p[i]);
            out.push((Some(label), p));
        }
    }
    if positive.len() < 2 {
        return out;
    }
    for k in 1..=JOINT_STARTS {
        let mut p = r.p.clone();
        let mut said = Vec::new();
        for (d, &i) in positive.iter().enumerate() {
            let f = 10f64.powf(2.0 * radical_inverse(k, PRIMES[d % PRIMES.len()]) - 1.0);
            p[i] = scaled(i, f);
            said.push(format!("{} = {:.6}", r.names[i], p[i]));
        }
        out.push((Some(said.join(", ")), p));
    }
    out
}

/// A starting point for the search, with what the user is told about it
/// when it wins (None: one of the search's own, not worth a word).
type LabelledStart = (Option<String>, Vec<f64>);

/// Joint scalings tried by [`scaled_starts`].
const JOINT_STARTS: usize = 16;

const PRIMES: [usize; 10] = [2, 3, 5, 7, 11, 13, 17, 19, 23, 29];

/// The k-th element of the van der Corput sequence in `base`, in (0, 1).
fn radical_inverse(mut k: usize, base: usize) -> f64 {
    let (mut x, mut scale) = (0.0, 1.0 / base as f64);
    while k > 0 {
        x += (k % base) as f64 * scale;
        k /= base;
        scale /= base as f64;
    }
    x
}

/// [`fit_from`] on a long log: converged first on evenly spaced segments of
/// about [`SCREEN_ROWS`] rows, then refined on all of them from there, where
/// a few passes over the whole log suffice (each costs a dead reckoning of
/// every row with its sensitivities). A log of up to four times that many rows
/// is fitted whole from the start.
fn coarse_to_fine(r: &Runner, split: &[Run], o: &FitOptions) -> Result<FitResult, FitError> {
    let rows: usize = split.iter().map(|x| x.t.len()).sum();
    if rows <= 4 * SCREEN_ROWS || r.free.is_empty() {
        return fit_from(r, split, o);
    }
    let coarse = fit_from(r, &thinned(split.to_vec(), SCREEN_ROWS), o)?;
    let mut from = r.clone();
    from.p = coarse.p.clone();
    // from the coarse optimum, the start headings are refined with the
    // parameters at once (fit_from's first stage guards against a far start)
    let fine = fit_stage_from(&from, split, o, Start::NearOptimum)?;
    Ok(FitResult {
        cost_before: cost_at_start(r, split, o),
        ..fine.continuing(&coarse)
    })
}

/// The parameters at the end of the continuation ladder, or None when no run is
/// long enough to be cut. Start headings stay measured here: the stages only have
/// to reach the basin; the final fit refines them.
pub(super) fn continuation(r: &Runner, runs: &[Run], o: &FitOptions) -> Option<Vec<f64>> {
    let stage = FitOptions {
        estimate_start: false,
        ..o.clone()
    };
    let mut at = r.clone();
    let mut moved = false;
    for len in LADDER_S {
        let pieces: Vec<Run> = runs.iter().flat_map(|x| x.segments(len)).collect();
        if pieces.len() <= runs.len() {
            continue;
        }
        if let Ok(f) = fit_stage(&at, &thinned(pieces, LADDER_ROWS), &stage) {
            at.p = f.p;
            moved = true;
        }
    }
    moved.then_some(at.p)
}

/// Evenly spaced pieces holding about `rows` rows in all (all of them when fewer).
fn thinned(pieces: Vec<Run>, rows: usize) -> Vec<Run> {
    let total: usize = pieces.iter().map(|x| x.t.len()).sum();
    let every = total.div_ceil(rows.max(1)).max(1);
    pieces.into_iter().step_by(every).collect()
}

/// The parameters of a gyro-only fit, when the logs have both a gyro the model
/// predicts and ground truth (with only one of them the direct fit is the same).
fn gyro_start(r: &Runner, runs: &[Run], o: &FitOptions) -> Option<Vec<f64>> {
    let has_gyro = runs.iter().any(|x| x.gyro.is_some())
        && r.ir.observation_kernels(YawRate).map(|o| o.value).is_some();
    let has_pose = runs.iter().any(|x| x.gt.is_some());
    if !(o.use_gyro && o.use_pose && has_gyro && has_pose) {
        return None;
    }
    let gyro_only = FitOptions {
        use_pose: false,
        ..o.clone()
    };
    fit_from(r, runs, &gyro_only).ok().map(|f| f.p)
}
