//! Which physical effect is missing?
//!
//! 1. Calibrate the base model.
//! 2. For each applicable catalogue effect: calibrate the augmented model and score
//!    it on the weighted residual (RMS), the Bayesian information criterion (so an
//!    extra parameter that only fits noise is not rewarded) and the error on
//!    held-out segments (last 40% of every run, fitted on the first 60%).
//! 3. Evidence: how well the base model's residual lines up with the effect's own
//!    signature (the sensitivity of the predictions to its parameter at zero).
//! 4. Whiteness: regress the one-step prediction residuals of the best model on
//!    motion features; structure that motion explains means something is still
//!    missing, and the channel and feature say where.
use super::clock::{ClockVerdict, SightingClock, Unmeasured};
use super::folds::{FoldTest, Folds};
use super::sensor::{diagnose_sensor, sensor_only, SensorCandidate, SensorUnmeasured, SightingFit};
use crate::estimation::discretisation::Discretisation;
use crate::estimation::fit::{fit, residuals, FitError, FitOptions, FitResult, Search};
use crate::logs::log::wrap;
use crate::model_on_log::derivation::EffectChains;
use crate::model_on_log::interp::lerp_rows;
use crate::model_on_log::model::Runner;
use crate::model_on_log::run::Run;
use kinegen_model::decl::ObservationRole::{Pose, RangeBearing, YawRate};
use kinegen_model::ir::StepForm;
use nalgebra::DVector;
use rayon::prelude::*;
use serde::Serialize;
use std::sync::OnceLock;

use super::estimate::{Estimate, Estimates};

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

#[derive(Debug, Clone, Serialize)]
pub struct Structure {
    pub structured: bool,
    /// Where the structure lives (channel, feature, regime), for people.
    pub findings: Vec<String>,
    pub r2: f64,
}

pub struct Diagnosis {
    pub baseline_rmse: f64,
    pub calibrated_rmse: f64,
    pub base_fit: FitResult,
    pub base_holdout_rmse: f64,
    pub candidates: Vec<Candidate>,
    /// Every effect found, in the order sequential diagnosis added them.
    pub chain: Vec<ChainStep>,
    /// What remains in the residuals of the final model (base plus chain).
    pub structure: Structure,
    /// The model's own discretisation error at the log's rate (counted with
    /// the noise floor when effects are judged): the calibrated base model's,
    /// or that of the chain's stage it was estimated at again (see
    /// [`RECHECK_STEP`]).
    pub discretisation: Discretisation,
    /// The noise floor (see `fit::noise_floor`) of the calibration the
    /// discretisation error was estimated at.
    pub noise_floor: f64,
    pub skipped: Vec<(String, String)>,
    /// How far the ground truth lags the landmark sightings, when the logs
    /// have both (what tells a late motion capture from a late command).
    pub clock: Option<SightingClock>,
    /// Why the logs' sightings and ground truth did not measure it.
    pub clock_unmeasured: Option<Unmeasured>,
    /// What the sightings say of the measurement delay the spec itself
    /// declares, as calibrated (None: it declares none, or no clock).
    pub spec_clock: Option<ClockVerdict>,
    /// The range-bearing sensor's effects, tested on the sightings seen from
    /// the ground truth (see [`super::sensor`]): the first round's
    /// candidates (their effects found are at the end of `chain`).
    pub sensor_candidates: Vec<SensorCandidate>,
    /// Why the sensor's effects were not tested, where the catalogue has some.
    pub sensor_unmeasured: Option<SensorUnmeasured>,
    /// The final model and its calibrated parameters.
    pub final_runner: Runner,
    pub final_p: Vec<f64>,
}

impl Diagnosis {
    /// The verdict: the first effect of the chain (None: no catalogue effect is significant).
    pub fn verdict(&self) -> Option<&str> {
        self.chain.first().map(|c| c.effect.as_str())
    }

    /// What the sightings say of the measurement delay `base` (the spec as
    /// the user wrote it) declares, in words (see [`ClockVerdict::of_spec_delay`]).
    pub fn spec_clock_said(&self, base: &Runner) -> Option<String> {
        let name = base.delay.map(|i| base.names[i].as_str())?;
        self.spec_clock.map(|v| v.of_spec_delay(name))
    }
}

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
fn cut_row(r: &Run, frac: f64) -> usize {
    let by_rows = (r.t.len() as f64 * frac) as usize;
    if r.gt.is_some() || r.landmarks.is_empty() {
        return by_rows;
    }
    let mut times: Vec<f64> = r.landmarks.iter().map(|o| o.t).collect();
    times.sort_by(f64::total_cmp);
    let at = times[((times.len() as f64 * frac) as usize).min(times.len() - 1)];
    r.t.partition_point(|t| *t < at)
}

fn bic(cost: f64, n: usize, k: usize) -> f64 {
    let n = n as f64;
    n * (2.0 * cost / n).max(1e-300).ln() + k as f64 * n.ln()
}

/// Start an augmented runner from the base estimates.
fn seeded(aug: &Runner, base: &Runner, p: &[f64]) -> Runner {
    let mut a = aug.clone();
    for (i, n) in base.names.iter().enumerate() {
        if let Some(j) = a.param_index(n) {
            a.p[j] = p[i];
        }
    }
    a
}

