//! Calibration: bounded Levenberg-Marquardt on the generated parameter Jacobians.
//!
//! Residuals, each divided by its sigma: dead-reckoned pose minus ground truth at
//! every row (through the model's `pose` observation when it has one, e.g. an
//! off-centre marker), and model minus measured gyro yaw rate at every step
//! (through `obs_gyro`, so gyro effects enter naturally). The Jacobian comes from
//! the forward sensitivities of the exact step, so it is exact, not numerical.
//!
//! Why not a solver crate (`levenberg-marquardt`, a MINPACK port, or argmin):
//! both take the Jacobian as one matrix, and a million-sample log cut into 833
//! segments with a start-heading nuisance each has a 4e6 x 836 Jacobian (27 GB);
//! here J^T J is summed block by block without forming J ([`normal_equations`])
//! and solved through its arrow shape ([`arrow`]). The loop also does what
//! those crates do not: directions the data do not determine take no step
//! (they stay at their nominal values instead of wandering along a null space),
//! bounds clamp the step, and it stops when a step is below a hundredth of a
//! standard deviation of the estimate.
mod arrow;
mod covariance;
mod drift;
pub mod excitation;
pub mod leave_one_out;
pub mod nominal_prior;
mod options;
mod residuals;
mod round_off;
mod rounding;
mod search;
pub mod sensor;
mod sink;
mod solver;
mod square_root;

use covariance::{correlation, correlation_warnings, psd_inverse, set_covariance, sizes};
pub use options::{FitError, FitOptions, FitResult, Likelihood, ParamEstimate, BASIN_TOLERANCE};
use residuals::{has_start_nuisance, priors, run_residuals, start_columns};
pub use residuals::{normal_equations, residual_sums, residuals, sightings_from_truth};
pub use sink::Sums;

use crate::model_on_log::deadreckon;
use crate::model_on_log::model::Runner;
use crate::model_on_log::run::Run;
use nalgebra::{DMatrix, DVector};
use search::{continuation, fit_unheld};
use solver::levenberg_marquardt;
use std::sync::Arc;

/// Length of the re-anchored segments of long runs (see [`fit`]).
pub const SEGMENT_S: f64 = 60.0;

/// Window of the increments likelihood ([`FitOptions::increments`]): long enough
/// that the random walk of the inputs, not the shared endpoint measurement,
/// dominates each window's residual (over 30 simulated seeds, 5 s windows gave
/// standard deviations within 15% of the estimates' spread for a differential
/// drive, 1-3 s windows overstated them 1.5-2x).
pub const WINDOW_S: f64 = 5.0;

/// The runs as calibration and scoring see them: runs longer than 2 min split
/// into re-anchored segments of about a minute.
pub fn segmented(runs: &[Run]) -> Vec<Run> {
    runs.iter().flat_map(|x| x.segments(SEGMENT_S)).collect()
}

/// The fitted start offsets `starts` of [`segmented`]`(runs)` carried to the
/// segments of `part`, whose runs begin where `runs`' do (a training part cut
/// from each run's start): a segment of both starts at the same row. None if
/// some segment of `part` has no such twin.
pub fn part_starts(runs: &[Run], part: &[Run], starts: &[[f64; 3]]) -> Option<Vec<[f64; 3]>> {
    if runs.len() != part.len() {
        return None;
    }
    let mut out = Vec::new();
    let mut first = 0;
    for (run, cut) in runs.iter().zip(part) {
        let whole = run.segments(SEGMENT_S);
        for seg in cut.segments(SEGMENT_S) {
            let k = whole.iter().position(|w| w.t[0] == seg.t[0])?;
            out.push(*starts.get(first + k)?);
        }
        first += whole.len();
    }
    Some(out)
}

/// The calibration `at`, an optimum on `runs` whose segments started at
/// `starts` ([`FitResult::starts`]), refined locally on `part` (runs cut from
/// the same starts, such as a training part): from the start headings of the
/// segments the two share, or from the measured ones when they share none.
fn refine_on_part(
    at: &Runner,
    runs: &[Run],
    part: &[Run],
    starts: &[[f64; 3]],
    o: &FitOptions,
) -> Result<FitResult, FitError> {
    match part_starts(runs, part, starts) {
        Some(warm) => refine_from(at, part, o, &warm),
        None => refine(at, part, o),
    }
}

