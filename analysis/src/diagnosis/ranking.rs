//! Candidate effects calibrated on top of a stage and ranked: their error,
//! BIC gain, held-out error, evidence (how the residual lines up with the
//! effect's signature), folds and clock, and which ones the logs cannot tell
//! apart from the winner.
use super::clock::{ClockVerdict, SightingClock};
use super::folds::{FoldTest, Folds};
use crate::estimation::fit::{fit, residuals, FitOptions, FitResult, Search};
use crate::model_on_log::model::Runner;
use crate::model_on_log::run::Run;
use kinegen_model::decl::ObservationRole::{RangeBearing, YawRate};
use nalgebra::DVector;
use rayon::prelude::*;
use serde::Serialize;

use super::estimate::{Estimate, Estimates};
use super::stage::{bic, evident, seeded, significant, weighted_rms, Stage};

/// The likelihood ratio (chi-square with one degree of freedom at 5%) under
/// which two candidates explain the logs equally (see [`ChainStep::equivalent`]).
pub const EQUIVALENT: f64 = 3.84;

#[derive(Debug, Clone, Serialize)]
pub struct Candidate {
    pub effect: String,
    pub rmse: f64,
    pub improvement: f64,
    pub significant: bool,
    pub parameters: Estimates,
    pub evidence: String,
    pub bic_gain: f64,
    pub holdout_rmse: f64,
    /// The cross-validation over the log's segments, when it was run (a
    /// long log, and a candidate the other criteria leave unproven).
    pub folds: Option<FoldTest>,
    /// What the landmark sightings say of the delay of the ground truth
    /// behind the inputs that this candidate's calibration needs, when it
    /// changes that delay (see [`super::clock`]). Contradicted: not
    /// significant, however well it fits. Confirmed: it ranks before the
    /// significant candidates the sightings do not confirm.
    pub clock: Option<ClockVerdict>,
    pub doc: String,
    /// The calibration of the model with this effect on all runs, and on the
    /// training part: the next stage of the chain when the effect wins.
    #[serde(skip)]
    pub fit: FitResult,
    #[serde(skip)]
    pub train_fit: FitResult,
}

/// The channel of each residual of `runs`, in the order fit's residuals
/// come (per run: pose, landmark sightings, gyro).
pub(crate) fn channel_names(r: &Runner, runs: &[Run], o: &FitOptions) -> Vec<&'static str> {
    let mut v = Vec::new();
    let sees = r.ir.observation_kernels(RangeBearing).is_some();
    for run in runs {
        if o.use_pose && run.gt.is_some() {
            for _ in 1..run.t.len() {
                v.extend(["x position", "y position", "heading"]);
            }
        }
        if o.use_landmarks && sees {
            for _ in &run.landmarks {
                v.extend(["landmark range", "landmark bearing"]);
            }
        }
        if o.use_gyro
            && run.gyro.is_some()
            && r.ir.observation_kernels(YawRate).map(|o| o.value).is_some()
        {
            v.extend(std::iter::repeat_n("gyro", run.steps()));
        }
    }
    v
}

/// The effect's signature against the base residual: correlation and the channel
/// that carries most of the signature.
pub(crate) fn evidence(
    aug: &Runner,
    effect_params: &[usize],
    runs: &[Run],
    o: &FitOptions,
) -> String {
    // the measured starts: no start-heading columns in this (dense) Jacobian
    let o = &FitOptions {
        estimate_start: false,
        ..o.clone()
    };
    let (res, jac) = residuals(aug, &aug.p, effect_params, runs, o, true, &[]);
    let j = jac.unwrap();
    let chans = channel_names(aug, runs, o);
    let r = DVector::from_vec(res);
    let mut parts = Vec::new();
    for (c, &pi) in effect_params.iter().enumerate() {
        let col = j.column(c);
        let denom = r.norm() * col.norm();
        let corr = if denom > 0.0 {
            r.dot(&col) / denom
        } else {
            0.0
        };
        let mut energy: Vec<(&str, f64)> = Vec::new();
        for (k, v) in col.iter().enumerate() {
            let ch = chans.get(k).copied().unwrap_or("?");
            match energy.iter_mut().find(|e| e.0 == ch) {
                Some(e) => e.1 += v * v,
                None => energy.push((ch, v * v)),
            }
        }
        let total: f64 = energy.iter().map(|e| e.1).sum();
        energy.sort_by(|a, b| b.1.total_cmp(&a.1));
        let main = energy
            .first()
            .map(|e| {
                format!(
                    "{} ({:.0}% of its signature)",
                    e.0,
                    100.0 * e.1 / total.max(1e-300)
                )
            })
            .unwrap_or_default();
        parts.push(format!(
            "base residual follows the signature of {} with |r| = {:.2}, mostly in {main}",
            aug.names[pi],
            corr.abs()
        ));
    }
    parts.join("; ")
}

