//! Whether the residuals a model leaves are noise or still structured:
//! one-step prediction residuals regressed on the motion (speed, turn rate,
//! regimes) and searched for periodic errors (an out-of-round wheel), and
//! the signature an effect's parameter leaves in them (what the report
//! draws). [`super::diagnose`] ranks effects; this module says what is left.
use crate::logs::log::wrap;
use crate::model_on_log::interp::lerp_rows;
use crate::model_on_log::model::Runner;
use crate::model_on_log::run::Run;
use kinegen_model::decl::ObservationRole::{Pose, YawRate};
use kinegen_model::ir::StepForm;

use super::stage::seeded;
use rayon::prelude::*;
use serde::Serialize;

#[derive(Debug, Clone, Serialize)]
pub struct Structure {
    pub structured: bool,
    /// Where the structure lives (channel, feature, regime), for people.
    pub findings: Vec<String>,
    pub r2: f64,
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
