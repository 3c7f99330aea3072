//! `kinegen fit` as one library call: [`calibrate`] runs the
//! Levenberg-Marquardt calibration through the method registry and judges it
//! (before and after, held-out runs, leave-one-run-out, whether it can be
//! used at all); [`compare_methods`] runs several registered methods on the
//! same logs and compares them with the nominal values and a known truth.
//! The CLI renders what these return.
use crate::estimation::fit::leave_one_out::{leave_one_out, LeftOut};
use crate::estimation::fit::{
    fitted_offsets, run_offsets, run_starts, segmented, FitOptions, FitResult,
};
use crate::estimation::methods::{
    full_fit, Calibration, Method, MethodChoice, MethodError, Settings,
};
use crate::model_on_log::coverage;
use crate::model_on_log::evaluation::{evaluation, evaluation_from, pairs, Evaluation};
use crate::model_on_log::load::Loaded;
use crate::model_on_log::metrics::{degenerate, errors_each, implausible, short_term_worse};
use crate::model_on_log::model::Runner;
use crate::model_on_log::run::Run;
use crate::model_on_log::track_rows::{Heading, Recipe};

/// Why a calibration job could not run.
#[derive(Debug, thiserror::Error)]
pub enum FitJobError {
    /// The method does not apply to these logs (named) or this model.
    #[error("{logs}: {source}")]
    Method { logs: String, source: MethodError },
}

/// What a whole-run error that grew under calibration means.
#[derive(Debug, Clone)]
pub enum Growth {
    /// Explained: said, the fit stands.
    Note(String),
    /// Explained by the spec's tolerances: said and kept with the warnings.
    Warning(String),
}

/// The held-out runs with the nominal and the calibrated values.
pub struct HeldOut<'r> {
    pub before: Evaluation<'r>,
    pub after: Evaluation<'r>,
    /// The start pose each held-out run's dead reckoning used (as measured).
    pub starts: Vec<[f64; 3]>,
    /// Why the calibration is worse on them, when it is.
    pub worse: Option<String>,
}

/// The Levenberg-Marquardt calibration, judged.
pub struct Calibrated<'r> {
    /// The fit; its warnings start with the logs' and end with the
    /// judgement's (a [`Growth::Warning`] included).
    pub fit: FitResult,
    /// Nominal and calibrated values on the fitted runs, each with the start
    /// headings refined for its own parameters, as the fit refines them.
    pub before: Evaluation<'r>,
    pub after: Evaluation<'r>,
    /// The start pose each fitted run's dead reckoning used.
    pub starts: Vec<[f64; 3]>,
    /// How many of `fit.warnings` were known before the growth was judged
    /// (said before it).
    pub warnings_before_growth: usize,
    pub growth: Option<Growth>,
    /// Why the calibration cannot be used (empty: it can).
    pub unusable: Vec<String>,
    pub holdout: Option<HeldOut<'r>>,
    /// Each fitted run left out in turn, scored with the others' calibration.
    pub leave_one_out: Vec<LeftOut>,
    /// The runs leave-one-run-out found unsupported, said as one warning.
    pub leave_one_out_warning: Option<String>,
}

impl Calibrated<'_> {
    /// What the user should know, in the order said: the fit's (the logs'
    /// among them), the held-out runs' and leave-one-run-out's.
    pub fn warnings(&self) -> Vec<String> {
        self.fit
            .warnings
            .iter()
            .chain(self.holdout.as_ref().and_then(|h| h.worse.as_ref()))
            .chain(&self.leave_one_out_warning)
            .cloned()
            .collect()
    }
}