/// The significant candidates of a ranking that explain the logs as well as
/// its winner `w` (see [`ChainStep::equivalent`]): a likelihood ratio between
/// the two calibrated models below [`EQUIVALENT`] (chi-square, one degree of
/// freedom, 5%), the residual variance taken from the winner's own fit.
/// (Held-out errors were tried as a second test: the few rows at the start
/// of each held-out part, where a late command and a late motion capture do
/// differ, decided it by chance.)
pub(crate) fn ranked_equivalents(ranked: &[Candidate], w: &Candidate) -> Vec<String> {
    // The ratio counts each residual as independent, which a log that
    // random drift dominates is far from: where the folds proved the winner,
    // each segment counts once (they are dead-reckoned apart). On a real
    // robot whose motion lags its commands, a late command and a late
    // motion capture differ by 0.1-2% of the error, thousands in the ratio
    // of residuals and under one in that of segments.
    let n = match w.folds.filter(|_| w.by_folds()) {
        Some(f) => f.segments as f64,
        None => w.fit.n_residuals as f64,
    };
    let s2 = (w.rmse * w.rmse).max(1e-300);
    // the sightings put the ground truth late by what the winner's delay is:
    // a rival that leaves the ground truth on time does not explain that
    let confirmed = w.confirmed_by_clock();
    ranked
        .iter()
        .filter(|c| c.effect != w.effect && c.significant)
        .filter(|c| !confirmed || c.confirmed_by_clock())
        .filter(|c| n * (c.rmse * c.rmse - w.rmse * w.rmse).abs() / s2 < EQUIVALENT)
        .map(|c| c.effect.clone())
        .collect()
}

/// The free parameters of an augmented runner that the current model lacks: the
/// ones its effect adds (indices into `aug`'s parameters).
pub(crate) fn effect_params(aug: &Runner, cur: &Runner) -> Vec<usize> {
    aug.free
        .iter()
        .copied()
        .filter(|&i| cur.param_index(&aug.names[i]).is_none())
        .collect()
}

/// [`FitOptions::cost_tolerance`] of the ranking's calibrations: 1e-6 of the
/// cost, a BIC gain known to about 0.05 where significance needs 10 (a
/// misspecified candidate's fit otherwise creeps on for dozens of passes).
pub(crate) const RANKING_TOLERANCE: f64 = 1e-6;

/// Error (weighted RMS) within this factor of the noise floor counts as
/// leaving only the noise (see [`rank`]).
pub(crate) const FLOOR_REACHED: f64 = 1.05;

/// Iterations a candidate's refinement from the current calibration gets
/// when searches from nominal values may follow (the first round): one that
/// has not arrived by then is creeping along a misspecified model's valley,
/// and the search gets there sooner. On 10,921-row omni_caster logs with a
/// steering offset of 40% of its bound, the refinement crept 68-98
/// iterations (1.5-2.8 s) to 7x the noise floor, where the search from
/// nominal values reached the floor in 12 (0.4 s).
pub(crate) const FIRST_ROUND_ITERATIONS: usize = 20;