/// Each run's start-pose offset in the fit: its first segment's (`starts` is per
/// segment of [`segmented`] runs, as in [`FitResult::starts`]).
pub fn run_offsets(runs: &[Run], starts: &[[f64; 3]]) -> Vec<[f64; 3]> {
    let mut seg = 0;
    runs.iter()
        .map(|run| {
            let off = starts.get(seg).copied().unwrap_or([0.0; 3]);
            seg += run.segments(SEGMENT_S).len();
            off
        })
        .collect()
}

/// The start pose each run's dead reckoning used in the fit: its measured start
/// plus the refinement of its first segment (see [`run_offsets`]).
pub fn run_starts(r: &Runner, p: &[f64], runs: &[Run], starts: &[[f64; 3]]) -> Vec<[f64; 3]> {
    runs.iter()
        .zip(run_offsets(runs, starts))
        .map(|(run, off)| deadreckon::placed_start(r, p, run, run.start_pose(), off).0)
        .collect()
}

/// Each segment's (of [`segmented`] runs) start-pose offset refined for
/// parameters `p` held fixed, as a fit at `p` would refine it: a fit's
/// "before" is scored as its "after" is.
pub fn fitted_offsets(r: &Runner, p: &[f64], runs: &[Run], o: &FitOptions) -> Vec<[f64; 3]> {
    at_fitted_starts(r, p, runs, o).2
}

/// `r` with parameters `p` held fixed, the runs as calibration sees them, and
/// each segment's start refined for those parameters: how a model is scored.
fn at_fitted_starts(
    r: &Runner,
    p: &[f64],
    runs: &[Run],
    o: &FitOptions,
) -> (Runner, Vec<Run>, Vec<[f64; 3]>) {
    let seg = segmented(runs);
    let mut fixed = r.clone();
    fixed.p = p.to_vec();
    fixed.free = vec![];
    let starts = fit_stage(&fixed, &seg, o)
        .map(|f| f.starts)
        .unwrap_or_default();
    (fixed, seg, starts)
}

/// Each run's start offset refined for parameters `p` held fixed, in the
/// layout of [`FitResult::starts`], with the cost there: on the whole runs
/// where `o` fits whole runs (each run's first segment holds its offset, the
/// later ones none, as [`on_whole_runs`] lays them out), else on the
/// segments ([`fitted_offsets`]). For a calibration changed after its fit
/// ([`nominal_prior`]), whose start headings were fitted with other values.
pub(crate) fn starts_for(
    r: &Runner,
    p: &[f64],
    runs: &[Run],
    o: &FitOptions,
) -> (Vec<[f64; 3]>, f64) {
    let counts: Vec<usize> = runs.iter().map(|x| x.segments(SEGMENT_S).len()).collect();
    let whole = o.whole_runs && o.increments.is_none() && counts.iter().any(|&c| c > 1);
    let mut fixed = r.clone();
    fixed.p = p.to_vec();
    fixed.free = vec![];
    if whole {
        if let Ok(f) = fit_stage(&fixed, runs, o) {
            let mut starts = Vec::with_capacity(counts.iter().sum());
            for (c, s) in counts.iter().zip(&f.starts) {
                starts.push(*s);
                starts.extend(std::iter::repeat_n([0.0; 3], c - 1));
            }
            return (starts, f.cost_after);
        }
    }
    let (fixed, seg, starts) = at_fitted_starts(r, p, runs, o);
    let cost = residual_sums(&fixed, p, &[], &seg, o, &starts).cost;
    (starts, cost)
}

/// Weighted residual RMS of `p` on `runs` (segmented as calibration sees them),
/// after refining only the start poses.
pub fn rms_with_fitted_starts(r: &Runner, p: &[f64], runs: &[Run], o: &FitOptions) -> f64 {
    let (fixed, seg, starts) = at_fitted_starts(r, p, runs, o);
    let (res, _) = residuals(&fixed, p, &[], &seg, o, false, &starts);
    (res.iter().map(|x| x * x).sum::<f64>() / res.len().max(1) as f64).sqrt()
}