/// Calibrate `l`'s model on its runs with Levenberg-Marquardt (options
/// `fo`), through the method registry like every method, and judge it.
pub fn calibrate<'r>(l: &'r Loaded, fo: &FitOptions) -> Result<Calibrated<'r>, FitJobError> {
    let r = &l.runner;
    // The nominal values' score does not wait for the calibration: on one
    // long run the fit keeps a core busy alone for most of its time (a
    // 1,000,001-row log: 1.5 s of 8 saved on 2 cores).
    let (fitted, (offsets_before, before)) = rayon::join(
        || full_fit().calibrate(r, &l.runs, &Settings::defaults(fo)),
        || {
            // scored with the start headings refined for the nominal values,
            // as the fit refines them (within what the measured start allows)
            let offsets = fitted_offsets(r, &r.p, &l.runs, fo);
            let before = evaluation_from(r, &r.p, &l.runs, &run_offsets(&l.runs, &offsets));
            (offsets, before)
        },
    );
    let mut res = match fitted {
        Ok(Calibration { fit: Some(x), .. }) => x,
        Ok(_) => unreachable!("a full fit's calibration carries its fit"),
        Err(source) => {
            return Err(FitJobError::Method {
                logs: logs_named(&l.runs),
                source,
            })
        }
    };
    res.warnings.splice(0..0, l.warnings.iter().cloned());
    let after = evaluation_from(r, &res.p, &l.runs, &run_offsets(&l.runs, &res.starts));
    let judged = judge(l, &mut res, (&before, &after), &offsets_before);
    let holdout = (!l.holdout.is_empty()).then(|| held_out(l, &res, &before));
    let left_out = leave_one_out(r, &res.p, &l.runs, fo);
    let leave_one_out_warning = unsupported_runs(&left_out);
    Ok(Calibrated {
        starts: run_starts(r, &res.p, &l.runs, &res.starts),
        fit: res,
        before,
        after,
        warnings_before_growth: judged.warnings_before_growth,
        growth: judged.growth,
        unusable: judged.unusable,
        holdout,
        leave_one_out: left_out,
        leave_one_out_warning,
    })
}

struct Judgement {
    warnings_before_growth: usize,
    growth: Option<Growth>,
    unusable: Vec<String>,
}

/// Why the calibration cannot be used, if it cannot (never shown as a
/// success), with its warnings added to `res`.
fn judge(
    l: &Loaded,
    res: &mut FitResult,
    (eval_before, eval_after): (&Evaluation, &Evaluation),
    offsets_before: &[[f64; 3]],
) -> Judgement {
    let r = &l.runner;
    let (before, after) = (&eval_before.errors, &eval_after.errors);
    let mut unusable = degenerate(&pairs(&l.runs, &eval_after.tracks));
    let (worse, worse_warnings) = short_term_worse(before, after);
    unusable.extend(worse);
    let odd = implausible(
        res.free
            .iter()
            .map(|&i| (r.names[i].as_str(), r.p[i], res.p[i])),
    );
    res.warnings.extend(worse_warnings.into_iter().chain(odd));
    res.warnings.extend(drift_dominates(l, eval_after));
    let warnings_before_growth = res.warnings.len();
    let mut growth = None;
    if after.rmse.is_finite() && after.rmse > 1.001 * before.rmse {
        match judge_growth(l, res, (before.rmse, after.rmse), offsets_before) {
            Judged::Stands(g) => growth = Some(g),
            Judged::Unusable(u) => unusable.push(u),
        }
    }
    if let Some(Growth::Warning(w)) = &growth {
        res.warnings.push(w.clone());
    }
    if !after.rmse.is_finite() || res.p.iter().any(|v| !v.is_finite()) {
        unusable.push("the calibrated model gives non-finite results".into());
    }
    Judgement {
        warnings_before_growth,
        growth,
        unusable,
    }
}

/// How many times the sensor's own sigmas the sightings may still err by,
/// after a calibration without a ground truth, before that error is taken
/// for the dead reckoning's drift (a calibrated simulated robot: 1.0 times).
const DRIFT_OVER_NOISE: f64 = 5.0;

/// A warning where no run has a ground truth and the sightings, after the
/// calibration, still err by many times the sensor's sigmas: the
/// dead-reckoned track drifts far beyond the sensor's noise, and parameters
/// fitted to that drift are biased by it. (MRCLAM robot 4, 15 minutes of
/// velocity commands: the sightings still err by 0.88 m and 0.74 rad, 18 and
/// 37 times the spec's sigmas; k_v is 0.975 against 0.919 with the ground
/// truth, whose distance per 30 s says 0.891.)
fn drift_dominates(l: &Loaded, after: &Evaluation) -> Option<String> {
    if l.runs.iter().any(|r| r.gt.is_some()) {
        return None;
    }
    let s = after.landmarks.as_ref()?;
    let sigma = crate::model_on_log::landmarks::sigma(&l.runner);
    let times = [
        s.range_robust_sd_m / sigma[0],
        s.bearing_robust_sd_rad / sigma[1],
    ];
    (times.iter().any(|t| *t > DRIFT_OVER_NOISE)).then(|| {
        format!(
            "after calibration the sightings still err by {:.3} m and {:.3} rad (robust sd), {:.0} and {:.0} times the spec's sigmas: the track dead-reckoned over each whole run drifts far beyond the sensor's noise, and parameters fitted to that drift are biased by it; a ground truth (or runs short enough for the sightings to anchor) would tell. `localize` tracks the robot from the same sightings",
            s.range_robust_sd_m, s.bearing_robust_sd_rad, times[0], times[1]
        )
    })
}