/// Calibrate every candidate on top of `cur` and score it against it. With
/// `from_nominal`, each candidate is also calibrated from nominal values (a
/// global search); see the comment inside.
#[allow(clippy::too_many_arguments)]
pub(crate) fn rank(
    cur: &Stage,
    from_nominal: bool,
    augmented: &[(String, String, Runner)],
    runs: &[Run],
    train: &[Run],
    test: &[Run],
    folds: Option<&Folds>,
    clock: Option<&SightingClock>,
    catalogue: &[kinegen_model::effects::Effect],
    o: &FitOptions,
    progress: &(dyn Fn(&str) + Sync),
) -> Vec<Candidate> {
    let strict = o;
    let o = &FitOptions {
        cost_tolerance: RANKING_TOLERANCE,
        ..o.clone()
    };
    // Every candidate's local refinement first. When one of them already
    // leaves only the noise (and the model's own discretisation), no search
    // from nominal values can find a calibration that explains more: the
    // searches are skipped. Diagnoses of 10,921-row omni_caster logs with a
    // steering offset: 4.7-8.0 s -> 3.6-4.9 s; clean ones 2.3-2.8 -> 1.5-1.8 s;
    // bench-diagnose --seeds 1 names the same effects in all 686 cases.
    // (each candidate's start and its local refinement)
    let floor = (cur.floor * cur.floor + cur.step_error * cur.step_error).sqrt();
    let local: Vec<(Runner, Local)> = augmented
        .par_iter()
        .map(|(_, _, aug)| {
            let start = seeded(aug, &cur.runner, &cur.fit.p);
            let local = local_refinement(&start, cur, runs, o, floor, from_nominal);
            (start, local)
        })
        .collect();
    let at_floor = local.iter().any(|(_, l)| {
        l.fit
            .as_ref()
            .is_some_and(|(_, rmse)| *rmse <= FLOOR_REACHED * floor)
    });
    let ranking = Ranking {
        cur,
        runs,
        train,
        test,
        o,
        strict,
        from_nominal: from_nominal && !at_floor,
        folds,
        clock,
        catalogue,
    };
    let mut candidates: Vec<Candidate> = augmented
        .par_iter()
        .zip(local)
        .filter_map(|((name, doc, aug), (start, local))| {
            let c = ranking.score(name, doc, aug, start, local);
            progress(name);
            c
        })
        .collect();
    candidates.sort_by(|a, b| {
        b.significant
            .cmp(&a.significant)
            .then(b.confirmed_by_clock().cmp(&a.confirmed_by_clock()))
            .then(b.bic_gain.total_cmp(&a.bic_gain))
    });
    candidates
}

impl Candidate {
    /// Whether the sightings measure the ground truth's delay this
    /// candidate needs (see [`ClockVerdict::Confirmed`]).
    pub fn confirmed_by_clock(&self) -> bool {
        matches!(self.clock, Some(ClockVerdict::Confirmed { .. }))
    }

    /// Significant by the fold-by-fold test alone (see [`super::folds`]).
    pub fn by_folds(&self) -> bool {
        self.significant && self.folds.as_ref().is_some_and(FoldTest::holds)
    }
}

/// What ranking a diagnosis round's candidates holds fixed: the current
/// stage, the runs (all, training and held-out parts) and the tolerances.
pub(crate) struct Ranking<'a> {
    pub(crate) cur: &'a Stage,
    pub(crate) runs: &'a [Run],
    pub(crate) train: &'a [Run],
    pub(crate) test: &'a [Run],
    /// The ranking tolerance, and the strict one a possible winner is polished with.
    pub(crate) o: &'a FitOptions,
    pub(crate) strict: &'a FitOptions,
    /// Whether candidates are also calibrated from nominal values.
    pub(crate) from_nominal: bool,
    /// The log's segments in folds, when it is long enough for them.
    pub(crate) folds: Option<&'a Folds>,
    /// The ground truth's lag behind the sightings, when the logs have both.
    pub(crate) clock: Option<&'a SightingClock>,
    /// The effects' definitions (their parameters' physical ranges).
    pub(crate) catalogue: &'a [kinegen_model::effects::Effect],
}