/// The white-noise level of the weighted residuals of `r` at `p`: the error a
/// model that explained every structure in the logs would reach. Estimated by
/// successive differences within each channel (von Neumann): a model error
/// varies smoothly along the track and cancels in r_k - r_(k-1), while white
/// sensor noise doubles its variance there. Channels: each pose coordinate,
/// the gyro, the range and the bearing.
pub fn noise_floor(r: &Runner, p: &[f64], runs: &[Run], o: &FitOptions) -> f64 {
    let (fixed, seg, starts) = at_fitted_starts(r, p, runs, o);
    let (mut sum, mut n) = (0.0, 0usize);
    for (stride, pose, gyro, landmarks) in [
        (3, true, false, false),
        (1, false, true, false),
        (2, false, false, true),
    ] {
        let only = FitOptions {
            use_pose: o.use_pose && pose,
            use_gyro: o.use_gyro && gyro,
            use_landmarks: o.use_landmarks && landmarks,
            ..o.clone()
        };
        if !(only.use_pose || only.use_gyro || only.use_landmarks) {
            continue;
        }
        let (res, _) = residuals(&fixed, p, &[], &seg, &only, false, &starts);
        for k in stride..res.len() {
            let d = res[k] - res[k - stride];
            sum += 0.5 * d * d;
            n += 1;
        }
    }
    (sum / n.max(1) as f64).sqrt()
}

/// Where a calibration starts and how far it searches (see [`fit`]).
#[derive(Debug, Clone, Copy, Default)]
pub enum Search<'a> {
    /// From the starting values and from every other start: the
    /// continuation ladder, a gyro-only fit and scaled starts (`global`).
    #[default]
    Global,
    /// The continuation ladder's part of the global search only
    /// (`fit_continued`): a candidate effect's calibration in diagnosis.
    Continued,
    /// Locally from the starting values (`refine`): a start already in the
    /// optimum's basin, such as the same model's fit on other data.
    Local,
    /// From an earlier optimum on the same runs, with its fitted start
    /// offsets ([`FitResult::starts`], see `refine_from`).
    From(&'a [[f64; 3]]),
    /// From an optimum on `whole` with its start offsets, refined on the runs
    /// given, a part cut from the same starts (`refine_on_part`).
    OnPart {
        whole: &'a [Run],
        starts: &'a [[f64; 3]],
    },
}

/// A calibration of `r` on `runs` (by [`fit`]) as it is handed to the
/// user: what the logs cannot tell stays near the nominal values
/// ([`nominal_prior`]), and a log that turns one way only is said
/// ([`excitation`]). Diagnosis compares [`fit`]'s maximum-likelihood costs
/// and does not call this.
pub fn for_use(r: &Runner, runs: &[Run], o: &FitOptions, res: FitResult) -> FitResult {
    let mut res = nominal_prior::toward_nominal(r, runs, o, res);
    res.warnings
        .extend(excitation::one_way_warning(r, &res.p, runs));
    res
}

/// Calibrate the free parameters of `r` on `runs`, starting from `r.p` and
/// searching as `search` says: the one entry point of calibration.
///
/// Where the sightings are seen from a ground truth, the parameters only the
/// range-bearing sensor reads are calibrated apart, after the motion's
/// ([`sensor`]): the motion's residuals do not depend on them.
pub fn fit(
    r: &Runner,
    runs: &[Run],
    o: &FitOptions,
    search: Search,
) -> Result<FitResult, FitError> {
    let sensor = sensor_apart(r, runs, o);
    if sensor.is_empty() {
        return fit_motion(r, runs, o, search);
    }
    let mut motion = r.clone();
    motion.free.retain(|i| !sensor.contains(i));
    let res = fit_motion(&motion, runs, o, search)?;
    Ok(with_sensor(r, runs, res, &sensor))
}

/// The free parameters of `r` that [`fit`] calibrates apart on the
/// sightings seen from the ground truth (none where there are too few).
fn sensor_apart(r: &Runner, runs: &[Run], o: &FitOptions) -> Vec<usize> {
    let seen = o.use_landmarks && o.sightings_from_truth;
    if !seen || sensor::Sightings::of(r, &r.p, runs).is_err() {
        return Vec::new();
    }
    sensor::sensor_params(r)
}

