//! The model at one stage of the diagnosis: calibrated, scored (weighted
//! residual RMS, BIC, held-out error) against its own noise floor, and the
//! tests of whether a candidate on top of it is significant.
use crate::estimation::fit::{fit, FitError, FitOptions, FitResult, Search};
use crate::model_on_log::model::Runner;
use crate::model_on_log::run::Run;
use std::sync::OnceLock;

/// Weighted residual RMS of a parameter vector, each run (segment) anchored at
/// its best start pose (see `FitOptions::estimate_start`).
pub fn weighted_rms(r: &Runner, p: &[f64], runs: &[Run], o: &FitOptions) -> f64 {
    crate::estimation::fit::rms_with_fitted_starts(r, p, runs, o)
}

/// Split every run at `frac` of its evidence: (train, test). With a ground
/// truth, at `frac` of its rows; without one, at the row of the sighting
/// `frac` of the way through its sightings, the residuals a run without a
/// ground truth has. Cut by rows, a robot that saw its landmarks only early
/// on (a tour that leaves the mapped area) had a held-out part without a
/// single residual, a held-out error of 0, and no effect could be
/// significant however clear (a 0.03 rad toe, estimated to 1%, its error
/// 60% lower: "no catalogue effect is significant").
pub fn split(runs: &[Run], frac: f64) -> (Vec<Run>, Vec<Run>) {
    let mut tr = Vec::new();
    let mut te = Vec::new();
    for r in runs {
        let n = r.t.len();
        let cut = cut_row(r, frac).clamp(2, n - 2);
        tr.push(r.slice(0, cut + 1));
        te.push(r.slice(cut, n));
    }
    (tr, te)
}

/// The row at `frac` of run `r`'s evidence (see [`split`]).
pub(crate) fn cut_row(r: &Run, frac: f64) -> usize {
    let by_rows = (r.t.len() as f64 * frac) as usize;
    if r.gt.is_some() || r.landmarks.is_empty() {
        return by_rows;
    }
    let mut times: Vec<f64> = r.landmarks.iter().map(|o| o.t).collect();
    times.sort_by(f64::total_cmp);
    let at = times[((times.len() as f64 * frac) as usize).min(times.len() - 1)];
    r.t.partition_point(|t| *t < at)
}

pub(crate) fn bic(cost: f64, n: usize, k: usize) -> f64 {
    let n = n as f64;
    n * (2.0 * cost / n).max(1e-300).ln() + k as f64 * n.ln()
}

/// Start an augmented runner from the base estimates.
pub(crate) fn seeded(aug: &Runner, base: &Runner, p: &[f64]) -> Runner {
    let mut a = aug.clone();
    for (i, n) in base.names.iter().enumerate() {
        if let Some(j) = a.param_index(n) {
            a.p[j] = p[i];
        }
    }
    a
}

/// Whether a candidate explains most of what the current model leaves above the
/// noise floor, in the fit and on held-out data: an effect small next to the
/// sensor noise (a 5% gyro scale under 3x noise lowers the error by 15%, to the
/// floor) is as real as a large one. Only when the current model leaves a clear
/// excess (its mean square 20% above the floor's). With `holdout_rmse` None,
/// only the fit's share is judged (see [`significant`]).
pub(crate) fn explains_excess(cur: &Stage, rmse: f64, holdout_rmse: Option<f64>) -> bool {
    // what no catalogue effect can explain: the sensor noise and the model's own
    // discretisation at the log's rate
    let f2 = cur.floor * cur.floor + cur.step_error * cur.step_error;
    let share =
        |before: f64, after: f64| (before * before - after * after) / (before * before - f2);
    cur.rmse * cur.rmse > 1.2 * f2
        && cur.holdout_rmse * cur.holdout_rmse > 1.2 * f2
        && share(cur.rmse, rmse) > 0.5
        && holdout_rmse.is_none_or(|h| share(cur.holdout_rmse, h) > 0.5)
}