/// The channel of each residual of `runs`, in the order fit's residuals
/// come (per run: pose, landmark sightings, gyro).
fn channel_names(r: &Runner, runs: &[Run], o: &FitOptions) -> Vec<&'static str> {
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
fn evidence(aug: &Runner, effect_params: &[usize], runs: &[Run], o: &FitOptions) -> String {
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

/// One-step prediction residuals (from each measured pose) in the body frame, with
/// the motion features of the step.
fn one_step(
    r: &Runner,
    p: &[f64],
    runs: &[Run],
) -> (Vec<[f64; 4]>, Vec<[f64; 6]>, Vec<&'static str>) {
    let step = r.ir.step(StepForm::Exact).value;
    let tw = r.ir.twist();
    let zeros = [0.0; 16];
    let mut res = Vec::new();
    let mut feat = Vec::new();
    let mut regimes = Vec::new();
    let gyro = r.ir.observation_kernels(YawRate).map(|o| o.value);
    let tau = crate::model_on_log::timeline::delay(r, p);
    for run in runs {
        // the inputs as the robot executed them (a late or lagging command)
        let executed = crate::model_on_log::timeline::executed(r, p, run);
        let run: &Run = &executed;
        let Some(g) = &run.gt else { continue };
        let twists: Vec<Vec<f64>> = (0..run.steps())
            .map(|k| r.eval(tw, &[&run.u[k], p]))
            .collect();
        for k in 0..run.steps() {
            let dt = [run.dt[k]];
            // with delayed measurements the motion between rows k and k+1 was
            // driven by the inputs of the interval shifted by the delay
            let shifted_u: Vec<f64>;
            let u_k: &[f64] = if tau == 0.0 {
                &run.u[k]
            } else {
                let (j, a) = crate::model_on_log::timeline::model_instant(run, k, tau);
                let a = a.clamp(0.0, 1.0);
                let j1 = (j + 1).min(run.steps() - 1);
                shifted_u = lerp_rows(&run.u[j], &run.u[j1], a);
                &shifted_u
            };
            // from the body pose behind the measured one, to the predicted measurement
            let (x0, _) = crate::model_on_log::deadreckon::body_start(r, p, g[k], u_k);
            let x1 = r.eval(step, &Runner::step_args(step, &x0, u_k, p, &dt, &zeros));
            let pred = match r.ir.observation_kernels(Pose).map(|o| o.value) {
                Some(h) => r.eval(h, &Runner::obs_args(h, &x1, &run.u[k], p, &[])),
                None => x1,
            };
            let (dx, dy) = (g[k + 1][0] - pred[0], g[k + 1][1] - pred[1]);
            let (c, s) = (g[k][2].cos(), g[k][2].sin());
            let gres = match (gyro, &run.gyro) {
                (Some(h), Some(m)) => {
                    m[k + 1] - r.eval(h, &Runner::obs_args(h, &x0, &run.u[k], p, &[]))[0]
                }
                _ => 0.0,
            };
            res.push([
                c * dx + s * dy,
                -s * dx + c * dy,
                wrap(g[k + 1][2] - pred[2]),
                gres,
            ]);
            let t = motion_around(&twists, k);
            let (v, w) = ((t[0] * t[0] + t[1] * t[1]).sqrt(), t[2]);
            let d = run.dt[k];
            feat.push([v * d, w * d, v * w * d, w.abs() * d, d, v * v * d]);
            // (the gyro channel is a rate: its regression uses the same features / dt,
            // see `whiteness`)
            regimes.push(crate::model_on_log::metrics::regime(
                &[t[0], t[1], t[2]],
                0.2,
            ));
        }
    }
    (res, feat, regimes)
}

/// The motion of step k for binning its residual, from its neighbours k-2 and
/// k+2: the step's own inputs carry its own encoder quantisation, which is also
/// in its residual, so binning by them finds structure that is only that noise
/// (a straight run whose counts differ by one between the wheels both turns the
/// model and errs by the turn). Neighbours two steps away share no count with
/// step k, and the motion is smooth over five steps.
fn motion_around(twists: &[Vec<f64>], k: usize) -> [f64; 3] {
    let near: Vec<&Vec<f64>> = [k.checked_sub(2), Some(k + 2)]
        .into_iter()
        .flatten()
        .filter_map(|j| twists.get(j))
        .collect();
    let near = if near.is_empty() {
        vec![&twists[k]]
    } else {
        near
    };
    let mut m = [0.0; 3];
    for t in &near {
        for (a, b) in m.iter_mut().zip(t.iter()) {
            *a += b / near.len() as f64;
        }
    }
    m
}

/// A residual signature: its channel and the (change of the prediction by
/// the effect, residual) points.
pub type Signature = (String, Vec<(f64, f64)>);

/// The effect's residual signature, for plotting: per step, x = how much the
/// effect parameter at `value` (from the spec's nominal) changes the one-step
/// prediction and y = the calibrated base model's one-step residual, in the
/// channel where the change is largest. For the missing effect the points
/// line up along y = x.
///
/// The change is taken at the fitted value, not per unit at nominal: a
/// delay of 0.28 s moves a command by some twenty rows of a 65 Hz log,
/// where its derivative at zero sees one row (its points then lay along a
/// slope of one step's duration, far from the fitted delay's).
pub fn signature(
    base: &Runner,
    pb: &[f64],
    aug: &Runner,
    runs: &[Run],
    param: &str,
    value: f64,
) -> Option<Signature> {
    let i = aug.param_index(param)?;
    let start = seeded(aug, base, pb);
    let mut moved = start.p.clone();
    moved[i] = value;
    let h = value - start.p[i];
    if h == 0.0 {
        return None;
    }
    let (r0, _, _) = one_step(&start, &start.p, runs);
    let (r1, _, _) = one_step(&start, &moved, runs);
    let (rb, _, _) = one_step(base, pb, runs);
    let chans = ["along-track", "lateral", "heading", "gyro"];
    // only channels the logs measure: a log without a gyro has no gyro
    // residual to plot, however large the effect's gyro signature
    let measured = |c: &usize| match c {
        3 => runs.iter().all(|r| r.gyro.is_some()),
        _ => runs.iter().all(|r| r.gt.is_some()),
    };
    let c = (0..4).filter(measured).max_by(|&a, &b| {
        let e = |c: usize| {
            r0.iter()
                .zip(&r1)
                .map(|(x, y)| (x[c] - y[c]).powi(2))
                .sum::<f64>()
        };
        e(a).total_cmp(&e(b))
    })?;
    let pts = r0
        .iter()
        .zip(&r1)
        .zip(&rb)
        .map(|((x0, x1), b)| (x0[c] - x1[c], b[c]))
        .collect();
    Some((chans[c].to_string(), pts))
}

/// Is anything left in the one-step residuals that the motion explains? For each
/// channel (along-track, lateral, heading, gyro) and each feature (speed, yaw rate,
/// v*omega, heading, time) the steps are split into 8 quantile bins of the feature
/// and a one-way ANOVA asks whether the residual's mean differs between bins; a
/// channel whose mean is off zero is structured too. Structured = a share of the
/// variance explained (eta^2) above 5% with an F statistic far beyond chance
/// (> 20), so noise, however large, is not called structure. Feature-agnostic:
/// any function of the binned feature is caught, not only the ones we thought of.
#[allow(clippy::needless_range_loop)] // k indexes several per-row arrays of the run together
pub fn whiteness(r: &Runner, p: &[f64], runs: &[Run]) -> Structure {
    let (res, feat, regimes) = one_step(r, p, runs);
    let n = res.len();
    let chans = ["along-track", "lateral", "heading", "gyro"];
    if n < 40 {
        return Structure {
            structured: false,
            findings: vec!["too few steps with ground truth to test".into()],
            r2: 0.0,
        };
    }
    let coords = crate::estimation::periodic::coordinates(r, runs);
    let features = residual_features(r, runs, &feat, &coords);
    let mut findings = Vec::new();
    let mut worst = 0.0f64;
    let mut structured = false;
    for (c, cname) in chans.iter().enumerate() {
        let y: Vec<f64> = res.iter().map(|r| r[c]).collect();
        if y.iter().all(|v| *v == 0.0) {
            continue;
        }
        let mean = y.iter().sum::<f64>() / n as f64;
        let ss_tot: f64 = y.iter().map(|v| (v - mean).powi(2)).sum();
        let sd = (ss_tot / (n - 1) as f64).sqrt();
        if ss_tot <= 0.0 {
            continue;
        }
        let t = mean / (sd / (n as f64).sqrt());
        if t.abs() > 8.0 && mean.abs() > 0.25 * sd {
            structured = true;
            findings.push(format!("{cname} residual has a constant offset of {mean:.3e} ({:.1} sigma of its noise, t = {t:.0})", mean / sd));
        }
        let (best, eta2_max) = strongest_dependence(&y, mean, ss_tot, &features);
        worst = worst.max(eta2_max);
        if let Some((eta2, f, j, bin, bm)) = best {
            if eta2 > 0.05 && f > 20.0 {
                structured = true;
                // the regime where the channel's residual is largest
                let per = regimes_by_variance(&y, mean, &regimes);
                findings.push(format!(
                    "{cname} residual depends on the {} (explains {:.0}% of its variance, F = {f:.0}; strongest in the {} octile, mean {bm:+.2e}); largest in `{}`",
                    features[j].0,
                    100.0 * eta2,
                    ["lowest", "2nd", "3rd", "4th", "5th", "6th", "7th", "highest"][bin],
                    per[0].0
                ));
            }
        }
    }
    for (finding, eta2) in periodic_findings(&coords, &res, &chans) {
        structured = true;
        worst = worst.max(eta2);
        findings.push(finding);
    }
    Structure {
        structured,
        findings,
        r2: worst,
    }
}

/// What a step's residual may depend on, per step with ground truth: speed,
/// yaw rate, their product, heading, time, each absolute input's value (a
/// steering angle acts through it) and each wheel's angle within its
/// revolution where the revolution is known exactly.
fn residual_features(
    r: &Runner,
    runs: &[Run],
    feat: &[[f64; 6]],
    coords: &[crate::estimation::periodic::Coordinate],
) -> Vec<(String, Vec<f64>)> {
    let n = feat.len();
    // features per step: v, omega, v*omega (from feat = [v dt, w dt, v w dt, ...]), heading, time
    let mut heading = Vec::with_capacity(n);
    let mut time = Vec::with_capacity(n);
    for run in runs {
        if let Some(g) = &run.gt {
            for k in 0..run.steps() {
                heading.push(wrap(g[k][2]));
                time.push(run.t[k] - run.t[0]);
            }
        }
    }
    let per_dt = |j: usize| -> Vec<f64> { feat.iter().map(|f| f[j] / f[4].max(1e-12)).collect() };
    let mut features: Vec<(String, Vec<f64>)> = vec![
        ("speed".into(), per_dt(0)),
        ("yaw rate".into(), per_dt(1)),
        ("v*omega".into(), per_dt(2)),
        ("heading".into(), heading),
        ("time".into(), time),
    ];
    // absolute inputs (a steering angle) act through their value
    for (i, inp) in r.ir.inputs.iter().enumerate() {
        if inp.kind == kinegen_model::decl::InputKind::Absolute {
            let v = runs
                .iter()
                .filter(|run| run.gt.is_some())
                .flat_map(|run| (0..run.steps()).map(move |k| run.u[k][i]))
                .collect();
            features.push((format!("`{}` value", inp.name), v));
        }
    }
    // wheel angles within the revolution, where a revolution is known exactly
    for c in coords {
        if let [(_, rev)] = c.revolution_candidates.as_slice() {
            if c.unit == "rad" {
                let v = c.values.iter().map(|v| v.rem_euclid(*rev)).collect();
                features.push((format!("`{}` wheel angle within a revolution", c.name), v));
            }
        }
    }
    features
}

/// The feature whose octiles explain most of the variance of `y` (one-way
/// analysis of variance over 8 bins): (eta^2, F, feature, the bin whose mean
/// is farthest from `mean`, that bin's offset), and the largest eta^2 seen.
#[allow(clippy::type_complexity)]
fn strongest_dependence(
    y: &[f64],
    mean: f64,
    ss_tot: f64,
    features: &[(String, Vec<f64>)],
) -> (Option<(f64, f64, usize, usize, f64)>, f64) {
    let n = y.len();
    let mut worst = 0.0f64;
    let mut best: Option<(f64, f64, usize, usize, f64)> = None; // (eta2, F, feature, bin, bin mean)
    for (j, (_, fv)) in features.iter().enumerate() {
        let mut idx: Vec<usize> = (0..n).collect();
        idx.sort_by(|a, b| fv[*a].total_cmp(&fv[*b]));
        let bins = 8;
        let mut ss_b = 0.0;
        let mut means = Vec::new();
        for b in 0..bins {
            let part = &idx[b * n / bins..(b + 1) * n / bins];
            let m = part.iter().map(|&i| y[i]).sum::<f64>() / part.len().max(1) as f64;
            ss_b += part.len() as f64 * (m - mean).powi(2);
            means.push(m);
        }
        let eta2 = ss_b / ss_tot;
        let f = (ss_b / (bins - 1) as f64) / ((ss_tot - ss_b).max(1e-300) / (n - bins) as f64);
        worst = worst.max(eta2);
        let (bin, bm) = means.iter().enumerate().fold((0, 0.0f64), |acc, (b, m)| {
            if (m - mean).abs() > acc.1.abs() {
                (b, m - mean)
            } else {
                acc
            }
        });
        if best.as_ref().is_none_or(|x| eta2 > x.0) {
            best = Some((eta2, f, j, bin, bm));
        }
    }
    (best, worst)
}

/// The driving regimes with the residual's summed squares and step counts,
/// largest mean square first.
fn regimes_by_variance<'a>(
    y: &[f64],
    mean: f64,
    regimes: &[&'a str],
) -> Vec<(&'a str, f64, usize)> {
    let mut per: Vec<(&str, f64, usize)> = Vec::new();
    for i in 0..y.len() {
        match per.iter_mut().find(|e| e.0 == regimes[i]) {
            Some(e) => {
                e.1 += (y[i] - mean).powi(2);
                e.2 += 1
            }
            None => per.push((regimes[i], (y[i] - mean).powi(2), 1)),
        }
    }
    per.sort_by(|a, b| (b.1 / b.2 as f64).total_cmp(&(a.1 / a.2 as f64)));
    per
}

/// Explained over residual variance a sinusoid must reach to count: chi-square
/// with 2 degrees of freedom beyond about 1e-7 under white noise, after the
/// thousands of frequencies x channels x coordinates tried, with a factor 2 of
/// margin because one-step residuals from measured poses are not white (each
/// measurement's noise enters two neighbouring steps).
const PERIODIC_STAT: f64 = 80.0;
/// Smallest share of a channel's variance a periodic finding must explain (on
/// very long logs a negligible ripple is significant but not worth acting on).
const PERIODIC_ETA2: f64 = 0.002;

/// Most periodic findings reported (each found after removing the ones before).
const MAX_PERIODIC: usize = 3;

/// Sinusoids of a wheel's cumulative angle or of time in the one-step residuals,
/// for people, each with its share of its channel's variance. Greedy: the
/// strongest (coordinate, channel) is reported and its sinusoid removed before
/// looking again, so one out-of-round wheel is not reported a second time as a
/// weaker echo in the other wheel or in time (they move together).
fn periodic_findings(
    coords: &[crate::estimation::periodic::Coordinate],
    res: &[[f64; 4]],
    chans: &[&str; 4],
) -> Vec<(String, f64)> {
    let mut channels: Vec<Vec<f64>> = (0..4)
        .map(|ch| res.iter().map(|r| r[ch]).collect())
        .collect();
    let moving: Vec<Vec<usize>> = coords
        .iter()
        .map(|c| (0..res.len()).filter(|&i| c.moving[i]).collect())
        .collect();
    // (coordinate, period, channels, strongest peak) per finding
    let mut found: Vec<(usize, f64, Vec<usize>, crate::estimation::periodic::Peak)> = Vec::new();
    for _ in 0..MAX_PERIODIC {
        let best = coords
            .par_iter()
            .zip(&moving)
            .enumerate()
            .filter_map(|(ci, (c, idx))| {
                let coord: Vec<f64> = idx.iter().map(|&i| c.values[i]).collect();
                let ys: Vec<Vec<f64>> = channels
                    .iter()
                    .map(|y| idx.iter().map(|&i| y[i]).collect())
                    .collect();
                crate::estimation::periodic::scan(&coord, &ys)
                    .into_iter()
                    .enumerate()
                    .filter_map(|(ch, p)| p.map(|p| (ci, ch, p)))
                    .filter(|(_, _, p)| p.stat > PERIODIC_STAT && p.eta2 > PERIODIC_ETA2)
                    .max_by(|a, b| a.2.stat.total_cmp(&b.2.stat))
            })
            .max_by(|a, b| a.2.stat.total_cmp(&b.2.stat));
        let Some((ci, ch, p)) = best else { break };
        let c = &coords[ci];
        // the same cycle seen again (another channel, or what is left of it in
        // the same one) is one finding
        match found
            .iter_mut()
            .find(|f| f.0 == ci && (f.1 / p.period - 1.0).abs() < 0.05)
        {
            Some(f) if !f.2.contains(&ch) => f.2.push(ch),
            Some(_) => {}
            None => found.push((ci, p.period, vec![ch], p)),
        }
        let coord: Vec<f64> = moving[ci].iter().map(|&i| c.values[i]).collect();
        let mut y: Vec<f64> = moving[ci].iter().map(|&i| channels[ch][i]).collect();
        p.remove(&coord, &mut y);
        for (&i, v) in moving[ci].iter().zip(y) {
            channels[ch][i] = v;
        }
    }
    found
        .into_iter()
        .map(|(ci, _, chs, p)| {
            let names: Vec<&str> = chs.iter().map(|&c| chans[c]).collect();
            (
                format!(
                    "{} {} periodic: {} (amplitude {:.2e} in {}, {:.1}% of its variance, chi2 = {:.0})",
                    names.join(" and "),
                    if names.len() > 1 { "residuals are" } else { "residual is" },
                    crate::estimation::periodic::describe(&coords[ci], p.period),
                    p.amplitude,
                    names[0],
                    100.0 * p.eta2,
                    p.stat
                ),
                p.eta2,
            )
        })
        .collect()
}

/// Whether a candidate explains most of what the current model leaves above the
/// noise floor, in the fit and on held-out data: an effect small next to the
/// sensor noise (a 5% gyro scale under 3x noise lowers the error by 15%, to the
/// floor) is as real as a large one. Only when the current model leaves a clear
/// excess (its mean square 20% above the floor's). With `holdout_rmse` None,
/// only the fit's share is judged (see [`significant`]).
fn explains_excess(cur: &Stage, rmse: f64, holdout_rmse: Option<f64>) -> bool {
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
fn significant(cur: &Stage, rmse: f64, gain: f64, holdout_rmse: Option<f64>) -> bool {
    let improvement = 1.0 - rmse / cur.rmse;
    let large = improvement > 0.2 && holdout_rmse.is_none_or(|h| h < 0.8 * cur.holdout_rmse);
    evident(cur, rmse, gain) && (large || explains_excess(cur, rmse, holdout_rmse))
}

/// The evidence every significant effect needs: a BIC gain, and more
/// explained than the model's own discretisation could account for.
fn evident(cur: &Stage, rmse: f64, gain: f64) -> bool {
    let beyond_step = cur.rmse * cur.rmse - rmse * rmse > cur.step_error * cur.step_error;
    gain > 10.0 && beyond_step && rmse.is_finite()
}

/// The current model of a diagnosis step: its runner, calibration and scores.
struct Stage {
    runner: Runner,
    fit: FitResult,
    rmse: f64,
    bic: f64,
    holdout_rmse: f64,
    /// The error a model explaining every structure would reach (white noise).
    floor: f64,
    /// The model's own discretisation error at the log's rate (the base
    /// model's, see `crate::estimation::discretisation`), which no effect explains.
    step_error: f64,
    /// Its held-out error in each fold of the log's segments, computed when
    /// a candidate first needs it (see [`Folds::held_out`]).
    fold_errors: OnceLock<Vec<f64>>,
}

fn stage(
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
fn stage_from(
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

/// The significant candidates of a ranking that explain the logs as well as
/// its winner `w` (see [`ChainStep::equivalent`]): a likelihood ratio between
/// the two calibrated models below [`EQUIVALENT`] (chi-square, one degree of
/// freedom, 5%), the residual variance taken from the winner's own fit.
/// (Held-out errors were tried as a second test: the few rows at the start
/// of each held-out part, where a late command and a late motion capture do
/// differ, decided it by chance.)
fn ranked_equivalents(ranked: &[Candidate], w: &Candidate) -> Vec<String> {
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

/// One step of the chain found by sequential diagnosis.
#[derive(Debug, Clone, Serialize)]
pub struct ChainStep {
    pub effect: String,
    pub parameters: Estimates,
    /// Error (weighted residual RMS) after adding this effect and recalibrating.
    pub rmse_after: f64,
    pub doc: String,
    /// Other significant candidates these logs cannot tell apart from it:
    /// their fit's likelihood ratio to its own under [`EQUIVALENT`] (a late
    /// command and a late motion capture move a pose-only log alike).
    pub equivalent: Vec<String>,
    /// The fold-by-fold test, when it is what proved the effect.
    pub folds: Option<FoldTest>,
    /// For an effect of the range-bearing sensor, how it fits the sightings
    /// seen from the ground truth, which is what proved it (the motion's
    /// error, `rmse_after`, does not move).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub sightings: Option<SightingFit>,
}

/// The likelihood ratio (chi-square with one degree of freedom at 5%) under
/// which two candidates explain the logs equally (see [`ChainStep::equivalent`]).
pub const EQUIVALENT: f64 = 3.84;

/// The effects a diagnosis tries, and how it gets the spec with a list of
/// them added.
pub struct Catalogue<'a> {
    /// (name, doc) of every applicable effect, in catalogue order.
    pub effects: Vec<(String, String)>,
    pub chains: &'a EffectChains<'a>,
}

/// A diagnosis that cannot run.
#[derive(Debug, thiserror::Error)]
pub enum DiagnoseError {
    #[error("{run}: {rows} rows; diagnosis needs at least {MIN_ROWS} per run (it holds out the last 40% of each)")]
    TooFewRows { run: String, rows: usize },
    #[error(transparent)]
    Fit(#[from] FitError),
}

/// Whether an effect adds nothing the calibrated model cannot already do on
/// these logs: the residual Jacobian columns of its parameters lie in the span of
/// the free parameters' columns (checked on the data, at the current estimates).
/// Returns the reason when it is redundant.
pub fn redundancy(
    start: &Runner,
    effect_params: &[usize],
    runs: &[Run],
    o: &FitOptions,
) -> Option<String> {
    let o = &FitOptions {
        estimate_start: false,
        huber: None,
        ..o.clone()
    };
    // a bounded sample of the data is enough to see the span
    let mut sample = Vec::new();
    let mut steps = 0;
    for run in runs {
        if steps >= 4000 {
            break;
        }
        let end = (run.t.len()).min(4000 - steps + 1).max(3);
        sample.push(run.slice(0, end));
        steps += end;
    }
    let (_, jac) = residuals(start, &start.p, &start.free, &sample, o, true, &[]);
    let j = jac?;
    let base: Vec<usize> = (0..start.free.len())
        .filter(|c| !effect_params.contains(&start.free[*c]))
        .collect();
    let unit = |c: usize| {
        let col = j.column(c).into_owned();
        let n = col.norm();
        (n > 0.0).then(|| col / n)
    };
    let cols: Vec<(usize, DVector<f64>)> = base
        .iter()
        .filter_map(|&c| unit(c).map(|v| (c, v)))
        .collect();
    if cols.is_empty() {
        return None;
    }
    let b = nalgebra::DMatrix::from_columns(&cols.iter().map(|x| x.1.clone()).collect::<Vec<_>>());
    let svd = b.clone().svd(true, true);
    let mut reasons = Vec::new();
    for &pi in effect_params {
        let c = start.free.iter().position(|&f| f == pi)?;
        let Some(e) = unit(c) else {
            reasons.push(format!(
                "{} changes nothing these logs measure",
                start.names[pi]
            ));
            continue;
        };
        let x = svd.solve(&e, 1e-10).ok()?;
        let left = (&b * &x - &e).norm();
        if left > 1e-3 {
            return None;
        }
        let big = x.amax();
        let by: Vec<&str> = cols
            .iter()
            .zip(x.iter())
            .filter(|(_, v)| v.abs() > 0.1 * big)
            .map(|((c, _), _)| start.names[start.free[*c]].as_str())
            .collect();
        reasons.push(format!(
            "{} is a combination of the calibrated {}",
            start.names[pi],
            by.join(", ")
        ));
    }
    let kind = if reasons.iter().all(|r| r.contains("changes nothing")) {
        "not observable in these logs"
    } else {
        "redundant"
    };
    Some(format!(
        "{kind}: {} (residual Jacobian columns, {} samples)",
        reasons.join("; "),
        steps
    ))
}

/// The free parameters of an augmented runner that the current model lacks: the
/// ones its effect adds (indices into `aug`'s parameters).
fn effect_params(aug: &Runner, cur: &Runner) -> Vec<usize> {
    aug.free
        .iter()
        .copied()
        .filter(|&i| cur.param_index(&aug.names[i]).is_none())
        .collect()
}

/// [`FitOptions::cost_tolerance`] of the ranking's calibrations: 1e-6 of the
/// cost, a BIC gain known to about 0.05 where significance needs 10 (a
/// misspecified candidate's fit otherwise creeps on for dozens of passes).
const RANKING_TOLERANCE: f64 = 1e-6;

/// Error (weighted RMS) within this factor of the noise floor counts as
/// leaving only the noise (see [`rank`]).
const FLOOR_REACHED: f64 = 1.05;

/// Iterations a candidate's refinement from the current calibration gets
/// when searches from nominal values may follow (the first round): one that
/// has not arrived by then is creeping along a misspecified model's valley,
/// and the search gets there sooner. On 10,921-row omni_caster logs with a
/// steering offset of 40% of its bound, the refinement crept 68-98
/// iterations (1.5-2.8 s) to 7x the noise floor, where the search from
/// nominal values reached the floor in 12 (0.4 s).
const FIRST_ROUND_ITERATIONS: usize = 20;

/// Calibrate every candidate on top of `cur` and score it against it. With
/// `from_nominal`, each candidate is also calibrated from nominal values (a
/// global search); see the comment inside.
#[allow(clippy::too_many_arguments)]
fn rank(
    cur: &Stage,
    from_nominal: bool,
    augmented: &[(String, String, Runner)],
    runs: &[Run],
    train: &[Run],
    test: &[Run],
    folds: Option<&Folds>,
    clock: Option<&SightingClock>,
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
struct Ranking<'a> {
    cur: &'a Stage,
    runs: &'a [Run],
    train: &'a [Run],
    test: &'a [Run],
    /// The ranking tolerance, and the strict one a possible winner is polished with.
    o: &'a FitOptions,
    strict: &'a FitOptions,
    /// Whether candidates are also calibrated from nominal values.
    from_nominal: bool,
    /// The log's segments in folds, when it is long enough for them.
    folds: Option<&'a Folds>,
    /// The ground truth's lag behind the sightings, when the logs have both.
    clock: Option<&'a SightingClock>,
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
        let significant = (classic || folds.is_some_and(|t| t.holds())) && !contradicted;
        let parameters = estimates(&start, &effect_params, &f);
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
        });
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
fn estimates(r: &Runner, which: &[usize], f: &FitResult) -> Estimates {
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
fn may_hold(cur: &Stage, rmse: f64, gain: f64, holdout_rmse: f64) -> bool {
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
fn gyro_only(aug: &Runner, effect_params: &[usize]) -> bool {
    aug.only_observed_by(effect_params, YawRate)
}

/// A candidate's calibration before any search from nominal values.
struct Local {
    /// The calibration and its error.
    fit: Option<(FitResult, f64)>,
    /// The effect's global search from nominal values ran already.
    searched: bool,
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
fn local_refinement(
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

/// Whether a stage leaves nothing above the noise floor and its own
/// discretisation: no effect added to it can then be significant (it would
/// need most of an excess that is not there, or an error 20% below the white
/// noise), so the chain ends without another round (the last round of every
/// chain: 0.5 s of an omni_caster diagnosis whose second effect reached the
/// floor).
fn leaves_only_noise(cur: &Stage) -> bool {
    cur.rmse * cur.rmse <= cur.floor * cur.floor + cur.step_error * cur.step_error
}

/// The discretisation error of `stage`'s calibration at the log's rate (see
/// `crate::estimation::discretisation`).
fn step_error(stage: &Stage, runs: &[Run], o: &FitOptions) -> Discretisation {
    let mut d = crate::estimation::discretisation::estimate(
        &stage.runner,
        &stage.fit.p,
        &stage.fit.starts,
        runs,
        o,
    );
    // the asymptotic e(2h) = 4 e(h) overstates the error of a coarse log
    // (larger steps err faster than that); the step cannot leave more than
    // what the calibrated model leaves above the noise
    let excess = (stage.rmse * stage.rmse - stage.floor * stage.floor)
        .max(0.0)
        .sqrt();
    d.error = d.error.min(excess);
    d
}

/// Share of a chain stage's noise floor above which the step's error, as
/// estimated at an earlier stage, is estimated again at this one. A model
/// far off the log (a rover missing a 0.08 rad steering offset: error 230
/// against a floor of 13) gives a meaningless Richardson estimate (its fits
/// at the two rates differ for reasons of their own), capped only by its own
/// excess: 3.8, which then hid every further effect (a 0.1 s time offset)
/// of the stage that reached 1.5. Stages whose step's error is already small
/// next to their floor (every bench case) are not checked again.
const RECHECK_STEP: f64 = 0.5;

/// Fewest rows per run diagnosis accepts.
pub const MIN_ROWS: usize = 20;

/// Longest chain sequential diagnosis builds: more effects than this at once
/// are not told apart reliably by a log of ordinary length.
pub const MAX_CHAIN: usize = 3;

/// The sightings' clock on `runs` (see [`super::clock`]) through the base
/// model's calibration, or why it was not measured; and what it says of the
/// measurement delay the spec itself declares, as calibrated.
fn read_clock(
    first: &Stage,
    runs: &[Run],
) -> (
    Option<SightingClock>,
    Option<Unmeasured>,
    Option<ClockVerdict>,
) {
    let (clock, unmeasured) = match super::clock::measure(&first.runner, &first.fit.p, runs) {
        Some(Ok(c)) => (Some(c), None),
        Some(Err(why)) => (None, Some(why)),
        None => (None, None),
    };
    let spec = clock.zip(first.runner.delay).and_then(|(c, _)| {
        c.judge(
            0.0,
            crate::model_on_log::timeline::delay(&first.runner, &first.fit.p),
        )
    });
    (clock, unmeasured, spec)
}

/// Effects (or anything) by name, with a text: a doc, a reason.
type Named = Vec<(String, String)>;

/// The effects of `remaining` to rank on top of `cur` (with the chain
/// `names` found so far), each with its runner. Left out: those the
/// calibrated parameters already express on these logs and those that do
/// not derive, said in `skipped` (in the first round only), and those only
/// the range-bearing sensor reads, collected in `sensor` for the sensor's
/// own chain (see [`super::sensor`]).
fn to_rank(
    cur: &Stage,
    names: &[String],
    remaining: &[(String, String)],
    cat: &Catalogue,
    runs: &[Run],
    o: &FitOptions,
    (skipped, sensor): (&mut Named, &mut Named),
) -> Vec<(String, String, Runner)> {
    let first_round = names.is_empty();
    let mut augmented = Vec::new();
    for (name, doc) in remaining {
        let mut list = names.to_vec();
        list.push(name.clone());
        match cat.chains.runner(&list).map_err(|e| e.to_string()) {
            Ok(aug) => {
                let start = seeded(&aug, &cur.runner, &cur.fit.p);
                let effect_params = effect_params(&start, &cur.runner);
                if sensor_only(&start, &effect_params) {
                    if first_round {
                        sensor.push((name.clone(), doc.clone()));
                    }
                    continue;
                }
                match redundancy(&start, &effect_params, runs, o) {
                    Some(why) if first_round => skipped.push((name.clone(), why)),
                    Some(_) => {}
                    None => augmented.push((name.clone(), doc.clone(), aug)),
                }
            }
            Err(why) if first_round => skipped.push((name.clone(), why)),
            Err(_) => {}
        }
    }
    augmented
}

/// The sensor's diagnosis after the motion's (see [`super::sensor`]): its
/// first round's candidates, or why it did not run, and the final model.
struct SensorOutcome {
    candidates: Vec<SensorCandidate>,
    unmeasured: Option<SensorUnmeasured>,
    runner: Runner,
    p: Vec<f64>,
}

/// Test the range-bearing sensor's `effects` on top of the motion's final
/// stage `cur`, appending the ones found to `chain` (the motion's error does
/// not move with them: they are proved on the sightings).
fn sensor_chain(
    cur: Stage,
    runs: &[Run],
    effects: &[(String, String)],
    chains: &EffectChains,
    chain: &mut Vec<ChainStep>,
) -> SensorOutcome {
    let unchanged = |unmeasured| SensorOutcome {
        candidates: vec![],
        unmeasured,
        runner: cur.runner.clone(),
        p: cur.fit.p.clone(),
    };
    if effects.is_empty() {
        return unchanged(None);
    }
    let motion: Vec<String> = chain.iter().map(|c| c.effect.clone()).collect();
    match diagnose_sensor(&cur.runner, &cur.fit.p, runs, effects, chains, &motion) {
        Ok(sd) => {
            chain.extend(sd.found.iter().map(|c| ChainStep {
                effect: c.effect.clone(),
                parameters: c.parameters.clone(),
                rmse_after: cur.rmse,
                doc: c.doc.clone(),
                equivalent: vec![],
                folds: None,
                sightings: Some(c.fit.clone()),
            }));
            SensorOutcome {
                candidates: sd.candidates,
                unmeasured: None,
                runner: sd.runner,
                p: sd.p,
            }
        }
        Err(why) => unchanged(Some(why)),
    }
}

/// The stage after `w` won a round ranked from `augmented`: the ranking
/// calibrated the winner already, on all runs and on the training part.
/// Its step error is the current stage's until it is measured again.
fn winner_stage(
    cur: &Stage,
    augmented: &[(String, String, Runner)],
    w: &Candidate,
    runs: &[Run],
    test: &[Run],
    o: &FitOptions,
) -> Stage {
    let (_, _, aug) = augmented
        .iter()
        .find(|a| a.0 == w.effect)
        .expect("ranked from augmented");
    let mut runner = aug.clone();
    runner.p = w.fit.p.clone();
    Stage {
        step_error: cur.step_error,
        ..stage_from(runner, w.fit.clone(), w.train_fit.clone(), runs, test, o)
    }
}

impl ChainStep {
    /// The chain's step for a round's winner `w`, with the candidates the
    /// logs cannot tell apart from it.
    fn won(w: &Candidate, equivalent: Vec<String>) -> ChainStep {
        ChainStep {
            effect: w.effect.clone(),
            parameters: w.parameters.clone(),
            rmse_after: w.rmse,
            doc: w.doc.clone(),
            equivalent,
            folds: w.folds.filter(|_| w.by_folds()),
            sightings: None,
        }
    }
}

/// Run the diagnosis: calibrate the base model, rank every applicable effect,
/// add the best significant one, re-test the rest on the augmented model, and
/// repeat until nothing is significant. `skipped` collects effects not tested,
/// with the reason (redundant on these logs, not derivable...).
///
/// `progress` is called with a step's name after each calibration (from worker
/// threads), for a progress bar.
pub fn diagnose(
    base: &Runner,
    runs: &[Run],
    cat: &Catalogue,
    mut skipped: Vec<(String, String)>,
    progress: &(dyn Fn(&str) + Sync),
) -> Result<Diagnosis, DiagnoseError> {
    // Beside a ground truth the sightings measure the sensor, not the motion
    // (fit sees them from the truth's pose): they are the sensor's chain's
    // to judge ([`super::sensor`]). In the motion's cost they only moved
    // `sensor_offset`'s range-bearing half, which then stood in for a camera
    // reading depth (named first on a simulated robot whose camera does).
    // Without a ground truth they are the motion's only pose information.
    let o = FitOptions {
        use_landmarks: runs
            .iter()
            .any(|r| r.gt.is_none() && !r.landmarks.is_empty()),
        ..FitOptions::default()
    };
    if let Some(r) = runs.iter().find(|r| r.t.len() < MIN_ROWS) {
        return Err(DiagnoseError::TooFewRows {
            run: r.name.clone(),
            rows: r.t.len(),
        });
    }
    let baseline_rmse = weighted_rms(base, &base.p, runs, &o);
    let (train, test) = split(runs, 0.6);
    let folds = Folds::of(runs);
    let first = stage(base.clone(), runs, &train, &test, &o)?;
    progress("base model calibrated");
    let (clock, clock_unmeasured, spec_clock) = read_clock(&first, runs);
    let mut disc = step_error(&first, runs, &o);
    let first = Stage {
        step_error: disc.error,
        ..first
    };
    let (calibrated_rmse, base_fit, base_holdout_rmse) =
        (first.rmse, first.fit.clone(), first.holdout_rmse);
    let mut noise_floor = first.floor;

    let mut cur = first;
    let mut chain: Vec<ChainStep> = Vec::new();
    let mut first_candidates: Option<Vec<Candidate>> = None;
    let mut remaining: Vec<(String, String)> = cat.effects.clone();
    let mut sensor_effects: Vec<(String, String)> = Vec::new();
    while chain.len() < MAX_CHAIN
        && !remaining.is_empty()
        && (chain.is_empty() || !leaves_only_noise(&cur))
    {
        let names: Vec<String> = chain.iter().map(|c| c.effect.clone()).collect();
        let first_round = (&mut skipped, &mut sensor_effects);
        let augmented = to_rank(&cur, &names, &remaining, cat, runs, &o, first_round);
        let ranked = rank(
            &cur,
            chain.is_empty(),
            &augmented,
            runs,
            &train,
            &test,
            folds.as_ref(),
            clock.as_ref(),
            &o,
            progress,
        );
        let winner = ranked.first().filter(|c| c.significant).cloned();
        let equivalent = winner
            .as_ref()
            .map(|w| ranked_equivalents(&ranked, w))
            .unwrap_or_default();
        if first_candidates.is_none() {
            first_candidates = Some(ranked);
        }
        let Some(w) = winner else { break };
        let mut next = winner_stage(&cur, &augmented, &w, runs, &test, &o);
        if next.step_error > RECHECK_STEP * next.floor {
            disc = step_error(&next, runs, &o);
            (next.step_error, noise_floor) = (disc.error, next.floor);
        }
        chain.push(ChainStep::won(&w, equivalent));
        remaining.retain(|(n, _)| n != &w.effect);
        cur = next;
    }
    let structure = whiteness(&cur.runner, &cur.fit.p, runs);
    let sensor = sensor_chain(cur, runs, &sensor_effects, cat.chains, &mut chain);
    progress("sensor effects tested");
    Ok(Diagnosis {
        baseline_rmse,
        calibrated_rmse,
        base_fit,
        base_holdout_rmse,
        candidates: first_candidates.unwrap_or_default(),
        chain,
        structure,
        discretisation: disc,
        noise_floor,
        skipped,
        clock,
        clock_unmeasured,
        spec_clock,
        sensor_candidates: sensor.candidates,
        sensor_unmeasured: sensor.unmeasured,
        final_runner: sensor.runner,
        final_p: sensor.p,
    })
}
