//! Calibration judged where its users feel it (issue 35): on runs it was not
//! fitted on. Each session (runs of one robot recorded together) is
//! calibrated by [`fit`]; its parameters, the nominal values and every
//! published method's parameters from the same session are then scored on
//! the runs of the robot's *other* sessions, each dead-reckoned from its
//! measured start: the median over those runs of the final position error
//! and of the whole-run position RMSE. Beside them, the study's own
//! in-sample figure: the largest final position error over the session's
//! own runs.
use crate::estimation::fit::{fit, for_use, FitOptions, Search};
use crate::model_on_log::metrics;
use crate::model_on_log::model::Runner;
use crate::model_on_log::run::Run;
use rayon::prelude::*;
use serde::Serialize;
use std::collections::BTreeMap;
use std::time::Instant;

pub mod optiodom;

/// One session: its runs, the model at the session's nominal values, and the
/// calibrations published from it.
pub struct Session {
    /// e.g. `diff/square/230620202144`
    pub name: String,
    /// The session its runs were recorded in (its own name, or the session
    /// [`each_run_alone`] cut it from): runs recorded together never score
    /// each other's calibration.
    pub recorded: String,
    /// The robot it was recorded with; sessions of the same robot score each other.
    pub robot: String,
    pub runner: Runner,
    pub runs: Vec<Run>,
    pub published: Vec<Calibration>,
}

/// Parameter values a method gives, by the spec's parameter index; the
/// others stay at the session's nominal values.
#[derive(Debug, Clone)]
pub struct Calibration {
    pub method: String,
    pub values: Vec<(usize, f64)>,
    /// The study's own in-sample figure for it (largest final position error
    /// over the session's runs, m), where published: a check that the spec
    /// dead-reckons as the study did.
    pub study_final_m: Option<f64>,
}

/// How one parameter set does.
#[derive(Debug, Clone, Serialize)]
pub struct Score {
    /// Median over the other sessions' runs of the final position error, m.
    pub held_out_final_m: Option<f64>,
    /// Median over the other sessions' runs of the whole-run position RMSE, m.
    pub held_out_rmse_m: Option<f64>,
    pub held_out_runs: usize,
    /// Largest final position error over the session's own runs, m.
    pub in_sample_final_m: f64,
    /// Each held-out run's (final position error, position RMSE), m, in the
    /// same order for every method of a session: paired comparisons.
    pub held_out: Vec<[f64; 2]>,
}

#[derive(Debug, Clone, Serialize)]
pub struct MethodResult {
    pub method: String,
    pub params: BTreeMap<String, f64>,
    pub score: Score,
    pub study_final_m: Option<f64>,
}

#[derive(Debug, Clone, Serialize)]
pub struct SessionResult {
    pub session: String,
    pub robot: String,
    pub runs: usize,
    /// Logged time over the session's runs, s.
    pub seconds: f64,
    /// Wall time of kinegen's calibration, s.
    pub fit_seconds: f64,
    /// What fit said (or why it failed).
    pub warnings: Vec<String>,
    /// `kinegen` first, then `nominal`, then the published methods.
    pub methods: Vec<MethodResult>,
}

/// The name kinegen's own calibration is listed under.
pub const KINEGEN: &str = "kinegen";
/// The name of the nominal values.
pub const NOMINAL: &str = "nominal";

/// A measure of a [`Score`] (smaller is better).
pub type Measure = fn(&Score) -> Option<f64>;

pub const HELD_OUT_FINAL: Measure = |s| s.held_out_final_m;
pub const HELD_OUT_RMSE: Measure = |s| s.held_out_rmse_m;
pub const IN_SAMPLE_FINAL: Measure = |s| Some(s.in_sample_final_m);

impl SessionResult {
    /// The published method with the smallest `measure`, with its value.
    pub fn best_published(&self, measure: Measure) -> Option<(&str, f64)> {
        self.methods
            .iter()
            .filter(|m| m.method != KINEGEN && m.method != NOMINAL)
            .filter_map(|m| measure(&m.score).map(|v| (m.method.as_str(), v)))
            .min_by(|a, b| a.1.total_cmp(&b.1))
    }