impl Ranking<'_> {
    /// Calibrate candidate `name` (its spec `doc`, runner `aug`, seeded
    /// `start` and local refinement `local`) and score it against the
    /// current stage.
    fn score(
        &self,
        name: &str,
        doc: &str,
        aug: &Runner,
        start: Runner,
        local: Local,
    ) -> Option<Candidate> {
        let Local {
            fit: from_cur,
            searched,
        } = local;
        let (from_cur, rmse_cur) = from_cur.unzip();
        let effect_params = effect_params(&start, &self.cur.runner);
        let ev = evidence(&start, &effect_params, self.runs, self.o);
        // start from the current estimates and from nominal: a structurally wrong
        // model can calibrate itself into a corner the effect cannot leave. The
        // current estimates are an optimum of all but the effect, so from there
        // a local refinement suffices; the global search (continuation,
        // other starts) is the one from nominal. Once the chain has an effect,
        // the current model is the winner's calibration, itself the best of
        // both searches: the global one is not repeated (it redid the whole
        // journey from nominal for every candidate: 11 s of a 36 s diagnosis
        // for one of them on an omni_caster log with a 0.2 rad offset).
        let from_nominal = (self.from_nominal && !searched && !gyro_only(&start, &effect_params))
            .then(|| fit(aug, self.runs, self.o, Search::Continued).ok())
            .flatten();
        let cur_start_wins = match (&from_cur, &from_nominal) {
            (Some(a), Some(b)) => a.cost_after <= b.cost_after,
            (a, _) => a.is_some(),
        };
        let mut f = if cur_start_wins {
            from_cur
        } else {
            from_nominal
        }?;
        let mut rmse = match rmse_cur {
            Some(e) if cur_start_wins => e,
            _ => weighted_rms(&start, &f.p, self.runs, self.o),
        };
        let mut gain = self.cur.bic - bic(f.cost_after, f.n_residuals, f.free.len());
        // what the verdict reports is converged fully: an effect that may
        // win is refined from its ranking fit with the strict tolerance
        if significant(self.cur, rmse, gain, None) {
            let mut at = start.clone();
            at.p = f.p.clone();
            if let Ok(polished) = fit(&at, self.runs, self.strict, Search::From(&f.starts)) {
                f = FitResult {
                    cost_before: f.cost_before,
                    iterations: f.iterations + polished.iterations,
                    ..polished
                };
                rmse = weighted_rms(&start, &f.p, self.runs, self.o);
                gain = self.cur.bic - bic(f.cost_after, f.n_residuals, f.free.len());
            }
        }
        // The training fit refines locally from the whole log's optimum,
        // as the base stage's does. From the current training calibration
        // it retraced the whole log's journey (round 2 of an omni_caster
        // log with a steering offset left after a time offset: 37
        // iterations after the whole log's 42), and after a search from
        // nominal values a second search on the training part did.
        let tr_start = Runner {
            p: f.p.clone(),
            ..start.clone()
        };
        let (whole, starts) = (self.runs, &f.starts);
        let on_part = Search::OnPart { whole, starts };
        let (train_fit, holdout_rmse) = match fit(&tr_start, self.train, self.o, on_part) {
            Ok(ft) => {
                let h = weighted_rms(&tr_start, &ft.p, self.test, self.o);
                (ft, h)
            }
            // no training calibration: the next stage, if any, starts
            // from the full one
            Err(_) => (f.clone(), f64::INFINITY),
        };
        let improvement = 1.0 - rmse / self.cur.rmse;
        let classic = significant(self.cur, rmse, gain, Some(holdout_rmse));
        let folds = (!classic && may_hold(self.cur, rmse, gain, holdout_rmse))
            .then(|| self.fold_test(&tr_start, &f))
            .flatten();
        let clock = self.clock_verdict(&start, &f);
        let contradicted = matches!(clock, Some(ClockVerdict::Contradicted { .. }));
        let parameters = estimates(&start, &effect_params, &f);
        let unphysical = super::estimate::unphysical(self.catalogue, name, &parameters);
        let significant =
            (classic || folds.is_some_and(|t| t.holds())) && !contradicted && unphysical.is_none();
        let evidence = format!(
            "{ev}; error {:.3} -> {:.3} (x{:.1}), BIC gain {:.0}, held-out error {:.3} -> {:.3}{}, noise floor {:.3}",
            self.cur.rmse,
            rmse,
            self.cur.rmse / rmse.max(1e-300),
            gain,
            self.cur.holdout_rmse,
            holdout_rmse,
            folds.map_or(String::new(), |t| format!(", {t}")),
            self.cur.floor
        ) + &self.clock.zip(clock).map_or(String::new(), |(c, v)| match v {
            ClockVerdict::Contradicted { delay } => format!(
                "; contradicted by the sightings: it needs the ground truth {delay:.3} s behind them, but {c}"
            ),
            ClockVerdict::Confirmed { delay } => {
                format!("; confirmed by the sightings ({delay:.3} s): {c}")
            }
        }) + &unphysical.map_or(String::new(), |why| format!("; not the physical effect: {why}"));
        Some(Candidate {
            effect: name.to_string(),
            rmse,
            improvement,
            significant,
            parameters,
            evidence,
            bic_gain: gain,
            holdout_rmse,
            folds,
            clock,
            doc: doc.to_string(),
            fit: f,
            train_fit,
        })
    }

    /// What the sightings say of the ground truth's delay that candidate
    /// `aug`, calibrated as `f`, needs. Only a candidate that adds a
    /// measurement delay to the current model claims anything about the
    /// ground truth's clock: the others leave it as the current model has it.
    fn clock_verdict(&self, aug: &Runner, f: &FitResult) -> Option<ClockVerdict> {
        let clock = self.clock?;
        let adds_delay = aug.delay.is_some() && self.cur.runner.delay.is_none();
        let before = crate::model_on_log::timeline::delay(&self.cur.runner, &self.cur.fit.p);
        adds_delay
            .then(|| clock.judge(before, crate::model_on_log::timeline::delay(aug, &f.p)))
            .flatten()
    }

    /// The candidate `aug`, calibrated as `f` on all runs, against the current
    /// model fold by fold (None: the log is too short for folds).
    fn fold_test(&self, aug: &Runner, f: &FitResult) -> Option<FoldTest> {
        let folds = self.folds?;
        let base = self
            .cur
            .fold_errors
            .get_or_init(|| folds.held_out(&self.cur.runner, &self.cur.fit, self.o));
        Some(super::folds::paired(
            base,
            &folds.held_out(aug, f, self.o),
            folds.segments(),
        ))
    }
}