/// A grown whole-run error judged: explained, or why the fit is unusable.
enum Judged {
    Stands(Growth),
    Unusable(String),
}

/// A whole-run position error that grew from `before` to `after`.
fn judge_growth(
    l: &Loaded,
    res: &FitResult,
    (before, after): (f64, f64),
    offsets_before: &[[f64; 3]],
) -> Judged {
    let r = &l.runner;
    // Long runs are fitted as re-anchored segments (fit::SEGMENT_S): judge the
    // fit on what it minimised; over a whole long run the absolute error is a
    // random walk the parameters cannot remove.
    let seg = segmented(&l.runs);
    let (sb, sa) = (
        evaluation_from(r, &r.p, &seg, offsets_before).errors.rmse,
        evaluation_from(r, &res.p, &seg, &res.starts).errors.rmse,
    );
    if seg.len() > l.runs.len() && sa <= 1.001 * sb {
        return Judged::Stands(Growth::Note(format!(
            "over whole runs the position error grew ({before:.4} m -> {after:.4} m) while over the {:.0} s segments the fit works on it fell ({sb:.4} m -> {sa:.4} m): the remaining long-run drift is noise the parameters cannot remove",
            crate::estimation::fit::SEGMENT_S
        )));
    }
    if after <= 1.05 * before {
        // within 5%: the starting values were already as good as these logs
        // can tell; the fit traded a little whole-track error for its cost
        return Judged::Stands(Growth::Note(format!(
            "the position error grew slightly ({before:.4} m -> {after:.4} m): the starting values were already about as good as these logs can tell"
        )));
    }
    let with_prior: Vec<&str> = res
        .free
        .iter()
        .filter(|&&i| r.ir.runtime_params()[i].tolerance.is_some())
        .map(|&i| r.names[i].as_str())
        .collect();
    let grew = format!("{before:.4} m -> {after:.4} m");
    if with_prior.is_empty() {
        return Judged::Unusable(format!(
            "calibration made the position error worse ({grew})"
        ));
    }
    // a prior may rightly cost some fit: the spec says what is known
    Judged::Stands(Growth::Warning(format!(
        "the position error grew ({grew}) under the spec's tolerances on {}: the log pulls them further than the tolerances allow; loosen a tolerance if the robot can differ from nominal that much",
        with_prior.join(", ")
    )))
}

/// The held-out runs before and after, and why they got worse if they did.
fn held_out<'r>(l: &'r Loaded, res: &FitResult, before: &Evaluation) -> HeldOut<'r> {
    let r = &l.runner;
    let (hb, ha) = (
        evaluation(r, &r.p, &l.holdout),
        evaluation(r, &res.p, &l.holdout),
    );
    let worse = held_out_worse(
        r,
        (&l.runs, &before.tracks),
        (&l.holdout, &hb.tracks),
        hb.errors.rmse,
        ha.errors.rmse,
    );
    HeldOut {
        starts: run_starts(r, &res.p, &l.holdout, &[]),
        before: hb,
        after: ha,
        worse,
    }
}