/// The motion's calibration `res` (of `r` without the `sensor` parameters)
/// with those calibrated on the sightings: their estimates and jackknife
/// standard deviations, uncorrelated with the motion's (their residuals do
/// not share a parameter).
fn with_sensor(r: &Runner, runs: &[Run], res: FitResult, sensor: &[usize]) -> FitResult {
    let mut at = r.clone();
    at.p = res.p.clone();
    let Ok(s) = sensor::Sightings::of(&at, &res.p, runs) else {
        return res;
    };
    let cal = sensor::calibrate_with_folds(&s, &at, &res.p, sensor);
    let free = r.free.clone();
    // where each parameter of `free` was: the motion's k-th, or the sensor's
    let from: Vec<Result<usize, usize>> = free
        .iter()
        .map(|i| match res.free.iter().position(|j| j == i) {
            Some(k) => Ok(k),
            None => Err(sensor
                .iter()
                .position(|j| j == i)
                .expect("free is motion or sensor")),
        })
        .collect();
    let m = free.len();
    let std = from
        .iter()
        .map(|w| match *w {
            Ok(k) => res.std[k],
            Err(k) => cal.std[k],
        })
        .collect();
    let corr = DMatrix::from_fn(m, m, |a, b| match (from[a], from[b]) {
        (Ok(i), Ok(j)) => res.corr[(i, j)],
        _ if a == b => 1.0,
        _ => 0.0,
    });
    let undetermined = res
        .undetermined
        .iter()
        .map(|u| DVector::from_fn(m, |a, _| from[a].map_or(0.0, |k| u[k])))
        .collect();
    FitResult {
        p: cal.p,
        free,
        std,
        corr,
        undetermined,
        ..res
    }
}

/// [`fit`] of the parameters the motion's residuals depend on.
fn fit_motion(
    r: &Runner,
    runs: &[Run],
    o: &FitOptions,
    search: Search,
) -> Result<FitResult, FitError> {
    match search {
        Search::Global => global(r, runs, o),
        Search::Continued => fit_continued(r, runs, o),
        Search::Local => refine(r, runs, o),
        Search::From(starts) => refine_from(r, runs, o, starts),
        Search::OnPart { whole, starts } => refine_on_part(r, whole, runs, starts, o),
    }
}

/// The global search ([`Search::Global`]): calibrate the free parameters of
/// `r` (starting from `r.p`).
///
/// The fit from the nominal values is tried first. Unless it already explains
/// the data down to the noise, it is also restarted from (a) the end of the
/// continuation ladder (`search::LADDER_S`) and (b) a gyro-only fit (the yaw-rate residual
/// does not accumulate along the track, so it is nearly convex in the
/// parameters); the candidate with the lowest full cost wins.
///
/// A direction the final fit finds undetermined keeps its starting value: when
/// an earlier stage or another starting point moved the parameters along it
/// (where it still looked determined: the first stage of [`fit_from`] has no
/// start-heading nuisance, and a turn-in-place log then slid a speed scale to
/// its bound), the whole fit is redone with that direction held.
fn global(r: &Runner, runs: &[Run], o: &FitOptions) -> Result<FitResult, FitError> {
    let searched = held_where_undetermined(r, runs, o, fit_unheld)?;
    let mut res = if !o.whole_runs || o.increments.is_some() || r.free.is_empty() {
        searched
    } else {
        on_whole_runs(r, runs, o, searched)
    };
    let notes = std::mem::take(&mut res.search_notes);
    res.warnings.extend(notes);
    // "kept at its starting value" is the last stage's start: say so where
    // that is not the value the user started from (a deadband slid into the
    // kink at the commonest command by an earlier stage reads -0.067 there)
    Ok(held_where_fitted(r, res))
}