    pub fn score_of(&self, method: &str) -> Option<&Score> {
        self.methods
            .iter()
            .find(|m| m.method == method)
            .map(|m| &m.score)
    }

    /// Kinegen against the best published method by `measure` (by its
    /// median), run by run on the held-out runs: the runs where kinegen's
    /// error (component `k` of [`Score::held_out`]: 0 final, 1 RMSE) is
    /// lower, the runs that differ, and the two-sided sign test's p-value
    /// (a small one: the difference is more than the runs' scatter).
    pub fn paired(&self, measure: Measure, k: usize) -> Option<Paired> {
        let (best, _) = self.best_published(measure)?;
        let ours = &self.score_of(KINEGEN)?.held_out;
        let theirs = &self.score_of(best)?.held_out;
        let (mut lower, mut differ) = (0, 0);
        for (a, b) in ours.iter().zip(theirs) {
            if a[k] != b[k] {
                differ += 1;
                lower += usize::from(a[k] < b[k]);
            }
        }
        Some(Paired {
            lower,
            differ,
            p_value: sign_test(lower, differ),
        })
    }

    /// Whether kinegen's `measure` is at or below every published method's
    /// (None: not measured, or nothing published to compare with).
    pub fn kinegen_wins(&self, measure: Measure) -> Option<bool> {
        let ours = measure(self.score_of(KINEGEN)?)?;
        let (_, best) = self.best_published(measure)?;
        Some(ours <= best)
    }
}

/// Calibrate every session and score every method (see the module doc).
/// `progress` hears each session's name as its calibration starts.
pub fn benchmark(
    sessions: &[Session],
    o: &FitOptions,
    progress: &(dyn Fn(&str) + Sync),
) -> Vec<SessionResult> {
    sessions
        .iter()
        .enumerate()
        .map(|(i, s)| {
            progress(&s.name);
            let started = Instant::now();
            // calibrated as `fit` calibrates (the `lm` method)
            let fitted = fit(&s.runner, &s.runs, o, Search::Global)
                .map(|res| for_use(&s.runner, &s.runs, o, res));
            let (ours, warnings) = match fitted {
                Ok(res) => (
                    Some(Calibration {
                        method: KINEGEN.into(),
                        values: res.free.iter().map(|&k| (k, res.p[k])).collect(),
                        study_final_m: None,
                    }),
                    res.warnings,
                ),
                Err(e) => (None, vec![format!("fit failed: {e}")]),
            };
            let fit_seconds = started.elapsed().as_secs_f64();
            let nominal = Calibration {
                method: NOMINAL.into(),
                values: vec![],
                study_final_m: None,
            };
            let others: Vec<&Session> = sessions
                .iter()
                .enumerate()
                .filter(|(j, o)| *j != i && o.robot == s.robot && o.recorded != s.recorded)
                .map(|x| x.1)
                .collect();
            let methods = ours
                .iter()
                .chain([&nominal])
                .chain(&s.published)
                .map(|c| MethodResult {
                    method: c.method.clone(),
                    params: named(&s.runner, c),
                    score: score(s, &others, c),
                    study_final_m: c.study_final_m,
                })
                .collect();
            SessionResult {
                session: s.name.clone(),
                robot: s.robot.clone(),
                runs: s.runs.len(),
                seconds: s.runs.iter().map(|r| r.t.last().unwrap() - r.t[0]).sum(),
                fit_seconds,
                warnings,
                methods,
            }
        })
        .collect()
}

/// Each run of each session as a session of its own (`NAME/RUN`): what one
/// run can tell, scored on the runs of the robot's other recorded sessions.
/// The published calibrations, made from whole sessions, are left out.
pub fn each_run_alone(sessions: Vec<Session>) -> Vec<Session> {
    sessions
        .into_iter()
        .flat_map(|s| {
            let Session {
                name,
                recorded,
                robot,
                runner,
                runs,
                ..
            } = s;
            runs.into_iter()
                .map(|run| Session {
                    name: format!("{name}/{}", run.name),
                    recorded: recorded.clone(),
                    robot: robot.clone(),
                    runner: runner.clone(),
                    runs: vec![run],
                    published: vec![],
                })
                .collect::<Vec<_>>()
        })
        .collect()
}