/// When a calibration made the held-out runs worse (`nominal` -> `now` m), the
/// warning that says so and why: the motions and inputs of the held-out runs
/// the fitted runs do not cover (dead-reckoned with the nominal values in
/// `fitted` and `held`), or else that the fitted runs do not determine what
/// the held-out runs need.
fn held_out_worse(
    r: &Runner,
    fitted: (&[Run], &[Recipe<'_>]),
    held: (&[Run], &[Recipe<'_>]),
    nominal: f64,
    now: f64,
) -> Option<String> {
    // (a NaN is not "worse": the fit's own checks name non-finite results)
    if now.partial_cmp(&(1.001 * nominal)) != Some(std::cmp::Ordering::Greater) {
        return None;
    }
    let gaps = coverage::uncovered(r, &pairs(fitted.0, fitted.1), &pairs(held.0, held.1));
    let why = if gaps.is_empty() {
        "the fitted runs do not determine what the held-out runs need (see the standard deviations): fit on runs that drive like the held-out ones".to_string()
    } else {
        format!(
            "the fitted runs do not cover them ({}): add runs that do to --data",
            gaps.join("; ")
        )
    };
    Some(format!(
        "worse than the nominal parameters on the held-out runs ({nominal:.4} m -> {now:.4} m): {why}"
    ))
}

/// Leave-one-run-out's verdict: the runs the others' calibration
/// dead-reckons worse than the starting values, named.
fn unsupported_runs(checked: &[LeftOut]) -> Option<String> {
    let unsupported: Vec<String> = checked
        .iter()
        .filter(|x| x.unsupported())
        .map(|x| {
            format!(
                "{} ({:.4} m -> {:.4} m)",
                x.path, x.nominal_rmse_m, x.calibrated_rmse_m
            )
        })
        .collect();
    (!unsupported.is_empty()).then(|| format!(
        "leave-one-run-out: calibrated on the other runs, {} of {} runs are dead-reckoned worse than with the starting values: {}. These runs do not support the estimate (too short, or driven differently from the rest): look at them, add runs like them, or give the parameters a `tolerance` in the spec",
        unsupported.len(),
        checked.len(),
        unsupported.join(", ")
    ))
}

/// The logs of `runs` by path, each once, for a message about all of them
/// (a few named, then how many more).
fn logs_named(runs: &[Run]) -> String {
    let mut paths: Vec<&str> = Vec::new();
    for r in runs {
        if !paths.contains(&r.path.as_str()) {
            paths.push(&r.path);
        }
    }
    match paths.len() {
        0..=3 => paths.join(", "),
        n => format!("{} and {} more", paths[..3].join(", "), n - 3),
    }
}

/// Which methods `fit --method` runs and with what.
pub struct MethodsJob<'a> {
    /// The method, or all of them.
    pub method: MethodChoice,
    /// What every method reads (its `hidden` is set per run for the methods
    /// that run once per size).
    pub settings: Settings<'a>,
    /// Hidden sizes of the methods that run once per size.
    pub hidden: &'a [u32],
    /// Known true values (simulated logs), NAME=VALUE.
    pub truth: &'a [(String, f64)],
}

/// One method's outcome on the logs.
pub struct MethodRow<'r> {
    /// Its name (`NAME-SIZE` for a method run per hidden size).
    pub name: String,
    pub calibration: Calibration,
    /// On the fitted runs.
    pub after: Evaluation<'r>,
    /// On the held-out runs, if any.
    pub holdout: Option<crate::model_on_log::metrics::Errors>,
    /// How it went, with a warning appended when it ends worse than nominal.
    pub note: String,
    /// Distance to the truth as a fraction of the nominal values' (when a
    /// truth is known).
    pub distance_to_truth: Option<f64>,
}

/// `fit --method M` (or all): each method's calibration, compared.
pub struct MethodsOutcome<'r> {
    /// The nominal values on the fitted runs.
    pub before: Evaluation<'r>,
    /// The nominal values' RMSE on the held-out runs, if any.
    pub holdout_before: Option<f64>,
    pub rows: Vec<MethodRow<'r>>,
    /// Methods of `all` that do not apply here, with why.
    pub not_applicable: Vec<(String, MethodError)>,
    /// The method closest to the truth, with its distance.
    pub closest: Option<(f64, String)>,
}

/// The methods `job.method` names (all of them for `all`), each with a run per
/// hidden size where the method has one (neural gyrodometry).
pub fn method_runs(
    job: &MethodsJob,
) -> Result<Vec<(String, &'static dyn Method, usize)>, FitJobError> {
    let methods: Vec<&dyn Method> = job.method.methods();
    Ok(methods
        .iter()
        .flat_map(|m| {
            if m.per_hidden_size() {
                job.hidden
                    .iter()
                    .map(|&h| (format!("{}-{h}", m.name()), *m, h as usize))
                    .collect::<Vec<_>>()
            } else {
                vec![(m.name().to_string(), *m, 0)]
            }
        })
        .collect())
}

/// Run every method `job` names on `l`'s runs and compare them; `progress`
/// hears each method's name before it runs.
pub fn compare_methods<'r>(
    l: &'r Loaded,
    job: &MethodsJob,
    progress: &dyn Fn(&str),
) -> Result<MethodsOutcome<'r>, FitJobError> {
    let r = &l.runner;
    let mut done = Vec::new();
    let mut not_applicable = Vec::new();
    for (name, m, hidden) in method_runs(job)? {
        progress(&name);
        let settings = Settings {
            hidden,
            ..job.settings
        };
        match m.calibrate(r, &l.runs, &settings) {
            Ok(c) => done.push((name, c)),
            Err(e) if matches!(job.method, MethodChoice::All) => not_applicable.push((name, e)),
            Err(source) => {
                return Err(FitJobError::Method {
                    logs: logs_named(&l.runs),
                    source,
                })
            }
        }
    }
    let before = evaluation(r, &r.p, &l.runs);
    let compared = Against::new(l, job.truth);
    let rows: Vec<MethodRow> = done
        .into_iter()
        .map(|(name, c)| compared.row(name, c, &before))
        .collect();
    let closest = rows
        .iter()
        .filter_map(|m| m.distance_to_truth.map(|d| (d, m.name.clone())))
        .fold(None, |best: Option<(f64, String)>, x| match best {
            Some(b) if b.0 <= x.0 => Some(b),
            _ => Some(x),
        });
    Ok(MethodsOutcome {
        before,
        holdout_before: compared.hold_nominal(),
        rows,
        not_applicable,
        closest,
    })
}