/// The calibrated values of parameters `which` of runner `r` in `f`.
pub(crate) fn estimates(r: &Runner, which: &[usize], f: &FitResult) -> Estimates {
    which
        .iter()
        .map(|&i| {
            let k = f.free.iter().position(|&j| j == i).unwrap();
            let (estimate, std) = (f.p[i], f.std[k]);
            (r.names[i].clone(), Estimate { estimate, std })
        })
        .collect()
}

/// Whether a candidate the other criteria leave unproven may still hold fold
/// by fold: it is [`evident`] and predicts the held-out part of the runs
/// better, the cheap check before the folds' calibrations.
pub(crate) fn may_hold(cur: &Stage, rmse: f64, gain: f64, holdout_rmse: f64) -> bool {
    evident(cur, rmse, gain) && holdout_rmse < cur.holdout_rmse
}

/// Whether an effect's parameters change only what the gyro reads (its bias,
/// its scale): neither the motion (the twist and the step), nor the delay,
/// nor another observation. Such an effect gets no search from nominal
/// values: the search is there for a model whose calibration sits in a
/// corner of the motion's parameters that the effect cannot leave, and the
/// base model's own search from nominal already explored that landscape.
/// With a steering offset and a time offset both hidden on 10,921-row
/// omni_caster logs the gyro effects' searches took 2.5-3.4 s each and ended
/// where their refinements from the current calibration did.
pub(crate) fn gyro_only(aug: &Runner, effect_params: &[usize]) -> bool {
    aug.only_observed_by(effect_params, YawRate)
}