/// How much worse than the nominal values on the held-out runs a
/// calibration may be before it counts as worse (issue 70: "none makes
/// them worse by more than 10%").
pub const WORSE_THAN_NOMINAL: f64 = 1.1;

/// Calibrations worse than the nominal values on the held-out runs by
/// `measure` (beyond [`WORSE_THAN_NOMINAL`]), of those measured, and how
/// many of the worse ones fit gave no warning with.
#[derive(Debug, Clone, Copy, Default, Serialize, PartialEq, Eq)]
pub struct WorseThanNominal {
    pub worse: usize,
    pub unwarned: usize,
    pub of: usize,
}

pub fn worse_than_nominal(results: &[SessionResult], measure: Measure) -> WorseThanNominal {
    let mut w = WorseThanNominal::default();
    for s in results {
        let ours = s.score_of(KINEGEN).and_then(measure);
        let nominal = s.score_of(NOMINAL).and_then(measure);
        if let (Some(a), Some(b)) = (ours, nominal) {
            w.of += 1;
            if a > WORSE_THAN_NOMINAL * b {
                w.worse += 1;
                w.unwarned += usize::from(s.warnings.is_empty());
            }
        }
    }
    w
}

/// A calibration's values by parameter name.
fn named(r: &Runner, c: &Calibration) -> BTreeMap<String, f64> {
    c.values
        .iter()
        .map(|&(k, v)| (r.names[k].clone(), v))
        .collect()
}

/// `c` scored on `own`'s runs (in sample) and on the runs of `others`, each
/// at that session's nominal values with `c`'s values in place.
fn score(own: &Session, others: &[&Session], c: &Calibration) -> Score {
    let own_errors = errors(own, c);
    let held: Vec<(f64, f64)> = others.par_iter().flat_map(|s| errors(s, c)).collect();
    // a run whose dead reckoning stops being a number counts as the worst
    Score {
        held_out_final_m: median(held.iter().map(|e| e.0).collect()),
        held_out_rmse_m: median(held.iter().map(|e| e.1).collect()),
        held_out_runs: held.len(),
        in_sample_final_m: own_errors.iter().map(|e| e.0).fold(0.0, f64::max),
        held_out: held.iter().map(|e| [e.0, e.1]).collect(),
    }
}

/// (final position error, position RMSE) of each of `s`'s runs dead-reckoned
/// with `c` from its measured start.
fn errors(s: &Session, c: &Calibration) -> Vec<(f64, f64)> {
    let mut p = s.runner.p.clone();
    for &(k, v) in &c.values {
        p[k] = v;
    }
    s.runs
        .par_iter()
        .map(|run| {
            let e = metrics::from_measured_start(&s.runner, &p, run);
            (e.final_position_error_m, e.rmse)
        })
        .collect()
}

/// A paired comparison over held-out runs (see [`SessionResult::paired`]).
#[derive(Debug, Clone, Copy, Serialize)]
pub struct Paired {
    pub lower: usize,
    pub differ: usize,
    pub p_value: f64,
}

/// Two-sided exact sign test: the probability, with no difference, of a
/// split at least as uneven as `k` of `n`.
pub fn sign_test(k: usize, n: usize) -> f64 {
    if n == 0 {
        return 1.0;
    }
    let tail = k.min(n - k);
    // sum_{i <= tail} C(n, i) / 2^n, in logs (n may be in the hundreds)
    let ln_choose =
        |i: usize| -> f64 { (1..=i).map(|j| ((n - i + j) as f64 / j as f64).ln()).sum() };
    let one: f64 = (0..=tail)
        .map(|i| (ln_choose(i) - n as f64 * 2f64.ln()).exp())
        .sum();
    (2.0 * one).min(1.0)
}

/// The median (mean of the middle two for an even count); None when empty.
pub fn median(mut v: Vec<f64>) -> Option<f64> {
    if v.is_empty() {
        return None;
    }
    v.sort_by(f64::total_cmp);
    let n = v.len();
    Some(if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    })
}