/// A method's evaluation: dead reckoning with its parameters, or, for a method
/// that learned the yaw rate (neural gyrodometry), gyrodometry with its virtual
/// gyro.
pub fn method_evaluation<'r>(r: &'r Runner, m: &Calibration, runs: &[Run]) -> Evaluation<'r> {
    let Some(f) = &m.yaw_rate else {
        return evaluation(r, &m.p, runs);
    };
    let tracks: Vec<Recipe> = runs
        .iter()
        .map(|_| Recipe {
            r,
            p: m.p.clone(),
            offset: [0.0; 3],
            heading: Heading::Learned(f.clone()),
        })
        .collect();
    let (errors, per_run) = errors_each(&pairs(runs, &tracks));
    Evaluation {
        errors,
        per_run,
        tracks,
        landmarks: None,
        landmarks_from_truth: None,
    }
}

/// What each method is compared with: the nominal values (on the held-out
/// runs here, on the fitted ones as `row`'s `before`) and the known truth.
struct Against<'a, 't> {
    l: &'a Loaded,
    truth: &'t [(String, f64)],
    /// the nominal values' distance to the truth
    d0: f64,
    /// the nominal values on the held-out runs, if there are any
    held_nominal: Option<Evaluation<'a>>,
}

impl<'a, 't> Against<'a, 't> {
    fn new(l: &'a Loaded, truth: &'t [(String, f64)]) -> Self {
        let r = &l.runner;
        let mut me = Against {
            l,
            truth,
            d0: 0.0,
            held_nominal: (!l.holdout.is_empty()).then(|| evaluation(r, &r.p, &l.holdout)),
        };
        me.d0 = me.scaled(&r.p);
        me
    }

    /// Distance to the truth, each parameter scaled by its size (so a 2 mm
    /// offset of a 0.3 m axis and of a 0 m axis weigh the same).
    fn scaled(&self, p: &[f64]) -> f64 {
        let r = &self.l.runner;
        self.truth
            .iter()
            .filter_map(|(n, v)| {
                r.param_index(n)
                    .map(|i| ((p[i] - v) / r.p[i].abs().max(v.abs()).max(1e-12)).powi(2))
            })
            .sum::<f64>()
            .sqrt()
    }

    /// The nominal values' RMSE on the held-out runs, if any.
    fn hold_nominal(&self) -> Option<f64> {
        self.held_nominal.as_ref().map(|h| h.errors.rmse)
    }

    /// One method's row: its errors, a warning in its note where it ends
    /// worse than the nominal values (on the held-out runs when there are
    /// some), and its distance to the truth. `before`: the nominal values on
    /// the fitted runs.
    fn row(&self, name: String, m: Calibration, before: &Evaluation) -> MethodRow<'a> {
        let (r, l) = (&self.l.runner, self.l);
        let after = method_evaluation(r, &m, &l.runs);
        let hold = (!l.holdout.is_empty()).then(|| method_evaluation(r, &m, &l.holdout).errors);
        let (what, now, nominal) = match (&hold, self.hold_nominal()) {
            (Some(h), Some(b)) => ("held-out runs", h.rmse, b),
            _ => ("fitted runs", after.errors.rmse, before.errors.rmse),
        };
        let mut note = m.note.clone();
        let held_worse = self.held_nominal.as_ref().and_then(|h| {
            held_out_worse(
                r,
                (&l.runs, &before.tracks),
                (&l.holdout, &h.tracks),
                nominal,
                now,
            )
        });
        if let Some(w) = held_worse {
            note += &format!("\n      WARNING: {w}: do not use these values");
        } else if now > 1.001 * nominal {
            note += &format!("\n      WARNING: worse than the nominal parameters on the {what} ({nominal:.4} m -> {now:.4} m): do not use these values");
        }
        let distance_to_truth = (!self.truth.is_empty()).then(|| {
            if self.d0 > 0.0 {
                self.scaled(&m.p) / self.d0
            } else {
                self.scaled(&m.p)
            }
        });
        MethodRow {
            name,
            calibration: m,
            after,
            holdout: hold,
            note,
            distance_to_truth,
        }
    }
}