/// Whether a candidate calibrated to `rmse` with BIC gain `gain` over `cur` is
/// significant: a large improvement that holds out, or most of the excess over
/// the noise explained, and more than the model's own discretisation could
/// account for. With `holdout_rmse` None: whether it can still be, once its
/// held-out error is known.
pub(crate) fn significant(cur: &Stage, rmse: f64, gain: f64, holdout_rmse: Option<f64>) -> bool {
    let improvement = 1.0 - rmse / cur.rmse;
    let large = improvement > 0.2 && holdout_rmse.is_none_or(|h| h < 0.8 * cur.holdout_rmse);
    evident(cur, rmse, gain) && (large || explains_excess(cur, rmse, holdout_rmse))
}

/// The evidence every significant effect needs: a BIC gain, and more
/// explained than the model's own discretisation could account for.
pub(crate) fn evident(cur: &Stage, rmse: f64, gain: f64) -> bool {
    let beyond_step = cur.rmse * cur.rmse - rmse * rmse > cur.step_error * cur.step_error;
    gain > 10.0 && beyond_step && rmse.is_finite()
}

/// The current model of a diagnosis step: its runner, calibration and scores.
#[derive(Clone)]
pub(crate) struct Stage {
    pub(crate) runner: Runner,
    pub(crate) fit: FitResult,
    pub(crate) rmse: f64,
    pub(crate) bic: f64,
    pub(crate) holdout_rmse: f64,
    /// The error a model explaining every structure would reach (white noise).
    pub(crate) floor: f64,
    /// The model's own discretisation error at the log's rate (the base
    /// model's, see `crate::estimation::discretisation`), which no effect explains.
    pub(crate) step_error: f64,
    /// Its held-out error in each fold of the log's segments, computed when
    /// a candidate first needs it (see [`Folds::held_out`]).
    pub(crate) fold_errors: OnceLock<Vec<f64>>,
}

pub(crate) fn stage(
    runner: Runner,
    runs: &[Run],
    train: &[Run],
    test: &[Run],
    o: &FitOptions,
) -> Result<Stage, FitError> {
    // The global search is the continuation ladder's, as each candidate's
    // from nominal values (see `Search::Continued`): fit's direct start from
    // nominal values wandered 201-301 passes on omni_caster logs with 0.2 rad
    // steering offsets (over half of their diagnosis) without ever ending
    // below the ladder's; a log too short for the ladder gets fit's search.
    let fit = fit(&runner, runs, o, Search::Continued)?;
    // The training part is the first 60% of the same runs: its calibration
    // starts where the whole log's ended, with the start headings of the
    // segments the two share, and refines locally, as each candidate's does
    // from this one. A second global search on the training part (run beside
    // the first) spent as many passes again retracing the same journey from
    // nominal values: on an omni_caster log with a 0.2 rad steering offset
    // left out, most of the base model's calibration.
    let mut from = runner.clone();
    from.p = fit.p.clone();
    let on_part = Search::OnPart {
        whole: runs,
        starts: &fit.starts,
    };
    let train_fit = crate::estimation::fit::fit(&from, train, o, on_part)
        .or_else(|_| crate::estimation::fit::fit(&runner, train, o, Search::Global))?;
    Ok(stage_from(runner, fit, train_fit, runs, test, o))
}

/// The stage of `runner` calibrated as `fit` on all runs and as `train_fit` on
/// the training part.
pub(crate) fn stage_from(
    runner: Runner,
    fit: FitResult,
    train_fit: FitResult,
    runs: &[Run],
    test: &[Run],
    o: &FitOptions,
) -> Stage {
    let rmse = weighted_rms(&runner, &fit.p, runs, o);
    let bic = bic(fit.cost_after, fit.n_residuals, fit.free.len());
    let holdout_rmse = weighted_rms(&runner, &train_fit.p, test, o);
    let floor = crate::estimation::fit::noise_floor(&runner, &fit.p, runs, o);
    Stage {
        runner,
        fit,
        rmse,
        bic,
        holdout_rmse,
        floor,
        step_error: 0.0,
        fold_errors: OnceLock::new(),
    }
}

/// Whether a stage leaves nothing above the noise floor and its own
/// discretisation: no effect added to it can then be significant (it would
/// need most of an excess that is not there, or an error 20% below the white
/// noise), so the chain ends without another round (the last round of every
/// chain: 0.5 s of an omni_caster diagnosis whose second effect reached the
/// floor).
pub(crate) fn leaves_only_noise(cur: &Stage) -> bool {
    cur.rmse * cur.rmse <= cur.floor * cur.floor + cur.step_error * cur.step_error
}