/// [`FitOptions::whole_runs`]: `searched` (an optimum on the segments)
/// refined on the whole runs, keeping the directions it found undetermined,
/// with the drift-aware standard deviations ([`drift`]). Its `starts` keep
/// the segmented layout of [`FitResult::starts`]: each run's first segment
/// holds the run's start offset, the later segments none.
///
/// The refinement is kept only where it keeps the short-term accuracy the
/// segments had: their cost within [`SHORT_TERM_SLACK`] of their own
/// optimum's, or the track's drift over 5 s windows within
/// [`DRIFT_SLACK`] of theirs. Over a long run whose drift is mostly noise,
/// the whole-run optimum bends the parameters to follow that run's
/// particular drift (a 546 s tricycle log: wheel radius 9 standard
/// deviations off the truth, 8x the drift over 5 s windows). The drift is
/// the second test because the segments' cost alone is too sharp on a log
/// rich in information: a clean 200 s log at 50 Hz from a simulator other
/// than kinegen's (nominal values, quantised encoders) put the whole-run
/// estimate 1.1 standard deviations from the truth with the same 5 s drift
/// as the segments' (0.0022 m), yet 15% over their cost, and the segments'
/// estimate took the whole-run error from the nominal values' 0.0018 m to
/// 0.0031 m. Where it fails or is not kept, `searched`, with its standard
/// deviations made drift-aware on its segments.
fn on_whole_runs(r: &Runner, runs: &[Run], o: &FitOptions, searched: FitResult) -> FitResult {
    let counts: Vec<usize> = runs.iter().map(|x| x.segments(SEGMENT_S).len()).collect();
    let split = segmented(runs);
    let mut at = r.clone();
    at.p = searched.p.clone();
    if counts.iter().all(|&c| c == 1) {
        let mut res = searched;
        drift::sandwich(&at, runs, o, &mut res);
        return res;
    }
    let warm = FitOptions {
        start_offsets: Some(Arc::new(run_offsets(runs, &searched.starts))),
        ..holding(o, &searched)
    };
    let Ok(whole) = fit_stage_from(&at, runs, &warm, Start::NearOptimum) else {
        let mut res = searched;
        drift::sandwich(&at, &split, o, &mut res);
        return res;
    };
    let whole = round_off::resolved_by_segments(whole, &searched);
    // whether the refinement keeps the short-term accuracy, and its
    // drift-aware standard deviations, side by side (on one long run each
    // keeps a core busy alone; the latter is dropped when not kept)
    let (kept, refined) = rayon::join(
        || {
            // the segments' cost at the whole-run estimate (start headings
            // refined for it) against theirs at their own optimum
            let (_, _, starts) = at_fitted_starts(r, &whole.p, runs, o);
            let cost = residual_sums(r, &whole.p, &[], &split, o, &starts).cost;
            cost <= SHORT_TERM_SLACK * searched.cost_after
                || drifts_as_little(r, (&whole.p, &searched.p), runs)
        },
        || {
            let mut starts = Vec::with_capacity(counts.iter().sum());
            for (c, s) in counts.iter().zip(&whole.starts) {
                starts.push(*s);
                starts.extend(std::iter::repeat_n([0.0; 3], c - 1));
            }
            let mut res = FitResult {
                starts,
                ..whole.clone().continuing(&searched)
            };
            let mut at = r.clone();
            at.p = res.p.clone();
            drift::sandwich(&at, runs, o, &mut res);
            res
        },
    );
    if kept {
        return refined;
    }
    let mut res = searched;
    drift::sandwich(&at, &split, o, &mut res);
    res
}

/// How much more than at their own optimum the segments may cost at the
/// whole-run estimate for [`on_whole_runs`] to keep it: 10% (RMS up 5%).
const SHORT_TERM_SLACK: f64 = 1.1;

/// How much more the whole-run estimate's track may drift over 5 s windows
/// than the segments' estimate's for [`on_whole_runs`] to keep it: 5%.
const DRIFT_SLACK: f64 = 1.05;

/// Whether parameters `whole` dead-reckon `runs` (each from its measured
/// start) with no more than [`DRIFT_SLACK`] times the 5 s drift of
/// `segments` (the relative pose over a window does not depend on the
/// start). False where the runs are too short to say.
fn drifts_as_little(r: &Runner, (whole, segments): (&[f64], &[f64]), runs: &[Run]) -> bool {
    let drift = |p: &[f64]| crate::model_on_log::metrics::from_measured_starts(r, p, runs).rpe_5s_m;
    match (drift(whole), drift(segments)) {
        (Some(a), Some(b)) => a.is_finite() && a <= DRIFT_SLACK * b,
        _ => false,
    }
}

/// The continuation ladder's part of [`fit`]'s search: from the end of the
/// ladder, refined on the whole log (no direct start from `r.p`, no gyro-only
/// start). Diagnosis searches each candidate effect's calibration so, beside a
/// local refinement from the current model's calibration: a candidate's
/// direct and gyro-only starts retrace the current model's own search, which
/// found nothing better than the current calibration (on an omni_caster log
/// with a 0.2 rad steering offset left out, they were 283 of the 318 passes of
/// a wrong candidate's search). Where no run is long enough for the ladder,
/// [`fit`].
fn fit_continued(r: &Runner, runs: &[Run], o: &FitOptions) -> Result<FitResult, FitError> {
    held_where_undetermined(r, runs, o, continued_unheld)
}