/// A candidate's calibration before any search from nominal values.
pub(crate) struct Local {
    /// The calibration and its error.
    pub(crate) fit: Option<(FitResult, f64)>,
    /// The effect's global search from nominal values ran already.
    pub(crate) searched: bool,
}

/// A candidate's local refinement from the current calibration (`start`),
/// of [`FIRST_ROUND_ITERATIONS`] at most in the `first_round`, where the
/// searches from nominal values may follow.
///
/// An effect that brings a measurement delay is also started from the delay
/// the motion's cross-correlation suggests
/// ([`crate::estimation::lag::delay_estimate`]), and the best kept: from the current
/// calibration and no delay the refinement stays near zero (10,921-row
/// omni_caster logs lagging 0.05-0.2 s: error 1.1-4.0 against floors of
/// 0.3-0.35), and every candidate then needed its global search from nominal
/// values. When that start halves the cost and still stays above the noise
/// `floor` (the other parameters absorbed part of a 0.2 s delay and hold the
/// refinement in their corner), the effect's own global search runs here,
/// from nominal values and the estimated delay, so that the other candidates'
/// searches can be skipped.
pub(crate) fn local_refinement(
    start: &Runner,
    cur: &Stage,
    runs: &[Run],
    o: &FitOptions,
    floor: f64,
    first_round: bool,
) -> Local {
    let scored = |f: FitResult| {
        let rmse = weighted_rms(start, &f.p, runs, o);
        (f, rmse)
    };
    let capped = FitOptions {
        max_iter: o.max_iter.min(FIRST_ROUND_ITERATIONS),
        ..o.clone()
    };
    let local_o = if first_round { &capped } else { o };
    let from_cur = fit(start, runs, local_o, Search::From(&cur.fit.starts))
        .ok()
        .map(scored);
    let plain = |fit| Local {
        fit,
        searched: false,
    };
    let Some(d) = start.delay.filter(|_| cur.runner.delay.is_none()) else {
        return plain(from_cur);
    };
    let q = start.ir.runtime_params()[d];
    let bounds = (q.min.unwrap_or(-1.0), q.max.unwrap_or(1.0));
    let Some(tau) = crate::estimation::lag::delay_estimate(start, &start.p, runs, bounds)
        .filter(|t| *t != start.p[d])
    else {
        return plain(from_cur);
    };
    let better = |a: Option<(FitResult, f64)>, b: Option<(FitResult, f64)>| match (a, b) {
        (Some(a), Some(b)) if b.0.cost_after < a.0.cost_after => Some(b),
        (None, b) => b,
        (a, _) => a,
    };
    let mut lagged = start.clone();
    lagged.p[d] = tau;
    let from_lag = fit(&lagged, runs, local_o, Search::From(&cur.fit.starts))
        .ok()
        .map(scored);
    // the search runs only where the estimated delay is plainly there: its
    // refinement halved the cost at least
    let clear = match (&from_cur, &from_lag) {
        (Some(a), Some(b)) => b.0.cost_after < 0.5 * a.0.cost_after,
        (None, b) => b.is_some(),
        _ => false,
    };
    let best = better(from_cur, from_lag);
    if !clear
        || best
            .as_ref()
            .is_some_and(|(_, rmse)| *rmse <= FLOOR_REACHED * floor)
    {
        return plain(best);
    }
    for (i, q) in start.ir.runtime_params().iter().enumerate() {
        lagged.p[i] = if i == d { tau } else { q.nominal };
    }
    let searched = fit(&lagged, runs, o, Search::Continued).ok().map(scored);
    Local {
        fit: better(best, searched),
        searched: true,
    }
}