fn continued_unheld(r: &Runner, runs: &[Run], o: &FitOptions) -> Result<FitResult, FitError> {
    let ladder = o
        .increments
        .is_none()
        .then(|| continuation(r, runs, o))
        .flatten();
    let Some(start) = ladder else {
        return fit_unheld(r, runs, o);
    };
    let split = segmented(runs);
    let mut from = r.clone();
    from.p = start;
    let res = fit_from(&from, &split, o)?;
    Ok(FitResult {
        cost_before: cost_at_start(r, &split, o),
        ..res
    })
}

/// The cost at the starting values `r.p` with the measured start poses, on all
/// of `split`: what a direct fit from them reports as its `cost_before`.
fn cost_at_start(r: &Runner, split: &[Run], o: &FitOptions) -> f64 {
    let starts = vec![[0.0; 3]; split.len()];
    residual_sums(r, &r.p, &r.free, split, o, &starts).cost
}

/// `search`, with its final check of the undetermined directions (see [`fit`]).
fn held_where_undetermined(
    r: &Runner,
    runs: &[Run],
    o: &FitOptions,
    search: fn(&Runner, &[Run], &FitOptions) -> Result<FitResult, FitError>,
) -> Result<FitResult, FitError> {
    let res = search(r, runs, o)?;
    if !moved_along_undetermined(r, &res) {
        return Ok(res);
    }
    let held = search(r, runs, &holding(o, &res))?;
    if !lock_undoes_fit(&held, &res) {
        return Ok(held.continuing(&res));
    }
    // a curved undetermined direction (see `fit_stage_from`): hold it from
    // where the data put the parameters, not from the start, and refine on
    // the residuals the search minimised (its re-anchored segments, from its
    // start headings). On the whole unsegmented run with the measured start
    // headings a misspecified tricycle's track cost 1.6e4 times more at the
    // optimum (3.9e11 against 2.5e7); the refinement wandered to a far worse
    // calibration (wheel radius 0.098 m against 0.144) and reported it.
    let mut at = r.clone();
    at.p = res.p.clone();
    let kept = held_where_fitted(r, refine_from(&at, runs, &holding(o, &res), &res.starts)?);
    Ok(FitResult {
        cost_before: res.cost_before,
        iterations: res.iterations + held.iterations + kept.iterations,
        search_notes: res.search_notes.clone(),
        ..kept
    })
}

/// Refine a calibration locally from `r.p` (no other starting points): for a
/// start already in the optimum's basin, such as the same model's fit on
/// other data.
fn refine(r: &Runner, runs: &[Run], o: &FitOptions) -> Result<FitResult, FitError> {
    fit_from(r, &segmented(runs), o)
}

/// Refine from an earlier fit's optimum on the same runs: `r.p` holds its
/// parameters (and those it did not have, such as a candidate effect's, at
/// their starting values), `starts` its fitted start offsets
/// ([`FitResult::starts`]). One joint stage from there: [`refine`]'s first
/// stage with the measured starts would leave the optimum only for the joint
/// stage to creep back to it (a misspecified model's Gauss-Newton steps shrink
/// by a constant factor: 40 passes over a diagnosis log for a candidate that
/// changes nothing). Without matching start offsets this is [`refine`].
fn refine_from(
    r: &Runner,
    runs: &[Run],
    o: &FitOptions,
    starts: &[[f64; 3]],
) -> Result<FitResult, FitError> {
    let split = segmented(runs);
    if !o.estimate_start || starts.len() != split.len() {
        return refine(r, runs, o);
    }
    let warm = FitOptions {
        start_offsets: Some(Arc::new(starts.to_vec())),
        ..o.clone()
    };
    fit_stage_from(r, &split, &warm, Start::NearOptimum)
}

/// Calibrate from `r.p`. With start-pose refinement the parameters are fitted
/// first with the measured starts, then jointly with the starts from there: a
/// free start heading from the outset can rotate a badly scaled track into a
/// local minimum (seen with a 5% speed-scale error).
fn fit_from(r: &Runner, runs: &[Run], o: &FitOptions) -> Result<FitResult, FitError> {
    if !o.estimate_start || r.free.is_empty() || !runs.iter().any(|x| has_start_nuisance(x, o)) {
        return fit_stage(r, runs, o);
    }
    let first = fit_stage(
        r,
        runs,
        &FitOptions {
            estimate_start: false,
            cost_tolerance: o.cost_tolerance.max(BASIN_TOLERANCE),
            ..o.clone()
        },
    )?;
    let mut from = r.clone();
    from.p = first.p.clone();
    let joint = fit_stage(&from, runs, o)?;
    Ok(joint.continuing(&first))
}

/// Cosine above which an accepted step continues the one before it (below
/// minus this, it turns back; see [`levenberg_marquardt_planned`]).
const PERSISTENT: f64 = 0.95;

/// At most 2^this times a step along a persistent direction.
const MAX_DOUBLINGS: u32 = 4;

fn cosine(a: &DVector<f64>, b: &DVector<f64>) -> f64 {
    a.dot(b) / (a.norm() * b.norm()).max(1e-300)
}

/// A fit ends when an accepted step moves the estimate by less than this many
/// of its standard deviations: nothing a user could see (see `negligible` in
/// [`levenberg_marquardt`]).
const STEP_TOLERANCE: f64 = 0.01;

/// Information (in scaled units, residuals weighted by their sigmas) below which
/// a parameter direction counts as undetermined by the data during the fit.
const UNDETERMINED_INFORMATION: f64 = 1.0;

/// Information below this fraction of the strongest direction's is
/// round-off in normal equations summed over many rows: such a direction is
/// held during the fit whatever the data say of it (see
/// [`FitResult::below_round_off`]).
const ROUND_OFF: f64 = 1e-14;

/// Scaled displacement (in units of [`Runner::param_scale`]) along an
/// undetermined direction below which a fit counts as not having moved along
/// it: 1% of a parameter's size. A direction computed from the information
/// matrix is a little off the true null space (by 0.02 rad on a turn in
/// place), so a step along the determined directions shows a small component
/// along it (0.0013 for a 0.04 step) that is no drift.
const NOT_MOVED: f64 = 0.01;

/// One Levenberg-Marquardt fit from `r.p`. The iterations judge a direction
/// undetermined with the nominal noise ([`UNDETERMINED_INFORMATION`]) and the
/// Jacobian of the moment; the final check uses the residuals' own variance at
/// the optimum. Where the final check finds a direction the iterations did not
/// (a turn-in-place log: the speed scale's information is tiny but not below
/// 1, so it slid to its bound and the held-out error went 0.74 m -> 26 m), the
/// fit is redone from the start with those directions locked, so that the
/// parameters stay at their starting values along what the data cannot see.
fn fit_stage(r: &Runner, runs: &[Run], o: &FitOptions) -> Result<FitResult, FitError> {
    fit_stage_from(r, runs, o, Start::Rough)
}

/// Where a Levenberg-Marquardt stage starts, which sets its damping.
#[derive(Clone, Copy, PartialEq)]
enum Start {
    /// Anywhere (nominal values, another stage's result): the usual damping
    /// of 1e-3 of the normal equations' diagonal, and the stage ends when an
    /// accepted step changes nothing.
    Rough,
    /// At the optimum of evenly spaced pieces of the same log (see
    /// [`coarse_to_fine`]), where the quadratic model is good. The usual
    /// damping would only slow the first steps along weakly determined
    /// directions (on a million rows: 7 passes with sensitivities instead of
    /// 3), so it starts at 1e-7; and the stage ends as soon as the undamped
    /// Gauss-Newton step predicts a negligible decrease, instead of trying a
    /// round-off-level step and then ever more damped ones (each a pass over
    /// the log). From a rough start that prediction cannot be trusted: a
    /// badly wrong model has a huge residual variance, so a step it calls
    /// negligible can still lead out of a collapse (seen: a tricycle whose
    /// fit then stopped with its wheel radius at zero).
    NearOptimum,
}

/// [`fit_stage`] from a `start` of the given kind.
fn fit_stage_from(
    r: &Runner,
    runs: &[Run],
    o: &FitOptions,
    start: Start,
) -> Result<FitResult, FitError> {
    let first = levenberg_marquardt(r, runs, o, start)?;
    if !moved_along_undetermined(r, &first) {
        return Ok(first);
    }
    let locked = levenberg_marquardt(r, runs, &holding(o, &first), start)?;
    if !lock_undoes_fit(&locked, &first) {
        return Ok(locked.continuing(&first));
    }
    // The undetermined direction is curved (a car-like robot that never
    // steered: only tan(steer_offset)/wheelbase is seen, a hyperbola in the
    // parameters). Its tangent at the optimum, held from the start, blocks
    // what the data do determine (the offset that moves from 0) and the fit
    // ends where it began. Hold it from the optimum instead: the parameters
    // stay where the data put them and do not move further along it.
    let mut at = r.clone();
    at.p = first.p.clone();
    let from_optimum = FitOptions {
        start_offsets: Some(Arc::new(first.starts.clone())),
        ..holding(o, &first)
    };
    let kept = levenberg_marquardt(&at, runs, &from_optimum, Start::NearOptimum)?;
    Ok(held_where_fitted(r, kept.continuing(&first)))
}

/// A fit whose undetermined directions were held from its optimum (see
/// [`fit_stage_from`]) may have moved along them from the start (`r.p`): the
/// warnings of those that moved say so instead of "kept at the starting value".
fn held_where_fitted(r: &Runner, mut res: FitResult) -> FitResult {
    let moved: Vec<&str> = res
        .free
        .iter()
        .filter(|&&i| (res.p[i] - r.p[i]).abs() > NOT_MOVED * r.param_scale(i, r.p[i]))
        .map(|&i| r.names[i].as_str())
        .collect();
    for w in &mut res.warnings {
        let words: Vec<&str> = w.split([' ', '(', ')', ';', ':']).collect();
        if !moved.iter().any(|n| words.contains(n)) {
            continue;
        }
        *w = w
            .replace(
                "(kept at its starting value)",
                "(one of many values that fit equally well: it had to move from its starting value with the parameters the data do determine)",
            )
            .replace(
                "kept at the starting values along it)",
                "the values shown are one of many that fit equally well: they had to move from the starting values with what the data do determine)",
            );
    }
    res
}

/// Whether holding the undetermined directions from the start (`locked`)
/// fits the data visibly worse than the free fit (`first`): its cost more
/// than doubled (RMS up by 41%) and by far more than the noise. Then those
/// directions were not undetermined where the fit started. (Going back along
/// a direction that is undetermined costs little next to the whole misfit:
/// a turn in place whose speed scale slid loses a few percent.)
fn lock_undoes_fit(locked: &FitResult, first: &FitResult) -> bool {
    let lost = locked.cost_after - first.cost_after;
    let dof = first.n_residuals.saturating_sub(first.free.len()).max(1) as f64;
    let s2 = 2.0 * first.cost_after / dof;
    // 25: a 5-sigma change of a one-parameter chi-square
    locked.cost_after > 2.0 * first.cost_after && 2.0 * lost > 25.0 * s2
}

/// Whether `res` moved the parameters away from `r.p` along a direction it
/// found undetermined (by [`NOT_MOVED`] in scaled units).
fn moved_along_undetermined(r: &Runner, res: &FitResult) -> bool {
    let scale: Vec<f64> = res.free.iter().map(|&i| r.param_scale(i, r.p[i])).collect();
    let moved = DVector::from_fn(scale.len(), |k, _| {
        let i = res.free[k];
        (res.p[i] - r.p[i]) / scale[k]
    });
    res.undetermined.iter().any(|u| {
        let v = u.component_div(&DVector::from_row_slice(&scale));
        v.dot(&moved).abs() > NOT_MOVED * v.norm()
    })
}

/// `o` that also holds the directions `res` found undetermined.
fn holding(o: &FitOptions, res: &FitResult) -> FitOptions {
    FitOptions {
        hold: o.hold.iter().chain(&res.undetermined).cloned().collect(),
        ..o.clone()
    }
}

/// Orthonormal basis of the span of `vs` (Gram-Schmidt), so that removing
/// each basis vector's component from a step removes the whole span's.
fn orthonormal(vs: impl IntoIterator<Item = DVector<f64>>) -> Vec<DVector<f64>> {
    let mut basis: Vec<DVector<f64>> = Vec::new();
    for v in vs {
        let Some(mut v) = v.try_normalize(0.0) else {
            continue;
        };
        for b in &basis {
            v -= b * b.dot(&v);
        }
        // a vector within 1% of the span so far is taken to be in it: a
        // direction found again, a little off numerically, would otherwise
        // add its (meaningless) difference as a new direction
        let n = v.norm();
        if n > 1e-2 {
            basis.push(v / n);
        }
    }
    basis
}
